"""`freespace evaluate`: a model (checkpoint or ONNX) on labelled frames — metrics, per-frame scores, overlays,
PR curve.

Two sources of labelled frames: a subset of a dataset's split (``dataset`` and ``root``: train, val or test as the
subset lists say, or all labelled frames) or a *labelled folder* (``images`` and ``labels`` in one of the formats of
:mod:`freespace.evaluation.labelled`: KITTI road ground truth, binary masks, class ids, palette colours).
Predictions are made at the model's input size and resized back (bilinear probabilities) to each frame's own size,
where the metrics are counted (the benchmark's way). Outputs in ``OUT``: ``metrics.json`` (pooled accuracy,
precision, recall, f_score, iou at p ≥ 0.5, with frame-level bootstrap intervals of precision, recall, F and IoU
— ``intervals`` null below two scored frames, ``interval`` says why; the KITTI max_f and ap from the 256 thresholds;
seconds per frame; ``frames``, the frames scored, and ``unevaluated_frames``/``unevaluated``, those whose label has
no evaluated pixel (don't care everywhere: not predicted, not scored, in no pooled score); what was evaluated: the
model, and ``subset``, ``dataset``, ``root`` and ``splits`` (the subset lists read, or null) or the labelled folder;
files written by earlier versions call the subset ``split``), ``per_frame.csv`` (each frame's counts and scores,
empty for a frame without an evaluated pixel), ``overlays/<frame>.png`` (TP green, FN red, FP blue) and
``pr_curve.png``.

A labelled folder's labels are checked before the model runs (:func:`~freespace.evaluation.labelled.check_labels`):
a set in which no label has an evaluated pixel, or a road value that no label holds, is refused in one line and
nothing is written. A run's subset lists are looked for only in a run folder (the checkpoint in
``RUN/checkpoints/``, beside ``RUN/config.yaml``): :func:`run_subset_lists`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.base import StereoRoadDataset
from freespace.data.registry import get_dataset
from freespace.data.splits import read_splits
from freespace.errors import DatasetError, InputFileError, InvalidOptionError, ShapeMismatchError, param
from freespace.evaluation.label_presets import resolve_label_format
from freespace.evaluation.labelled import (
    LabelFormat,
    PooledScores,
    check_labels,
    pair_labelled_frames,
)
from freespace.evaluation.metrics import Counts, RoadEvaluator, confusion_counts
from freespace.evaluation.viz import overlay_errors, write_pr_curve
from freespace.inference.predictor import Predictor
from freespace.io.codecs import write_image
from freespace.io.files import PathLike, check_outputs, check_writable, shown_path, write_csv, write_json
from freespace.io.outdir import claim_folder
from freespace.labels import RoadLabel
from freespace.limits import check_threads

__all__ = ["evaluate", "evaluate_checkpoint", "evaluate_frames", "evaluate_labelled", "evaluate_report", "score_frames",
           "run_subset_lists"]

#: what metrics.json and the command's line report of the pooled counts
SUMMARY_KEYS = ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap")
PER_FRAME_FIELDS = ("frame", "tp", "fp", "fn", "tn", "precision", "recall", "f_score", "iou")

#: a frame to score: its name and a function that reads its image (H×W×3 RGB) and its label
Frame = tuple[str, Callable[[], tuple[np.ndarray, RoadLabel]]]


def run_subset_lists(checkpoint: PathLike) -> Path | None:
    """The subset lists of the training run a checkpoint belongs to: ``RUN/splits`` when the checkpoint lies in
    ``RUN/checkpoints/`` and ``RUN`` holds its run record (``config.yaml``, written by ``freespace train``); None for
    a checkpoint anywhere else (a model folder's ``models/X/model.ckpt``, a copied file), whose neighbours' lists
    belong to no run of it."""
    checkpoint = Path(checkpoint)
    run = checkpoint.parent.parent
    if checkpoint.parent.name == "checkpoints" and (run / "config.yaml").is_file():
        return run / "splits"
    return None


def _frames(ds: StereoRoadDataset, subset: str, checkpoint: Path | None,
            splits_dir: PathLike | None) -> tuple[list[str], Path | None]:
    """The names of ``subset``'s frames and the folder of the subset lists they come from (None for ``all``)."""
    if subset == "all":
        return [f.name for f in ds.labelled()], None
    hint = f"give {param('splits_dir')} DIR (train.txt, val.txt, test.txt) or {param('subset')} all"
    if splits_dir is None and checkpoint is None:
        raise InvalidOptionError(f"an ONNX model has no run folder with subset lists; {hint}")
    folder = Path(splits_dir) if splits_dir else run_subset_lists(checkpoint)  # type: ignore[arg-type]
    if folder is None:
        raise InvalidOptionError(f"{param('checkpoint')} {checkpoint} is not in a training run's folder "
                                 f"(RUN/checkpoints/ beside RUN/config.yaml), so no subset lists come with it; {hint}")
    if not (folder / f"{subset}.txt").is_file():
        raise InputFileError(f"no subset lists at {folder}; {hint}")
    return read_splits(folder, known=[f.name for f in ds.frames])[subset], folder


def score_frames(predictor: Predictor, frames: Iterable[Frame], *, overlays: Path | None = None,
                 progress: bool = False, total: int | None = None) -> tuple[RoadEvaluator, PooledScores, float]:
    """Predict each frame and count it against its label at the label's size.

    Returns the filled :class:`RoadEvaluator` (pooled counts and the KITTI curve), the per-frame
    :class:`~freespace.evaluation.labelled.PooledScores` and the seconds spent in the network; with ``overlays``,
    writes ``<overlays>/<frame>.png`` (TP green, FN red, FP blue) too. A frame whose label has no evaluated pixel
    (don't care everywhere) is not predicted: its row is listed without scores and it enters no pooled count.

    Raises:
        ShapeMismatchError: a label's size differs from its image's.
    """
    from freespace.runtime.log import progress_bar

    evaluator, scores, seconds = RoadEvaluator(), PooledScores(), 0.0
    for name, load in progress_bar(frames, desc="evaluate", unit="frame", enabled=progress, total=total):
        image, label = load()
        if image.shape[:2] != label.shape:
            raise ShapeMismatchError(f"the label of {name} is {label.shape[1]}×{label.shape[0]} but its image is "
                                     f"{image.shape[1]}×{image.shape[0]} (W×H); pair each image with its own label")
        if not label.valid.any():  # nothing to measure on it: listed, not scored
            scores.add(name, Counts())
            continue
        t0 = time.perf_counter()
        prob = predictor.predict([image])[0]
        seconds += time.perf_counter() - t0
        evaluator.process(prob, label.road, label.valid)
        pred = prob >= evaluator.threshold
        scores.add(name, confusion_counts(pred, label.road, label.valid))
        if overlays is not None:
            write_image(overlays / f"{name}.png", overlay_errors(image, pred, label.road, label.valid))
    return evaluator, scores, seconds


def evaluate_frames(predictor: Predictor, ds: StereoRoadDataset, names: list[str], *, overlays: Path | None = None,
                    progress: bool = False) -> tuple[RoadEvaluator, float]:
    """Predict the named labelled frames of ``ds`` and count them at each frame's own size.

    Returns the filled :class:`RoadEvaluator` and the seconds spent in the network; with ``overlays``,
    writes ``<overlays>/<frame>.png`` (TP green, FN red, FP blue) too.
    """
    evaluator, _, seconds = score_frames(predictor, _dataset_frames(ds, names), overlays=overlays,
                                         progress=progress, total=len(names))
    return evaluator, seconds


def _dataset_frames(ds: StereoRoadDataset, names: list[str]) -> Iterable[Frame]:
    def loader(name: str) -> Callable[[], tuple[np.ndarray, RoadLabel]]:
        def load() -> tuple[np.ndarray, RoadLabel]:
            sample = ds.load(ds.index(name), right=False, disparity=False)
            return sample.left, sample.label
        return load
    return [(name, loader(name)) for name in names]


def _write_results(staging: Path, evaluator: RoadEvaluator, scores: PooledScores, seconds: float,
                   record: dict[str, Any]) -> dict[str, Any]:
    pooled, kitti = scores.summary(), evaluator.evaluate()
    metrics = {**{k: kitti[k] for k in SUMMARY_KEYS}, "intervals": pooled["intervals"], "interval": pooled["interval"],
               "frames": pooled["frames"], "unevaluated_frames": pooled["unevaluated_frames"],
               "unevaluated": pooled["unevaluated"], "seconds_per_frame": seconds / pooled["frames"], **record}
    write_pr_curve(staging / "pr_curve.png", *evaluator.kitti.pr_curve())
    write_csv(staging / "per_frame.csv", PER_FRAME_FIELDS, scores.rows)
    write_json(staging / "metrics.json", metrics)
    return metrics


def _model(checkpoint: PathLike | None, onnx: PathLike | None, threads: int | None,
           tta: bool = False, crop_top: float = 0.0) -> tuple[Predictor, dict]:
    predictor = Predictor(checkpoint=checkpoint, onnx=onnx, threads=threads, tta=tta, crop_top=crop_top)
    return predictor, ({"checkpoint": str(checkpoint)} if checkpoint is not None else {"onnx": str(onnx)}) | \
        {"tta": tta, "crop_top": predictor.crop_top}


def evaluate_checkpoint(checkpoint: PathLike | None, dataset: str, root: PathLike, out: PathLike,
                        subset: str = "test", splits_dir: PathLike | None = None, split: str | None = None,
                        progress: bool = True, onnx: PathLike | None = None,
                        threads: int | None = None, tta: bool = False, crop_top: float = 0.0) -> dict[str, Any]:
    """Evaluate a model (``checkpoint`` or ``onnx``; ``tta`` and ``crop_top``: as
    :class:`~freespace.inference.predictor.Predictor` takes them) on ``subset`` (train/val/test from the run's
    lists, or all labelled frames) of the on-disk ``split`` of a dataset; writes ``out`` (see the module
    docstring)."""
    if subset not in ("train", "val", "test", "all"):
        raise InvalidOptionError(f"{param('subset')} must be train, val, test or all, got {subset!r}")
    out = Path(out)
    check_writable(out, folder=True)
    check_outputs({"out": out}, {"checkpoint": checkpoint, "onnx": onnx, "root": root, "splits_dir": splits_dir})
    predictor, record = _model(checkpoint, onnx, threads, tta, crop_top)
    ds = get_dataset(dataset, root, split, disparity_source="none")
    if not any(ds.has_label(f) for f in ds.frames):
        raise DatasetError(f"{dataset} at {root} has no road labels to evaluate against; evaluate on a labelled "
                           f"folder instead ({param('images')} DIR {param('labels')} DIR {param('label_format')} ...)")
    names, lists = _frames(ds, subset, Path(checkpoint) if checkpoint is not None else None, splits_dir)
    if not names:
        raise DatasetError(f"subset {subset!r} has no labelled frames")
    with claim_folder(out, "evaluate") as folder, folder.staged() as staging:  # all or nothing
        evaluator, scores, seconds = score_frames(predictor, _dataset_frames(ds, names), progress=progress,
                                                  overlays=staging / "overlays", total=len(names))
        return _write_results(staging, evaluator, scores, seconds,
                              {"subset": subset, "dataset": dataset, "root": str(root),
                               "splits": None if lists is None else str(lists), **record})


def evaluate_labelled(images: PathLike, labels: PathLike, label_format: LabelFormat, out: PathLike, *,
                      checkpoint: PathLike | None = None, onnx: PathLike | None = None, threads: int | None = None,
                      overlays: bool = True, progress: bool = True, tta: bool = False,
                      crop_top: float = 0.0) -> dict[str, Any]:
    """Evaluate a model (``checkpoint`` or ``onnx``; ``tta`` and ``crop_top`` as
    :class:`~freespace.inference.predictor.Predictor` takes them) on a labelled folder: every label file of
    ``labels`` with the image of the same name in ``images``
    (:func:`~freespace.evaluation.labelled.pair_labelled_frames`), the labels decoded by ``label_format``. Writes
    ``out`` (see the module docstring); returns ``metrics.json``'s content.

    Raises:
        DatasetError: no label has an evaluated pixel, or a road value is in no label
            (:func:`~freespace.evaluation.labelled.check_labels`); nothing is written.
    """
    out = Path(out)
    check_writable(out, folder=True)
    check_outputs({"out": out}, {"checkpoint": checkpoint, "onnx": onnx, "images": images, "labels": labels})
    frames = pair_labelled_frames(images, labels, label_format)
    check_labels(frames, label_format)  # a set that would score nothing is refused before the model runs
    predictor, record = _model(checkpoint, onnx, threads, tta, crop_top)

    with claim_folder(out, "evaluate") as folder, folder.staged() as staging:  # all or nothing
        evaluator, scores, seconds = score_frames(predictor, [(f.name, partial(f.read, label_format)) for f in frames],
                                                  overlays=staging / "overlays" if overlays else None,
                                                  progress=progress, total=len(frames))
        return _write_results(staging, evaluator, scores, seconds,
                              {"images": str(images), "labels": str(labels),
                               "label_format": label_format.describe(), **record})


#: the options of a labelled folder (``images``, ``labels``, ``label_format``) and of its labels' values
_FOLDER = ("images", "labels", "label_format")
_FOLDER_VALUES = ("road", "ignore", "tolerance")


def evaluate(out: PathLike, *, checkpoint: PathLike | None = None, onnx: PathLike | None = None,
             dataset: str | None = None, root: PathLike | None = None, split: str | None = None,
             subset: str = "test", splits_dir: PathLike | None = None, images: PathLike | None = None,
             labels: PathLike | None = None, label_format: str | None = None, road: str | None = None,
             ignore: str | None = None, tolerance: int | None = None, threads: int | None = None,
             overlays: bool = True, progress: bool = True, labels_like: str | None = None,
             tta: bool = False, crop_top: float = 0.0) -> dict[str, Any]:
    """``freespace evaluate``: a model (``checkpoint`` or ``onnx``) on a dataset's frames (``dataset`` and
    ``root``: :func:`evaluate_checkpoint`) or on a labelled folder (``images``, ``labels`` and ``label_format``,
    with ``road``, ``ignore`` and ``tolerance`` as :func:`~freespace.evaluation.labelled.parse_label_format`
    reads them, or a public label set's preset ``labels_like``: :func:`evaluate_labelled`); ``overlays`` is the
    labelled folder's. Writes ``out``.

    Returns:
        ``metrics.json``'s content.

    Raises:
        InvalidOptionError: both sources or neither, a labelled folder without all three of its parameters, or
            the label values of a labelled folder given with a dataset.
    """
    check_threads(threads)  # before anything is read: 0 is no "all cores"
    given = dict(images=images, labels=labels, label_format=label_format or labels_like)
    folder = [n for n in _FOLDER if given[n] is not None]
    if dataset is not None and folder:
        raise InvalidOptionError(f"give either {param('dataset')}/{param('root')} or {param('images')}/"
                                 f"{param('labels')}/{param('label_format')}, not both")
    if folder:
        missing = [param(n) for n in _FOLDER if n not in folder]
        if missing:
            raise InvalidOptionError(f"a labelled folder needs {param('images')}, {param('labels')} and "
                                     f"{param('label_format')} (or {param('labels_like')}); add "
                                     f"{', '.join(missing)}")
        fmt = resolve_label_format(label_format, labels_like, road, ignore, tolerance)
        return evaluate_labelled(images, labels, fmt, out, checkpoint=checkpoint, onnx=onnx,  # type: ignore[arg-type]
                                 threads=threads, overlays=overlays, progress=progress, tta=tta,
                                 crop_top=crop_top)
    if dataset is None or root is None:
        raise InvalidOptionError(f"give the frames to evaluate on: {param('dataset')} NAME {param('root')} DIR, or a "
                                 f"labelled folder ({param('images')} DIR {param('labels')} DIR {param('label_format')}"
                                 f" FORMAT)")
    if any(v is not None for v in (road, ignore, tolerance)):
        raise InvalidOptionError(f"{param('road')}, {param('ignore')} and {param('tolerance')} describe a labelled "
                                 f"folder's labels ({param('images')}/{param('labels')}/{param('label_format')}), not "
                                 f"a dataset's")
    return evaluate_checkpoint(checkpoint, dataset, root, out, subset=subset, splits_dir=splits_dir, split=split,
                               progress=progress, onnx=onnx, threads=threads, tta=tta, crop_top=crop_top)


def evaluate_report(metrics: dict[str, Any], out: PathLike) -> str:
    """One line on an evaluation (``metrics``: :func:`evaluate`'s return value) written to ``out``: the pooled
    scores, F's 95 % interval (or that one scored frame makes none), the number of scored frames and of those
    left out for having no evaluated pixel."""
    frames, left, intervals = metrics["frames"], metrics.get("unevaluated_frames", 0), metrics.get("intervals")
    more = f"; {left} more without an evaluated pixel, not scored" if left else ""
    if intervals:
        ci = intervals["f_score"]
        said = f"F 95 % [{ci[0]:.4f}, {ci[1]:.4f}] ({frames} frames{more})"
    else:
        said = f"no F interval: {frames} frame scored, an interval needs 2{more}"
    return " ".join(f"{k} {metrics[k]:.4f}" for k in SUMMARY_KEYS) + f"  {said} → {shown_path(out)}"
