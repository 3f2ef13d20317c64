"""How a frame is fitted to a network's input size, and a prediction brought back to the frame.

Two ways, named in a model's record (its checkpoint's ``resize``, its ONNX file's metadata) so that prediction
feeds frames as training did:

* ``stretch`` (every model before this one): the frame is resized to the input's H×W whatever its aspect: a 4:3
  frame in a 192×640 input is squeezed to a third of its height relative to its width, and the road's far end lands
  on another row than a 10:3 frame's;
* ``letterbox``: the frame is scaled to fit the input with its aspect kept and centred on a black canvas (a label's
  border is don't care): the far road of every camera lies where the camera sees it.

A prediction at the input's size goes back to the frame's (:func:`unfit`): the content box cut out (letterbox) and
resized bilinearly. Only NumPy and OpenCV.
"""

from __future__ import annotations

import cv2
import numpy as np

from freespace.errors import InvalidOptionError, param

__all__ = ["RESIZE_MODES", "check_resize", "content_box", "fit", "unfit"]

#: the ways a frame is fitted to a network's input
RESIZE_MODES = ("stretch", "letterbox")


def check_resize(mode: object, what: str = "resize") -> str:
    """``mode`` when it is one of :data:`RESIZE_MODES`, else an :class:`InvalidOptionError` naming ``what``."""
    if mode not in RESIZE_MODES:
        raise InvalidOptionError(f"{param(what)} must be one of {', '.join(RESIZE_MODES)}, got {mode!r}")
    return mode  # type: ignore[return-value]


def content_box(src: tuple[int, int], dst: tuple[int, int]) -> tuple[int, int, int, int]:
    """Where a ``src`` = (H, W) frame lies in a ``dst`` = (H, W) letterboxed input: ``(y0, x0, h, w)`` pixels, the
    frame scaled by the larger factor that fits both sides, centred (at least one pixel a side).

    Example:
        >>> content_box((360, 480), (192, 640))   # CamVid's 4:3 frame in KITTI's 10:3 input
        (0, 192, 192, 256)
    """
    scale = min(dst[0] / src[0], dst[1] / src[1])
    h, w = max(1, min(dst[0], round(src[0] * scale))), max(1, min(dst[1], round(src[1] * scale)))
    return (dst[0] - h) // 2, (dst[1] - w) // 2, h, w


def fit(image: np.ndarray, size: tuple[int, int], mode: str, *, label: bool = False, fill: int = 0) -> np.ndarray:
    """``image`` (``H×W`` or ``H×W×C``) at ``size`` = (h, w) as ``mode`` says; area interpolation for an image,
    nearest for a ``label`` (class ids are never blended), the letterbox's border filled with ``fill`` (a label's
    don't-care id)."""
    h, w = size
    flag = cv2.INTER_NEAREST if label else cv2.INTER_AREA
    if mode == "stretch" or image.shape[:2] == (h, w):
        return image if image.shape[:2] == (h, w) else cv2.resize(image, (w, h), interpolation=flag)
    y0, x0, ch, cw = content_box(image.shape[:2], size)
    out = np.full((h, w) + image.shape[2:], fill, image.dtype)
    out[y0:y0 + ch, x0:x0 + cw] = cv2.resize(image, (cw, ch), interpolation=flag).reshape((ch, cw) + image.shape[2:])
    return out


def unfit(prob: np.ndarray, size: tuple[int, int], mode: str) -> np.ndarray:
    """A prediction ``prob`` (``float32 h×w``, at the input's size) back at the frame's ``size`` = (H, W): the
    content box (letterbox) resized bilinearly (a threshold after it gives a smooth boundary)."""
    h, w = size
    if prob.shape == (h, w):
        return prob
    if mode == "letterbox":
        y0, x0, ch, cw = content_box((h, w), prob.shape[:2])
        prob = prob[y0:y0 + ch, x0:x0 + cw]
    return cv2.resize(np.ascontiguousarray(prob), (w, h), interpolation=cv2.INTER_LINEAR)
