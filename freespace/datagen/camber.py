"""Cambered streets for the autolabel method (:mod:`freespace.datagen.labeller`): the lanes beside the labelled road
that fall away from the crown onto a plane of their own, taken as road when that plane meets the road without a
step (a curb and a pavement do not). NumPy and OpenCV only, never torch.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from freespace.datagen.label_pass import box_mean, components
from freespace.datagen.options import AutolabelOptions
from freespace.errors import RoadFitError
from freespace.geometry import RoadModel, fit_road_model

__all__ = ["side_planes"]


def side_planes(disparity: np.ndarray, valid: np.ndarray, model: RoadModel, road: np.ndarray, p: dict[str, Any],
                 options: AutolabelOptions, min_size: int) -> np.ndarray:
    """Road beside the labelled road on a plane of its own that meets it without a step (``bool H×W``): the lanes
    of a cambered street, which fall away from its crown and leave the one fitted plane.

    Candidates are pixels with a disparity, near enough for a curb to show (``p["near"]``), not road, and within
    ``8·t`` of the road plane (four curb heights' worth of residual); each 8-connected group of them that touches the
    road and has ``min_size`` pixels gets a plane of its own (MSAC + least squares). The group's road is the part
    within the tolerance ``t`` of that plane (box-averaged, as in the first pass), kept when the plane slopes as a
    road does, its roll differs from the road's by at most :attr:`AutolabelOptions.max_camber_deg`, its camera
    height by at most 15 %, and it meets the road without a step: the road's own pixels along their border lie on the
    group's plane (median residual below ``t``), where a curb would leave them about ``2t`` off it; and the group's road
    lies below the road's plane (median), as lanes do that fall away from the crown to drain, where a pavement
    stands above the road.
    """
    h, w = disparity.shape
    tol, near = p["tol"], p["near"]
    with np.errstate(invalid="ignore"):
        off = np.abs(disparity - p["m"]) <= 8 * tol
    candidates = valid & near & ~road & off
    labels, sizes, _ = components(candidates, min_size)
    ring = cv2.dilate(road.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    extra = np.zeros((h, w), bool)
    for k in np.unique(labels[ring & candidates]):
        if k == 0 or sizes[k] < min_size:
            continue
        group = labels == k
        try:
            side = fit_road_model(disparity, group, inlier_threshold=max(1.0, options.noise_factor * p["noise"]))
        except RoadFitError:
            continue
        if (side.affine[1] <= 0 or abs(side.roll_deg - model.roll_deg) > options.max_camber_deg
                or abs(side.affine[1] / model.affine[1] - 1) > 0.15):
            continue
        residual, _ = box_mean(disparity - side.disparity((h, w)), valid, options.window)
        border = road & (cv2.dilate(group.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0) & np.isfinite(residual)
        if not border.any() or np.median(np.abs(residual[border]) / tol[border]) >= 1:
            continue  # the road beside it is off its plane: a step (a curb and a pavement), not a lane's camber
        with np.errstate(invalid="ignore"):
            lane = group & (np.abs(residual) <= tol)
            if lane.any() and np.median((disparity - p["m"])[lane] / tol[lane]) <= 0:
                extra |= lane  # below the road's plane, as a lane falling away from the crown; a pavement is above
    return extra & _touching(extra, road)


def _touching(mask: np.ndarray, road: np.ndarray) -> np.ndarray:
    """The 8-connected parts of ``mask`` that touch ``road`` (``bool H×W``)."""
    labels, _, _ = components(mask | road, 1)
    keep = np.unique(labels[road])
    return np.isin(labels, keep[keep > 0]) & mask
