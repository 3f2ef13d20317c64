"""Labels that reach the whole road from a teacher's road probability (issue 70, item 1): where one global
confidence (road where p > 0.9) leaves the far road and the lanes beside the cars unlabelled, because the teacher is
less sure there, two ways label more of them.

- :func:`balanced_label`: class-balanced thresholds per image band. In each band of rows, the pixels the teacher
  calls road (p ≥ 0.5) are ranked by their probability and the most confident ``share`` of them labelled road (the
  same for not road); the far band, where every probability is lower, keeps its share of labels instead of losing
  them all to a global threshold. A floor (``min_confidence``) keeps near-coin-flips unlabelled.
- :func:`complete_by_appearance`: from the confident seeds, road grows into the uncertain pixels that look like it:
  a graph cut (OpenCV's GrabCut: colour models of road and not road, a smoothness term along the image's edges)
  seeded with the confident labels as certain and the rest as probable by the teacher's side of 0.5; an uncertain
  pixel takes the cut's side, and the seeds stay as they were. With ``release`` the teacher's confident not-road
  pixels near its road are released to the cut as well (:func:`released_seeds`): a teacher that stops the road a
  band short of its far end, or leaves out the lane beyond the cars, is sure of it, so completing only its uncertain
  pixels cannot reach them.

Labels are class maps: 1 road, 0 not road, :data:`~freespace.labels.IGNORE_INDEX` don't care. Torch-free.
"""

from __future__ import annotations

import cv2
import numpy as np

from freespace.errors import InvalidOptionError, ShapeMismatchError
from freespace.labels import IGNORE_INDEX

__all__ = ["confident_label", "balanced_label", "released_seeds", "complete_by_appearance"]


def _check(prob: np.ndarray, image: np.ndarray | None = None) -> np.ndarray:
    prob = np.asarray(prob, np.float32)
    if prob.ndim != 2:
        raise InvalidOptionError(f"a road probability is an H×W map, got shape {prob.shape}")
    if image is not None and image.shape[:2] != prob.shape:
        raise ShapeMismatchError(f"the image is {image.shape[1]}×{image.shape[0]} but the probability "
                                 f"{prob.shape[1]}×{prob.shape[0]} (W×H); give the probability of that image")
    return prob


def confident_label(prob: np.ndarray, threshold: float = 0.9) -> np.ndarray:
    """The one-global-confidence label of a road probability (``float H×W`` in [0, 1]): road where ``p >
    threshold``, not road where ``p < 1 − threshold``, don't care between (``uint8 H×W`` class map)."""
    prob = _check(prob)
    out = np.full(prob.shape, IGNORE_INDEX, np.uint8)
    out[prob > threshold] = 1
    out[prob < 1 - threshold] = 0
    return out


def balanced_label(prob: np.ndarray, share: float = 0.8, bands: int = 8, min_confidence: float = 0.7) -> np.ndarray:
    """Class-balanced thresholds per band of rows (see the module docstring).

    Args:
        prob: ``float H×W`` road probability in [0, 1].
        share: of each class's pixels in a band (road: p ≥ 0.5; not road: p < 0.5), the most confident share is
            labelled, in (0, 1].
        bands: horizontal bands of equal height (≥ 1), each thresholded on its own.
        min_confidence: a pixel is labelled only where max(p, 1 − p) is at least this, in [0.5, 1).

    Returns:
        ``uint8 H×W``: 1 road, 0 not road, :data:`~freespace.labels.IGNORE_INDEX` don't care.

    Example:
        >>> prob = np.array([[0.6, 0.55, 0.2], [0.99, 0.95, 0.01]], np.float32)
        >>> balanced_label(prob, share=0.5, bands=2, min_confidence=0.55).tolist()  # each row its own band
        [[1, 255, 0], [1, 255, 0]]
    """
    prob = _check(prob)
    if not 0 < share <= 1 or bands < 1 or not 0.5 <= min_confidence < 1:
        raise InvalidOptionError(f"share must be in (0, 1], bands ≥ 1 and min_confidence in [0.5, 1); got {share}, "
                                 f"{bands}, {min_confidence}")
    out = np.full(prob.shape, IGNORE_INDEX, np.uint8)
    confidence = np.maximum(prob, 1 - prob)
    edges = np.linspace(0, prob.shape[0], bands + 1).round().astype(int)
    for top, bottom in zip(edges[:-1], edges[1:]):
        p, c = prob[top:bottom], confidence[top:bottom]
        for value, side in ((1, p >= 0.5), (0, p < 0.5)):
            sure = side & (c >= min_confidence)
            if not sure.any():
                continue
            cut = np.quantile(c[side], 1 - share)  # the class's most confident share in this band
            out[top:bottom][sure & (c >= cut)] = value
    return out


def released_seeds(seeds: np.ndarray, prob: np.ndarray, release: float, far: float = 1.0) -> np.ndarray:
    """Which not-road seeds a graph cut may relabel: those within ``release`` × H pixels (Euclidean) of the
    teacher's road (``prob`` ≥ 0.5) and, with ``far`` < 1, in the far part of it: above the row ``top + far ×
    (H − top)``, ``top`` the road's highest row (the far road and the lanes beside it, not the pavements by the car).

    Args:
        seeds: ``uint8 H×W`` class map (1 road, 0 not road, :data:`~freespace.labels.IGNORE_INDEX` don't care).
        prob: the teacher's road probability, ``float H×W`` in [0, 1].
        release: the distance as a share of the image height, in [0, 1] (0: none released).
        far: the share of the road's rows, from its top, where seeds are released, in (0, 1].

    Returns:
        ``bool H×W``: the released not-road seeds.

    Example:
        >>> prob = np.zeros((10, 4), np.float32); prob[6:] = 1
        >>> seeds = confident_label(prob)
        >>> released_seeds(seeds, prob, 0.2).any(1).tolist()  # the two rows above the road
        [False, False, False, False, True, True, False, False, False, False]
    """
    if not 0 <= release <= 1 or not 0 < far <= 1:
        raise InvalidOptionError(f"release must be in [0, 1] and far in (0, 1], got {release} and {far}")
    road = prob >= 0.5
    if release == 0 or not road.any():
        return np.zeros(prob.shape, bool)
    distance = cv2.distanceTransform((~road).astype(np.uint8), cv2.DIST_L2, 5)
    near = (seeds == 0) & (distance <= release * prob.shape[0])
    if far < 1:
        top = int(np.argmax(road.any(1)))
        near[int(top + far * (prob.shape[0] - top)):] = False
    return near


def complete_by_appearance(image: np.ndarray, prob: np.ndarray, threshold: float = 0.9,
                           iterations: int = 3, seeds: np.ndarray | None = None, release: float = 0.0,
                           far: float = 1.0) -> np.ndarray:
    """The confident label (:func:`confident_label`) with its uncertain pixels completed by a graph cut on the
    image's colours (see the module docstring).

    Args:
        image: ``H×W×3 uint8`` RGB frame. prob: its road probability, ``float H×W`` in [0, 1].
        threshold: the seeds' confidence (road above it, not road below 1 − it).
        iterations: GrabCut's iterations (each re-fits the colour models).
        seeds: a class map (``uint8 H×W``) to complete instead of the confident label, e.g. labels carried along
            time (:mod:`freespace.datagen.temporal`).
        release, far: the not-road seeds near the teacher's road that the cut may relabel too
            (:func:`released_seeds`; ``release`` 0: none).

    Returns:
        ``uint8 H×W``: 1 road, 0 not road (every pixel labelled, unless a class has no seed: then the confident
        label as it is).
    """
    prob = _check(prob, image)
    if seeds is None:
        seeds = confident_label(prob, threshold)
    elif seeds.shape != prob.shape:
        raise ShapeMismatchError(f"the seeds are {seeds.shape[1]}×{seeds.shape[0]} but the probability "
                                 f"{prob.shape[1]}×{prob.shape[0]} (W×H); give the seeds of that image")
    if not ((seeds == 1).any() and (seeds == 0).any()):
        return seeds
    mask = np.where(prob >= 0.5, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    mask[seeds == 1] = cv2.GC_FGD
    mask[seeds == 0] = cv2.GC_BGD
    mask[released_seeds(seeds, prob, release, far)] = cv2.GC_PR_BGD
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.grabCut(cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR), mask, None, bgd, fgd, iterations,
                cv2.GC_INIT_WITH_MASK)
    return np.where((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD), 1, 0).astype(np.uint8)
