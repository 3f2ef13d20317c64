"""Shifted copies of KITTI's frames of other streets: the development frames as two cameras the models never saw
would show them, a stand-in for the issue's unseen places (labels for measuring only, as ever).

- ``washed``: contrast halved towards a light grey and a bluish haze: ``0.35 + 0.5 · rgb · (0.9, 1.0, 1.1)``;
- ``dark``: gamma 1.8 and a warm cast: ``rgb^1.8 · (1.15, 0.95, 0.8)`` (clipped to [0, 1]).

Each copy is a folder laid out as ``real_dev/make.sh``'s ``DEST``: ``OUT/<shift>/kitti_dev/images`` (the shifted
frames, PNG) and ``kitti_dev/masks`` (the human masks, copied), so that ``errors.py --real-dev OUT/<shift>`` scores
models on it.

    python studies/real-roads/shifted.py --real-dev DEV --out DIR
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import cv2
import numpy as np

#: each shift: an RGB image in [0, 1] → the shifted one
SHIFTS = {"washed": lambda rgb: 0.35 + 0.5 * rgb * np.array([0.9, 1.0, 1.1]),
          "dark": lambda rgb: rgb ** 1.8 * np.array([1.15, 0.95, 0.8])}


def shift(image: np.ndarray, name: str) -> np.ndarray:
    """``image`` (``H×W×3 uint8`` BGR, as OpenCV reads it) under the shift ``name`` of :data:`SHIFTS`, BGR uint8."""
    rgb = image[:, :, ::-1].astype(np.float64) / 255.0
    out = np.clip(SHIFTS[name](rgb), 0.0, 1.0)
    return np.round(out[:, :, ::-1] * 255.0).astype(np.uint8)


def write_shifted(real_dev: Path, out: Path) -> int:
    """Write every shift's copy of ``real_dev/kitti_dev`` under ``out`` (a new folder); the number of frames."""
    images, masks = real_dev / "kitti_dev" / "images", real_dev / "kitti_dev" / "masks"
    frames = sorted(images.glob("*.png"))
    if not frames or not masks.is_dir():
        raise ValueError(f"{real_dev} holds no kitti_dev/images/*.png and kitti_dev/masks: lay the development sets "
                         f"out with shared/data/real_dev/make.sh")
    if out.exists():
        raise ValueError(f"{out} exists: choose a new folder")
    part = out.with_name(out.name + ".part")
    shutil.rmtree(part, ignore_errors=True)
    for name in SHIFTS:
        (part / name / "kitti_dev" / "images").mkdir(parents=True)
        shutil.copytree(masks, part / name / "kitti_dev" / "masks")
        for frame in frames:
            image = cv2.imread(str(frame), cv2.IMREAD_COLOR)
            if image is None:
                raise ValueError(f"{frame} is not a readable image")
            cv2.imwrite(str(part / name / "kitti_dev" / "images" / frame.name), shift(image, name))
    part.rename(out)
    return len(frames)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real-dev", type=Path, required=True, help="the development sets (real_dev/make.sh's DEST)")
    ap.add_argument("--out", type=Path, required=True, help="a new folder")
    a = ap.parse_args()
    if a.out.resolve().is_relative_to(a.real_dev.resolve()):
        ap.error(f"--out {a.out} lies inside --real-dev {a.real_dev}: write the copies elsewhere")
    try:
        n = write_shifted(a.real_dev, a.out)
    except ValueError as exc:
        ap.error(str(exc))
    print(f"{n} frames in each of {', '.join(SHIFTS)} → {a.out}")


if __name__ == "__main__":
    main()
