"""Training data: splits, the DS-Generator views (``--augment homography``), paired conventional
augmentation, an epoch-seeded sampler (exact resumes, DDP sharding) and decoded-image caching."""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from freespace.data.base import StereoRoadDataset
from freespace.data.registry import get_dataset
from freespace.data.splits import make_splits, read_splits, write_splits
from freespace.data.torch_dataset import IGNORE_INDEX, label_to_index
from freespace.engine.config import TrainConfig
from freespace.errors import DatasetError
from freespace.io import read_image

log = logging.getLogger(__name__)

__all__ = ["Item", "RoadFrames", "EpochSampler", "prepare_data", "is_rank_zero"]


def is_rank_zero() -> bool:
    """True in the launching process (DDP children have LOCAL_RANK/RANK > 0)."""
    return int(os.environ.get("LOCAL_RANK", os.environ.get("RANK", "0"))) == 0


@dataclass(frozen=True)
class Item:
    """One training/evaluation sample: frame ``index`` of the dataset, and the image to use instead of
    its left image (a DS-Generator view) or None."""

    index: int
    name: str
    image: str | None = None


def _augmenter():
    import albumentations as A

    # the paper's conventional augmentation: random translation and rotation of image and label together
    return A.Compose([A.Affine(translate_percent=(-0.1, 0.1), rotate=(-10, 10), p=0.8,
                               border_mode=cv2.BORDER_CONSTANT, fill=0, fill_mask=IGNORE_INDEX)], seed=0)


class RoadFrames(torch.utils.data.Dataset):
    """Samples of a dataset resized to ``size`` (H, W); with ``augment``, keys are ``(epoch, i)`` pairs and
    the augmentation of sample i in an epoch depends only on (seed, epoch, i)."""

    def __init__(self, dataset: StereoRoadDataset, items: list[Item], size: tuple[int, int], augment: bool,
                 seed: int) -> None:
        self.dataset, self.items, self.size, self.augment, self.seed = dataset, items, size, augment, seed
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._aug = _augmenter() if augment else None

    def __len__(self) -> int:
        return len(self.items)

    def decoded(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Resized image (uint8 H×W×3) and class map (uint8 H×W) of item i, decoded once."""
        if i not in self._cache:
            item = self.items[i]
            sample = self.dataset.load(item.index, right=False, disparity=False)
            image = read_image(item.image) if item.image else sample.left
            label = label_to_index(sample.label.road, sample.label.valid)  # type: ignore[union-attr]
            h, w = self.size
            if image.shape[:2] != (h, w):
                image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
                label = cv2.resize(label, (w, h), interpolation=cv2.INTER_NEAREST)  # labels: never bilinear
            self._cache[i] = (image, label)
        return self._cache[i]

    def __getitem__(self, key: int | tuple[int, int]) -> dict[str, Any]:
        epoch, i = key if isinstance(key, tuple) else (0, key)
        image, label = self.decoded(i)
        if self._aug is not None:
            self._aug.set_random_seed(int(np.random.default_rng([self.seed, epoch, i]).integers(2**31)))
            out = self._aug(image=image, mask=label)
            image, label = out["image"], out["mask"]
        return {"image": torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1))).float().div_(255.0),
                "label": torch.from_numpy(np.ascontiguousarray(label)).long(), "index": i}


class EpochSampler(torch.utils.data.Sampler):
    """Yields ``(epoch, i)``: a permutation drawn from (seed, epoch) when shuffling, this rank's share
    under DDP (training shares are padded to equal length; evaluation shares are disjoint)."""

    def __init__(self, n: int, seed: int, shuffle: bool) -> None:
        self.n, self.seed, self.shuffle, self.epoch = n, seed, shuffle, 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def _order(self) -> list[int]:
        order = np.random.default_rng([self.seed, self.epoch]).permutation(self.n) if self.shuffle else np.arange(self.n)
        if torch.distributed.is_available() and torch.distributed.is_initialized():
            rank, world = torch.distributed.get_rank(), torch.distributed.get_world_size()
            if self.shuffle:
                order = np.resize(order, -(-self.n // world) * world)
            order = order[rank::world]
        return [int(i) for i in order]

    def __iter__(self):
        return iter([(self.epoch, i) for i in self._order()])

    def __len__(self) -> int:
        return len(self._order())


def prepare_data(config: TrainConfig, run_dir: Path) -> dict[str, Any]:
    """Open the dataset, decide the splits (list files in ``run_dir/splits``) and, with
    ``--augment homography``, make the DS-Generator views of the training frames (``run_dir/generated``).

    Returns ``{"dataset", "train", "val", "test"}`` (lists of :class:`Item`) and ``"size"`` (H, W).
    """
    ds = get_dataset(config.dataset, config.root, config.split, disparity_mode=config.disparity_mode,
                     cache_dir=config.cache_dir)
    labelled = ds.labelled().frames
    if config.max_frames is not None:
        labelled = labelled[: config.max_frames]
    if len(labelled) < 3:
        raise DatasetError(f"{config.dataset} at {config.root} has {len(labelled)} labelled frames; training needs ≥ 3")
    names = [f.name for f in labelled]
    split_dir = run_dir / "splits"
    if config.splits_dir:
        splits = read_splits(config.splits_dir, known=names)
    elif (split_dir / "train.txt").is_file():
        splits = read_splits(split_dir, known=names)
    else:
        splits = make_splits([(f.name, f.scenario) for f in labelled], seed=config.seed)
    if is_rank_zero():
        write_splits(split_dir, splits)
    if not all(splits[k] for k in ("train", "val", "test")):
        raise DatasetError(f"a split is empty ({', '.join(f'{k} {len(v)}' for k, v in splits.items())}); use more "
                           f"frames or scenarios, or give --splits")
    index = {f.name: ds.index(f.name) for f in labelled}
    items = {k: [Item(index[n], n) for n in v] for k, v in splits.items()}
    if config.augment == "homography":
        items["train"] += _generated_views(ds, [index[n] for n in splits["train"]], run_dir / "generated")
    size = config.image_size or tuple(int(x) for x in ds.load(index[names[0]], right=False, disparity=False).left.shape[:2])
    return {"dataset": ds, **items, "size": size}


def _generated_views(ds: StereoRoadDataset, indices: list[int], folder: Path) -> list[Item]:
    """DS-Generator views of the given frames (made once, resumable), as items with the frames' labels."""
    from freespace.generate import generate_dataset

    sub = ds.subset(ds.frames[i].name for i in indices if ds.frames[i].right is not None)
    if not sub.frames:
        raise DatasetError("--augment homography needs right images; this dataset has none")
    if is_rank_zero():
        summary = generate_dataset(sub, folder)
        if summary["failed"]:
            log.warning("%d of %d frames gave no generated view (skipped): %s", len(summary["failed"]),
                        len(sub.frames), "; ".join(f"{k}: {v}" for k, v in list(summary["failed"].items())[:3]))
    return [Item(ds.index(f.name), f.name, str(folder / f"{f.name}.png")) for f in sub.frames
            if (folder / f"{f.name}.png").is_file()]
