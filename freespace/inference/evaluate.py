"""`freespace evaluate`: a trained checkpoint on a dataset split — metrics, overlays, PR curve.

Predictions are made at the checkpoint's training size and resized back (bilinear probabilities) to
each frame's own size, where the metrics are counted (the benchmark's way). Outputs in ``OUT``:
``metrics.json`` (accuracy, precision, recall, f_score, iou at p ≥ 0.5; max_f, ap from the 256
thresholds; seconds per frame), ``overlays/<frame>.png`` (TP green, FN red, FP blue) and ``pr_curve.png``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from freespace.data.base import StereoRoadDataset
from freespace.data.registry import get_dataset
from freespace.data.splits import read_splits
from freespace.errors import DatasetError, InputFileError, InvalidOptionError, param
from freespace.evaluation.metrics import RoadEvaluator
from freespace.evaluation.viz import overlay_errors, write_pr_curve
from freespace.inference.predictor import Predictor
from freespace.io.codecs import write_image
from freespace.io.files import PathLike, check_outputs, check_writable, write_json
from freespace.io.outdir import claim_folder

__all__ = ["evaluate_checkpoint", "evaluate_frames"]


def _frames(ds, subset: str, checkpoint: Path, splits_dir: PathLike | None) -> list[str]:
    if subset == "all":
        return [f.name for f in ds.labelled()]
    folder = Path(splits_dir) if splits_dir else checkpoint.parent.parent / "splits"
    if not (folder / f"{subset}.txt").is_file():
        raise InputFileError(f"no split lists at {folder}; give {param('splits_dir')} DIR (train.txt, val.txt, "
                             f"test.txt) or {param('subset')} all")
    return read_splits(folder, known=[f.name for f in ds.frames])[subset]


def evaluate_frames(predictor: Predictor, ds: StereoRoadDataset, names: list[str], *, overlays: Path | None = None,
                    progress: bool = False) -> tuple[RoadEvaluator, float]:
    """Predict the named labelled frames of ``ds`` and count them at each frame's own size.

    Returns the filled :class:`RoadEvaluator` and the seconds spent in the network; with ``overlays``,
    writes ``<overlays>/<frame>.png`` (TP green, FN red, FP blue) too.
    """
    from freespace.runtime.log import progress_bar

    evaluator, seconds = RoadEvaluator(), 0.0
    for name in progress_bar(names, desc="evaluate", unit="frame", enabled=progress):
        sample = ds.load(ds.index(name), right=False, disparity=False)
        t0 = time.perf_counter()
        prob = predictor.predict([sample.left])[0]
        seconds += time.perf_counter() - t0
        label = sample.label
        evaluator.process(prob, label.road, label.valid)
        if overlays is not None:
            write_image(overlays / f"{name}.png",
                        overlay_errors(sample.left, prob >= evaluator.threshold, label.road, label.valid))
    return evaluator, seconds


def evaluate_checkpoint(checkpoint: PathLike, dataset: str, root: PathLike, out: PathLike, subset: str = "test",
                        splits_dir: PathLike | None = None, split: str | None = None,
                        progress: bool = True) -> dict[str, Any]:
    """Evaluate ``checkpoint`` on ``subset`` (train/val/test from the run's lists, or all labelled frames) of
    the on-disk ``split`` of a dataset."""
    if subset not in ("train", "val", "test", "all"):
        raise InvalidOptionError(f"{param('subset')} must be train, val, test or all, got {subset!r}")
    checkpoint, out = Path(checkpoint), Path(out)
    check_writable(out, folder=True)
    check_outputs({"out": out}, {"checkpoint": checkpoint, "root": root})
    predictor = Predictor(checkpoint=checkpoint)
    ds = get_dataset(dataset, root, split, disparity_source="none")
    names = _frames(ds, subset, checkpoint, splits_dir)
    if not names:
        raise DatasetError(f"subset {subset!r} has no labelled frames")
    with claim_folder(out, "evaluate") as folder, folder.staged() as staging:  # all or nothing
        evaluator, seconds = evaluate_frames(predictor, ds, names, overlays=staging / "overlays", progress=progress)
        scores = evaluator.evaluate()
        metrics = {**{k: scores[k] for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap")},
                   "seconds_per_frame": seconds / len(names), "frames": len(names), "split": subset,
                   "checkpoint": str(checkpoint)}
        write_pr_curve(staging / "pr_curve.png", *evaluator.kitti.pr_curve())
        write_json(staging / "metrics.json", metrics)
    return metrics
