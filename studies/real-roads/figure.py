"""The real-roads page's pictures (issue 45), from the study's run folders.

    python studies/real-roads/figure.py --runs RUNS --seed 0 --out docs/real_roads.jpg
    python studies/real-roads/figure.py --views RUN --raw RAW --autolabels AL --out docs/real_views.jpg

``--runs``: one row per variant (its ``<model>-<tag>-s<seed>`` cell), the two KITTI stereo 2015 frames with the
variant's mask coloured against the human mask (true positive green, false negative red, false positive blue;
F in the caption). ``--views``: for two training frames of a HA-R-auto run, the left image, its autolabel
(road magenta, non-road red, don't care black) and the DS-Generator view made from the real right image.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

WIDTH = 620  # pixels per picture: two KITTI frames side by side stay legible at ~1240 px


def variant_rows(runs: Path, seed: int, model: str) -> np.ndarray:
    from evaluate import THRESHOLD, VARIANT_TAGS
    from freespace.evaluation.metrics import confusion_counts
    from freespace.evaluation.real_frames import available
    from freespace.evaluation.viz import caption, grid, overlay_errors
    from freespace.inference.predictor import Predictor
    from freespace.io.codecs import read_image

    frames = [f for f in available() if f.kind == "mask"]
    images = [read_image(f.image) for f in frames]
    rows = [[caption(im, f"{f.name}: image") for f, im in zip(frames, images)]]
    for tag, variant in VARIANT_TAGS.items():
        run = runs / f"{model}-{tag}-s{seed}"
        if not (run / "checkpoints" / "best.ckpt").is_file():
            continue
        probs = Predictor(checkpoint=run / "checkpoints" / "best.ckpt").predict(images)
        row = []
        for f, im, p in zip(frames, images, probs):
            pred = p >= THRESHOLD
            score = confusion_counts(pred, f.road).metrics()["f_score"]
            row.append(caption(overlay_errors(im, pred, f.road), f"{variant}: F {100 * score:.1f}"))
        rows.append(row)
    return grid(rows, width=WIDTH)


def view_rows(run: Path, raw: Path, autolabels: Path, count: int = 2) -> np.ndarray:
    from freespace.evaluation.viz import caption, grid
    from freespace.io.codecs import read_image

    views = sorted((run / "generated").glob("*_sync/*.png"))
    picks = [views[i] for i in np.linspace(0, len(views) - 1, count).round().astype(int)]
    drives = {p.name: p for p in raw.rglob("*_drive_*_sync") if p.is_dir()}
    rows = []
    for view in picks:
        drive, frame = view.parent.name, view.stem
        left = read_image(drives[drive] / "image_02" / "data" / f"{frame}.png")
        label = read_image(autolabels / drive / f"{frame}.png")
        rows.append([caption(left, f"{drive[-9:-5]}/{frame[-3:]}: left"), caption(label, "autolabel"),
                     caption(read_image(view), "DS-Generator view (right image)")])
    return grid(rows, width=WIDTH * 2 // 3)


def main() -> None:
    from freespace.io.codecs import write_image

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=Path)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--model", default="unet")
    ap.add_argument("--views", type=Path, metavar="RUN")
    ap.add_argument("--raw", type=Path)
    ap.add_argument("--autolabels", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args()
    picture = variant_rows(a.runs, a.seed, a.model) if a.runs else view_rows(a.views, a.raw, a.autolabels)
    write_image(a.out, picture)
    print(f"{picture.shape[1]}×{picture.shape[0]} → {a.out}")


if __name__ == "__main__":
    main()
