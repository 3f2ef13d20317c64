"""Where a network trained on autolabels goes wrong (issue 22 §3): the errors of X, X-auto and X-mix on a test
set, split by what the autolabel says about each pixel of the test frames.

The autolabel of a test frame (`freespace autolabel` on its SGBM disparity, as the training autolabels of
X-auto and X-mix were made) puts every pixel the human label evaluates into one class:

- `road`, `non-road`: the autolabel labels it; training on autolabels saw pixels like it with that label;
- `don't care, no disparity`: SGBM gave no disparity there (the matcher's empty left margin, occlusions);
- `don't care, ambiguous`: a disparity, but the residual is too close to the threshold or the row too far
  for a curb to show (near the horizon);
- `no label`: the frame's road plane was not found, so the whole frame is don't care.

The networks never got a training signal on pixels like the last three. For each class the table gives its
share of the evaluated pixels, its share of human road, and each variant's false road (FP: predicted road on
human non-road) and missed road (FN), in ‰ of all evaluated pixels (they add up over the classes), at the
probability threshold 0.5, summed over the frames and averaged over the seeds.

Runs come from a `reproduce` folder (`WORK/RES/runs/<net>-<orig|auto|mix>-s<seed>/`, with their
checkpoints), for example the converged run's working folder (studies/converged/run.sh). The test frames
are autolabelled with the SGBM of the package that runs the script: to classify them as the training autolabels
were made, run it with the package the cells' autolabels came from (the converged run's `autolabels`: SGBM
version 1, `PYTHONPATH=` a worktree at f341a7f):

    {env}.venv/bin/python bench/autolabel_training.py --work WORK [--res res-final] [--net unet] [--seeds 3,4]
                                                 [--set same-rigs] [--write]

`--write` puts the table into BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import freespace.geometry.stereo as stereo  # noqa: E402
from _common import machine, write_section  # noqa: E402
from freespace.data import get_dataset  # noqa: E402
from freespace.datagen.autolabel import autolabel  # noqa: E402
from freespace.errors import RoadFitError  # noqa: E402
from freespace.inference.predictor import Predictor  # noqa: E402
from freespace.io.codecs import read_road_label  # noqa: E402

CLASSES = ("road", "non-road", "don't care, no disparity", "don't care, ambiguous", "no label")
VARIANTS = {"X": "orig", "X-auto": "auto", "X-mix": "mix"}


def pixel_classes(ds, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(class index H×W into CLASSES, human road H×W bool, human valid H×W bool) of one frame."""
    sample = ds.load(index)
    road, valid = sample.label.road, sample.label.valid
    disparity = sample.disparity
    calib = sample.calibration
    classes = np.full(road.shape, CLASSES.index("no label"), np.uint8)
    try:
        auto = autolabel(disparity, baseline=calib.baseline if calib is not None and calib.baseline > 0 else None)
    except RoadFitError:
        return classes, road, valid
    has_disparity = np.isfinite(disparity) & (disparity > 0)
    classes[:] = np.where(has_disparity, CLASSES.index("don't care, ambiguous"),
                          CLASSES.index("don't care, no disparity"))
    classes[auto.label.valid & auto.label.road] = CLASSES.index("road")
    classes[auto.label.valid & ~auto.label.road] = CLASSES.index("non-road")
    return classes, road, valid


def training_labels(work: Path) -> str:
    """How the autolabels of the training set (``WORK/autolabels``, all of ``WORK/syn``'s frames) cover each
    quarter of the image rows, against the human labels: a markdown table."""
    ds = get_dataset("synth", work / "syn", disparity_source="none")
    counts = np.zeros((4, 4))  # row quarter × (auto road, auto non-road, don't care on human road, on non-road)
    for frame in ds.labelled().frames:
        auto = read_road_label(work / "autolabels" / f"{frame.name}.png")
        human = ds.load(ds.index(frame.name), right=False, disparity=False).label
        h = human.road.shape[0]
        kinds = [auto.valid & auto.road, auto.valid & ~auto.road, ~auto.valid & human.road, ~auto.valid & ~human.road]
        for q in range(4):
            rows = slice(q * h // 4, (q + 1) * h // 4)
            counts[q] += [(k[rows] & human.valid[rows]).sum() for k in kinds]
    lines = ["| image rows | autolabel road % | autolabel non-road % | don't care, human road % | "
             "don't care, human non-road % |", "|---|---:|---:|---:|---:|"]
    for q, name in enumerate(("top quarter", "second quarter", "third quarter", "bottom quarter")):
        lines.append(f"| {name} | " + " | ".join(f"{100 * c / counts[q].sum():.1f}" for c in counts[q]) + " |")
    return "\n".join(lines)


def checkpoint(run: Path) -> Path:
    """The checkpoint a reproduce run was tested with (its best epoch's)."""
    found = sorted(run.glob("checkpoints/best*.ckpt"))
    if not found:
        raise SystemExit(f"no checkpoints/best*.ckpt in {run}; run the cell first (its checkpoints stay in WORK)")
    return found[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, required=True, help="the reproduce run's working folder")
    parser.add_argument("--res", default="res-final")
    parser.add_argument("--net", default="unet")
    parser.add_argument("--seeds", default="3")
    parser.add_argument("--set", default="same-rigs", help="a test set folder in WORK (synth layout)")
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]

    ds = get_dataset("synth", args.work / args.set, disparity_source="sgbm")
    frames = [f.name for f in ds.labelled().frames]
    print(f"{len(frames)} frames of {args.set}: autolabelling from SGBM", flush=True)
    frame_classes = [pixel_classes(ds, ds.index(name)) for name in frames]
    share = np.zeros(len(CLASSES))
    human_road = np.zeros(len(CLASSES))
    for classes, road, valid in frame_classes:
        share += np.bincount(classes[valid], minlength=len(CLASSES))
        human_road += np.bincount(classes[valid & road], minlength=len(CLASSES))
    total = share.sum()

    errors = {v: np.zeros((2, len(CLASSES))) for v in VARIANTS}  # FP, FN per class, summed over seeds
    f_scores: dict[str, list[float]] = {v: [] for v in VARIANTS}
    for seed in seeds:
        for variant, tag in VARIANTS.items():
            predictor = Predictor(checkpoint=checkpoint(args.work / args.res / "runs" / f"{args.net}-{tag}-s{seed}"))
            tp = fp = fn = 0
            for name, (classes, road, valid) in zip(frames, frame_classes):
                pred = predictor.predict([ds.load(ds.index(name), right=False, label=False,
                                                  disparity=False).left])[0] >= 0.5
                wrong_road, missed = pred & ~road & valid, ~pred & road & valid
                errors[variant][0] += np.bincount(classes[wrong_road], minlength=len(CLASSES))
                errors[variant][1] += np.bincount(classes[missed], minlength=len(CLASSES))
                tp, fp, fn = tp + int((pred & road & valid).sum()), fp + int(wrong_road.sum()), fn + int(missed.sum())
            f_scores[variant].append(200 * tp / (2 * tp + fp + fn))
            print(f"seed {seed} {variant}: F {f_scores[variant][-1]:.2f}", flush=True)

    per_mille = {v: 1000 * e / (total * len(seeds)) for v, e in errors.items()}
    head = " | ".join(f"{v} FP ‰ | {v} FN ‰" for v in VARIANTS)
    rows = [f"| autolabel class | pixels % | human road % | {head} |",
            "|---|---:|---:|" + "---:|" * (2 * len(VARIANTS))]
    for i, name in enumerate(CLASSES):
        cells = " | ".join(f"{per_mille[v][0, i]:.1f} | {per_mille[v][1, i]:.1f}" for v in VARIANTS)
        rows.append(f"| {name} | {100 * share[i] / total:.1f} | {100 * human_road[i] / max(share[i], 1):.1f} | "
                    f"{cells} |")
    cells = " | ".join(f"{per_mille[v][0].sum():.1f} | {per_mille[v][1].sum():.1f}" for v in VARIANTS)
    rows.append(f"| **all** | 100 | {100 * human_road.sum() / total:.1f} | {cells} |")
    f_line = ", ".join(f"{v} {np.mean(f):.2f}" for v, f in f_scores.items())
    table = "\n".join(rows)
    coverage = training_labels(args.work)
    print(table)
    print(coverage)
    print(f"F at threshold 0.5 (mean over seeds {args.seeds}): {f_line}")
    version = getattr(stereo, "SGBM_VERSION", 1)
    # the package the test frames were autolabelled with: version 1 is the converged run's pinned commit
    env = "PYTHONPATH=WORKTREE " if version == 1 else ""
    if args.write:
        write_section("Where training on autolabels goes wrong", f"""
`{args.net}` (EfficientNet-Lite0, ImageNet) of the converged run, seeds {args.seeds}, on `{args.set}`
({len(frames)} frames): false road (FP) and missed road (FN) in ‰ of the evaluated pixels, split by the class
the autolabel of each test frame (SGBM version {version}{", the package of a git worktree WORKTREE at f341a7f" if env
else ""}; the training autolabels in `WORK/autolabels` are version 1) gives the pixel. F at threshold 0.5: {f_line}. \
Machine: {machine()}.

    {env}.venv/bin/python bench/autolabel_training.py --work WORK --net {args.net} --seeds {args.seeds} \
--set {args.set} --write

{table}

The training autolabels (`WORK/autolabels`, the 100 frames of `syn`), by quarter of the image rows:

{coverage}
""")


if __name__ == "__main__":
    main()
