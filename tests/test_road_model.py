"""The road disparity model fit: exactness, robustness, the paper's closed form, user mistakes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize

from freespace.errors import RoadFitError, ShapeMismatchError
from freespace.geometry import RoadModel, fit_road_model, fit_road_model_closed_form, road_energy, road_pixels

from helpers import plane_disparity, road_mask

SHAPE = (375, 1242)


def _scipy_minimiser(u: np.ndarray, v: np.ndarray, d: np.ndarray, start: tuple[float, float, float]) -> np.ndarray:
    """Minimise the paper's E(Φ, ϰ, κ) with a generic optimiser (test oracle)."""
    res = minimize(lambda p: road_energy(p, u, v, d) / d.size, np.array(start), method="Nelder-Mead",
                   options={"xatol": 1e-12, "fatol": 1e-16, "maxiter": 40000, "maxfev": 40000})
    res = minimize(lambda p: road_energy(p, u, v, d) / d.size, res.x, method="BFGS", options={"gtol": 1e-12})
    return res.x


def _noisy_plane(rng: np.random.Generator, roll_deg: float = 2.0, noise: float = 0.3):
    disp = plane_disparity(SHAPE, roll_deg, 0.31, -170.0)
    disp = disp + rng.normal(0, noise, disp.shape).astype(np.float32)
    return disp, road_mask(SHAPE)


@pytest.mark.parametrize("roll_deg", [-3.0, 0.0, 0.7, 2.5])
def test_exact_plane_recovered(roll_deg: float) -> None:
    disp = plane_disparity(SHAPE, roll_deg, 0.32, -175.0)
    model = fit_road_model(disp, road_mask(SHAPE))
    assert abs(model.roll_deg - roll_deg) < 1e-3
    assert model.kappa_hat == pytest.approx(0.32, rel=1e-5)
    assert model.kappa == pytest.approx(-175.0, abs=1e-2)
    assert model.rms < 1e-3
    assert model.num_inliers == model.num_valid == np.count_nonzero(road_mask(SHAPE))


def test_plain_fit_equals_scipy_minimiser_of_E() -> None:
    disp, mask = _noisy_plane(np.random.default_rng(1))
    model = fit_road_model(disp, mask, robust=False)
    u, v, d = road_pixels(disp, mask)
    start = (model.roll + 0.01, model.kappa_hat * 1.02, model.kappa + 3.0)
    phi, kh, k = _scipy_minimiser(u, v, d, start)
    assert math.degrees(phi) == pytest.approx(model.roll_deg, abs=1e-4)
    assert kh == pytest.approx(model.kappa_hat, rel=1e-5)
    assert k == pytest.approx(model.kappa, abs=1e-2)
    assert road_energy((model.roll, model.kappa_hat, model.kappa), u, v, d) \
        <= road_energy((phi, kh, k), u, v, d) * (1 + 1e-9)


def test_robust_fit_is_the_minimiser_of_E_over_its_inliers() -> None:
    rng = np.random.default_rng(2)
    disp, mask = _noisy_plane(rng)
    outliers = mask & (rng.random(SHAPE) < 0.25)
    disp[outliers] = rng.uniform(1, 100, outliers.sum())
    model = fit_road_model(disp, mask)
    u, v, d = road_pixels(disp, model.inlier_mask)
    plain = fit_road_model(disp, model.inlier_mask, robust=False)
    assert plain.affine == pytest.approx(model.affine, rel=1e-9, abs=1e-9)
    phi, kh, k = _scipy_minimiser(u, v, d, (0.0, 0.3, -160.0))
    assert math.degrees(phi) == pytest.approx(model.roll_deg, abs=1e-4)
    assert kh == pytest.approx(model.kappa_hat, rel=1e-5)


def test_closed_form_agrees_with_least_squares() -> None:
    disp, mask = _noisy_plane(np.random.default_rng(3), roll_deg=-1.7)
    closed = fit_road_model_closed_form(disp, mask)
    plain = fit_road_model(disp, mask, robust=False)
    assert closed.roll_deg == pytest.approx(plain.roll_deg, abs=1e-7)
    assert closed.kappa_hat == pytest.approx(plain.kappa_hat, rel=1e-9)
    assert closed.kappa == pytest.approx(plain.kappa, abs=1e-6)
    assert closed.rms == pytest.approx(plain.rms, rel=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_robust_to_25_percent_gross_outliers(seed: int) -> None:
    rng = np.random.default_rng(seed)
    disp = plane_disparity(SHAPE, 1.1, 0.3, -170.0) + rng.normal(0, 0.2, SHAPE).astype(np.float32)
    mask = road_mask(SHAPE)
    bad = mask & (rng.random(SHAPE) < 0.25)
    # gross outliers: uniformly random disparities, plus a structured block (an unlabelled car)
    disp[bad] = rng.uniform(0.5, 120, bad.sum())
    disp[300:360, 500:700] += 15.0
    model = fit_road_model(disp, mask)
    assert abs(model.roll_deg - 1.1) < 0.05
    assert model.kappa_hat == pytest.approx(0.3, rel=2e-3)
    assert 0.65 < model.num_inliers / model.num_valid < 0.8
    # least squares alone is far off: the robust path is doing the work
    assert abs(fit_road_model(disp, mask, robust=False).kappa_hat - 0.3) > 0.01


def test_invalid_disparities_are_ignored() -> None:
    disp = plane_disparity(SHAPE, 0.5, 0.3, -170.0)
    mask = road_mask(SHAPE)
    holes = np.random.default_rng(0).random(SHAPE) < 0.5
    disp[holes] = np.nan
    disp[:, :10] = np.inf
    disp[:, 10:20] = 0
    disp[:, 20:30] = -4
    model = fit_road_model(disp, mask)
    assert abs(model.roll_deg - 0.5) < 1e-3
    assert model.num_valid == np.count_nonzero(mask & np.isfinite(disp) & (disp > 0))


def test_fit_is_deterministic() -> None:
    rng = np.random.default_rng(4)
    disp, mask = _noisy_plane(rng)
    disp[mask & (rng.random(SHAPE) < 0.3)] = 50.0
    assert fit_road_model(disp, mask).affine == fit_road_model(disp, mask).affine


def test_model_parametrisations_agree() -> None:
    model = RoadModel.from_roll(math.radians(-2.0), 0.25, -150.0)
    a, b, c = model.affine
    assert model.roll_deg == pytest.approx(-2.0)
    assert RoadModel.from_affine(a, b, c).kappa == pytest.approx(-150.0)
    phi, kh, k = model.roll, model.kappa_hat, model.kappa
    paper = kh * np.array([[1 / kh + math.sin(phi), -math.cos(phi), -k], [0, 1 / kh, 0], [0, 0, 1 / kh]])
    np.testing.assert_allclose(model.homography, paper, atol=1e-12)
    d = model.disparity((10, 20))
    assert d[7, 13] == pytest.approx(kh * (7 * math.cos(phi) - 13 * math.sin(phi) + k), rel=1e-5)
    summary = model.to_dict()
    assert set(summary) >= {"roll_deg", "kappa_hat", "kappa", "affine", "homography", "num_inliers", "rms_px"}


# --- user mistakes -----------------------------------------------------------------------------------

def test_too_few_road_pixels() -> None:
    disp = plane_disparity(SHAPE, 0.0, 0.3, -170.0)
    mask = np.zeros(SHAPE, bool)
    mask[370, 600:610] = True
    with pytest.raises(RoadFitError, match="only 10 road pixels"):
        fit_road_model(disp, mask)
    with pytest.raises(RoadFitError, match="only 0 road pixels"):
        fit_road_model(np.full(SHAPE, np.nan, np.float32), road_mask(SHAPE))


def test_collinear_road_pixels() -> None:
    disp = plane_disparity(SHAPE, 0.0, 0.3, -170.0)
    mask = np.zeros(SHAPE, bool)
    mask[300, :] = True
    with pytest.raises(RoadFitError, match="one line"):
        fit_road_model(disp, mask, robust=False)
    with pytest.raises(RoadFitError, match="one line"):
        fit_road_model(disp, mask)


def test_constant_disparity_is_degenerate() -> None:
    with pytest.raises(RoadFitError, match="does not change"):
        fit_road_model(np.full(SHAPE, 20.0, np.float32), road_mask(SHAPE))


def test_mask_of_another_size() -> None:
    with pytest.raises(ShapeMismatchError, match="road mask is 1000×375"):
        fit_road_model(plane_disparity(SHAPE, 0, 0.3, -170), np.ones((375, 1000), bool))


def test_no_plane_has_enough_inliers() -> None:
    rng = np.random.default_rng(0)
    disp = rng.uniform(1, 100, SHAPE).astype(np.float32)
    with pytest.raises(RoadFitError, match="agree with one plane"):
        fit_road_model(disp, road_mask(SHAPE), inlier_threshold=0.01, min_pixels=5000)


def test_the_reweighting_solves_as_plain_least_squares() -> None:
    """The fit's iterations solve each inlier set from sums of the pixels' products (one matrix-vector product):
    the same plane as the centred least squares, to rounding (issue 71: the drives' autolabels kept their hash)."""
    from freespace.geometry.road_model import _plane_from_sums, _plane_lsq, _products

    rng = np.random.default_rng(3)
    x, y = rng.uniform(-1, 1, 5000), rng.uniform(-1, 1, 5000)
    d = 0.3 * x + 12.0 * y + 40.0 + rng.normal(0, 0.5, 5000)
    keep = rng.random(5000) < 0.7
    direct = _plane_lsq(x[keep], y[keep], d[keep])
    summed = _plane_from_sums(keep.astype(np.float64) @ _products(x, y, d))
    np.testing.assert_allclose(summed, direct, rtol=1e-10, atol=1e-10)
