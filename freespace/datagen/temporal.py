"""Road labels carried along time on monocular frames (issue 70, item 1): the paper's tool, the road plane's
homography, applied along the drive instead of across the rig, with no depth and no calibration.

A teacher's labels of one frame (:mod:`freespace.datagen.completion`'s class maps) are sure of the road near the car
and unsure of the far road and the lanes beside the cars. A few frames later the car has driven on: the far road lies
near the camera, well labelled, and the road a car stood on is free. Between two frames of one camera, the road's
pixels move by a homography (a plane's image under any camera motion), which matched road pixels give without depth:

1. **The homography** (:func:`road_homography`): ORB features inside the earlier frame's road (the teacher's road,
   where the camera sees texture: lane marks, the asphalt's grain, patches; after a contrast equalisation, CLAHE)
   and inside the later frame's, matched (nearest neighbours that pass Lowe's ratio test), then a RANSAC homography.
   Its inliers are road points of both frames; too few, or a homography that flips or folds the image, gives
   ``None`` (the pair is skipped).
2. **Chains**: the homography from frame ``t`` to ``t + k`` is the product of the consecutive ones
   (:func:`chain_homographies`), so a frame reaches sources further than one pair's features would.
3. **Votes** (:func:`carried_votes`): each source frame's labelled pixels are warped onto frame ``t`` by the chained
   homography; a vote counts only where the two blurred images agree there (a car above the road, or one that has
   moved, does not warp like the road), and only where the pixel lies in front of both cameras.
4. **The label** (:func:`decide_votes`, the rule of :mod:`freespace.datagen.road_votes`): a don't-care pixel becomes
   road when a source says road and none says not road; a contradicted label becomes don't care when more sources
   contradict than agree. With ``override``, a pixel the teacher called not road becomes road when at least
   ``override`` sources say road and none agrees with the teacher: the far lanes the teacher is sure of and wrong
   about.

Conventions: pixels 0-based (``u`` column, ``v`` row); a homography ``H_ts`` maps frame ``t``'s pixel ``(u, v, 1)``
to frame ``s``'s (``x_s ~ H_ts x_t``), as in :mod:`freespace.datagen.road_votes`. Labels are ``uint8 H×W`` class
maps: 1 road, 0 not road, :data:`~freespace.labels.IGNORE_INDEX` don't care. NumPy and OpenCV only, never torch.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from freespace.datagen.road_votes import blurred_grey, decide_votes
from freespace.errors import InvalidOptionError, ShapeMismatchError
from freespace.labels import IGNORE_INDEX

__all__ = ["CarryOptions", "road_homography", "sequence_homographies", "chain_homographies", "carried_votes",
           "carry_along"]


@dataclass(frozen=True)
class CarryOptions:
    """Settings of :func:`carry_along`.

    The defaults are the settings measured on CamVid ``val`` (15 frames a second) with the published model as the
    teacher: 24 frames ahead label 91 % of the human road as road where the confident label alone labels 86 %.

    Attributes:
        window: source frames after each frame (and before it when ``both_ways``), ≥ 1.
        both_ways: also take sources before the frame (the road a car stood on, seen from behind it).
        min_inliers: a pair's homography needs at least this many RANSAC inliers (≥ 8).
        ransac_pixels: RANSAC's reprojection threshold, pixels (> 0).
        max_grey_difference: grey levels (0–255, after a 5-pixel blur) by which the two images may differ where a
            vote counts (> 0).
        override: sources saying road (and none agreeing with the teacher) that turn a not-road label to road;
            0 never does.
    """

    window: int = 24
    both_ways: bool = False
    min_inliers: int = 20
    ransac_pixels: float = 3.0
    max_grey_difference: float = 20.0
    override: int = 3

    def check(self) -> CarryOptions:
        """The options, or :class:`~freespace.errors.InvalidOptionError` naming the first bad one."""
        if self.window < 1 or self.min_inliers < 8 or self.override < 0:
            raise InvalidOptionError(f"window must be ≥ 1, min_inliers ≥ 8 and override ≥ 0; got {self.window}, "
                                     f"{self.min_inliers}, {self.override}")
        if not (self.ransac_pixels > 0 and self.max_grey_difference > 0):
            raise InvalidOptionError("ransac_pixels and max_grey_difference must be > 0; got "
                                     f"{self.ransac_pixels}, {self.max_grey_difference}")
        return self


def _features(grey: np.ndarray, mask: np.ndarray) -> tuple[list, np.ndarray | None]:
    """ORB keypoints and descriptors within 12 pixels of ``mask``, on the contrast-equalised (CLAHE) grey image:
    dark frames (dusk) keep enough corners."""
    orb = cv2.ORB_create(nfeatures=2000, scaleFactor=1.2, nlevels=6, edgeThreshold=15, patchSize=15,
                         fastThreshold=5)
    near = cv2.dilate(mask.astype(np.uint8) * 255, np.ones((25, 25), np.uint8))
    return orb.detectAndCompute(cv2.createCLAHE(3.0, (8, 8)).apply(grey), near)


def road_homography(earlier: np.ndarray, later: np.ndarray, road_earlier: np.ndarray, road_later: np.ndarray,
                    options: CarryOptions = CarryOptions()) -> np.ndarray | None:
    """The road plane's homography from ``earlier`` to ``later`` (step 1 of the module docstring).

    Args:
        earlier, later: ``H×W×3 uint8`` RGB frames of one camera (or ``H×W`` grey).
        road_earlier, road_later: ``bool H×W``: where each frame's road is (e.g. the teacher's p ≥ 0.5); features
            are taken within 12 pixels of it.
        options: ``min_inliers`` and ``ransac_pixels`` are used.

    Returns:
        ``float64 3×3`` ``H`` with ``x_later ~ H x_earlier`` (normalised ``H[2, 2] = 1``), or ``None`` when the
        frames share too few road features or the fit is degenerate.
    """
    if earlier.shape[:2] != later.shape[:2]:
        raise ShapeMismatchError(f"frames of {earlier.shape[1]}×{earlier.shape[0]} and {later.shape[1]}×"
                                 f"{later.shape[0]} pixels (W×H): carry labels between frames of one camera")
    return _fit(_features(_grey(earlier), road_earlier), _features(_grey(later), road_later), earlier.shape[:2],
                options)


def _fit(a_features: tuple, b_features: tuple, shape: tuple[int, int], options: CarryOptions) -> np.ndarray | None:
    """:func:`road_homography` from the two frames' ORB keypoints and descriptors (:func:`_features`)."""
    (kp_a, des_a), (kp_b, des_b) = a_features, b_features
    if des_a is None or des_b is None or len(kp_a) < options.min_inliers or len(kp_b) < options.min_inliers:
        return None
    pairs = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(des_a, des_b, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < 0.8 * p[1].distance]
    if len(good) < options.min_inliers:
        return None
    a = np.float32([kp_a[m.queryIdx].pt for m in good])
    b = np.float32([kp_b[m.trainIdx].pt for m in good])
    H, inliers = cv2.findHomography(a, b, cv2.RANSAC, options.ransac_pixels, maxIters=2000, confidence=0.999)
    if H is None or int(inliers.sum()) < options.min_inliers or not _plausible(H, shape):
        return None
    return H / H[2, 2]


def _grey(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image


def _plausible(H: np.ndarray, shape: tuple[int, int]) -> bool:
    """Whether ``H`` keeps the image's bottom half in front of the camera, unfolded and of a sane scale."""
    h, w = shape
    corners = np.float64([[0, h / 2, 1], [w - 1, h / 2, 1], [w - 1, h - 1, 1], [0, h - 1, 1]]).T
    mapped = H @ corners
    if np.any(mapped[2] <= 0) or abs(H[2, 2]) < 1e-12:
        return False
    x, y = mapped[:2] / mapped[2]
    area = 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))  # the shoelace formula: > 0 unflipped
    return bool(0.05 < area / (w * h / 2) < 20)


def chain_homographies(steps: Sequence[np.ndarray | None]) -> list[np.ndarray | None]:
    """Homographies from frame 0 to frames 1…n given the consecutive ones (``steps[i]``: frame ``i`` → ``i + 1``);
    after a missing step, every later one is ``None`` (the chain is broken)."""
    out: list[np.ndarray | None] = []
    H: np.ndarray | None = np.eye(3)
    for step in steps:
        H = None if H is None or step is None else step @ H
        out.append(None if H is None else H / H[2, 2])
    return out


def carried_votes(image: np.ndarray, sources: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
                  max_grey_difference: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """Road and not-road votes of ``sources`` on ``image`` (step 3 of the module docstring).

    Args:
        image: ``H×W×3 uint8`` RGB frame ``t``.
        sources: per source frame ``s``: its image, its class-map label (``uint8 H×W``) and ``H_ts`` (``t``'s pixels
            → ``s``'s pixels).
        max_grey_difference: see :class:`CarryOptions`.

    Returns:
        ``int16 H×W`` road votes and not-road votes.
    """
    h, w = image.shape[:2]
    grey_t = blurred_grey(image)
    road = np.zeros((h, w), np.int16)
    other = np.zeros((h, w), np.int16)
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    flags = cv2.WARP_INVERSE_MAP
    for src_image, src_label, H in sources:
        if src_image.shape[:2] != (h, w) or src_label.shape != (h, w):
            raise ShapeMismatchError(f"a source frame or label is not {w}×{h} (W×H) like the frame it votes on")
        ahead = (H[2, 0] * u + H[2, 1] * v + H[2, 2]) > 0  # in front of both cameras
        code = np.where(src_label == 1, 2, np.where(src_label == 0, 1, 0)).astype(np.uint8)
        code_t = cv2.warpPerspective(code, H, (w, h), flags=cv2.INTER_NEAREST | flags, borderValue=0)
        grey_s = cv2.warpPerspective(blurred_grey(src_image), H, (w, h), flags=cv2.INTER_LINEAR | flags,
                                     borderValue=-1000.0)
        agree = (np.abs(grey_s - grey_t) <= max_grey_difference) & ahead
        road += (code_t == 2) & agree
        other += (code_t == 1) & agree
    return road, other


def sequence_homographies(images: Sequence[np.ndarray], roads: Sequence[np.ndarray],
                          options: CarryOptions = CarryOptions()) -> list[np.ndarray | None]:
    """The road homographies of consecutive frames: ``out[i]`` maps frame ``i``'s pixels to frame ``i + 1``'s
    (:func:`road_homography`; ``None`` where the pair shares too little road). ``images``: ``H×W×3 uint8`` RGB
    frames of one camera in time order; ``roads``: each frame's road region (``bool H×W``). Each frame's features
    are found once and matched with both its neighbours'."""
    if len(roads) != len(images):
        raise ShapeMismatchError(f"{len(images)} frames and {len(roads)} road maps: give one road map a frame")
    shapes = {image.shape[:2] for image in images}
    if len(shapes) > 1:
        raise ShapeMismatchError(f"frames of {len(shapes)} sizes: carry labels between frames of one camera")
    features = [_features(_grey(image), road) for image, road in zip(images, roads)]
    return [_fit(features[i], features[i + 1], images[i].shape[:2], options) for i in range(len(images) - 1)]


def carry_along(images: Sequence[np.ndarray], labels: Sequence[np.ndarray], roads: Sequence[np.ndarray] | None,
                options: CarryOptions = CarryOptions(), steps: Sequence[np.ndarray | None] | None = None,
                voters: Sequence[bool] | None = None) -> tuple[list[np.ndarray], dict[str, float]]:
    """Every frame's label with the road its neighbours saw (the module docstring's steps 1–4).

    Args:
        images: ``H×W×3 uint8`` RGB frames of one camera, consecutive, in time order.
        labels: each frame's class map (``uint8 H×W``: 1 road, 0 not road, 255 don't care), e.g. the teacher's
            confident label.
        roads: each frame's road region for the features (``bool H×W``, e.g. the teacher's p ≥ 0.5); unused when
            ``steps`` are given.
        options: :class:`CarryOptions`.
        steps: the consecutive homographies (:func:`sequence_homographies`), when already known.
        voters: per frame, whether its label may vote on other frames (None: every frame's); e.g. adapt's held-out
            frames give no label.

    Returns:
        The new labels (class maps) and a record: ``pairs`` (consecutive pairs), ``pairs_fitted`` (with a
        homography), and over the voting frames' pixels ``gained`` (don't care → road), ``overridden`` (not road →
        road), ``conflicts`` (→ don't care).
    """
    options = options.check()
    n = len(images)
    if len(labels) != n:
        raise ShapeMismatchError(f"{n} frames and {len(labels)} labels: give one label a frame")
    if steps is None:
        steps = sequence_homographies(images, roads if roads is not None else [], options)
    elif len(steps) != max(n - 1, 0):
        raise ShapeMismatchError(f"{n} frames and {len(steps)} homographies: give one a consecutive pair")
    if voters is None:
        voters = [True] * n
    elif len(voters) != n:
        raise ShapeMismatchError(f"{n} frames and {len(voters)} voter flags: give one a frame")
    inverse = [None if H is None else np.linalg.inv(H) for H in steps]
    out, totals = [], np.zeros(3)
    for t in range(n):
        ahead = chain_homographies(steps[t:t + options.window])
        sources = [(images[t + k + 1], labels[t + k + 1], H) for k, H in enumerate(ahead)
                   if H is not None and voters[t + k + 1]]
        if options.both_ways:
            behind = chain_homographies(inverse[max(t - options.window, 0):t][::-1])
            sources += [(images[t - k - 1], labels[t - k - 1], H) for k, H in enumerate(behind)
                        if H is not None and voters[t - k - 1]]
        road_votes, other_votes = carried_votes(images[t], sources, options.max_grey_difference)
        label, change = _decide(labels[t], road_votes, other_votes, options.override)
        out.append(label)
        if voters[t]:
            totals += [np.mean(change == k) for k in (1, 3, 2)]
    shares = totals / max(sum(bool(v) for v in voters), 1)
    return out, {"pairs": max(n - 1, 0), "pairs_fitted": sum(H is not None for H in steps),
                 "gained": round(float(shares[0]), 4), "overridden": round(float(shares[1]), 4),
                 "conflicts": round(float(shares[2]), 4)}


def _decide(label: np.ndarray, road_votes: np.ndarray, other_votes: np.ndarray,
            override: int) -> tuple[np.ndarray, np.ndarray]:
    """A class map's vote (:func:`~freespace.datagen.road_votes.decide_votes`), then the override; the change map
    adds 3 for not road → road."""
    valid = label != IGNORE_INDEX
    road = label == 1
    flipped = np.zeros(label.shape, bool)
    if override:
        flipped = valid & ~road & (road_votes >= override) & (other_votes == 0)
        road = road | flipped
    road, valid, change = decide_votes(road, valid, road_votes, other_votes)
    change[flipped & valid & road] = 3
    out = np.where(valid, road.astype(np.uint8), IGNORE_INDEX).astype(np.uint8)
    return out, change
