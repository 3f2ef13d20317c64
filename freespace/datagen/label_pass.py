"""One labelling pass of the autolabel method (:mod:`freespace.datagen.labeller`, steps 1–3): the seed road plane, the
residual of each pixel to a road model (less the road's row profile, box-averaged), its noise model ``σ(m) = σ_px +
s·m``, and the road / non-road / sky decision with the curb-scaled tolerance. The connected components that the
method's clean-up and the cambered lanes (:mod:`freespace.datagen.camber`) use are here too. NumPy and OpenCV only,
never torch.
"""

from __future__ import annotations

import math
import re
from typing import Any

import cv2
import numpy as np

from freespace.datagen.options import AutolabelOptions
from freespace.errors import FreespaceError, RoadFitError
from freespace.geometry import RoadModel, fit_road_model

__all__ = ["box_mean", "seed_window", "fit_seed", "check_road_plane", "components", "row_profile", "label_once",
           "noise_model"]


def box_mean(values: np.ndarray, weights: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Weighted box average of ``values`` over ``window×window`` (``weights`` 0/1); NaN where no weight."""
    if window == 1:
        return np.where(weights > 0, values, np.nan).astype(np.float32), weights.astype(np.float32)
    k = (window, window)
    num = cv2.boxFilter(np.where(weights > 0, values, 0).astype(np.float32), -1, k, normalize=False,
                        borderType=cv2.BORDER_CONSTANT)
    den = cv2.boxFilter(weights.astype(np.float32), -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.maximum(den, 1e-6), np.nan).astype(np.float32), den


def seed_window(shape: tuple[int, int]) -> np.ndarray:
    """``bool H×W``: the lower image centre (bottom quarter of the rows, middle half of the columns)."""
    h, w = shape
    seed = np.zeros((h, w), bool)
    seed[3 * h // 4:, w // 4: w - w // 4] = True
    return seed


def fit_seed(disparity: np.ndarray, valid: np.ndarray, max_roll_deg: float) -> RoadModel:
    """The dominant plane (MSAC + least squares) of the lower image centre, else of the lower half,
    checked to be a road seen from above."""
    h = disparity.shape[0]
    lower = valid.copy()
    lower[: h // 2] = False
    failure: FreespaceError | None = None
    for region in (seed_window(disparity.shape) & valid, lower):
        if np.count_nonzero(region) < 50:
            continue
        try:
            model = fit_road_model(disparity, region, inlier_threshold=1.0)
        except RoadFitError as exc:  # its words are for a labelled road; autolabel reads no label
            failure = RoadFitError(f"the disparity of the lower image fits no road plane "
                                   f"({re.split('[:;]', str(exc))[0]}); check that the disparity is the left image's "
                                   f"and that the road fills the lower image centre")
            continue
        try:
            check_road_plane(model, max_roll_deg)
            return model
        except RoadFitError as exc:
            failure = exc
    if failure is not None:
        raise failure
    raise RoadFitError(f"only {np.count_nonzero(lower)} pixels of the lower half of the image have a disparity; "
                       f"a road label needs the road's disparity (check the disparity map or the stereo pair)")


def check_road_plane(model: RoadModel, max_roll_deg: float) -> None:
    if model.affine[1] <= 0 or abs(model.roll_deg) > max_roll_deg:
        raise RoadFitError(f"the dominant plane of the lower image (roll {model.roll_deg:+.1f}°, disparity "
                           f"{'growing' if model.affine[1] > 0 else 'not growing'} downwards) is not a road seen "
                           f"by a forward-looking stereo rig; check that the disparity is the left image's and "
                           f"that the road fills the lower image centre")


def components(mask: np.ndarray, min_size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """8-connected components of ``mask``: labels, sizes (index = label) and the mask of specks (< min_size)."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    sizes = stats[:, cv2.CC_STAT_AREA]
    small = np.zeros(n, bool)
    small[1:] = sizes[1:] < min_size
    return labels, sizes, small[labels]


def row_profile(residual: np.ndarray, road: np.ndarray, window: int = 9, min_pixels: int = 5) -> np.ndarray:
    """The road's offset from the plane, row by row (``float32 H``): the median residual of each row's
    road pixels, a running median over ``window`` rows, interpolated across rows without road (constant
    beyond the first and last). Zero when no row has ``min_pixels`` road pixels. This is the v-disparity
    profile of a road that is not quite planar (a change of slope, a car's pitch)."""
    h = residual.shape[0]
    rows, values = [], []
    for v in range(h):
        r = residual[v][road[v]]
        if r.size >= min_pixels:
            rows.append(v)
            values.append(float(np.median(r)))
    if not rows:
        return np.zeros(h, np.float32)
    half = window // 2
    arr = np.asarray(values)
    smooth = [float(np.median(arr[max(0, i - half): i + half + 1])) for i in range(arr.size)]
    return np.interp(np.arange(h), rows, smooth).astype(np.float32)


def label_once(disparity: np.ndarray, valid: np.ndarray, model: RoadModel, road: np.ndarray, baseline: float | None,
                options: AutolabelOptions, noise: float | None) -> dict[str, Any]:
    """One labelling pass with a given model and the road of the pass before (``bool H×W``, for the row
    profile and the noise): the arrays and numbers :func:`~freespace.datagen.labeller.autolabel` assembles."""
    h, w = disparity.shape
    m = model.disparity((h, w))
    raw = disparity - m
    raw -= row_profile(raw, road & valid)[:, None]
    residual, _ = box_mean(raw, valid, options.window)
    camera_height = baseline / model.kappa_hat if baseline else options.camera_height
    if noise is None:
        noise_px, slope = noise_model(residual, m, road & valid & np.isfinite(residual))
        noise_px = max(noise_px, options.min_noise)
    else:
        noise_px, slope = noise, 0.0
    mp = np.maximum(m, 0)
    sigma = noise_px + slope * mp                              # residual noise: matcher + road roughness
    curb = options.curb_height * mp / camera_height            # a curb's residual
    tol = np.maximum(options.curb_fraction * curb, options.noise_factor * sigma)
    ratio = np.abs(residual) / tol
    near = curb >= options.noise_factor * sigma                # a curb stands above the noise here
    has = np.isfinite(ratio)
    road = has & near & (ratio <= 1)
    nonroad = has & (ratio >= options.band) & (m > 0)
    # the far limit (curb = noise_factor·σ) and the horizon band, as far above the horizon as that is below
    denom = options.curb_height / camera_height - options.noise_factor * slope
    m_far = options.noise_factor * noise_px / denom if denom > 0 else math.inf
    sky = m <= -m_far
    noise = noise_px
    roughness = slope * camera_height
    return {"m": m, "residual": residual, "ratio": ratio, "road": road, "nonroad": nonroad, "sky": sky,
            "noise": noise, "roughness": roughness, "camera_height": camera_height, "m_far": m_far, "tol": tol,
            "near": near}


def noise_model(residual: np.ndarray, m: np.ndarray, road: np.ndarray, bins: int = 8) -> tuple[float, float]:
    """``(σ_px, s)`` of the residual's robust spread on the road, ``σ(m) = σ_px + s·m``: a constant matcher
    noise and a part that grows with the model disparity ``m`` as a height does (a road that is not
    quite planar, ``s·H`` metres). Both ≥ 0; a line fitted to the 1.4826·MAD of ``bins`` disparity bins."""
    r, d = residual[road], m[road]
    ok = d > 0
    r, d = r[ok], d[ok]
    if r.size < 20 * bins:
        return (float(1.4826 * np.median(np.abs(r - np.median(r)))) if r.size else 0.0), 0.0
    edges = np.quantile(d, np.linspace(0, 1, bins + 1))
    idx = np.clip(np.searchsorted(edges, d, side="right") - 1, 0, bins - 1)
    centres, spreads = [], []
    for b in range(bins):
        rb = r[idx == b]
        if rb.size >= 10:
            centres.append(float(np.median(d[idx == b])))
            spreads.append(float(1.4826 * np.median(np.abs(rb - np.median(rb)))))
    x, y = np.asarray(centres), np.asarray(spreads)
    slope, icpt = np.polyfit(x, y, 1) if x.size >= 2 and np.ptp(x) > 0 else (0.0, float(np.mean(y)))
    if slope < 0:
        return float(np.mean(y)), 0.0
    if icpt < 0:
        return 0.0, float(x @ y / (x @ x))
    return float(icpt), float(slope)
