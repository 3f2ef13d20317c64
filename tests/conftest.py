"""Shared fixtures; the shared helper functions are in ``helpers.py``."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import plane_disparity, road_mask


@pytest.fixture
def kitti_like_plane() -> tuple[np.ndarray, np.ndarray]:
    """(disparity, road mask) of an exact plane at KITTI size with 1.3° roll."""
    shape = (375, 1242)
    return plane_disparity(shape, 1.3, 0.32, -175.0 + 0.0), road_mask(shape)
