"""The DS-Generator warp: direction convention, back-and-forth, validity mask, user mistakes."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

import freespace.geometry.warp
from freespace.errors import InvalidOptionError, ShapeMismatchError
from freespace.geometry import RoadModel, generate_view, valid_column_ranges

from helpers import textured_image

SHAPE = (120, 200)


def _bilinear_reference(target: np.ndarray, reference: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The paper's formula, pixel by pixel: g(p) = t(H p̃) bilinear, r(p) outside."""
    h, w = target.shape[:2]
    out = reference.astype(np.float64).copy()
    mask = np.zeros((h, w), bool)
    for v in range(h):
        for u in range(w):
            x, y, s = H @ np.array([u, v, 1.0])
            if s <= 0:
                continue
            x, y = x / s, y / s
            if not (0 <= x <= w - 1 and 0 <= y <= h - 1):
                continue
            x0, y0 = min(int(np.floor(x)), w - 2), min(int(np.floor(y)), h - 2)
            fx, fy = x - x0, y - y0
            out[v, u] = ((1 - fx) * (1 - fy) * target[y0, x0] + fx * (1 - fy) * target[y0, x0 + 1]
                         + (1 - fx) * fy * target[y0 + 1, x0] + fx * fy * target[y0 + 1, x0 + 1])
            mask[v, u] = True
    return out, mask


@pytest.mark.parametrize("H", [
    RoadModel.from_affine(0.01, 0.3, -20.0).homography,
    np.array([[0.98, 0.05, -6.0], [0.01, 1.02, 3.0], [2e-4, -1e-4, 1.0]]),
], ids=["road", "projective"])
def test_matches_per_pixel_formula(H: np.ndarray) -> None:
    ref = textured_image(SHAPE, seed=1)
    tgt = textured_image(SHAPE, seed=2)
    got, mask = generate_view(ref, tgt, H, return_mask=True)
    want, want_mask = _bilinear_reference(tgt, ref, H)
    inner = want_mask.copy()
    inner[:, :1] = inner[:, -1:] = False
    np.testing.assert_array_equal(mask, want_mask)
    assert np.abs(got.astype(float) - want)[mask].max() <= 1.0  # OpenCV's 1/32-pixel fixed point
    np.testing.assert_array_equal(got[~mask], ref[~mask])


def test_integer_shift_is_exact() -> None:
    ref = textured_image(SHAPE, seed=3)
    tgt = textured_image(SHAPE, seed=4)
    g = generate_view(ref, tgt, np.array([[1.0, 0, -7.0], [0, 1, 0], [0, 0, 1]]))  # d = 7 everywhere
    np.testing.assert_array_equal(g[:, 7:], tgt[:, :-7])
    np.testing.assert_array_equal(g[:, :7], ref[:, :7])


def test_back_and_forth() -> None:
    tgt = textured_image(SHAPE, seed=5)
    H = RoadModel.from_affine(-0.02, 0.15, 2.0).homography
    zeros = np.zeros_like(tgt)
    g, m1 = generate_view(zeros, tgt, H, return_mask=True)
    back, m2 = generate_view(zeros, g, np.linalg.inv(H), return_mask=True)
    # overlap: pixels whose round trip stayed inside both images, one pixel away from the edges
    m1_at = generate_view(np.zeros(SHAPE, np.uint8), m1.astype(np.uint8) * 255, np.linalg.inv(H))
    ok = m2 & (m1_at == 255)
    ok[:, :2] = ok[:, -2:] = False
    assert ok.mean() > 0.7
    err = np.abs(back.astype(float) - tgt.astype(float))[ok]
    assert err.mean() < 0.6 and err.max() <= 4


def test_mask_is_the_target_image_region() -> None:
    H = np.array([[1.1, 0.1, -15.0], [0.02, 0.95, 4.0], [1e-4, 0, 1.0]])
    lo, hi = valid_column_ranges(H, SHAPE)
    v, u = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    x, y, s = np.tensordot(H, np.stack([u, v, np.ones_like(u)]).astype(float), axes=1)
    inside = (s > 0) & (x / s >= 0) & (x / s <= SHAPE[1] - 1) & (y / s >= 0) & (y / s <= SHAPE[0] - 1)
    np.testing.assert_array_equal((u >= lo[:, None]) & (u <= hi[:, None]), inside)


def test_grey_float_and_shapes() -> None:
    model = RoadModel.from_affine(0.0, 0.2, -5.0)
    grey = textured_image(SHAPE, channels=1)
    assert generate_view(grey, grey, model).shape == SHAPE
    f = textured_image(SHAPE).astype(np.float32) / 255
    out = generate_view(f, f, model)
    assert out.dtype == np.float32 and out.shape == SHAPE + (3,)


def test_docstring_example() -> None:
    result = doctest.testmod(freespace.geometry.warp, verbose=False)
    assert result.attempted > 0 and result.failed == 0


def test_user_mistakes() -> None:
    img = textured_image(SHAPE)
    model = RoadModel.from_affine(0.0, 0.2, -5.0)
    with pytest.raises(ShapeMismatchError, match="same size"):
        generate_view(img, img[:, :100], model)
    with pytest.raises(ShapeMismatchError):
        generate_view(img, img.astype(np.float32), model)
    with pytest.raises(InvalidOptionError, match="singular"):
        generate_view(img, img, np.zeros((3, 3)))
    with pytest.raises(InvalidOptionError, match="3×3"):
        generate_view(img, img, np.eye(2))
    with pytest.raises(InvalidOptionError, match="image"):
        generate_view(np.zeros(5, np.uint8), np.zeros(5, np.uint8), model)
