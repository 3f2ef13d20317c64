"""`freespace evaluate`: a trained checkpoint on a dataset split — metrics, overlays, PR curve.

Predictions are made at the checkpoint's training size and resized back (bilinear probabilities) to
each frame's own size, where the metrics are counted (the benchmark's way). Outputs in ``OUT``:
``metrics.json`` (accuracy, precision, recall, f_score, iou at p ≥ 0.5; max_f, ap from the 256
thresholds; seconds per frame), ``overlays/<frame>.png`` (TP green, FN red, FP blue) and ``pr_curve.png``.
"""

from __future__ import annotations

import pickle
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from freespace.data.registry import get_dataset
from freespace.data.splits import read_splits
from freespace.errors import CorruptFileError, DatasetError, InputFileError, InvalidOptionError
from freespace.io import PathLike, write_image, write_json
from freespace.metrics import Counts, KittiCounts, confusion_counts, kitti_counts, kitti_scores
from freespace.models import SegmentationModel, create_model
from freespace.viz import overlay_errors

__all__ = ["load_checkpoint", "evaluate_checkpoint"]


def load_checkpoint(path: PathLike) -> tuple[SegmentationModel, dict[str, Any]]:
    """A network and its hyper-parameters from a training checkpoint (``weights_only=True``: runs no code)."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"checkpoint not found: {path}")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
        hp = ckpt["hyper_parameters"]
        model = create_model(hp["model"], **hp.get("model_options", {}))
        state = {k[len("net."):]: v for k, v in ckpt["state_dict"].items() if k.startswith("net.")}
        model.load_state_dict(state)
    except (KeyError, RuntimeError, ValueError, TypeError, EOFError, OSError, pickle.UnpicklingError) as exc:
        raise CorruptFileError(f"{path} is not a freespace training checkpoint ({type(exc).__name__})") from None
    return model.eval(), hp


def _frames(ds, subset: str, checkpoint: Path, splits_dir: PathLike | None) -> list[str]:
    if subset == "all":
        return [f.name for f in ds.labelled()]
    folder = Path(splits_dir) if splits_dir else checkpoint.parent.parent / "splits"
    if not (folder / f"{subset}.txt").is_file():
        raise InputFileError(f"no split lists at {folder}; give --splits DIR (train.txt, val.txt, test.txt) or --subset all")
    return read_splits(folder, known=[f.name for f in ds.frames])[subset]


def evaluate_checkpoint(checkpoint: PathLike, dataset: str, root: PathLike, out: PathLike, subset: str = "test",
                        splits_dir: PathLike | None = None, split: str | None = None,
                        progress: bool = True) -> dict[str, Any]:
    """Evaluate ``checkpoint`` on ``subset`` (train/val/test from the run's lists, or all labelled frames) of
    the on-disk ``split`` of a dataset."""
    if subset not in ("train", "val", "test", "all"):
        raise InvalidOptionError(f"--subset must be train, val, test or all, got {subset!r}")
    from freespace.infer import Predictor

    checkpoint, out = Path(checkpoint), Path(out)
    predictor = Predictor(checkpoint=checkpoint)
    ds = get_dataset(dataset, root, split, disparity_mode="none")
    names = _frames(ds, subset, checkpoint, splits_dir)
    if not names:
        raise DatasetError(f"subset {subset!r} has no labelled frames")
    from tqdm import tqdm

    counts, kitti, seconds = Counts(), KittiCounts(), 0.0
    for name in tqdm(names, desc="evaluate", unit="frame", disable=not progress):
        sample = ds.load(ds.index(name), right=False, disparity=False)
        t0 = time.perf_counter()
        prob = predictor.predict([sample.left])[0]
        seconds += time.perf_counter() - t0
        label = sample.label
        pred = prob >= 0.5
        counts = counts + confusion_counts(pred, label.road, label.valid)
        kitti = kitti + kitti_counts(np.clip(np.round(prob * 255), 0, 255).astype(np.uint8), label.road, label.valid)
        write_image(out / "overlays" / f"{name}.png", overlay_errors(sample.left, pred, label.road, label.valid))
    scores = kitti_scores(kitti)
    metrics = {**counts.metrics(), "max_f": scores["max_f"], "ap": scores["ap"], "seconds_per_frame": seconds / len(names),
               "frames": len(names), "split": subset, "checkpoint": str(checkpoint)}
    _pr_curve(kitti, out / "pr_curve.png")
    write_json(out / "metrics.json", metrics)
    return metrics


def _pr_curve(kitti: KittiCounts, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tp = kitti.pos - kitti.fn
    keep = tp > 0
    recall = tp[keep] / max(kitti.pos, 1)
    precision = tp[keep] / (tp[keep] + kitti.fp[keep] + 1e-10)
    fig, ax = plt.subplots(figsize=(4, 4), dpi=100)
    ax.plot(recall, precision)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.01)
    ax.grid(True, alpha=0.3)
    ax.set_title("road precision-recall (256 thresholds)")
    import io as _io

    buf = _io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    plt.close(fig)
    from freespace.io import atomic_write_bytes

    atomic_write_bytes(path, buf.getvalue())
