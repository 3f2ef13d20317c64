"""A copy of a generic training dataset whose frames of one camera are padded, left and right, to another aspect:
the CamVid frames (480×360, 4:3) of the real-roads mix at KITTI's aspect (1242/375), so that resizing every frame
to the training size keeps their proportions instead of squeezing them vertically (session 35's ``mixpad``); with
``--cut-top F``, every frame (image and label) also loses its top ``round(F × H)`` rows first — the region of
interest that ``predict --crop-top F`` feeds a network.

The padding is black in the image and don't care (black) in the label; frames left as they are, the subset lists
and ``freespace.yaml`` are linked, not copied. Refuses an ``--out`` that exists or lies inside ``--root``.

    python studies/real-roads/padded.py --root MIX --out MIXPAD [--prefix camvid-] [--aspect 3.312] [--cut-top F]
"""

from __future__ import annotations

import argparse
import os
import shutil
from pathlib import Path

import cv2
import numpy as np

from freespace.limits import MAX_CROP_TOP

#: KITTI's frame aspect (1242×375)
KITTI_ASPECT = 1242 / 375


def pad_to_aspect(image: np.ndarray, aspect: float) -> np.ndarray:
    """``image`` (``H×W`` or ``H×W×C``, any dtype) with zero columns added equally left and right (the odd one on the
    right) so that its width over height is ``aspect`` (rounded to a pixel); an image already as wide is returned
    as it is."""
    h, w = image.shape[:2]
    extra = int(round(h * aspect)) - w
    if extra <= 0:
        return image
    left = extra // 2
    widths = ((0, 0), (left, extra - left)) + ((0, 0),) * (image.ndim - 2)
    return np.pad(image, widths)


def build(root: Path, out: Path, prefix: str, aspect: float, cut_top: float = 0.0) -> dict[str, int]:
    """Lay out ``out`` from the generic dataset ``root`` (``left/``, ``label/``, ``splits/``, ``freespace.yaml``):
    every frame without its top ``round(cut_top × H)`` rows, and those whose name starts with ``prefix`` padded to
    ``aspect`` (0: none); frames left as they are linked → counts of written and linked frames."""
    counts = {"written": 0, "linked": 0}
    for sub in ("left", "label"):
        (out / sub).mkdir(parents=True)
        for path in sorted((root / sub).iterdir()):
            pad = aspect > 0 and path.name.startswith(prefix)
            if not pad and cut_top == 0:
                os.symlink(path.resolve(), out / sub / path.name)
                counts["linked"] += sub == "left"
                continue
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if image is None:
                raise ValueError(f"{path} is not an image: rebuild {root}")
            image = image[int(round(cut_top * image.shape[0])):]
            cv2.imwrite(str(out / sub / path.name), pad_to_aspect(image, aspect) if pad else image)
            counts["written"] += sub == "left"
    for name in ("splits", "freespace.yaml"):
        if (root / name).exists():
            os.symlink((root / name).resolve(), out / name)
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, required=True, help="a generic dataset (left/, label/, splits/)")
    ap.add_argument("--out", type=Path, required=True, help="the padded copy (a new folder)")
    ap.add_argument("--prefix", default="camvid-", help="pad the frames whose name starts with this")
    ap.add_argument("--aspect", type=float, default=KITTI_ASPECT, help="width over height after padding (0: none)")
    ap.add_argument("--cut-top", type=float, default=0.0, metavar="F",
                    help=f"also cut the top F of every frame's height (image and label) first; in [0, {MAX_CROP_TOP})")
    args = ap.parse_args()
    if not (args.root / "left").is_dir() or not (args.root / "label").is_dir():
        ap.error(f"{args.root} has no left/ and label/: give a generic dataset's root")
    if args.out.exists():
        ap.error(f"{args.out} exists: give a new folder")
    if args.out.resolve().is_relative_to(args.root.resolve()):
        ap.error(f"{args.out} lies inside {args.root}: give a folder outside it")
    if args.aspect < 0:
        ap.error(f"--aspect {args.aspect} must be positive (0: no padding)")
    if not 0 <= args.cut_top < MAX_CROP_TOP:
        ap.error(f"--cut-top {args.cut_top} must be in [0, {MAX_CROP_TOP})")
    tmp = args.out.with_name(args.out.name + ".partial")
    if tmp.exists():
        ap.error(f"{tmp} exists (an interrupted run?): remove it")
    try:
        counts = build(args.root, tmp, args.prefix, args.aspect, args.cut_top)
    except ValueError as err:
        shutil.rmtree(tmp)
        ap.exit(1, f"padded.py: {err}\n")
    tmp.rename(args.out)
    print(f"padded.py: {counts['written']} frames written (aspect {args.aspect:.3f}, top {args.cut_top} cut), "
          f"{counts['linked']} linked → {args.out}")


if __name__ == "__main__":
    main()
