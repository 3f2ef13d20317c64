"""Real-frame evaluation of the real-roads study's cells (issue 45).

    python studies/real-roads/evaluate.py RUN [RUN ...]     # writes RUN/real.json for each run folder
    python studies/real-roads/evaluate.py --rendered TREE RUN [RUN ...]   # also RUN/rendered.json
    python studies/real-roads/evaluate.py --table RUNS      # the variants' table (Markdown) from RUNS/*/real.json

Each run's best checkpoint predicts the real labelled frames of ``freespace/evaluation/real_frames.py`` at full
resolution (the network at its training size, the probabilities upsampled; road where p ≥ 0.5). Full-mask frames:
precision, recall, F and IoU per frame and pooled over the frames' pixels; polygon frames: recall inside the polygon. A
frame the run trained or validated on (its ``splits/train.txt``/``val.txt``) is left out and named.

``--rendered TREE`` also scores the run on every frame of a rendered tree (``freespace synth``'s KITTI road
layout; the study uses the converged run's ``same-rigs``: 200 frames of 40 drives, 416×320): F at p ≥ 0.5 and
the KITTI MaxF from counts summed over the frames, in ``RUN/rendered.json``. For the R-auto variants these
frames are out of domain; for S they are the domain it trained on.

The table gives, per network and variant, the mean over seeds with its 95 % t-interval (n − 1 degrees of
freedom; ``n`` seeds), and the paired gains of every variant over S, of HA-R-auto and S+R-auto over R-auto,
of HA-R-auto over R-auto-dup, and of the -fp variants (mirror and colour jitter) over their bases, one
difference per seed (the cells of a seed share the seed; the paired interval is
:func:`freespace.experiments.stats.paired_gain`'s).
"""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

VARIANT_TAGS = {"s": "S", "r-auto": "R-auto", "ha-r-auto": "HA-R-auto", "r-auto-dup": "R-auto-dup",
                "s_r-auto": "S+R-auto", "r-auto-fp": "R-auto-fp", "s_r-auto-fp": "S+R-auto-fp"}
_RUN = re.compile(r"(?P<model>[a-z0-9]+(?:-\d+x\d+)?)-(?P<tag>[a-z_-]+)-s(?P<seed>\d+)$")
THRESHOLD = 0.5


def _seen(run: Path) -> set[str]:
    """Frame names the run trained or validated on, in the real frames' spelling (``<drive>/<frame>``)."""
    names: set[str] = set()
    for part in ("train", "val"):
        path = run / "splits" / f"{part}.txt"
        if path.is_file():
            for name in path.read_text().split():
                names.add(name)
                m = re.match(r"(.+_sync)-(\d+)$", name)  # the S+R-auto dataset's spelling
                if m:
                    names.add(f"{m.group(1)}/{m.group(2)}")
    return names


def evaluate(run: Path) -> dict:
    """Measure ``run``'s best checkpoint on the real frames; return (and write to ``run/real.json``) the
    per-frame figures, the pooled full-mask figures and the frames left out."""
    from freespace.evaluation.metrics import Counts, confusion_counts
    from freespace.evaluation.real_frames import available
    from freespace.inference.predictor import Predictor
    from freespace.io.codecs import read_image
    from freespace.io.files import atomic_write_text

    predictor = Predictor(checkpoint=run / "checkpoints" / "best.ckpt")
    seen = _seen(run)
    frames, left_out, pooled = {}, [], Counts()
    for frame in available():
        if frame.name in seen:
            left_out.append(frame.name)
            continue
        prob = predictor.predict([read_image(frame.image)])[0]
        pred = prob >= THRESHOLD
        if frame.kind == "mask":
            counts = confusion_counts(pred, frame.road)
            pooled = pooled + counts
            frames[frame.name] = {"kind": "mask", **{k: v for k, v in counts.metrics().items() if k != "accuracy"}}
        else:
            frames[frame.name] = {"kind": "polygon", "recall": float(pred[frame.road].mean())}
    if not frames:  # no figure at all: never write the scores of an empty set (F = 1 of no pixel)
        why = (f"all {len(left_out)} are in its splits/train.txt or val.txt" if left_out else
               "none is here: put the KITTI stereo 2015 frames under FREESPACE_SHARED_DATA, or give "
               "FREESPACE_KITTI_RAW=DIR for the raw frames")
        raise SystemExit(f"evaluate.py: error: no real frame to evaluate {run} on ({why}); nothing written")
    masks = any(v["kind"] == "mask" for v in frames.values())
    result = {"checkpoint": str(run / "checkpoints" / "best.ckpt"), "threshold": THRESHOLD, "frames": frames,
              "pooled_masks": {k: (v if masks else math.nan) for k, v in pooled.metrics().items() if k != "accuracy"},
              "left_out": left_out}
    atomic_write_text(run / "real.json", json.dumps(result, indent=2) + "\n")
    return result


def evaluate_rendered(run: Path, tree: Path) -> dict:
    """Measure ``run``'s best checkpoint on every frame of the rendered tree ``tree``; return (and write to
    ``run/rendered.json``) F at p ≥ 0.5, the MaxF and the number of frames."""
    from freespace.evaluation.labelled import pair_labelled_frames, parse_label_format
    from freespace.evaluation.metrics import RoadEvaluator
    from freespace.inference.predictor import Predictor
    from freespace.io.files import atomic_write_text

    training = tree / "data_road" / "training"
    if not (training / "image_2").is_dir() or not any((training / "image_2").glob("*.png")):
        raise SystemExit(f"--rendered {tree}: no data_road/training/image_2 frames; give a `freespace synth` tree")
    kitti = parse_label_format("kitti")
    predictor = Predictor(checkpoint=run / "checkpoints" / "best.ckpt")
    evaluator = RoadEvaluator()  # F and MaxF from the counts summed over the frames, at each image's own size
    for frame in pair_labelled_frames(training / "image_2", training / "gt_image_2", kitti):
        image, label = frame.read(kitti)
        evaluator.process(predictor.predict([image])[0], label.road, label.valid)
    scores = evaluator.evaluate()
    result = {"checkpoint": str(run / "checkpoints" / "best.ckpt"), "tree": str(tree), "threshold": THRESHOLD,
              "f": scores["f_score"], "max_f": scores["max_f"], "images": scores["images"]}
    atomic_write_text(run / "rendered.json", json.dumps(result, indent=2) + "\n")
    return result


def _interval(values: list[float]) -> str:
    """``mean [low, high]`` in points (×100) with the 95 % t-interval; the mean alone for one value; ``—`` for
    none (NaN values, a figure some runs lack, are left out, and the figure then says over how many runs it is:
    ``(n = k)``, so that the row's seed count is not read as its)."""
    from scipy import stats

    x = 100 * np.asarray([v for v in values if not math.isnan(v)])
    if len(x) == 0:
        return "—"
    n = f" (n = {len(x)})" if len(x) < len(values) else ""
    if len(x) < 2:
        return f"{x.mean():.1f}{n}"
    half = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x))
    return f"{x.mean():.1f} [{x.mean() - half:.1f}, {x.mean() + half:.1f}]{n}"


def _figures(result: dict) -> dict[str, float]:
    frames = result["frames"]
    masks = [v for v in frames.values() if v["kind"] == "mask"]
    polygons = [v["recall"] for v in frames.values() if v["kind"] == "polygon"]
    out = {f"F {name}": v["f_score"] for name, v in frames.items() if v["kind"] == "mask"}
    out["mean F (masks)"] = float(np.mean([v["f_score"] for v in masks])) if masks else float("nan")
    out.update({f"pooled {k}": result["pooled_masks"][k] for k in ("precision", "recall", "f_score", "iou")})
    out["polygon recall"] = float(np.mean(polygons)) if polygons else float("nan")
    return out


def table(runs: Path) -> str:
    """The Markdown table of every ``runs/<model>-<tag>-s<seed>/real.json``."""
    from freespace.experiments.stats import paired_gain

    cells: dict[tuple[str, str], dict[int, dict[str, float]]] = {}
    for path in sorted(runs.glob("*/real.json")):
        m = _RUN.match(path.parent.name)
        if m is None or m.group("tag") not in VARIANT_TAGS:
            continue
        key = (m.group("model"), VARIANT_TAGS[m.group("tag")])
        figures = _figures(json.loads(path.read_text()))
        rendered = path.parent / "rendered.json"
        figures["F rendered"] = json.loads(rendered.read_text())["f"] if rendered.is_file() else float("nan")
        cells.setdefault(key, {})[int(m.group("seed"))] = figures
    if not cells:
        raise SystemExit(f"no run folder with real.json under {runs}")
    columns = list(next(iter(next(iter(cells.values())).values())))
    lines = ["| network | variant | seeds | " + " | ".join(columns) + " |", "|---|---|---:|" + "---:|" * len(columns)]
    for (model, variant), seeds in sorted(cells.items()):
        row = [_interval([s[c] for s in seeds.values()]) for c in columns]
        lines.append(f"| {model} | {variant} | {len(seeds)} | " + " | ".join(row) + " |")
    lines += ["", "Paired gains (points, mean [95 % t-interval], one difference per seed):", "",
              "| network | gain | seeds | mean F (masks) | pooled F | polygon recall | F rendered |",
              "|---|---|---:|---:|---:|---:|---:|"]
    for model in sorted({m for m, _ in cells}):
        pairs = [(v, "S") for v in ("R-auto", "HA-R-auto", "R-auto-dup", "S+R-auto")] + [
            ("HA-R-auto", "R-auto-dup"), ("HA-R-auto", "R-auto"), ("S+R-auto", "R-auto"), ("R-auto-fp", "R-auto"),
            ("S+R-auto-fp", "S+R-auto"), ("S+R-auto-fp", "R-auto")]
        for a, b in pairs:
            if (model, a) not in cells or (model, b) not in cells:
                continue
            seeds = sorted(set(cells[model, a]) & set(cells[model, b]))
            if not seeds:
                continue
            row = []
            for c in ("mean F (masks)", "pooled f_score", "polygon recall", "F rendered"):
                g = paired_gain([100 * cells[model, a][s][c] for s in seeds],
                                [100 * cells[model, b][s][c] for s in seeds])
                row.append("—" if np.isnan(g.mean) else f"{g.mean:+.1f}" if g.n < 2 else
                           f"{g.mean:+.1f} [{g.ci_low:+.1f}, {g.ci_high:+.1f}]")
            lines.append(f"| {model} | {a} − {b} | {len(seeds)} | " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="*", type=Path, help="run folders to evaluate")
    ap.add_argument("--table", type=Path, metavar="RUNS", help="print the table of RUNS/*/real.json")
    ap.add_argument("--rendered", type=Path, metavar="TREE", help="also score each run on this rendered tree "
                    "(RUN/rendered.json)")
    a = ap.parse_args()
    if not a.table and not a.runs:
        ap.error("give run folders to evaluate, or --table RUNS")
    if a.table:
        print(table(a.table), end="")
    for run in a.runs:
        figures = _figures(evaluate(run))
        if a.rendered:
            figures["F rendered"] = evaluate_rendered(run, a.rendered)["f"]
        print(run.name, json.dumps(figures))


if __name__ == "__main__":
    main()
