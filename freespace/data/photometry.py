"""The strong colour augmentation: frames as another camera or the dusk might show them (torch-free).

Shared by the training dataset (``photometric="strong"``) and ``freespace adapt``'s student views, drawn from a
NumPy generator so that a draw depends on its seed only (each of its factors drawn independently).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["strong_photometry"]


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
