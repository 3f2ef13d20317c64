"""SGBM disparity: values on synthetic pairs with known disparity, left-right check, user mistakes."""

from __future__ import annotations

import numpy as np
import pytest

from freespace.errors import InvalidOptionError, ShapeMismatchError
from freespace.geometry import RoadModel, compute_disparity, fit_road_model, generate_view

from helpers import road_mask


def _noise_texture(shape: tuple[int, int], seed: int) -> np.ndarray:
    import cv2

    rng = np.random.default_rng(seed)
    img = rng.uniform(0, 255, shape).astype(np.float32)
    return np.clip(cv2.GaussianBlur(img, (0, 0), 1.0) * 2 - 128, 0, 255).astype(np.uint8)


def test_constant_shift() -> None:
    left = _noise_texture((120, 240), 0)
    right = np.roll(left, -12, axis=1)
    disp = compute_disparity(left, right, max_disparity=32)
    inner = disp[10:-10, 50:-20]
    assert np.isfinite(inner).mean() > 0.95
    assert np.nanmedian(np.abs(inner - 12)) < 0.1
    assert np.isnan(disp[:, :8]).all()  # no match possible at the left margin


def test_right_margin_covered_left_margin_left_empty() -> None:
    # OpenCV leaves the first max_disparity columns empty, and the left-right check used to empty the last
    # ones (the right image's own empty margin); the matcher pads the pair on the right, so every column from
    # max_disparity on gets a disparity, and the left margin, where a match may lie outside the right
    # image, stays empty
    left = _noise_texture((120, 240), 0)
    right = np.roll(left, -12, axis=1)
    disp = compute_disparity(left, right, max_disparity=96)
    assert np.isnan(disp[:, :96]).all()
    assert np.isfinite(disp[10:-10, 96:-4]).mean() > 0.95
    assert np.nanmedian(np.abs(disp[10:-10, 160:-4] - 12)) < 0.1


def test_slanted_road_plane_recovered() -> None:
    shape = (200, 400)
    model = RoadModel.from_affine(0.005, 0.25, -10.0)  # roll −1.15°, d = 40 at the bottom row
    left = _noise_texture(shape, 1)
    # right image such that right(H p) = left(p): warp the left image with H⁻¹
    right = generate_view(left, left, np.linalg.inv(model.homography))
    disp = compute_disparity(left, right, max_disparity=64)
    mask = road_mask(shape, top=0.3)
    fitted = fit_road_model(disp, mask)
    assert abs(fitted.roll_deg - model.roll_deg) < 0.1
    assert fitted.kappa_hat == pytest.approx(model.kappa_hat, rel=0.01)
    assert fitted.rms < 0.3


def test_left_right_check_removes_occlusions() -> None:
    left = _noise_texture((100, 200), 2)
    right = np.roll(left, -10, axis=1)
    # a near square in the left image only: its pixels have no consistent partner
    left[30:70, 100:140] = _noise_texture((40, 40), 3)
    checked = compute_disparity(left, right, max_disparity=32)
    unchecked = compute_disparity(left, right, max_disparity=32, lr_check=False)
    assert np.isfinite(checked).sum() < np.isfinite(unchecked).sum()
    good = np.isfinite(checked[:, 40:])
    assert np.mean(np.abs(checked[:, 40:][good] - 10) < 1) > 0.97


def test_user_mistakes() -> None:
    img = _noise_texture((50, 80), 0)
    with pytest.raises(ShapeMismatchError, match="one size"):
        compute_disparity(img, img[:, :60])
    with pytest.raises(InvalidOptionError, match="uint8"):
        compute_disparity(img.astype(np.float32), img.astype(np.float32))
    with pytest.raises(InvalidOptionError, match="odd"):
        compute_disparity(img, img, block_size=4)
