"""Road labels in memory: the :class:`RoadLabel` type and the class-map convention of training.

A road label is a pair of ``bool H×W`` arrays, ``road`` and ``valid`` (``valid`` False = don't care). As a
class map (training, losses) it is 1 road, 0 non-road, :data:`IGNORE_INDEX` (255) don't care. Files of
labels are read and written by :mod:`freespace.io.codecs`.

Only NumPy is imported here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["IGNORE_INDEX", "RoadLabel"]

#: the class id of don't-care pixels in label class maps (losses ignore it, metrics skip it)
IGNORE_INDEX = 255


@dataclass(frozen=True)
class RoadLabel:
    """A road label: ``road`` and ``valid`` are ``bool H×W``; ``valid`` False marks don't-care pixels."""

    road: np.ndarray
    valid: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.road.shape  # type: ignore[return-value]
