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
the left (reference) image, NaN (or ≤ 0, ±inf) = none. This module imports NumPy and OpenCV only, never
torch.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass, field
from typing import Any

import cv2
import numpy as np

from freespace.errors import FreespaceError, InvalidOptionError, RoadFitError, param
from freespace.geometry import SGBM_MAX_DISPARITY, RoadModel, fit_road_model
from freespace.geometry.road_model import CAMERA_HEIGHT_RANGE_M
from freespace.io.codecs import road_label_to_kitti
from freespace.labels import RoadLabel

__all__ = ["AutolabelOptions", "AutolabelResult", "autolabel"]



@dataclass(frozen=True)
class AutolabelOptions:
    """Settings of :func:`autolabel` (see the module docstring for what each does).

    Attributes:
        curb_height: metres; the smallest step off the road the label must tell apart (default 0.10).
        camera_height: metres above the road, used for ``H`` when the baseline is not known (default 1.65,
            KITTI's rig); with a baseline, ``H = B/ϰ`` from the fit.
        curb_fraction: the road tolerance as a share of a curb's residual (default 0.5: half-way).
        noise_factor: the road tolerance's floor in units of the disparity noise σ (default 2).
        noise: σ in pixels, constant, or None to estimate ``σ_px`` and the roughness from the fit (default).
        min_noise: floor of the estimated σ in pixels (default 0.05: exact disparities are not exact
            on a pixel grid).
        band: non-road from ``band·t`` on; between ``t`` and ``band·t`` don't care (default 2).
        window: side in pixels of the box the residual is averaged over (odd; default 5).
        max_roll_deg: largest |roll| of an acceptable road plane, degrees (default 15).
        min_speck: road or non-road regions smaller than this share of the image become don't care
            (default 0.0005).
        max_hole: don't-care holes enclosed by road and smaller than this share of the image become
            road (default 0.002).
        max_disparity: SGBM search range (pixels) when the disparity is computed from a stereo pair.
        max_camber_deg: lanes beside the road on a plane of their own (a cambered street) are road when that
            plane's roll differs from the road's by at most this many degrees and it meets the road without a
            step (default 5; 0: one plane only).
    """

    curb_height: float = 0.10
    camera_height: float = 1.65
    curb_fraction: float = 0.5
    noise_factor: float = 2.0
    noise: float | None = None
    min_noise: float = 0.05
    band: float = 2.0
    window: int = 5
    max_roll_deg: float = 15.0
    min_speck: float = 0.0005
    max_hole: float = 0.002
    max_disparity: int = SGBM_MAX_DISPARITY
    max_camber_deg: float = 5.0

    def check(self) -> None:
        """Raise :class:`InvalidOptionError` (one line) for a value out of range."""
        positive = {"curb_height": self.curb_height, "camera_height": self.camera_height,
                    "curb_fraction": self.curb_fraction, "noise_factor": self.noise_factor,
                    "min_noise": self.min_noise, "max_roll_deg": self.max_roll_deg}
        for name, value in positive.items():
            if not 0 < value < math.inf:
                raise InvalidOptionError(f"{param(name)} must be a finite number > 0, got {value}")
        if not CAMERA_HEIGHT_RANGE_M[0] <= self.camera_height <= CAMERA_HEIGHT_RANGE_M[1]:
            raise InvalidOptionError(f"{param('camera_height')} must be {CAMERA_HEIGHT_RANGE_M[0]:g}–"
                                     f"{CAMERA_HEIGHT_RANGE_M[1]:g} m (the heights every road fit keeps), got "
                                     f"{self.camera_height}")
        if self.noise is not None and not 0 < self.noise < math.inf:
            raise InvalidOptionError(f"{param('noise')} must be a finite number of pixels > 0, got {self.noise}")
        if not 1 < self.band < math.inf:
            raise InvalidOptionError(f"{param('band')} must be a finite number > 1, got {self.band}")
        if self.window < 1 or self.window % 2 == 0:
            raise InvalidOptionError(f"{param('window')} must be an odd number of pixels ≥ 1, got {self.window}")
        if not (0 <= self.min_speck < 1 and 0 <= self.max_hole < 1):
            raise InvalidOptionError(f"{param('min_speck')} and {param('max_hole')} are shares of the image, in [0, 1)")
        if not 0 <= self.max_camber_deg <= 30:
            raise InvalidOptionError(f"{param('max_camber_deg')} must be 0–30 degrees, got {self.max_camber_deg}")
        if not 1 <= self.max_disparity <= 1024:
            raise InvalidOptionError(f"{param('max_disparity')} must be in 1..1024 pixels, got {self.max_disparity}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings."""
        return asdict(self)


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


def _box_mean(values: np.ndarray, weights: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Weighted box average of ``values`` over ``window×window`` (``weights`` 0/1); NaN where no weight."""
    if window == 1:
        return np.where(weights > 0, values, np.nan).astype(np.float32), weights.astype(np.float32)
    k = (window, window)
    num = cv2.boxFilter(np.where(weights > 0, values, 0).astype(np.float32), -1, k, normalize=False,
                        borderType=cv2.BORDER_CONSTANT)
    den = cv2.boxFilter(weights.astype(np.float32), -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.maximum(den, 1e-6), np.nan).astype(np.float32), den


def _seed_window(shape: tuple[int, int]) -> np.ndarray:
    """``bool H×W``: the lower image centre (bottom quarter of the rows, middle half of the columns)."""
    h, w = shape
    seed = np.zeros((h, w), bool)
    seed[3 * h // 4:, w // 4: w - w // 4] = True
    return seed


def _fit_seed(disparity: np.ndarray, valid: np.ndarray, max_roll_deg: float) -> RoadModel:
    """The dominant plane (MSAC + least squares) of the lower image centre, else of the lower half,
    checked to be a road seen from above."""
    h = disparity.shape[0]
    lower = valid.copy()
    lower[: h // 2] = False
    failure: FreespaceError | None = None
    for region in (_seed_window(disparity.shape) & valid, lower):
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
            _check_road_plane(model, max_roll_deg)
            return model
        except RoadFitError as exc:
            failure = exc
    if failure is not None:
        raise failure
    raise RoadFitError(f"only {np.count_nonzero(lower)} pixels of the lower half of the image have a disparity; "
                       f"a road label needs the road's disparity (check the disparity map or the stereo pair)")


def _check_road_plane(model: RoadModel, max_roll_deg: float) -> None:
    if model.affine[1] <= 0 or abs(model.roll_deg) > max_roll_deg:
        raise RoadFitError(f"the dominant plane of the lower image (roll {model.roll_deg:+.1f}°, disparity "
                           f"{'growing' if model.affine[1] > 0 else 'not growing'} downwards) is not a road seen "
                           f"by a forward-looking stereo rig; check that the disparity is the left image's and "
                           f"that the road fills the lower image centre")


def _components(mask: np.ndarray, min_size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """8-connected components of ``mask``: labels, sizes (index = label) and the mask of specks (< min_size)."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    sizes = stats[:, cv2.CC_STAT_AREA]
    small = np.zeros(n, bool)
    small[1:] = sizes[1:] < min_size
    return labels, sizes, small[labels]


def _row_profile(residual: np.ndarray, road: np.ndarray, window: int = 9, min_pixels: int = 5) -> np.ndarray:
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


def _label_once(disparity: np.ndarray, valid: np.ndarray, model: RoadModel, road: np.ndarray, baseline: float | None,
                options: AutolabelOptions, noise: float | None) -> dict[str, Any]:
    """One labelling pass with a given model and the road of the pass before (``bool H×W``, for the row
    profile and the noise): the arrays and numbers :func:`autolabel` assembles."""
    h, w = disparity.shape
    m = model.disparity((h, w))
    raw = disparity - m
    raw -= _row_profile(raw, road & valid)[:, None]
    residual, _ = _box_mean(raw, valid, options.window)
    camera_height = baseline / model.kappa_hat if baseline else options.camera_height
    if noise is None:
        noise_px, slope = _noise_model(residual, m, road & valid & np.isfinite(residual))
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


def _side_planes(disparity: np.ndarray, valid: np.ndarray, model: RoadModel, road: np.ndarray, p: dict[str, Any],
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
    labels, sizes, _ = _components(candidates, min_size)
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
        residual, _ = _box_mean(disparity - side.disparity((h, w)), valid, options.window)
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
    labels, _, _ = _components(mask | road, 1)
    keep = np.unique(labels[road])
    return np.isin(labels, keep[keep > 0]) & mask


def _noise_model(residual: np.ndarray, m: np.ndarray, road: np.ndarray, bins: int = 8) -> tuple[float, float]:
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
        road = road | _side_planes(disparity, valid, model, road, p, options, min_speck)
    nonroad = (p["nonroad"] | p["sky"]) & ~road
    _, _, nonroad_specks = _components(nonroad & ~p["sky"], min_speck)
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
    labelling's maps (:func:`_label_once`): label with the seed plane's model, refit to that road, twice. A
    rough seed plane (no road found, noise estimated) widens its noise band until it finds road.

    Raises:
        RoadFitError: no road of at least 50 pixels connected to the lower centre.
    """
    model = _fit_seed(disparity, valid, options.max_roll_deg)
    seed = _seed_window(disparity.shape)
    noise = options.noise
    road = model.inlier_mask if model.inlier_mask is not None else valid
    for final in (False, False, True):  # label with the seed's plane, refit to that road, twice
        for _ in range(4):
            p = _label_once(disparity, valid, model, road, baseline, options, noise)
            labels, sizes, _ = _components(p["road"], min_speck)
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
        _check_road_plane(model, options.max_roll_deg)
        noise = options.noise
    return road, model, p


def _enclosed_holes(road: np.ndarray, nonroad: np.ndarray, max_hole: float) -> np.ndarray:
    """The don't-care regions (neither ``road`` nor ``nonroad``, ``bool H×W``) that road encloses: touching
    neither the image border nor non-road, and at most ``max_hole`` of the image's pixels. They become road."""
    h, w = road.shape
    unknown = ~(road | nonroad)
    hole_labels, hole_sizes, _ = _components(unknown, 1)
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
