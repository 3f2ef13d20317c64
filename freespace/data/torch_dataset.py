"""The torch ``Dataset`` of training and evaluation: labelled frames of any
:class:`~freespace.data.base.StereoRoadDataset` as segmentation samples.

Samples are dicts: ``image`` float32 ``3×H×W`` in [0, 1] (normalisation belongs to the model),
``label`` int64 ``H×W`` (0 = non-road, 1 = road, :data:`~freespace.io.IGNORE_INDEX` 255 = don't care),
``name`` str and ``index`` (the sample's position in this dataset). Options, all off by default:

* ``size=(H, W)``: images are resized with area interpolation, labels with nearest (never bilinear);
* ``cache=True``: decoded (and resized) frames are kept in memory, decoded once;
* ``augment=True``: the paper's conventional augmentation (random translation ±10 % and rotation ±10° of
  image and label together; label borders become don't care). Keys may be ``(epoch, i)`` pairs (see
  :class:`freespace.engine.data.EpochSampler`): the augmentation of sample i in an epoch depends only on
  (``seed``, epoch, i), so a resumed run sees exactly the same data;
* ``transform(image, label) -> (image, label)``: a user function on the NumPy arrays (``H×W×3 uint8``,
  ``H×W uint8``), applied last, before the conversion to tensors.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import torch

from freespace.data.base import StereoRoadDataset
from freespace.errors import DatasetError
from freespace.io import IGNORE_INDEX, read_image

__all__ = ["RoadSegmentationDataset", "Item", "IGNORE_INDEX", "label_to_index"]


def label_to_index(road: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``uint8 H×W`` class map: 1 road, 0 non-road, :data:`IGNORE_INDEX` don't care."""
    out = road.astype(np.uint8)
    out[~valid] = IGNORE_INDEX
    return out


@dataclass(frozen=True)
class Item:
    """One sample: frame ``index`` of the dataset (named ``name``), and the image file to use instead of
    its left image (e.g. a DS-Generator view, which takes the left image's label) or None."""

    index: int
    name: str
    image: str | None = None


def _augmenter():
    import albumentations as A

    # the paper's conventional augmentation: random translation and rotation of image and label together
    return A.Compose([A.Affine(translate_percent=(-0.1, 0.1), rotate=(-10, 10), p=0.8,
                               border_mode=cv2.BORDER_CONSTANT, fill=0, fill_mask=IGNORE_INDEX)], seed=0)


class RoadSegmentationDataset(torch.utils.data.Dataset):
    """Labelled frames of ``dataset`` as segmentation samples (see the module docstring for the options).

    Args:
        dataset: any dataset layout.
        names: the frames, by name or as :class:`Item` (default: every labelled frame).
        transform: ``(image, label) -> (image, label)`` on NumPy arrays, applied last.
        size: ``(H, W)`` to resize to, or None (each frame's own size).
        augment: the conventional augmentation, drawn from (``seed``, epoch, i).
        seed: the augmentation's seed.
        cache: keep decoded frames in memory.

    Raises:
        DatasetError: a requested frame is unknown or has no label.
    """

    def __init__(self, dataset: StereoRoadDataset, names: Sequence[str | Item] | None = None,
                 transform: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None, *,
                 size: tuple[int, int] | None = None, augment: bool = False, seed: int = 0,
                 cache: bool = False) -> None:
        self.dataset = dataset
        wanted = list(names) if names is not None else [f.name for f in dataset.labelled()]
        self.items = [n if isinstance(n, Item) else Item(dataset.index(n), n) for n in wanted]
        unlabelled = [it.name for it in self.items if dataset.frames[it.index].label is None]
        if unlabelled:
            raise DatasetError(f"{len(unlabelled)} frames have no road label (first: {unlabelled[0]}); "
                               f"train on a labelled split")
        self.transform, self.size, self.augment, self.seed, self.cache = transform, size, augment, seed, cache
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._aug = _augmenter() if augment else None

    def __len__(self) -> int:
        return len(self.items)

    def decoded(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Image (``uint8 H×W×3``) and class map (``uint8 H×W``) of sample i, resized to ``size`` if set
        (before augmentation and ``transform``)."""
        if i in self._cache:
            return self._cache[i]
        item = self.items[i]
        sample = self.dataset.load(item.index, right=False, disparity=False)
        image = read_image(item.image) if item.image else sample.left
        label = label_to_index(sample.label.road, sample.label.valid)  # type: ignore[union-attr]
        if self.size is not None and image.shape[:2] != tuple(self.size):
            h, w = self.size
            image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
            label = cv2.resize(label, (w, h), interpolation=cv2.INTER_NEAREST)  # labels: never bilinear
        if self.cache:
            self._cache[i] = (image, label)
        return image, label

    def __getitem__(self, key: int | tuple[int, int]) -> dict[str, Any]:
        epoch, i = key if isinstance(key, tuple) else (0, key)
        image, label = self.decoded(i)
        if self._aug is not None:
            self._aug.set_random_seed(int(np.random.default_rng([self.seed, epoch, i]).integers(2**31)))
            out = self._aug(image=image, mask=label)
            image, label = out["image"], out["mask"]
        if self.transform is not None:
            image, label = self.transform(image, label)
        return {"image": torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1))).float().div_(255.0),
                "label": torch.from_numpy(np.ascontiguousarray(label)).long(), "name": self.items[i].name,
                "index": i}
