"""The road disparity model of Fan et al. and its robust fit.

Conventions
-----------
Pixel coordinates are 0-based, ``u`` = column (to the right), ``v`` = row (down), pixel centres at
integers. The reference view is the left camera, the target the right one: a reference pixel
``(u, v)`` with disparity ``d`` sees the same point as the target pixel ``(u − d, v)``.

On a planar road the disparity is ``d = ϰ (v cos Φ − u sin Φ + κ)`` (Φ: roll angle of the rig, ϰ, κ:
road disparity projection coefficients). With ``a = −ϰ sin Φ``, ``b = ϰ cos Φ``, ``c = ϰ κ`` this is the
plane ``d = a u + b v + c``; the map (Φ, ϰ, κ) ↔ (a, b, c) is one-to-one for ϰ > 0, so minimising the
paper's energy ``E = Σ (dᵢ − ϰ (vᵢ cos Φ − uᵢ sin Φ + κ))²`` is a linear least-squares plane fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from freespace.errors import InvalidOptionError, RoadFitError, ShapeMismatchError, param

__all__ = ["RoadModel", "MAX_ROLL_DEG", "CAMERA_HEIGHT_RANGE_M", "MIN_INLIER_SHARE", "fit_road_model",
           "fit_road_model_closed_form", "road_energy", "road_pixels"]

#: Smallest number of valid road pixels :func:`fit_road_model` accepts.
MIN_ROAD_PIXELS = 50

#: Physical bounds of a fit (:meth:`RoadModel.check_plausible`), ones that a stereo rig on a road vehicle
#: cannot leave. Real rigs: KITTI's roll is within ±3° and its cameras 1.65 m above the road; cars, buses
#: and trucks carry cameras 0.3–4 m up. The renderer (``freespace synth``) draws the roll within
#: ±``max_roll_deg`` (at most 15°) and the height within ``camera_heights`` (0.3–6 m). A flipped
#: disparity map, or one of another frame, leaves them: vertically flipped PFMs of the two real KITTI
#: stereo frames give rolls of −179.7° and +35.0°.
MAX_ROLL_DEG = 20.0
#: (lowest, highest) camera height above the road in metres; checked when the rig's focal length and
#: baseline are known (:meth:`freespace.geometry.RoadPlane.from_road_model`).
CAMERA_HEIGHT_RANGE_M = (0.1, 8.0)
#: Smallest share of the valid road pixels that must agree with the fitted plane (robust fits). With the
#: default 1 px inlier threshold real KITTI frames keep 73–89 % (LiDAR and SGBM disparities); a threshold
#: of 0.25 px, below SGBM's noise, still keeps 24 %.
MIN_INLIER_SHARE = 0.1


@dataclass(frozen=True)
class RoadModel:
    """A fitted (or calibrated) road disparity model.

    Attributes:
        roll: Φ, the stereo rig's roll angle in radians (``atan2(−a, b)``).
        kappa_hat: ϰ = ``hypot(a, b)``, in disparity pixels per image pixel (> 0).
        kappa: κ = ``c / ϰ``, in image pixels.
        affine: ``(a, b, c)`` of the disparity plane ``d = a u + b v + c`` (pixels).
        num_inliers: road pixels the final fit used (0 for a model made from calibration).
        rms: root-mean-square disparity residual over those pixels, in pixels (NaN when not fitted).
        num_valid: valid road pixels offered to the fit.
        inlier_mask: ``bool H×W`` of the pixels used, or None.
    """

    roll: float
    kappa_hat: float
    kappa: float
    affine: tuple[float, float, float]
    num_inliers: int = 0
    rms: float = float("nan")
    num_valid: int = 0
    inlier_mask: np.ndarray | None = field(default=None, repr=False, compare=False)

    @classmethod
    def from_affine(cls, a: float, b: float, c: float, **stats: Any) -> RoadModel:
        """Build the model of the disparity plane ``d = a u + b v + c``.

        Raises:
            RoadFitError: ``a = b = 0`` (the disparity does not vary over the image: no roll angle).

        Example:
            >>> m = RoadModel.from_affine(0.0, 0.5, -20.0)  # d = (v − 40) / 2: zero on row 40
            >>> m.roll_deg == 0, m.kappa_hat, m.kappa
            (True, 0.5, -40.0)
        """
        kappa_hat = math.hypot(a, b)
        if not (np.isfinite([a, b, c]).all() and kappa_hat > 1e-9):
            raise RoadFitError(f"degenerate road plane d = {a:.3g}·u + {b:.3g}·v + {c:.3g}: the disparity does not "
                               f"change across the road, so it is not a road seen by a stereo rig; check the "
                               f"road label and the disparity")
        return cls(roll=math.atan2(-a, b), kappa_hat=kappa_hat, kappa=c / kappa_hat,
                   affine=(float(a), float(b), float(c)), **stats)

    @classmethod
    def from_roll(cls, roll: float, kappa_hat: float, kappa: float) -> RoadModel:
        """Build the model from the paper's parameters (Φ in radians, ϰ > 0, κ).

        Example:
            >>> [round(x, 4) for x in RoadModel.from_roll(math.radians(2.0), 0.5, -40.0).affine]
            [-0.0174, 0.4997, -20.0]
        """
        return cls.from_affine(-kappa_hat * math.sin(roll), kappa_hat * math.cos(roll), kappa_hat * kappa)

    @property
    def roll_deg(self) -> float:
        """Φ in degrees."""
        return math.degrees(self.roll)

    @property
    def homography(self) -> np.ndarray:
        """``H_tr`` (3×3 float64): homogeneous reference pixel → target pixel, on the road plane.

        ``H_tr = ϰ [[1/ϰ + sin Φ, −cos Φ, −κ], [0, 1/ϰ, 0], [0, 0, 1/ϰ]] = [[1 − a, −b, −c], [0, 1, 0],
        [0, 0, 1]]``, i.e. ``(u, v) ↦ (u − d(u, v), v)``.
        """
        a, b, c = self.affine
        return np.array([[1.0 - a, -b, -c], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])

    def disparity(self, shape: tuple[int, int]) -> np.ndarray:
        """The model's disparity ``a u + b v + c`` over an image of ``shape = (H, W)`` (float32 H×W).

        Example:
            >>> RoadModel.from_affine(0.0, 0.5, -20.0).disparity((43, 3))[40:].tolist()  # rows 40–42
            [[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [1.0, 1.0, 1.0]]
        """
        a, b, c = self.affine
        h, w = shape
        return (a * np.arange(w, dtype=np.float32)[None, :] + b * np.arange(h, dtype=np.float32)[:, None]
                + np.float32(c)).astype(np.float32)

    def check_plausible(self, camera_height: float | None = None) -> RoadModel:
        """``self`` when the fit is one a stereo rig on a road can give, else a :class:`RoadFitError` that
        names the bound crossed and by how much.

        Bounds, in this order: at least :data:`MIN_INLIER_SHARE` of the valid road pixels are inliers
        (fitted models only); ``|Φ| ≤`` :data:`MAX_ROLL_DEG`; and ``camera_height``, when given (metres,
        e.g. the height of :meth:`freespace.geometry.RoadPlane.from_road_model`), within
        :data:`CAMERA_HEIGHT_RANGE_M`.

        Example:
            >>> m = RoadModel.from_affine(0.0, 0.5, -20.0)
            >>> m.check_plausible(camera_height=1.65) is m
            True
            >>> try:
            ...     RoadModel.from_roll(math.radians(30.0), 0.5, -40.0).check_plausible()
            ... except RoadFitError as e:
            ...     print(str(e).split(";")[0])
            implausible road fit: roll +30.0° is 10.0° beyond the ±20° a stereo rig on a road can have
        """
        hint = ("check that the disparity (file, depth map or LiDAR scan) belongs to this reference image and is "
                "the right way up (a PFM's rows run bottom to top), and that the label marks the road")
        if self.num_valid and self.num_inliers < MIN_INLIER_SHARE * self.num_valid:
            share = self.num_inliers / self.num_valid
            raise RoadFitError(f"implausible road fit: only {100 * share:.1f} % of the {self.num_valid} valid road "
                               f"pixels agree with the plane, {100 * (MIN_INLIER_SHARE - share):.1f} points below "
                               f"the {100 * MIN_INLIER_SHARE:g} % a road gives; raise {param('inlier_threshold')} "
                               f"if it is "
                               f"below the disparity's noise, else {hint}")
        if abs(self.roll_deg) > MAX_ROLL_DEG:
            raise RoadFitError(f"implausible road fit: roll {self.roll_deg:+.1f}° is "
                               f"{abs(self.roll_deg) - MAX_ROLL_DEG:.1f}° beyond the ±{MAX_ROLL_DEG:g}° a stereo rig "
                               f"on a road can have; {hint}")
        lo, hi = CAMERA_HEIGHT_RANGE_M
        if camera_height is not None and not lo <= camera_height <= hi:
            off = f"{camera_height - hi:.2f} m above the highest" if camera_height > hi else \
                f"{lo - camera_height:.2f} m below the lowest"
            raise RoadFitError(f"implausible road fit: it puts the camera {camera_height:.2f} m above the road, "
                               f"{off} ({lo:g}–{hi:g} m) a vehicle's rig can have; check the calibration's focal "
                               f"length and baseline, and {hint.removeprefix('check ')}")
        return self

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: ``roll_deg``, ``kappa_hat``, ``kappa``, ``affine``, ``homography``,
        ``num_inliers``, ``num_valid``, ``rms_px`` (None when not fitted).

        Example:
            >>> d = RoadModel.from_affine(0.0, 0.5, -20.0).to_dict()
            >>> d["kappa"], d["affine"], d["num_inliers"], d["rms_px"]  # made, not fitted: no inliers, no rms
            (-40.0, [0.0, 0.5, -20.0], 0, None)
        """
        return {
            "roll_deg": self.roll_deg,
            "kappa_hat": self.kappa_hat,
            "kappa": self.kappa,
            "affine": list(self.affine),
            "homography": self.homography.tolist(),
            "num_inliers": self.num_inliers,
            "num_valid": self.num_valid,
            "rms_px": self.rms if math.isfinite(self.rms) else None,
        }


def road_pixels(disparity: np.ndarray, road_mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The valid road pixels: ``(u, v, d)`` float64 vectors of the pixels where ``road_mask`` is true
    and the disparity is finite and > 0.

    Raises:
        ShapeMismatchError: disparity and mask differ in size. InvalidOptionError: not 2-D.

    Example:
        >>> disparity = np.array([[np.nan, 2.0], [0.0, 3.0]])
        >>> road_pixels(disparity, np.array([[True, True], [True, False]]))  # NaN and 0 are no value
        (array([1.]), array([0.]), array([2.]))
    """
    disparity = np.asarray(disparity)
    road_mask = np.asarray(road_mask)
    if disparity.ndim != 2:
        raise InvalidOptionError(f"disparity must be a 2-D H×W map, got shape {disparity.shape}")
    if road_mask.shape != disparity.shape:
        raise ShapeMismatchError(f"road mask is {_size(road_mask.shape)} but the disparity is "
                                 f"{_size(disparity.shape)}; both must be of the reference image's size")
    with np.errstate(invalid="ignore"):
        valid = road_mask.astype(bool, copy=False) & (disparity > 0) & (disparity < np.inf)
    v, u = np.nonzero(valid)
    return u.astype(np.float64), v.astype(np.float64), disparity[v, u].astype(np.float64)


def _size(shape: tuple[int, ...]) -> str:
    return f"{shape[1]}×{shape[0]} (W×H)" if len(shape) >= 2 else str(shape)


class _Normaliser:
    """Centres and scales pixel coordinates so the normal equations are well conditioned."""

    def __init__(self, u: np.ndarray, v: np.ndarray) -> None:
        self.mu_u, self.mu_v = float(u.mean()), float(v.mean())
        self.scale = max(float(np.abs(u - self.mu_u).max(initial=0.0)),
                         float(np.abs(v - self.mu_v).max(initial=0.0)), 1.0)

    def design(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (u - self.mu_u) / self.scale, (v - self.mu_v) / self.scale

    def to_pixels(self, an: float, bn: float, cn: float) -> tuple[float, float, float]:
        a, b = an / self.scale, bn / self.scale
        return a, b, cn - a * self.mu_u - b * self.mu_v


def _plane_lsq(x: np.ndarray, y: np.ndarray, d: np.ndarray) -> tuple[float, float, float]:
    """Least-squares ``d ≈ a x + b y + c`` (normalised coordinates); RoadFitError when degenerate."""
    n = d.size
    mx, my, md = x.mean(), y.mean(), d.mean()
    xc, yc = x - mx, y - my
    return _solve_plane(n, mx, my, md, xc @ xc / n, yc @ yc / n, xc @ yc / n, xc @ d / n, yc @ d / n)


#: the products whose sums over a pixel set give its plane's normal equations (:func:`_plane_from_sums`)
_PRODUCTS = ("xx", "xy", "x", "yy", "y", "1", "xd", "yd", "d")


def _products(x: np.ndarray, y: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``n×9`` float64: each pixel's :data:`_PRODUCTS`, so that a 0/1 weight vector's product with it gives the
    sums of a subset (one matrix-vector product instead of indexing three arrays)."""
    return np.column_stack([x * x, x * y, x, y * y, y, np.ones_like(x), x * d, y * d, d])


def _plane_from_sums(sums: np.ndarray) -> tuple[float, float, float]:
    """:func:`_plane_lsq` of the pixels whose :func:`_products` sum to ``sums``."""
    sxx, sxy, sx, syy, sy, n, sxd, syd, sd = (float(v) for v in sums)
    mx, my, md = sx / n, sy / n, sd / n
    return _solve_plane(int(n), mx, my, md, sxx / n - mx * mx, syy / n - my * my, sxy / n - mx * my,
                        sxd / n - mx * md, syd / n - my * md)


def _solve_plane(n: int, mx: float, my: float, md: float, sxx: float, syy: float, sxy: float, sxd: float,
                 syd: float) -> tuple[float, float, float]:
    """The plane of a pixel set from its means and (co)variances; RoadFitError when its pixels lie on a line."""
    det = sxx * syy - sxy * sxy
    # smallest eigenvalue of the 2×2 coordinate covariance, relative to the largest
    tr = sxx + syy
    if tr <= 0 or det <= 1e-10 * tr * tr:
        raise RoadFitError(f"degenerate road region: its {n} valid pixels lie on (or very near) one line, so "
                           f"no plane can be fitted; label a road area that spans several rows and columns")
    a = (syy * sxd - sxy * syd) / det
    b = (sxx * syd - sxy * sxd) / det
    return float(a), float(b), float(md - a * mx - b * my)


def _ransac(x: np.ndarray, y: np.ndarray, d: np.ndarray, threshold: float, rng: np.random.Generator,
            num_hypotheses: int, sample_size: int) -> tuple[float, float, float] | None:
    """MSAC over random triples drawn from a random subset; returns the best plane or None."""
    n = d.size
    idx = rng.choice(n, size=min(n, sample_size), replace=False) if n > sample_size else np.arange(n)
    xs, ys, ds = x[idx], y[idx], d[idx]
    tri = rng.integers(0, idx.size, size=(num_hypotheses, 3))
    A = np.stack([xs[tri], ys[tri], np.ones(tri.shape)], axis=-1)  # K×3×3
    det = np.linalg.det(A)
    ok = np.abs(det) > 1e-9
    if not ok.any():
        return None
    params = np.linalg.solve(A[ok], ds[tri[ok]][..., None])[..., 0]  # K'×3
    # residuals of every sample pixel under every hypothesis (S×K'), one matrix product, squared in place
    res = np.column_stack([xs, ys, np.ones_like(xs)]) @ params.T
    np.subtract(ds[:, None], res, out=res)
    np.multiply(res, res, out=res)
    cost = np.minimum(res, threshold * threshold, out=res).sum(axis=0)
    a, b, c = params[int(np.argmin(cost))]
    return float(a), float(b), float(c)


def fit_road_model(disparity: np.ndarray, road_mask: np.ndarray, *, robust: bool = True,
                   inlier_threshold: float = 1.0, max_iterations: int = 10, num_hypotheses: int = 128,
                   sample_size: int = 2048, seed: int = 0, min_pixels: int = MIN_ROAD_PIXELS) -> RoadModel:
    """Fit the road disparity model ``d = ϰ (v cos Φ − u sin Φ + κ)`` to the road pixels of a stereo pair.

    Args:
        disparity: ``float H×W`` disparity of the reference (left) image in pixels; NaN, ±inf and values
            ≤ 0 are invalid and ignored.
        road_mask: ``bool H×W`` (non-zero = road), the reference image's road label.
        robust: if True (default), MSAC on random triples finds the dominant plane, then the fit is
            iterated as least squares with 0/1 weights: pixels whose residual exceeds
            ``inlier_threshold`` get weight 0, until the inlier set stops changing. The result is the
            exact minimiser of E over its inliers. If False, plain least squares over all valid pixels.
        inlier_threshold: residual in disparity pixels above which a pixel is an outlier (robust mode).
        max_iterations: cap on the reweighting iterations.
        num_hypotheses, sample_size: MSAC triples and the random subset they are scored on.
        seed: seed of the random sampling; the same inputs and seed give the same model.
        min_pixels: fewest valid road pixels (and inliers) accepted.

    Returns:
        The :class:`RoadModel`, with ``num_valid``, ``num_inliers``, ``rms`` (over inliers, pixels) and
        ``inlier_mask`` (``bool H×W``).

    Raises:
        ShapeMismatchError: mask and disparity sizes differ.
        RoadFitError: fewer than ``min_pixels`` valid road pixels or inliers, collinear road pixels, or a
            plane with no disparity gradient.

    Example:
        >>> v, u = np.mgrid[0:60, 0:80].astype(np.float32)
        >>> disparity = 0.02 * u + 0.3 * v + 5.0  # a road plane d = a·u + b·v + c
        >>> disparity[40:45, 10:20] = 60.0  # a car on the road: 50 outliers
        >>> m = fit_road_model(disparity, np.ones((60, 80), bool))
        >>> [round(x, 4) for x in m.affine], m.num_inliers, round(m.roll_deg, 2)
        ([0.02, 0.3, 5.0], 4750, -3.81)
    """
    if inlier_threshold <= 0 or max_iterations < 1 or num_hypotheses < 1 or sample_size < 3:
        raise InvalidOptionError("inlier_threshold must be > 0 and max_iterations, num_hypotheses ≥ 1, "
                                 "sample_size ≥ 3")
    u, v, d = road_pixels(disparity, road_mask)
    n = d.size
    if n < min_pixels:
        road_count = int(np.count_nonzero(road_mask))
        raise RoadFitError(f"only {n} road pixels have a valid disparity ({road_count} labelled road, "
                           f"{min_pixels} needed); check that the road mask marks the road and that the "
                           f"disparity map is valid there")
    norm = _Normaliser(u, v)
    x, y = norm.design(u, v)
    keep = np.ones(n, dtype=bool)
    plane = _plane_lsq(x, y, d)
    if robust:
        rng = np.random.default_rng(seed)
        hypothesis = _ransac(x, y, d, inlier_threshold, rng, num_hypotheses, sample_size)
        if hypothesis is not None:
            plane = hypothesis
        products = _products(x, y, d)
        for _ in range(max_iterations):
            a, b, c = plane
            new_keep = np.abs(d - (a * x + b * y + c)) <= inlier_threshold
            count = int(np.count_nonzero(new_keep))
            if count < min_pixels:
                raise RoadFitError(f"only {count} of {n} valid road pixels agree with one plane within "
                                   f"{inlier_threshold} px ({min_pixels} needed); the disparity on the road is "
                                   f"too noisy or the label does not mark a planar road")
            if count == np.count_nonzero(keep) and np.array_equal(new_keep, keep):
                break
            keep = new_keep
            plane = _plane_from_sums(keep.astype(np.float64) @ products)
        else:
            a, b, c = plane
            keep = np.abs(d - (a * x + b * y + c)) <= inlier_threshold
    a, b, c = plane
    residual = d[keep] - (a * x[keep] + b * y[keep] + c)
    rms = float(np.sqrt(np.mean(residual * residual)))
    mask = np.zeros(np.shape(disparity), dtype=bool)
    mask[v[keep].astype(np.intp), u[keep].astype(np.intp)] = True
    return RoadModel.from_affine(*norm.to_pixels(a, b, c), num_inliers=int(np.count_nonzero(keep)), rms=rms,
                                 num_valid=n, inlier_mask=mask)


def road_energy(params: tuple[float, float, float] | np.ndarray, u: np.ndarray, v: np.ndarray,
                d: np.ndarray) -> float:
    """The paper's energy ``E(Φ, ϰ, κ) = Σ (dᵢ − ϰ (vᵢ cos Φ − uᵢ sin Φ + κ))²`` (pixels²).

    ``params = (Φ [rad], ϰ, κ)``; ``u, v, d`` are equal-length vectors of road pixels.

    Example:
        >>> u, v = np.array([0.0, 10.0]), np.array([100.0, 100.0])
        >>> d = 0.5 * (v + 4.0)  # Φ = 0, ϰ = 0.5, κ = 4
        >>> road_energy((0.0, 0.5, 4.0), u, v, d), road_energy((0.0, 0.5, 6.0), u, v, d)  # κ off by 2: 1 px each
        (0.0, 2.0)
    """
    roll, kappa_hat, kappa = params
    r = d - kappa_hat * (v * np.cos(roll) - u * np.sin(roll) + kappa)
    return float(r @ r)


def fit_road_model_closed_form(disparity: np.ndarray, road_mask: np.ndarray) -> RoadModel:
    """The paper's closed-form minimiser of E over all valid road pixels (no outlier rejection).

    For a fixed Φ, E is quadratic in ϰ and ϰκ; eliminating them leaves ``E(Φ) = n·(var d − cov(t, d)² /
    var t)`` with ``t = v cos Φ − u sin Φ``. Setting ``dE/dΦ = 0`` gives ``tan Φ = x₂ / x₁`` with
    ``x = S⁻¹ g`` (``S`` the covariance of (v, −u), ``g`` = (cov(v, d), −cov(u, d))), i.e.
    ``Φ = arctan(x₂ / x₁) + qπ``; of the two roots (q = 0, 1 — the authors' ``q = ±1``) the one with
    ϰ > 0 is kept. Then ϰ = cov(t, d) / var t and κ = mean(d) / ϰ − mean(t). This is the long way to
    the same optimum as :func:`fit_road_model` with ``robust=False``; it serves as a cross-check.

    Example:
        >>> v, u = np.mgrid[0:60, 0:80].astype(np.float64)
        >>> m = fit_road_model_closed_form(0.02 * u + 0.3 * v + 5.0, np.ones((60, 80), bool))
        >>> [round(x, 6) for x in m.affine], round(m.rms, 6)
        ([0.02, 0.3, 5.0], 0.0)
    """
    u, v, d = road_pixels(disparity, road_mask)
    if d.size < 3:
        raise RoadFitError(f"only {d.size} valid road pixels; at least 3 are needed")
    uc, vc, dc = u - u.mean(), v - v.mean(), d - d.mean()
    S = np.array([[vc @ vc, -(vc @ uc)], [-(vc @ uc), uc @ uc]])
    g = np.array([vc @ dc, -(uc @ dc)])
    x = np.linalg.solve(S, g)  # ∝ (cos Φ, sin Φ)
    best = None
    for q in (0, 1):
        roll = math.atan(x[1] / x[0]) + q * math.pi if x[0] != 0 else math.copysign(math.pi / 2, x[1])
        roll = math.atan2(math.sin(roll), math.cos(roll))
        t = v * math.cos(roll) - u * math.sin(roll)
        tc = t - t.mean()
        kappa_hat = float(tc @ dc / (tc @ tc))
        if kappa_hat > 0:
            best = (roll, kappa_hat, float(d.mean() / kappa_hat - t.mean()))
    if best is None:
        raise RoadFitError("degenerate road region: no roll angle gives ϰ > 0")
    rm = RoadModel.from_roll(*best)
    return RoadModel(rm.roll, rm.kappa_hat, rm.kappa, rm.affine, num_inliers=d.size,
                     rms=math.sqrt(road_energy(best, u, v, d) / d.size), num_valid=d.size)
