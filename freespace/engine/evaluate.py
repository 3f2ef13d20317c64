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

from freespace.data.base import get_dataset
from freespace.data.splits import read_splits
from freespace.errors import DatasetError, InputFileError, InvalidOptionError
from freespace.io import PathLike, write_image, write_json
from freespace.metrics import RoadEvaluator
from freespace.predictor import Predictor
from freespace.viz import overlay_errors, write_pr_curve

__all__ = ["evaluate_checkpoint"]


def _frames(ds, split: str, checkpoint: Path, splits_dir: PathLike | None) -> list[str]:
    labelled = [f.name for f in ds.frames if f.label is not None]
    if split == "all":
        return labelled
    folder = Path(splits_dir) if splits_dir else checkpoint.parent.parent / "splits"
    if not (folder / f"{split}.txt").is_file():
        raise InputFileError(f"no split lists at {folder}; give --splits DIR (train.txt, val.txt, test.txt) or --split all")
    return read_splits(folder, known=[f.name for f in ds.frames])[split]


def evaluate_checkpoint(checkpoint: PathLike, dataset: str, root: PathLike, out: PathLike, split: str = "test",
                        splits_dir: PathLike | None = None, on_disk_split: str | None = None,
                        progress: bool = True) -> dict[str, Any]:
    """Evaluate ``checkpoint`` on ``split`` (train/val/test from the run's lists, or all) of a dataset."""
    if split not in ("train", "val", "test", "all"):
        raise InvalidOptionError(f"--split must be train, val, test or all, got {split!r}")
    checkpoint, out = Path(checkpoint), Path(out)
    predictor = Predictor(checkpoint=checkpoint)
    ds = get_dataset(dataset, root, on_disk_split, disparity="none")
    names = _frames(ds, split, checkpoint, splits_dir)
    if not names:
        raise DatasetError(f"split {split!r} has no labelled frames")
    from tqdm import tqdm

    evaluator, seconds = RoadEvaluator(), 0.0
    for name in tqdm(names, desc="evaluate", unit="frame", disable=not progress):
        sample = ds.load(ds.index(name), right=False, disparity=False)
        t0 = time.perf_counter()
        prob = predictor.predict([sample.left])[0]
        seconds += time.perf_counter() - t0
        label = sample.label
        evaluator.process(prob, label.road, label.valid)
        pred = prob >= evaluator.threshold
        write_image(out / "overlays" / f"{name}.png", overlay_errors(sample.left, pred, label.road, label.valid))
    scores = evaluator.evaluate()
    metrics = {**{k: scores[k] for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap")},
               "seconds_per_frame": seconds / len(names), "frames": len(names), "split": split,
               "checkpoint": str(checkpoint)}
    write_pr_curve(out / "pr_curve.png", *evaluator.kitti.pr_curve())
    write_json(out / "metrics.json", metrics)
    return metrics
