"""Road labels without people: a road label from a left image's disparity alone (:func:`autolabel`; files,
datasets and ``freespace autolabel``: :mod:`freespace.datagen.autolabel`).

The method (all in disparity pixels, so it needs neither the focal length nor, by default, the baseline):

1. **Road model, fitted to the whole frame.** The road disparity model ``d = ϰ (v cos Φ − u sin Φ + κ)``
   (:mod:`freespace.geometry.road_model`) is fitted robustly (MSAC, then least squares on the inliers)
   to every valid pixel of the lower half of the image, where the road is the dominant plane of a
   driving scene; the plane must slope the right way (ϰ > 0, disparity growing downwards, |Φ| below
   :attr:`AutolabelOptions.max_roll_deg`). It is then fitted again to the road the first pass labelled.
   The **seed** of the road is the lower image centre: the labelled road is the part connected to the
   pixels of the bottom quarter's middle half that agree with the plane.
2. **Residuals, scaled by what a curb does.** A point ``h`` metres above the road, seen at model
   disparity ``m``, has disparity ``m·H/(H − h) ≈ m (1 + h/H)`` (H: camera height above the road,
   ``B/ϰ`` when the baseline ``B`` is known, else :attr:`AutolabelOptions.camera_height`): a curb of height
   ``h_c`` leaves a residual of about ``c(m) = h_c·m/H`` pixels, which shrinks with distance, while the
   disparity noise does not. The residual ``r = d − m``, less each row's median road residual (a running
   median over rows: the v-disparity profile of a road that is not quite planar), is averaged over a small
   window (valid pixels only). Its noise is modelled as ``σ(m) = σ_px + s·m`` — a matcher's constant noise
   and a road roughness of ``s·H`` metres, which grows with ``m`` as a height does — fitted to the robust
   spread (1.4826·MAD) of the averaged residual on the road, in disparity bins; ``σ_px`` is floored at
   :attr:`AutolabelOptions.min_noise`.
3. **The label.** With ``t(m) = max(curb_fraction·c(m), noise_factor·σ)`` — a tolerance in pixels that,
   as a height above the road (``H·t/m`` metres), grows with distance — a pixel is road when
   ``|r| ≤ t``, non-road when ``|r| ≥ band·t``, and don't care in between (residual near the threshold).
4. **Don't care where the evidence is weak:** no disparity; a residual near the threshold; far rows, where
   a whole curb's residual ``c(m)`` is below ``noise_factor·σ(m)`` (there only a
   clearly off-plane pixel, ``|r| ≥ band·t``, is labelled, as non-road); road-plane regions not connected
   to the seed; specks smaller than :attr:`AutolabelOptions.min_speck` of the image.
5. **Above the horizon.** The band from the far limit up to as many rows above the plane's horizon
   (where ``m = 0``) is don't care; what lies above that band is **non-road**, with or without a
   disparity: a planar road cannot be seen above its own horizon, and the sky — which has no disparity —
   would otherwise be don't care and cap the coverage at about three quarters of a driving image.
   This is the one place where a pixel without disparity gets a label; roads that climb steeply above
   the fitted plane's horizon are the case it gets wrong.
6. **Clean-up.** Holes in the road (don't care, not non-road, smaller than :attr:`AutolabelOptions.max_hole`
   of the image and enclosed by road) become road: lane markings a matcher failed on, LiDAR gaps.

The confidence (``float32`` in [0, 1]) is 0 on don't care, 1 above the horizon band, and grows with the
distance of ``|r|/t`` from the decision band elsewhere (at least 0.5 on every labelled pixel; filled holes
0.5).

Conventions: pixels 0-based, ``u`` = column, ``v`` = row; a disparity map is ``float32 H×W`` in pixels of
the left (reference) image, NaN (or ≤ 0, ±inf) = none. NumPy and OpenCV only, never torch.

Where each step lives: the settings in :mod:`freespace.datagen.options` (:class:`AutolabelOptions`, importable from
here too), steps 1–3 (one labelling pass) in :mod:`freespace.datagen.label_pass`, the cambered lanes in
:mod:`freespace.datagen.camber`; this module grows the road from the seed, cleans it up and scores the confidence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from freespace.datagen.camber import side_planes
from freespace.datagen.label_pass import check_road_plane, components, fit_seed, label_once, seed_window
from freespace.datagen.options import AutolabelOptions
from freespace.errors import InvalidOptionError, RoadFitError
from freespace.geometry import RoadModel, fit_road_model
from freespace.io.codecs import road_label_to_kitti
from freespace.labels import RoadLabel

__all__ = ["AutolabelOptions", "AutolabelResult", "autolabel"]


@dataclass
class AutolabelResult:
    """An autolabel: the label, its confidence, the fitted road model and statistics.

    Attributes:
        label: ``road`` and ``valid`` (``bool H×W``; ``valid`` False = don't care).
        confidence: ``float32 H×W`` in [0, 1]; 0 exactly on don't care.
        model: the road model fitted to the labelled road.
        stats: ``noise_px`` (σ), ``camera_height_m`` (H used), ``horizon_row`` (at the image centre
            column), ``coverage`` (share of pixels labelled), ``road_fraction``, ``valid_disparity``.
    """

    label: RoadLabel
    confidence: np.ndarray
    model: RoadModel
    stats: dict[str, Any] = field(default_factory=dict)

    def kitti(self) -> np.ndarray:
        """The label in KITTI colours (``H×W×3 uint8`` RGB: road magenta, non-road red, don't care black)."""
        return road_label_to_kitti(self.label)

    def confidence_u8(self) -> np.ndarray:
        """The confidence as ``uint8 H×W`` (``round(255·c)``)."""
        return np.rint(np.clip(self.confidence, 0, 1) * 255).astype(np.uint8)

    def report(self) -> dict[str, Any]:
        """JSON-ready road model and statistics."""
        return {**self.model.to_dict(), **self.stats}


def autolabel(disparity: np.ndarray, *, baseline: float | None = None,
              options: AutolabelOptions = AutolabelOptions()) -> AutolabelResult:
    """A road label of the left image from its disparity alone (the method: module docstring).

    Args:
        disparity: ``float32 H×W`` left disparity in pixels; NaN, ±inf and values ≤ 0 are "none".
        baseline: the rig's baseline in metres, if known: the camera height becomes ``B/ϰ`` of the fit
            instead of ``options.camera_height``. The focal length is never needed.
        options: thresholds (:class:`AutolabelOptions`).

    Returns:
        An :class:`AutolabelResult` (label with don't care, confidence in [0, 1], model, statistics).

    Raises:
        InvalidOptionError: not a 2-D map, or a bad option. RoadFitError: no road plane in the lower
        image (too little disparity there, or its dominant plane is not a road).
    """
    options.check()
    disparity = np.asarray(disparity, dtype=np.float32)
    if disparity.ndim != 2:
        raise InvalidOptionError(f"disparity must be a 2-D H×W map, got shape {disparity.shape}")
    if baseline is not None and not 0 < baseline < math.inf:
        raise InvalidOptionError(f"the baseline must be a finite number of metres > 0, got {baseline}")
    h, w = disparity.shape
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(disparity) & (disparity > 0)
    min_speck = max(1, int(round(options.min_speck * h * w)))
    road, model, p = _grow_road(disparity, valid, baseline, options, min_speck)
    if options.max_camber_deg > 0:
        road = road | side_planes(disparity, valid, model, road, p, options, min_speck)
    nonroad = (p["nonroad"] | p["sky"]) & ~road
    _, _, nonroad_specks = components(nonroad & ~p["sky"], min_speck)
    nonroad &= ~nonroad_specks
    filled = _enclosed_holes(road, nonroad, options.max_hole)
    road |= filled
    label = RoadLabel(road=road, valid=road | nonroad)
    centre = p["m"][:, w // 2]
    below = np.nonzero(centre > 0)[0]
    stats = {"noise_px": round(float(p["noise"]), 4), "roughness_m": round(float(p["roughness"]), 4),
             "camera_height_m": round(float(p["camera_height"]), 4),
             "horizon_row": int(below[0]) if below.size else None,
             "coverage": round(float(label.valid.mean()), 4), "road_fraction": round(float(road.mean()), 4),
             "valid_disparity": round(float(valid.mean()), 4)}
    return AutolabelResult(label=label, confidence=_confidence(road, filled, nonroad, p, options.band), model=model,
                           stats=stats)


def _grow_road(disparity: np.ndarray, valid: np.ndarray, baseline: float | None, options: AutolabelOptions,
               min_speck: int) -> tuple[np.ndarray, RoadModel, dict[str, Any]]:
    """The road connected to the lower image centre (``bool H×W``), the road model refitted to it and the last
    labelling's maps (:func:`label_once`): label with the seed plane's model, refit to that road, twice. A
    rough seed plane (no road found, noise estimated) widens its noise band until it finds road.

    Raises:
        RoadFitError: no road of at least 50 pixels connected to the lower centre.
    """
    model = fit_seed(disparity, valid, options.max_roll_deg)
    seed = seed_window(disparity.shape)
    noise = options.noise
    road = model.inlier_mask if model.inlier_mask is not None else valid
    for final in (False, False, True):  # label with the seed's plane, refit to that road, twice
        for _ in range(4):
            p = label_once(disparity, valid, model, road, baseline, options, noise)
            labels, sizes, _ = components(p["road"], min_speck)
            keep = np.unique(labels[seed & p["road"]])
            keep = keep[(keep > 0) & (sizes[keep] >= min_speck)]
            found = np.isin(labels, keep)
            if np.count_nonzero(found) >= 50 or options.noise is not None:
                break
            noise = 2 * p["noise"] + p["roughness"]  # a rough seed plane: widen until it finds road
        road = found
        if np.count_nonzero(road) < 50:
            raise RoadFitError("no road connected to the lower image centre agrees with the fitted road plane; "
                               "the lower centre of the image must show road")
        if final:
            break
        model = fit_road_model(disparity, road, inlier_threshold=max(1.0, options.noise_factor * p["noise"]))
        check_road_plane(model, options.max_roll_deg)
        noise = options.noise
    return road, model, p


def _enclosed_holes(road: np.ndarray, nonroad: np.ndarray, max_hole: float) -> np.ndarray:
    """The don't-care regions (neither ``road`` nor ``nonroad``, ``bool H×W``) that road encloses: touching
    neither the image border nor non-road, and at most ``max_hole`` of the image's pixels. They become road."""
    h, w = road.shape
    unknown = ~(road | nonroad)
    hole_labels, hole_sizes, _ = components(unknown, 1)
    border = np.unique(np.concatenate([hole_labels[0], hole_labels[-1], hole_labels[:, 0], hole_labels[:, -1]]))
    touching = np.unique(hole_labels[cv2.dilate(nonroad.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0])
    fill_ok = np.zeros(hole_sizes.size, bool)
    fill_ok[1:] = hole_sizes[1:] <= max_hole * h * w
    fill_ok[border] = False
    fill_ok[touching] = False
    return fill_ok[hole_labels] & unknown


def _confidence(road: np.ndarray, filled: np.ndarray, nonroad: np.ndarray, p: dict[str, Any],
                band: float) -> np.ndarray:
    """The label's confidence (``float32 H×W`` in [0, 1]; 0 where don't care): road from how well its disparity
    fits the model (``p["ratio"]``: residual over the noise band), filled holes 0.5, non-road from how far it
    lies beyond the band, sky 1."""
    conf = np.zeros(road.shape, np.float32)
    ratio = np.nan_to_num(p["ratio"], nan=0.0)
    conf[road] = 0.5 + 0.5 * np.clip(1.0 - ratio[road], 0, 1)
    conf[filled] = 0.5
    conf[nonroad] = 0.5 + 0.5 * np.clip((ratio[nonroad] - band) / band, 0, 1)
    conf[nonroad & p["sky"]] = 1.0
    return conf
