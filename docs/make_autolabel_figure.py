"""Draw docs/autolabel.jpg for the README (*Labels without people*): `freespace autolabel` next to the
human label, on a real KITTI stereo 2015 frame and on a rendered frame.

    .venv/bin/python docs/make_autolabel_figure.py [SHARED_DATA] [--frame 000000_10]

SHARED_DATA is the shared real samples folder (default ../shared/data beside the checkout); the KITTI frame
is read from SHARED_DATA/kitti_stereo_2015 (image_2/, image_3/, disp_occ_0/, road_mask/). Layout:

- KITTI, three rows of two panels: the left image and its human road label; the autolabel from the LiDAR
  disparity (disp_occ_0) and its confidence; the autolabel from SGBM on the stereo pair and its confidence;
- rendered (frame 0 of the `rendered test` set of bench/autolabel.py), one row of four panels: the left
  image, the renderer's label, the autolabel from the renderer's exact disparity, its confidence.

Overlays: road green, non-road red, don't care grey (unshaded, desaturated). Confidence: 0 (don't care)
black, 0.5…1 dark to bright. Precision, recall and coverage are measured as in bench/autolabel.py (road
class on the pixels the autolabel labels; coverage = share of the human label's pixels it labels).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from freespace.data.synthetic import SynthConfig, render_sample
from freespace.datagen.autolabel import autolabel
from freespace.evaluation.viz import caption, grid
from freespace.geometry import compute_disparity
from freespace.io.codecs import read_disparity, read_image, read_road_label
from freespace.io.files import atomic_write_bytes
from freespace.labels import RoadLabel

ROOT = Path(__file__).resolve().parent.parent
KITTI_BASELINE = 0.54  # metres, KITTI 2015's rig (no calibration comes with the shared frames)
WIDTH = 1200  # pixels, the whole figure


def label_overlay(image: np.ndarray, label: RoadLabel, alpha: float = 0.45) -> np.ndarray:
    """``image`` (H×W×3 uint8 RGB) with road tinted green, non-road red and don't care in grey."""
    out = image.astype(np.float32)
    grey = out.mean(axis=2, keepdims=True)
    out = np.where(label.valid[..., None], out, 0.6 * grey + 40)
    for mask, colour in ((label.road & label.valid, (0, 255, 0)), (~label.road & label.valid, (255, 40, 40))):
        out[mask] = out[mask] * (1 - alpha) + np.array(colour, np.float32) * alpha
    return np.clip(out, 0, 255).astype(np.uint8)


def confidence_map(confidence: np.ndarray) -> np.ndarray:
    """``float H×W`` confidence in [0, 1] → H×W×3 uint8 RGB: 0 (don't care) black, labelled pixels (≥ 0.5)
    on the viridis map from dark to bright."""
    scaled = np.rint(np.clip((confidence - 0.5) * 2, 0, 1) * 255).astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(scaled, cv2.COLORMAP_VIRIDIS), cv2.COLOR_BGR2RGB)
    rgb[confidence <= 0] = 0
    return rgb


def scores(auto: RoadLabel, human: RoadLabel) -> str:
    """Precision and recall of the road class on the pixels both labels evaluate, and coverage (the share
    of the human label's evaluated pixels the autolabel labels), as ``"P .. R .. cov .."`` (percent)."""
    covered = auto.valid & human.valid
    tp = np.count_nonzero(auto.road & human.road & covered)
    precision = 100 * tp / max(1, np.count_nonzero(auto.road & covered))
    recall = 100 * tp / max(1, np.count_nonzero(human.road & covered))
    coverage = 100 * np.count_nonzero(covered) / max(1, np.count_nonzero(human.valid))
    return f"P {precision:.1f} R {recall:.1f} cov {coverage:.1f} %"


def panel(image: np.ndarray, width: int, text: str) -> np.ndarray:
    """``image`` resized to ``width`` pixels (aspect kept), then captioned (so the text stays legible)."""
    size = (width, round(image.shape[0] * width / image.shape[1]))
    return caption(cv2.resize(image, size, interpolation=cv2.INTER_AREA), text)


def kitti_rows(root: Path, frame: str) -> list[list[np.ndarray]]:
    """Three rows of two panels for KITTI stereo 2015 frame ``frame`` (see the module docstring)."""
    name = f"{frame}.png"
    left, right = read_image(root / "image_2" / name), read_image(root / "image_3" / name)
    human = read_road_label(root / "road_mask" / name)
    w = WIDTH // 2
    rows = [[panel(left, w, f"KITTI 2015 {frame}, left image"),
             panel(label_overlay(left, human), w, "human label (road_mask)")]]
    for source, disparity in (("LiDAR disp_occ_0", read_disparity(root / "disp_occ_0" / name)),
                              ("SGBM", compute_disparity(left, right))):
        result = autolabel(disparity, baseline=KITTI_BASELINE)
        rows.append([panel(label_overlay(left, result.label), w, f"autolabel, {source}: {scores(result.label, human)}"),
                     panel(confidence_map(result.confidence), w, f"confidence, {source} (black: don't care)")])
    return rows


def rendered_row() -> list[np.ndarray]:
    """One row of four panels for frame 0 of bench/autolabel.py's rendered test set (exact disparity)."""
    s = render_sample(0, 0, SynthConfig(width=320, height=240, frames_per_scenario=5))
    result = autolabel(s.disparity, baseline=s.calibration.baseline)
    w = WIDTH // 4
    return [panel(s.left, w, f"rendered {s.name}"), panel(label_overlay(s.left, s.label), w, "renderer's label"),
            panel(label_overlay(s.left, result.label), w, f"auto, exact: {scores(result.label, s.label)}"),
            panel(confidence_map(result.confidence), w, "confidence (black: don't care)")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("shared", nargs="?", type=Path, default=ROOT.parent / "shared" / "data",
                        help="the shared real samples folder (default ../shared/data beside the checkout)")
    parser.add_argument("--frame", default="000000_10", help="the KITTI stereo 2015 frame (default 000000_10)")
    parser.add_argument("--quality", type=int, default=85, help="JPEG quality (default 85)")
    args = parser.parse_args()
    root = args.shared / "kitti_stereo_2015"
    needed = [root / sub / f"{args.frame}.png" for sub in ("image_2", "image_3", "disp_occ_0", "road_mask")]
    missing = [str(p) for p in needed if not p.is_file()]
    if missing:
        sys.exit(f"error: {missing[0]} not found; give the shared data folder that holds kitti_stereo_2015/ "
                 f"(e.g. python docs/make_autolabel_figure.py /work/shared/data) and a frame it has (--frame)")
    cv2.setNumThreads(1)
    figure = grid([*kitti_rows(root, args.frame), rendered_row()])
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(figure, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, args.quality])
    assert ok, "OpenCV could not encode a JPEG"
    out = atomic_write_bytes(Path(__file__).resolve().parent / "autolabel.jpg", buf.tobytes())
    print(f"{out} ({figure.shape[1]}×{figure.shape[0]}, {len(buf) // 1024} KB)")


if __name__ == "__main__":
    main()
