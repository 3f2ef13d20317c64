"""Dense disparity from a rectified stereo pair with OpenCV's semi-global block matching.

Convention: the disparity is that of the left (reference) image, ``d = u_left − u_right`` in pixels,
``float32 H×W``, NaN where there is no reliable value (no match, failed uniqueness or left-right check,
or the left margin of ``numDisparities`` columns, where the search range leaves the right image).

OpenCV's SGBM leaves the first ``numDisparities`` columns of its output empty (their match may lie outside
the right image), and the left-right check used to empty the last ones as well: the right image's disparity,
computed on the mirrored pair, has the same empty margin on the right. The pair is therefore matched with
``numDisparities`` replicated columns added on its right and the result cropped back, so that every column
from ``numDisparities`` on can pass the check. (Padding the left too would fill the left margin, but with
false matches wherever the true one lies outside the right image: on the rendered `shifted` set the SGBM
autolabel's precision fell from 95.8 % to 92.8 %.) On the converged run's 100 rendered 416×320 training frames
(search range 128 px) the SGBM autolabel covers 76.9 % of the pixels instead of 68.6 %, at a precision of
98.6 % instead of 98.7 % (BENCHMARKS.md, "Autolabel quality").
"""

from __future__ import annotations

import cv2
import numpy as np

from freespace.errors import InvalidOptionError, ShapeMismatchError, param

__all__ = ["compute_disparity", "SGBM_MAX_DISPARITY", "SGBM_VERSION"]

SGBM_MAX_DISPARITY = 128  # the default SGBM search range in pixels, wherever SGBM runs (KITTI needs ~128)
# what compute_disparity computes, in the settings of every output made from SGBM disparities and in the SGBM
# cache's key, so that a resumed run never mixes two matchers: 1 until 2026-11-25 (empty left and right
# margins), 2 since (the pair padded on the right by the search range: the right margin is matched)
SGBM_VERSION = 2


def _grey(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img)
    if img.dtype != np.uint8:
        raise InvalidOptionError(f"stereo matching needs uint8 images, got {img.dtype}")
    if img.ndim == 3:
        return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    if img.ndim == 2:
        return img
    raise InvalidOptionError(f"expected an H×W or H×W×3 image, got shape {img.shape}")


def check_search_range(max_disparity: int, width: int,
                       fix: str = "") -> int:
    """SGBM's search range for ``max_disparity`` (pixels, rounded up to a multiple of 16), or an
    :class:`InvalidOptionError` when it is not smaller than the image ``width`` (pixels); ``fix`` ends the
    message (how else to get a disparity; default: give a disparity file).

    Example:
        >>> check_search_range(100, 640)  # rounded up to a multiple of 16
        112
    """
    fix = fix or f"give the disparity ({param('disparity')}; {param('disparity_dir')} for a dataset)"
    num = int(np.ceil(max_disparity / 16.0)) * 16
    if num >= width:
        raise InvalidOptionError(f"the stereo matcher's maximum disparity ({num} px, {param('max_disparity')} "
                                 f"rounded up to "
                                 f"a multiple of 16) must be smaller than the image width ({width} px); "
                                 f"lower {param('max_disparity')}, or {fix}")
    return num


def compute_disparity(left: np.ndarray, right: np.ndarray, *, max_disparity: int = SGBM_MAX_DISPARITY,
                      block_size: int = 5, uniqueness: int = 10, lr_check: bool = True, lr_tolerance: float = 1.0,
                      speckle_window: int = 100, speckle_range: int = 2) -> np.ndarray:
    """Disparity of the left image with OpenCV SGBM, tuned for driving scenes.

    Settings: ``MODE_SGBM_3WAY``, smoothness ``P1 = 8·c·b²``, ``P2 = 32·c·b²`` (c = 1 grey channel,
    b = block size), uniqueness ratio 10 %, speckle filtering, sub-pixel output (1/16 px).

    Args:
        left, right: rectified ``H×W×3`` RGB or ``H×W`` uint8 images of the same size.
        max_disparity: search range in pixels (rounded up to a multiple of 16). KITTI needs ~128.
        block_size: odd matching block size in pixels.
        uniqueness: SGBM uniqueness ratio in percent.
        lr_check: run the matcher right-to-left too and keep only consistent pixels.
        lr_tolerance: largest left-right disagreement in pixels that still passes the check.
        speckle_window, speckle_range: speckle filter (region size in pixels, disparity range in px).

    Returns:
        ``float32 H×W`` left disparity in pixels, NaN = invalid.

    Example:
        >>> left = np.random.default_rng(0).integers(0, 256, (64, 128), dtype=np.uint8)  # a textured image
        >>> right = np.roll(left, -8, axis=1)  # the right camera sees every pixel 8 px further left
        >>> d = compute_disparity(left, right, max_disparity=32)
        >>> float(np.nanmedian(d))
        8.0
    """
    gl, gr = _grey(left), _grey(right)
    if gl.shape != gr.shape:
        raise ShapeMismatchError(f"left image is {gl.shape[1]}×{gl.shape[0]} but right is {gr.shape[1]}×{gr.shape[0]}; "
                                 f"a rectified stereo pair has two images of one size")
    if max_disparity < 1 or block_size < 1 or block_size % 2 == 0:
        raise InvalidOptionError(f"max_disparity must be ≥ 1 and block_size odd (got {max_disparity}, {block_size})")
    w = gl.shape[1]
    num = check_search_range(max_disparity, w)
    gl, gr = (cv2.copyMakeBorder(g, 0, 0, 0, num, cv2.BORDER_REPLICATE) for g in (gl, gr))
    matcher = cv2.StereoSGBM_create(
        minDisparity=0, numDisparities=num, blockSize=block_size,
        P1=8 * block_size * block_size, P2=32 * block_size * block_size,
        disp12MaxDiff=-1, uniquenessRatio=uniqueness, speckleWindowSize=speckle_window,
        speckleRange=speckle_range, preFilterCap=63, mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    disp = matcher.compute(gl, gr)[:, :w].astype(np.float32) / 16.0
    disp[disp <= 0] = np.nan
    if lr_check:
        # the right image's disparity, computed as a left disparity of the mirrored pair
        disp_r = np.fliplr(matcher.compute(np.ascontiguousarray(np.fliplr(gr)), np.ascontiguousarray(np.fliplr(gl))))
        disp_r = disp_r[:, :w].astype(np.float32) / 16.0
        cols = np.arange(w, dtype=np.float32)[None, :]
        with np.errstate(invalid="ignore"):
            ur = np.rint(cols - disp)
            ok = np.isfinite(ur) & (ur >= 0)
            ur_i = np.where(ok, ur, 0).astype(np.intp)
            dr = np.take_along_axis(disp_r, ur_i, axis=1)
            ok &= (dr > 0) & (np.abs(dr - disp) <= lr_tolerance)
        disp[~ok] = np.nan
    return disp
