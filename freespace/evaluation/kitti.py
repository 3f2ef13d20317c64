"""`freespace evaluate-kitti`: KITTI road confidence maps against KITTI ground truth, as the devkit does.

Ground truth: ``GT_DIR/<cat>_road_<id>.png`` (KITTI colours, read as the devkit reads them: road = blue
> 0, evaluated = red > 0). Predictions: ``PRED_DIR/<cat>_road_<id>.png`` (the benchmark's naming) or
``PRED_DIR/<cat>_<id>.png``, 8-bit grey (255 = sure road; a colour file must have three equal channels).
Counts are summed per category (``um_road``, ``umm_road``, ``uu_road``) and over all images (``all``). With a
calibration folder the evaluation is in the benchmark's bird's-eye view (``bev=True``).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from freespace.errors import (
    CorruptFileError,
    DatasetError,
    InputFileError,
    InvalidOptionError,
    ShapeMismatchError,
    param,
)
from freespace.evaluation.bev import to_bev
from freespace.evaluation.metrics import KITTI_CATEGORIES, RoadEvaluator
from freespace.io.codecs import label_image_problem, read_image, road_label_from_image
from freespace.io.files import PathLike, check_outputs, check_suffix, check_writable, missing_input, write_json
from freespace.io.kitti import read_kitti_calib

__all__ = ["evaluate_kitti", "evaluate_kitti_dirs", "kitti_table", "read_confidence"]

_GT = re.compile(r"^(um|umm|uu)_road_(\d{6})$")


def read_confidence(path: PathLike) -> np.ndarray:
    """An 8-bit road confidence map (``uint8 H×W``, 255 = sure road): a one-channel file, or a colour file
    whose three channels are equal (a grey image saved as RGB).

    Raises:
        CorruptFileError: a colour image (its channels differ): an overlay or a KITTI ground truth, not a
            confidence map; the devkit would turn its colours into grey levels and score them.
    """
    img = read_image(path, what="prediction")
    if img.ndim == 2:
        return img
    if not (np.array_equal(img[:, :, 0], img[:, :, 1]) and np.array_equal(img[:, :, 1], img[:, :, 2])):
        raise CorruptFileError(f"prediction {path} is a colour image, not a confidence map (8-bit grey, 255 = sure "
                               f"road); give the <name>.png files of freespace predict, not overlays or ground truth")
    return np.ascontiguousarray(img[:, :, 0])


def evaluate_kitti_dirs(gt_dir: PathLike, pred_dir: PathLike, calib_dir: PathLike | None = None) -> dict[str, Any]:
    """Evaluate every ground-truth file of ``gt_dir`` against its prediction in ``pred_dir``.

    With ``calib_dir`` (``<cat>_<id>.txt`` KITTI calibration files), ground truth and predictions are
    both transformed into the benchmark's bird's-eye view first (:mod:`freespace.evaluation.bev`), as the server does.

    Returns:
        ``{category: {"max_f", "ap", "pre", "rec", "fpr", "fnr", "threshold", "images"}}`` for the
        categories present and ``"all"``.

    Raises:
        InputFileError: a folder or a prediction is missing. ShapeMismatchError: sizes differ.
    """
    gt_dir, pred_dir = Path(gt_dir), Path(pred_dir)
    folders = [(gt_dir, "ground-truth"), (pred_dir, "prediction")]
    if calib_dir is not None:
        calib_dir = Path(calib_dir)
        folders.append((calib_dir, "calibration"))
    for d, what in folders:
        if not d.is_dir():
            raise missing_input(d, f"{what} folder", "folder")
    gts = [p for p in sorted(gt_dir.glob("*.png")) if _GT.match(p.stem)]
    if not gts:
        raise DatasetError(f"no KITTI road ground truth (<cat>_road_<id>.png) in {gt_dir}")
    missing, pairs = [], []
    for gt in gts:
        cat, idx = _GT.match(gt.stem).groups()  # type: ignore[union-attr]
        candidates = [pred_dir / gt.name, pred_dir / f"{cat}_{idx}.png"]
        pred = next((c for c in candidates if c.is_file()), None)
        if pred is None:
            missing.append(gt.name)
        else:
            pairs.append((f"{cat}_road", gt, pred))
    if missing:
        raise InputFileError(f"no prediction in {pred_dir} for {len(missing)} of {len(gts)} ground-truth files "
                             f"(first: {missing[0]}); name them like the ground truth")
    evaluators: dict[str, RoadEvaluator] = {}
    for cat, gt, pred in pairs:
        calib = read_kitti_calib(calib_dir / f"{gt.stem.replace('_road_', '_')}.txt") if calib_dir is not None else None
        gt_image = read_image(gt, what="ground truth")
        problem = label_image_problem(gt_image)  # e.g. --gt and --pred swapped: a confidence map is no label
        if problem is not None:
            raise CorruptFileError(f"ground truth {gt} is {problem}; {param('gt')} is the folder of KITTI road "
                                   f"ground truth (gt_image_2)")
        conf = read_confidence(pred)
        if conf.shape != gt_image.shape[:2]:
            raise ShapeMismatchError(f"{pred.name} is {conf.shape[1]}×{conf.shape[0]} but its ground truth is "
                                     f"{gt_image.shape[1]}×{gt_image.shape[0]}")
        if calib is not None:
            gt_image, conf = to_bev(gt_image, calib), to_bev(conf, calib)
        label = road_label_from_image(gt_image)
        evaluators.setdefault(cat, RoadEvaluator()).process(conf, label.road, label.valid)
    order = [c for c in KITTI_CATEGORIES if c in evaluators] + ["all"]
    evaluators["all"] = RoadEvaluator.from_vector(sum(ev.to_vector() for ev in evaluators.values()))
    if evaluators["all"].kitti.pos + evaluators["all"].kitti.neg == 0:
        where = " in the bird's-eye view" if calib_dir is not None else ""
        raise DatasetError(f"the ground truth in {gt_dir} has no evaluated pixel{where} (every file all black: don't "
                           f"care everywhere), so there is nothing to score; give KITTI road ground truth (road "
                           f"magenta, non-road red)")
    keys = ("max_f", "ap", "pre", "rec", "fpr", "fnr", "threshold", "images")
    return {k: {m: v for m, v in evaluators[k].evaluate().items() if m in keys} for k in order}


def evaluate_kitti(gt: PathLike, pred: PathLike, out: PathLike, calib: PathLike | None = None,
                   bev: bool = False) -> dict[str, Any]:
    """``freespace evaluate-kitti``: :func:`evaluate_kitti_dirs` of ``gt`` and ``pred`` (in the bird's-eye view
    with ``bev``, which needs ``calib``), its result written to the JSON file ``out`` (checked before any work).

    Returns:
        :func:`evaluate_kitti_dirs`' result.

    Raises:
        InvalidOptionError: ``bev`` without ``calib`` or the reverse; an ``out`` that may not be written.
    """
    if bev and not calib:
        raise InvalidOptionError(f"{param('bev')} needs {param('calib')} CALIB_DIR (the frames' <cat>_<id>.txt "
                                 f"calibration files)")
    if calib and not bev:
        raise InvalidOptionError(f"{param('calib')} is only used with {param('bev')} (the bird's-eye view); add "
                                 f"{param('bev')}, or leave out {param('calib')} for the perspective view")
    check_writable(out)
    check_outputs({"out": out}, {"gt": gt, "pred": pred, "calib": calib})
    check_suffix(out, (".json",))
    results = evaluate_kitti_dirs(gt, pred, calib_dir=calib)
    write_json(out, results)
    return results


def kitti_table(results: dict[str, Any]) -> str:
    """:func:`evaluate_kitti_dirs`' ``results`` as a table: a row per category, the scores in percent."""
    lines = [f"{'category':<10} {'images':>6} {'MaxF':>7} {'AP':>7} {'PRE':>7} {'REC':>7} {'FPR':>7} {'FNR':>7}"]
    for cat, r in results.items():
        lines.append(f"{cat:<10} {r['images']:>6} "
                     + " ".join(f"{100 * r[k]:7.2f}" for k in ("max_f", "ap", "pre", "rec", "fpr", "fnr")))
    return "\n".join(lines)
