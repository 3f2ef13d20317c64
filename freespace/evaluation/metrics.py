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

__all__ = ["Counts", "confusion_counts", "KittiCounts", "kitti_counts", "kitti_scores", "KITTI_CATEGORIES",
           "to_confidence", "RoadEvaluator"]

KITTI_CATEGORIES = ("um_road", "umm_road", "uu_road")


def to_confidence(prob: np.ndarray) -> np.ndarray:
    """The KITTI 8-bit road confidence (``uint8``, 255 = sure road) of a road probability map (``float``
    in [0, 1], any shape): ``round(255 · p)``, halves to even, clipped to [0, 255]."""
    return np.clip(np.round(prob * 255.0), 0, 255).astype(np.uint8)


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

    def pr_curve(self) -> tuple[np.ndarray, np.ndarray]:
        """``(recall, precision)``: ``float64`` arrays over the thresholds j/255 with TP > 0, in threshold
        order (recall falls), as the devkit computes them; empty without road pixels."""
        tp = self.pos - self.fn
        keep = tp > 0
        if self.pos == 0 or not keep.any():
            return np.zeros(0), np.zeros(0)
        return tp[keep] / float(self.pos), tp[keep] / (tp[keep] + self.fp[keep] + 1e-10)


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
    recall, precision = counts.pr_curve()
    if not recall.size:
        fpr = float(np.float32(counts.fp[0]) / np.float32(counts.neg)) if counts.neg else 0.0
        return {"max_f": 0.0, "ap": 0.0, "pre": 0.0, "rec": 0.0, "fpr": fpr, "fnr": 1.0 if counts.pos else 0.0,
                "threshold": 0.0}
    ap_terms = [precision[recall >= r].max() for r in np.arange(0, 1.1, 0.1) if (recall >= r).any()]
    ap = float(np.mean(ap_terms)) if ap_terms else 0.0
    f = 2 * precision * recall / (precision + recall + 1e-10)
    best = int(np.argmax(f))  # the first maximum
    i = np.flatnonzero(keep)[best]
    TP, FP, FN = np.float32(tp[i]), np.float32(counts.fp[i]), np.float32(counts.fn[i])
    P, N = np.float32(counts.pos), np.float32(counts.neg)
    return {"max_f": float(f[best]), "ap": ap, "pre": float(TP / (TP + FP)), "rec": float(TP / P),
            "fpr": float(FP / N) if N > 0 else 0.0, "fnr": float(FN / P), "threshold": float(thresholds[i])}


class RoadEvaluator:
    """Accumulates the counts of a whole split, then computes every metric once (detectron2's
    ``reset`` / ``process`` / ``evaluate``).

    Serves training (validation and test in :class:`freespace.engine.module.RoadModule`, summed over DDP
    ranks through :meth:`to_vector` / :meth:`from_vector`), ``freespace evaluate`` and ``freespace
    evaluate-kitti``. Each processed image adds its confusion :class:`Counts` at ``threshold`` and its
    :class:`KittiCounts` of the 8-bit confidence (:func:`to_confidence`).
    """

    #: length of :meth:`to_vector`: tp, fp, fn, tn, fn[256], fp[256], pos, neg, images
    VECTOR_SIZE = 4 + 2 * 256 + 3

    def __init__(self, threshold: float = 0.5) -> None:
        self.threshold = threshold
        self.reset()

    def reset(self) -> None:
        """Forget every processed image."""
        self.counts = Counts()
        self.kitti = KittiCounts()
        self.images = 0

    def process(self, prediction: np.ndarray, road: np.ndarray, valid: np.ndarray | None = None) -> None:
        """Add one image (``H×W``) or a batch (``N×H×W``; the counts are sums over all its pixels).

        Args:
            prediction: road probability (``float``, ``H×W`` or ``N×H×W``, in [0, 1]; road where
                p ≥ ``threshold``), or an 8-bit confidence map (``uint8``, 255 = sure road, as KITTI
                submissions are; road where value ≥ ``round(255 · threshold)``).
            road: ``bool``, same shape, True = road. valid: ``bool``, same shape, False = don't care
                (default: every pixel counts).
        """
        if prediction.dtype == np.uint8:
            confidence, pred = prediction, prediction >= round(255 * self.threshold)
        else:
            confidence, pred = to_confidence(prediction), prediction >= self.threshold
        self.counts = self.counts + confusion_counts(pred, road, valid)
        self.kitti = self.kitti + kitti_counts(confidence, road, valid)
        self.images += prediction.shape[0] if prediction.ndim == 3 else 1

    def evaluate(self) -> dict[str, Any]:
        """The metrics of everything processed since :meth:`reset` (fractions): ``accuracy``,
        ``precision``, ``recall``, ``f_score``, ``iou`` (at ``threshold``); the KITTI ``max_f``, ``ap``,
        ``pre``, ``rec``, ``fpr``, ``fnr`` and ``threshold`` (see :func:`kitti_scores`); ``images``."""
        return {**self.counts.metrics(), **kitti_scores(self.kitti), "images": self.images}

    def to_vector(self) -> np.ndarray:
        """The accumulated state as one ``float64`` vector (:attr:`VECTOR_SIZE`), to sum over processes
        (exact below 2^53 pixels)."""
        c = self.counts
        return np.concatenate([[c.tp, c.fp, c.fn, c.tn], self.kitti.fn, self.kitti.fp,
                               [self.kitti.pos, self.kitti.neg, self.images]]).astype(np.float64)

    @classmethod
    def from_vector(cls, vector: np.ndarray, threshold: float = 0.5) -> RoadEvaluator:
        """An evaluator holding the state of :meth:`to_vector` (e.g. summed over DDP ranks)."""
        v = np.rint(np.asarray(vector, np.float64)).astype(np.int64)
        if v.shape != (cls.VECTOR_SIZE,):
            raise ShapeMismatchError(f"an evaluator state has {cls.VECTOR_SIZE} values, got shape {v.shape}")
        ev = cls(threshold)
        ev.counts = Counts(*(int(x) for x in v[:4]))
        ev.kitti = KittiCounts(v[4:260].copy(), v[260:516].copy(), int(v[516]), int(v[517]))
        ev.images = int(v[518])
        return ev
