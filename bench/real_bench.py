"""The real test bench (issue 61): every road model on every real labelled set, pooled scores with intervals.

    .venv/bin/python bench/real_bench.py --real-dev DIR [--shared DIR] [--model NAME=PATH ...] [--threads N]
        [--out bench/out/real_bench.json] [--write-benchmarks]

``--real-dev``: the development sets laid out by ``shared/data/real_dev/make.sh`` (``kitti_dev/``, ``camvid/``);
``--shared``: the shared samples (default ``../shared/data``: the two KITTI stereo 2015 frames with full road masks
and the drawn road polygons of :mod:`freespace.evaluation.real_frames`). A set whose files are absent is skipped and
said so.
``--model``: ``NAME=PATH`` of an ONNX model or a training checkpoint, repeatable; default: every published model
(``models/*/model.onnx``). Always scored beside them: **mean mask**, a fixed road mask fitted on the set's labels,
leave-one-out: each frame against the per-pixel mean of the set's *other* labels, thresholded at 0.5 — a reference
that knows where road usually lies in that camera's frames and nothing else (a model below it has learnt less about
the set than that). ``--kitti-raw``: a KITTI raw root with drive 0000 for its polygon (``$FREESPACE_KITTI_RAW``).

Sets (the labels are for measuring only; never train on them):

=================  ======  ============================================================================
set                frames  labels
=================  ======  ============================================================================
``kitti2015``      2       KITTI stereo 2015 ``000000_10``, ``000001_10``: full road masks (binary)
``kitti_dev``      22      KITTI semantics frames of other streets (1536×512, Cityscapes palette: road
                           (128, 64, 128), within 8 levels)
``camvid_val``     101     CamVid ``val``: another city and camera (480×360, class ids: road 3, void 11
                           don't care)
``camvid_dusk``    62      CamVid's dusk drive ``0001TP`` (frames of ``train``; their labels ``duskannot``)
``camvid_pool``    163     ``camvid_val`` and ``camvid_dusk`` pooled: the CamVid development pool
``polygons``       6       recall inside conservative drawn road polygons (``freespace/evaluation/real_frames.py``)
=================  ======  ============================================================================

Each set's figures: pooled precision, recall, F and IoU (counts summed over its frames, p ≥ 0.5) with a 95 %
frame-level percentile bootstrap interval of F (2000 resamples). Frames of one video are correlated, so the
interval is a lower bound on the uncertainty of a *place*: it says how much the figure depends on which of these
frames were drawn, not how it would move on another street. Writes the JSON to ``--out`` and a markdown table
beside it (``.md``), and BENCHMARKS.md's section *Real test bench* with ``--write-benchmarks``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, machine, write_section  # noqa: E402
from freespace.evaluation.labelled import (  # noqa: E402
    LabelFormat,
    PooledScores,
    pair_labelled_frames,
    parse_label_format,
)
from freespace.io.codecs import read_image  # noqa: E402


@dataclass(frozen=True)
class LabelledSet:
    """A labelled folder of the bench: images and labels relative to a root (``real_dev`` or ``shared``)."""

    name: str
    root: str
    images: str
    labels: str
    label_format: LabelFormat


SETS = (
    LabelledSet("kitti2015", "shared", "kitti_stereo_2015/image_2", "kitti_stereo_2015/road_mask",
                parse_label_format("binary")),
    LabelledSet("kitti_dev", "real_dev", "kitti_dev/images", "kitti_dev/masks",
                parse_label_format("palette", "128,64,128")),
    LabelledSet("camvid_val", "real_dev", "camvid/val", "camvid/valannot", parse_label_format("class-id", "3", "11")),
    LabelledSet("camvid_dusk", "real_dev", "camvid/train", "camvid/duskannot",
                parse_label_format("class-id", "3", "11")),
)
#: pooled sets: name → the sets whose frames they pool
POOLS = {"camvid_pool": ("camvid_val", "camvid_dusk")}
MEAN_MASK = "mean mask"


def mean_mask_scores(frames: list[tuple[str, Any]], size: tuple[int, int] = (256, 256)) -> PooledScores:
    """The leave-one-out mean mask's per-frame counts: each frame is scored against the per-pixel mean of the
    *other* frames' road labels (each resized to ``size``, the mean resized to the frame's, road where ≥ 0.5)."""
    import cv2

    from freespace.evaluation.metrics import confusion_counts

    labels = [load()[1] for _, load in frames]
    roads = [cv2.resize(lab.road.astype(np.float32), size[::-1], interpolation=cv2.INTER_AREA) for lab in labels]
    total, scores = np.sum(roads, axis=0), PooledScores()
    for (name, _), label, road in zip(frames, labels, roads):
        mean = (total - road) / max(len(roads) - 1, 1)
        h, w = label.shape
        pred = cv2.resize(mean, (w, h), interpolation=cv2.INTER_LINEAR) >= 0.5
        scores.add(name, confusion_counts(pred, label.road, label.valid))
    return scores


def _frames(s: LabelledSet, roots: dict[str, Path]) -> list[tuple[str, Any]]:
    root = roots[s.root]
    frames = pair_labelled_frames(root / s.images, root / s.labels, s.label_format)
    return [(f.name, partial(f.read, s.label_format)) for f in frames]


def score_set(predictor: Any, frames: list[tuple[str, Any]]) -> PooledScores:
    """Per-frame counts of ``predictor`` on ``frames`` (name, loader) — freespace evaluate's scoring."""
    from freespace.inference.evaluate import score_frames

    return score_frames(predictor, frames)[1]


def polygon_recall(predictor: Any) -> dict[str, Any] | None:
    """Recall inside the drawn road polygons (pooled over the polygons' pixels; mean over frames), or None."""
    from freespace.evaluation import real_frames

    frames = [f for f in real_frames.available() if f.kind == "polygon"]
    if not frames:
        return None
    hits = total = 0
    per = []
    for f in frames:
        prob = predictor.predict([read_image(f.image)])[0]
        inside = prob[f.road] >= 0.5
        hits, total = hits + int(inside.sum()), total + int(f.road.sum())
        per.append(float(inside.mean()))
    return {"recall": hits / total, "mean_recall": float(np.mean(per)), "frames": len(frames)}


def _summary(scores: PooledScores) -> dict[str, Any]:
    return {**scores.summary(), "per_frame": scores.rows}


def _predictor(path: Path, threads: int | None) -> Any:
    from freespace.inference.predictor import Predictor

    return Predictor(onnx=path, threads=threads) if path.suffix == ".onnx" else Predictor(checkpoint=path)


def run(models: dict[str, Path], roots: dict[str, Path], threads: int | None) -> dict[str, Any]:
    """Every model (and the mean mask) on every set whose files are here → ``{set: {model: figures}}``."""
    frames, skipped = {}, []
    for s in SETS:
        if (roots[s.root] / s.labels).is_dir():
            frames[s.name] = _frames(s, roots)
        else:
            skipped.append(s.name)
    results: dict[str, Any] = {name: {} for name in [*frames, *POOLS, "polygons"]}
    for model, path in models.items():
        predictor, t0 = _predictor(path, threads), time.perf_counter()
        for name, fr in frames.items():
            results[name][model] = _summary(score_set(predictor, fr))
        results["polygons"][model] = polygon_recall(predictor)
        print(f"{model}: {time.perf_counter() - t0:.1f} s", flush=True)
    for name, fr in frames.items():
        results[name][MEAN_MASK] = _summary(mean_mask_scores(fr))
    for pool, parts in POOLS.items():
        if all(p in frames for p in parts):
            for model in models:
                pooled = PooledScores([r for p in parts for r in results[p][model]["per_frame"]])
                results[pool][model] = _summary(pooled)
            results[pool][MEAN_MASK] = _summary(mean_mask_scores([f for p in parts for f in frames[p]]))
    return {"sets": {k: v for k, v in results.items() if v and any(x is not None for x in v.values())},
            "skipped": skipped, "models": {k: str(v) for k, v in models.items()}, "machine": machine()}


def markdown(res: dict[str, Any]) -> str:
    """The bench's table: one row per model and set (F points with their interval; precision, recall, IoU)."""
    lines = ["| set | frames | model | F [95 % bootstrap] | precision | recall | IoU |",
             "|---|---:|---|---|---:|---:|---:|"]
    for name, by_model in res["sets"].items():
        for model, r in by_model.items():
            if r is None:
                continue
            if name == "polygons":
                lines.append(f"| polygons | {r['frames']} | {model} | — | — | {100 * r['recall']:.1f} (inside) | — |")
                continue
            ci = r["intervals"] and r["intervals"]["f_score"]  # None below two scored frames: no interval
            interval = f"[{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]" if ci else "[no interval: 1 frame]"
            lines.append(f"| {name} | {r['frames']} | {model} | **{100 * r['f_score']:.1f}** {interval} | "
                         f"{100 * r['precision']:.1f} | {100 * r['recall']:.1f} | {100 * r['iou']:.1f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--real-dev", type=Path, required=True, help="the development sets (real_dev/make.sh's DEST)")
    p.add_argument("--shared", type=Path, default=Path(os.environ.get("FREESPACE_SHARED_DATA")
                                                       or ROOT.parent / "shared" / "data"))
    p.add_argument("--kitti-raw", type=Path, help="a KITTI raw root (drive 0000's polygon frame)")
    p.add_argument("--model", action="append", default=[], metavar="NAME=PATH")
    p.add_argument("--threads", type=int)
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "out" / "real_bench.json")
    p.add_argument("--write-benchmarks", action="store_true")
    args = p.parse_args(argv)
    if args.kitti_raw:
        os.environ["FREESPACE_KITTI_RAW"] = str(args.kitti_raw)  # read by real_frames at import
    if not args.real_dev.is_dir():
        p.error(f"--real-dev {args.real_dev} is not a folder; lay the sets out with shared/data/real_dev/make.sh")
    models = dict(m.split("=", 1) for m in args.model) if args.model else {
        f.parent.name: f for f in sorted((ROOT / "models").glob("*/model.onnx"))}
    models = {k: Path(v) for k, v in models.items()}
    res = run(models, {"real_dev": args.real_dev, "shared": args.shared}, args.threads)
    table = markdown(res)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(res, indent=1))
    args.out.with_suffix(".md").write_text(table + "\n")
    print(table)
    if args.write_benchmarks:
        write_section("Real test bench", f"{res['machine']}. `python bench/real_bench.py --real-dev DIR "
                                         f"--write-benchmarks` (issue 61).\n\n{table}\n\n{BENCH_NOTE}")
    return 0


BENCH_NOTE = ("F, precision, recall and IoU in points, pooled over each set's frames (summed pixel counts, p ≥ 0.5); "
              "the interval is a frame-level bootstrap (frames of one drive are correlated: it is narrower than the "
              "uncertainty of another street). *mean mask*: the mean of the set's own labels thresholded at 0.5 "
              "(leave-one-out: each frame against the mean of the set's other labels, thresholded at 0.5). The labels "
              "are for measuring only.")

if __name__ == "__main__":
    raise SystemExit(main())
