"""The DS-Generator: warp the target (right) image into the reference (left) view with ``H_tr``.

Conventions
-----------
Pixels are 0-based, ``u`` = column, ``v`` = row, centres at integers. ``H_tr`` maps homogeneous
reference pixels to target pixels. The generated image is ``g(p) = t(H_tr p̃)`` sampled bilinearly
where the target coordinate lies inside the target image (``0 ≤ x ≤ W − 1``, ``0 ≤ y ≤ H − 1``,
positive homogeneous scale) and ``g(p) = r(p)`` elsewhere. Every pixel is warped with the road
homography, so objects above the road come out distorted: that is the method. The generated image
takes the reference image's label.
"""

from __future__ import annotations

from typing import Literal, overload

import cv2
import numpy as np

from freespace.errors import InvalidOptionError, ShapeMismatchError
from freespace.geometry.road_model import RoadModel

__all__ = ["generate_view", "valid_column_ranges"]


def _check_homography(H: RoadModel | np.ndarray) -> np.ndarray:
    H = H.homography if isinstance(H, RoadModel) else np.asarray(H, dtype=np.float64)
    if H.shape != (3, 3) or not np.isfinite(H).all():
        raise InvalidOptionError(f"the homography must be a finite 3×3 matrix (or a RoadModel), got shape {H.shape}")
    if abs(np.linalg.det(H)) < 1e-12:
        raise InvalidOptionError("the homography is singular; it cannot map a plane between two views")
    return H


def valid_column_ranges(H: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """For each reference row, the columns whose target coordinate ``H p̃`` lands inside the image.

    The conditions ``w > 0``, ``0 ≤ x w⁻¹ ≤ W − 1``, ``0 ≤ y w⁻¹ ≤ H − 1`` (with ``(x, y, w) = H p̃``) are
    linear in ``u`` on a row, so the valid pixels of a row form one interval.

    Args:
        H: ``H_tr`` (3×3), reference → target pixels.
        shape: ``(H, W)`` of both images.

    Returns:
        ``(lo, hi)``: int64 arrays of length H; row ``v`` is valid on columns ``lo[v] ≤ u ≤ hi[v]``
        (empty when ``lo[v] > hi[v]``).

    Example:
        >>> H = np.array([[1.0, 0, -2], [0, 1, 0], [0, 0, 1]])  # every pixel 2 px to the left
        >>> lo, hi = valid_column_ranges(H, (2, 6))
        >>> lo.tolist(), hi.tolist()  # columns 0 and 1 would land left of the image
        ([2, 2], [5, 5])
    """
    h, w = shape
    v = np.arange(h, dtype=np.float64)
    eps = 1e-9
    # each condition: alpha * u + beta >= 0 (beta depends on the row)
    wa, wb = H[2, 0], H[2, 1] * v + H[2, 2]
    xa, xb = H[0, 0], H[0, 1] * v + H[0, 2]
    ya, yb = H[1, 0], H[1, 1] * v + H[1, 2]
    conditions = [
        (wa, wb - eps),
        (xa, xb + eps),
        ((w - 1) * wa - xa, (w - 1) * wb - xb + eps),
        (ya, yb + eps),
        ((h - 1) * wa - ya, (h - 1) * wb - yb + eps),
    ]
    lo = np.zeros(h)
    hi = np.full(h, w - 1.0)
    for alpha, beta in conditions:
        if alpha > 0:
            lo = np.maximum(lo, -beta / alpha)
        elif alpha < 0:
            hi = np.minimum(hi, -beta / alpha)
        else:
            hi = np.where(beta >= 0, hi, -1.0)
    return np.ceil(lo - 1e-9).astype(np.int64), np.floor(hi + 1e-9).astype(np.int64)


@overload
def generate_view(reference: np.ndarray, target: np.ndarray, model_or_homography: RoadModel | np.ndarray, *,
                  return_mask: Literal[False] = ...) -> np.ndarray: ...


@overload
def generate_view(reference: np.ndarray, target: np.ndarray, model_or_homography: RoadModel | np.ndarray, *,
                  return_mask: Literal[True]) -> tuple[np.ndarray, np.ndarray]: ...


def generate_view(reference: np.ndarray, target: np.ndarray, model_or_homography: RoadModel | np.ndarray, *,
                  return_mask: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """The DS-Generator: the target image seen from the reference view through the road homography.

    Args:
        reference: ``H×W×C`` or ``H×W`` image of the reference (left) camera (uint8, or float32).
        target: image of the target (right) camera, same shape and dtype.
        model_or_homography: a :class:`RoadModel` or ``H_tr`` (3×3, reference → target pixels).
        return_mask: also return the validity mask.

    Returns:
        The generated image (same shape and dtype as the inputs): bilinear samples of ``target`` at
        ``H_tr p̃``, and the reference pixel where that falls outside the target image. With
        ``return_mask``, also ``bool H×W``: True where the pixel came from the target.

    Raises:
        ShapeMismatchError: reference and target differ in shape or dtype.
        InvalidOptionError: not an image, or a singular/non-finite homography.

    Example:
        >>> import numpy as np
        >>> from freespace.geometry import RoadModel, generate_view
        >>> ref = np.zeros((4, 6), np.uint8); tgt = np.tile(np.arange(6, dtype=np.uint8) * 10, (4, 1))
        >>> generate_view(ref, tgt, RoadModel.from_affine(0.0, 0.5, 0.0))[2].tolist()  # d = 1 on row 2
        [0, 0, 10, 20, 30, 40]
    """
    reference = np.asarray(reference)
    target = np.asarray(target)
    if reference.ndim not in (2, 3) or (reference.ndim == 3 and reference.shape[2] not in (1, 3, 4)):
        raise InvalidOptionError(f"reference must be an H×W or H×W×3 image, got shape {reference.shape}")
    if reference.shape != target.shape or reference.dtype != target.dtype:
        raise ShapeMismatchError(f"reference is {reference.shape} {reference.dtype} but target is {target.shape} "
                                 f"{target.dtype}; the two images of a stereo pair must have the same size and type")
    if reference.dtype not in (np.uint8, np.float32):
        raise InvalidOptionError(f"images must be uint8 or float32, got {reference.dtype}")
    H = _check_homography(model_or_homography)
    h, w = reference.shape[:2]
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    if H[2, 0] == 0 and H[2, 1] == 0:
        out = cv2.warpAffine(target, (H[:2] / H[2, 2]), (w, h), flags=flags, borderMode=cv2.BORDER_REPLICATE)
    else:
        out = cv2.warpPerspective(target, H, (w, h), flags=flags, borderMode=cv2.BORDER_REPLICATE)
    out = out.reshape(reference.shape)
    lo, hi = valid_column_ranges(H, (h, w))
    lo_c = np.clip(lo, 0, w)
    hi_c = np.clip(hi + 1, lo_c, w)
    for row in np.flatnonzero((lo_c > 0) | (hi_c < w)):
        out[row, : lo_c[row]] = reference[row, : lo_c[row]]
        out[row, hi_c[row]:] = reference[row, hi_c[row]:]
    if not return_mask:
        return out
    cols = np.arange(w)
    mask = (cols[None, :] >= lo_c[:, None]) & (cols[None, :] < hi_c[:, None])
    return out, mask
