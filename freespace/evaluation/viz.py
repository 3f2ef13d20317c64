"""Pictures: disparity colour maps, road overlays, captioned image grids (NumPy + OpenCV), and the
precision-recall curve (matplotlib, imported when drawn).

The image functions take and return ``H×W×3 uint8`` RGB images.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from freespace.io.files import PathLike, atomic_write_bytes

__all__ = ["colorize_disparity", "overlay_road", "overlay_errors", "caption", "grid", "write_pr_curve"]


def colorize_disparity(disparity: np.ndarray, max_disparity: float | None = None) -> np.ndarray:
    """Colour-map a ``float H×W`` disparity (NaN = invalid, drawn black); ``max_disparity`` defaults to the
    99th percentile of the valid values."""
    valid = np.isfinite(disparity) & (disparity > 0)
    top = max_disparity or (float(np.percentile(disparity[valid], 99)) if valid.any() else 1.0)
    scaled = np.zeros(disparity.shape, np.uint8)
    scaled[valid] = np.clip(disparity[valid] / max(top, 1e-6) * 255, 0, 255).astype(np.uint8)
    rgb = cv2.cvtColor(cv2.applyColorMap(scaled, cv2.COLORMAP_TURBO), cv2.COLOR_BGR2RGB)
    rgb[~valid] = 0
    return rgb


def overlay_road(image: np.ndarray, road: np.ndarray, colour: tuple[int, int, int] = (255, 0, 255),
                 alpha: float = 0.45) -> np.ndarray:
    """Tint the ``bool H×W`` road pixels of ``image`` with ``colour`` (KITTI magenta by default)."""
    out = image.copy() if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    tint = np.array(colour, np.float32)
    out[road] = (out[road].astype(np.float32) * (1 - alpha) + tint * alpha).astype(np.uint8)
    return out


def overlay_errors(image: np.ndarray, pred: np.ndarray, road: np.ndarray, valid: np.ndarray | None = None,
                   alpha: float = 0.5) -> np.ndarray:
    """The paper's figure colours: true positives green, false negatives red, false positives blue
    (``pred``, ``road``, ``valid``: bool H×W; don't-care pixels untouched)."""
    valid = np.ones(road.shape, bool) if valid is None else valid
    out = image.astype(np.float32).copy() if image.ndim == 3 else np.repeat(image[..., None], 3, 2).astype(np.float32)
    for mask, colour in ((pred & road, (0, 255, 0)), (~pred & road, (255, 0, 0)), (pred & ~road, (0, 0, 255))):
        m = mask & valid
        out[m] = out[m] * (1 - alpha) + np.array(colour, np.float32) * alpha
    return out.astype(np.uint8)


def caption(image: np.ndarray, text: str) -> np.ndarray:
    """A copy of ``image`` with ``text`` written in its top-left corner on a dark band."""
    out = image.copy()
    scale = max(0.4, image.shape[1] / 900)
    (w, h), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    cv2.rectangle(out, (0, 0), (w + 8, h + base + 8), (0, 0, 0), -1)
    cv2.putText(out, text, (4, h + 4), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def grid(rows: Sequence[Sequence[np.ndarray]], width: int | None = None) -> np.ndarray:
    """Stack equally sized RGB images into a grid (rows of columns), each resized to ``width`` if given."""
    def fit(img: np.ndarray) -> np.ndarray:
        if width is None or img.shape[1] == width:
            return img
        return cv2.resize(img, (width, round(img.shape[0] * width / img.shape[1])), interpolation=cv2.INTER_AREA)

    return np.vstack([np.hstack([fit(img) for img in row]) for row in rows])


def write_pr_curve(path: PathLike, recall: np.ndarray, precision: np.ndarray) -> None:
    """Draw a road precision-recall curve (fractions, one point per threshold, e.g. from
    :meth:`freespace.evaluation.metrics.KittiCounts.pr_curve`) into a PNG file, written atomically."""
    import io as _io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4, 4), dpi=100)
    ax.plot(recall, precision)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.01)
    ax.grid(True, alpha=0.3)
    ax.set_title("road precision-recall (256 thresholds)")
    buf = _io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
