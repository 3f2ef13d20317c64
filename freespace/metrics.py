"""Road segmentation metrics: the paper's (from summed confusion counts) and the KITTI road benchmark's.

Conventions: metrics are fractions in [0, 1]. Counts are summed over images first and the metrics
computed once from the sums — never an average of per-image or per-batch scores. Don't-care pixels
(``valid`` False) leave every count. Degenerate ratios (a zero denominator) are defined, never NaN:
they are 1.0 when the quantity has nothing to get wrong (no predicted road for precision, no road for
recall, neither for IoU, no pixel for accuracy) — see :meth:`Counts.metrics`.

The KITTI evaluation reproduces the official devkit (``devkit_road/python``, ``evalExp`` and
``pxEval_maximizeFMeasure``): 256 thresholds ``j/255`` on 8-bit confidences (road where value ≥ j),
FN/FP and the positive/negative totals summed over a category's images, TP = P − FN, recall = TP/P,
precision = TP/(TP + FP + 1e-10), thresholds with TP = 0 dropped, F = 2PR/(P + R + 1e-10), MaxF = the
first maximum, AP = the 11-point interpolated precision (mean over r ∈ arange(0, 1.1, 0.1) of the highest
precision with recall ≥ r), and PRE, REC, FPR = FP/N, FNR = FN/P at the MaxF threshold in float32.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from freespace.errors import ShapeMismatchError

__all__ = ["Counts", "confusion_counts", "KittiCounts", "kitti_counts", "kitti_scores", "KITTI_CATEGORIES"]

KITTI_CATEGORIES = ("um_road", "umm_road", "uu_road")


def _ratio(num: float, den: float, empty: float = 1.0) -> float:
    return float(num) / float(den) if den > 0 else empty


@dataclass
class Counts:
    """Confusion counts of the road class (pixels)."""

    tp: int = 0
    fp: int = 0
    fn: int = 0
    tn: int = 0

    def __add__(self, other: Counts) -> Counts:
        return Counts(self.tp + other.tp, self.fp + other.fp, self.fn + other.fn, self.tn + other.tn)

    def metrics(self) -> dict[str, float]:
        """``accuracy``, ``precision``, ``recall``, ``f_score``, ``iou`` of the road class.

        Zero denominators: precision (nothing predicted as road) and recall (no road) are 1.0, IoU (no
        road predicted or present) 1.0, accuracy (no valid pixel) 1.0; the F-score is 0 when precision and
        recall are both 0.
        """
        p = _ratio(self.tp, self.tp + self.fp)
        r = _ratio(self.tp, self.tp + self.fn)
        return {
            "accuracy": _ratio(self.tp + self.tn, self.tp + self.fp + self.fn + self.tn),
            "precision": p,
            "recall": r,
            "f_score": 2 * p * r / (p + r) if p + r > 0 else 0.0,
            "iou": _ratio(self.tp, self.tp + self.fp + self.fn),
        }


def _check(pred: np.ndarray, road: np.ndarray, valid: np.ndarray | None) -> np.ndarray:
    if pred.shape != road.shape or (valid is not None and valid.shape != road.shape):
        raise ShapeMismatchError(f"prediction {pred.shape} and ground truth {road.shape} differ in size")
    return np.ones(road.shape, bool) if valid is None else valid.astype(bool)


def confusion_counts(pred: np.ndarray, road: np.ndarray, valid: np.ndarray | None = None) -> Counts:
    """Counts of ``pred`` (bool H×W, True = road) against ``road`` (bool H×W) over ``valid`` pixels."""
    valid = _check(pred, road, valid)
    pred, road = pred.astype(bool), road.astype(bool)
    tp = int(np.count_nonzero(pred & road & valid))
    fp = int(np.count_nonzero(pred & ~road & valid))
    fn = int(np.count_nonzero(~pred & road & valid))
    return Counts(tp, fp, fn, int(np.count_nonzero(valid)) - tp - fp - fn)


@dataclass
class KittiCounts:
    """Per-threshold counts of the KITTI evaluation, summed over images: ``fn[j]``, ``fp[j]`` for
    thresholds j/255 (j = 0…255), and the totals of valid road (``pos``) and non-road (``neg``) pixels."""

    fn: np.ndarray = field(default_factory=lambda: np.zeros(256, np.int64))
    fp: np.ndarray = field(default_factory=lambda: np.zeros(256, np.int64))
    pos: int = 0
    neg: int = 0

    def __add__(self, other: KittiCounts) -> KittiCounts:
        return KittiCounts(self.fn + other.fn, self.fp + other.fp, self.pos + other.pos, self.neg + other.neg)


def kitti_counts(confidence: np.ndarray, road: np.ndarray, valid: np.ndarray | None = None) -> KittiCounts:
    """KITTI counts of one image. ``confidence``: ``uint8 H×W`` (255 = sure road); ``road``/``valid``: bool."""
    valid = _check(confidence, road, valid)
    if confidence.dtype != np.uint8:
        raise ShapeMismatchError(f"KITTI confidences are 8-bit (uint8), got {confidence.dtype}")
    road = road.astype(bool)
    hist_road = np.bincount(confidence[road & valid], minlength=256)
    hist_non = np.bincount(confidence[~road & valid], minlength=256)
    # FN[j]: road pixels with value < j; FP[j]: non-road pixels with value ≥ j
    fn = np.concatenate([[0], np.cumsum(hist_road)[:-1]])
    fp = np.cumsum(hist_non[::-1])[::-1]
    return KittiCounts(fn.astype(np.int64), fp.astype(np.int64), int(hist_road.sum()), int(hist_non.sum()))


def kitti_scores(counts: KittiCounts) -> dict[str, Any]:
    """The benchmark's scores from summed counts: ``max_f``, ``ap``, ``pre``, ``rec``, ``fpr``, ``fnr``
    (fractions) and ``threshold`` (the MaxF threshold j/255).

    Degenerate sums (no road pixel, or no threshold with TP > 0) give ``max_f = ap = pre = rec = 0``,
    ``fnr = 1`` (0 without road) and ``fpr`` at the lowest threshold.
    """
    tp = counts.pos - counts.fn
    thresholds = np.arange(256) / 255.0
    keep = tp > 0
    if counts.pos == 0 or not keep.any():
        fpr = float(np.float32(counts.fp[0]) / np.float32(counts.neg)) if counts.neg else 0.0
        return {"max_f": 0.0, "ap": 0.0, "pre": 0.0, "rec": 0.0, "fpr": fpr, "fnr": 1.0 if counts.pos else 0.0,
                "threshold": 0.0}
    recall = tp[keep] / float(counts.pos)
    precision = tp[keep] / (tp[keep] + counts.fp[keep] + 1e-10)
    ap_terms = [precision[recall >= r].max() for r in np.arange(0, 1.1, 0.1) if (recall >= r).any()]
    ap = float(np.mean(ap_terms)) if ap_terms else 0.0
    f = 2 * precision * recall / (precision + recall + 1e-10)
    best = int(np.argmax(f))  # the first maximum
    i = np.flatnonzero(keep)[best]
    TP, FP, FN = np.float32(tp[i]), np.float32(counts.fp[i]), np.float32(counts.fn[i])
    P, N = np.float32(counts.pos), np.float32(counts.neg)
    return {"max_f": float(f[best]), "ap": ap, "pre": float(TP / (TP + FP)), "rec": float(TP / P),
            "fpr": float(FP / N) if N > 0 else 0.0, "fnr": float(FN / P), "threshold": float(thresholds[i])}
