"""Votes of later frames on an earlier frame's label, for propagation (:mod:`freespace.datagen.propagate`, steps 2–4):
the plane-induced homography of the earlier frame's road plane and the motion to each source frame carries each
source's sure labels onto the earlier frame, where the images agree; road fills don't care, contradictions become
don't care. NumPy and OpenCV only, never torch.
"""

from __future__ import annotations

import cv2
import numpy as np

from freespace.datagen.ego_motion import Motion, grey
from freespace.datagen.options import PropagateOptions
from freespace.geometry import RoadModel
from freespace.geometry.homography import homography_from_pose
from freespace.geometry.plane import RoadPlane
from freespace.labels import RoadLabel

__all__ = ["propagate_frame", "decide_votes", "blurred_grey"]


def blurred_grey(image: np.ndarray) -> np.ndarray:
    """``image`` (``H×W×3`` RGB or ``H×W`` grey, ``uint8``) as ``float32 H×W`` grey levels after a 5-pixel Gaussian
    blur: what two frames are compared on where a vote counts."""
    return cv2.GaussianBlur(grey(image).astype(np.float32), (5, 5), 0)


def decide_votes(road: np.ndarray, valid: np.ndarray, road_votes: np.ndarray,
                 other_votes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A label after its sources' votes (step 4 of :mod:`freespace.datagen.propagate`).

    Args:
        road, valid: ``bool H×W``: the frame's own label (road where ``valid & road``; don't care where not valid).
        road_votes, other_votes: ``int H×W``: sources saying road and not road at each pixel.

    Returns:
        The new ``road`` and ``valid`` (``bool H×W``) and a ``uint8 H×W`` change map: 0 unchanged, 1 don't care →
        road, 2 → don't care (more sources contradict the label than agree with it).
    """
    road, valid = road.copy(), valid.copy()
    gained = ~valid & (road_votes > 0) & (other_votes == 0)
    against = np.where(road, other_votes, road_votes)
    support = np.where(road, road_votes, other_votes)
    conflict = valid & (against > 0) & (against > support)
    road[gained], valid[gained] = True, True
    road[conflict], valid[conflict] = False, False
    change = np.zeros(road.shape, np.uint8)
    change[gained], change[conflict] = 1, 2
    return road, valid, change


def propagate_frame(image: np.ndarray, label: RoadLabel, model: RoadModel, K: np.ndarray, baseline: float,
                    sources: list[tuple[np.ndarray, RoadLabel, RoadModel, Motion]], *,
                    options: PropagateOptions = PropagateOptions()) -> tuple[RoadLabel, np.ndarray]:
    """Frame ``t``'s label with the road its later frames saw (steps 2–4 of :mod:`freespace.datagen.propagate`).

    Args:
        image: ``H×W×3`` RGB ``uint8`` left image of ``t``. label: its own autolabel. model: its fitted road model.
        K: 3×3 intrinsics (pixels). baseline: metres.
        sources: per source frame ``s``: its left image, autolabel, road model, and the motion from ``t`` to ``s``.

    Returns:
        The new label and a ``uint8 H×W`` map of what changed: 0 unchanged, 1 don't care → road, 2 → don't care
        (a conflict).
    """
    h, w = label.shape
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    plane = RoadPlane.from_road_model(model, fx, baseline, cx, cy, fy)
    below_horizon = model.disparity((h, w)) > 0
    grey_t = blurred_grey(image)
    road_votes = np.zeros((h, w), np.int16)
    other_votes = np.zeros((h, w), np.int16)
    near_disparity = fx * baseline / options.near_depth
    for src_image, src_label, src_model, motion in sources:
        H = homography_from_pose(K, K, motion.R, motion.t, plane)  # t's road pixels → s's pixels
        sure = src_label.valid & (src_model.disparity((h, w)) >= near_disparity)
        code = np.where(sure, np.where(src_label.road, 2, 1), 0).astype(np.uint8)
        flags = cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP
        code_t = cv2.warpPerspective(code, H, (w, h), flags=flags, borderValue=0)
        grey_s = cv2.warpPerspective(blurred_grey(src_image), H, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                     borderValue=-1000.0)
        agree = (np.abs(grey_s - grey_t) <= options.max_grey_difference) & below_horizon
        road_votes += (code_t == 2) & agree
        other_votes += (code_t == 1) & agree
    road, valid, change = decide_votes(label.road, label.valid, road_votes, other_votes)
    return RoadLabel(road=road, valid=valid), change
