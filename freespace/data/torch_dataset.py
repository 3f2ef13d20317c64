"""A thin torch ``Dataset`` over any :class:`~freespace.data.base.StereoRoadDataset` (training only).

Samples are dicts: ``image`` float32 ``3×H×W`` in [0, 1] (normalisation belongs to the model),
``label`` int64 ``H×W`` (0 = non-road, 1 = road, 255 = don't care), ``name`` str. An optional
``transform(image, label) -> (image, label)`` acts on the NumPy arrays (``H×W×3 uint8``, ``H×W uint8``)
before conversion, e.g. albumentations' paired augmentation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch

from freespace.data.base import StereoRoadDataset
from freespace.errors import DatasetError

__all__ = ["RoadSegmentationDataset", "IGNORE_INDEX", "label_to_index"]

IGNORE_INDEX = 255


def label_to_index(road: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``uint8 H×W`` class map: 1 road, 0 non-road, :data:`IGNORE_INDEX` don't care."""
    out = road.astype(np.uint8)
    out[~valid] = IGNORE_INDEX
    return out


class RoadSegmentationDataset(torch.utils.data.Dataset):
    """Labelled frames of ``dataset`` (optionally only ``names``) as segmentation samples.

    Raises:
        DatasetError: a requested frame is unknown or has no label.
    """

    def __init__(self, dataset: StereoRoadDataset, names: Sequence[str] | None = None,
                 transform: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None) -> None:
        self.dataset = dataset
        wanted = list(names) if names is not None else [f.name for f in dataset.labelled()]
        self.indices = [dataset.index(n) for n in wanted]
        unlabelled = [n for n, i in zip(wanted, self.indices) if dataset.frames[i].label is None]
        if unlabelled:
            raise DatasetError(f"{len(unlabelled)} frames have no road label (first: {unlabelled[0]}); "
                               f"train on a labelled split")
        self.transform = transform

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, i: int) -> dict[str, Any]:
        sample = self.dataset.load(self.indices[i], right=False, disparity=False)
        image = sample.left
        label = label_to_index(sample.label.road, sample.label.valid)  # type: ignore[union-attr]
        if self.transform is not None:
            image, label = self.transform(image, label)
        return {"image": torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1))).float().div_(255.0),
                "label": torch.from_numpy(np.ascontiguousarray(label)).long(), "name": sample.name}
