"""Photometry of frames (torch-free): the strong colour augmentation, frames as another camera or the dusk might
show them (shared by the training dataset's ``photometric="strong"`` and ``freespace adapt``'s student views, drawn
from a NumPy generator so that a draw depends on its seed only, each of its factors drawn independently); and the
light normaliser (:func:`normalise_light`), the view of ``adapt``'s teacher and of prediction with ``tta``.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["strong_photometry", "normalise_light", "LABEL_BRIGHTNESS"]

#: the teacher labels a frame after a gamma that brings its mean brightness to this (in [0, 1]; the published
#: model's KITTI frames average 0.35) and a local contrast equalisation (:func:`normalise_light`): seeing CamVid's
#: dusk frames so, the first published ``real-road-fast``'s F there (commit 732c574) rises from 0.35 to 0.76, on
#: its daylight ones it stays 0.88 (chosen on those development frames; the student still learns the frames as
#: they are)
LABEL_BRIGHTNESS = 0.40



def strong_photometry(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A strongly recoloured copy of an ``H×W×3 float32`` RGB frame in [0, 1] (returned the same way).

    In this order: saturation ×0.4…1.4 (about the grey of each pixel), contrast ×0.6…1.4 (about the frame's mean),
    brightness ×0.5…1.3 then a gamma 0.7…2 (above 1 darkens like dusk), a Gaussian blur of σ 0.3…1.5 px a third
    of the time, Gaussian noise of σ 0…0.03; clipped to [0, 1].
    """
    grey = x.mean(2, keepdims=True)
    x = grey + (x - grey) * rng.uniform(0.4, 1.4)  # saturation
    x = x.mean() + (x - x.mean()) * rng.uniform(0.6, 1.4)  # contrast
    x = np.clip(x * rng.uniform(0.5, 1.3), 0, 1) ** rng.uniform(0.7, 2.0)  # brightness, gamma
    if rng.random() < 1 / 3:
        x = cv2.GaussianBlur(x, (0, 0), rng.uniform(0.3, 1.5))
    x = x + rng.normal(0, rng.uniform(0, 0.03), x.shape).astype(np.float32)
    return np.clip(x, 0, 1).astype(np.float32)


def normalise_light(image: np.ndarray) -> np.ndarray:
    """The teacher's view of an ``H×W×3 uint8`` RGB frame: a gamma that brings its mean brightness to
    :data:`LABEL_BRIGHTNESS`, then CLAHE (clip limit 2, 8×8 tiles) on the lightness (CIE Lab's L)."""
    x = np.clip(image.astype(np.float32) / 255.0, 1e-6, 1.0)
    gamma = math.log(LABEL_BRIGHTNESS) / math.log(min(max(float(x.mean()), 1e-3), 0.999))
    lab = cv2.cvtColor((x ** gamma * 255.0).astype(np.uint8), cv2.COLOR_RGB2LAB)
    lab[..., 0] = cv2.createCLAHE(clipLimit=2.0, tileGridSize=(8, 8)).apply(np.ascontiguousarray(lab[..., 0]))
    return cv2.cvtColor(lab, cv2.COLOR_LAB2RGB)
