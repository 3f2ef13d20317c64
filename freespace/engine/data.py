"""Training data: splits, the DS-Generator views (``--augment homography``), road-plane virtual views
(``--augment virtual``, drawn on the fly), paired conventional augmentation, an epoch-seeded sampler (exact resumes, DDP sharding) and decoded-image caching."""

from __future__ import annotations

import copy
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from freespace.data.base import StereoRoadDataset, get_dataset
from freespace.data.splits import make_splits, read_splits, write_splits
from freespace.data.torch_dataset import IGNORE_INDEX, label_to_index
from freespace.engine.config import TrainConfig, parse_augment, parse_ranges
from freespace.errors import DatasetError
from freespace.io import read_image

log = logging.getLogger(__name__)

__all__ = ["Item", "RoadFrames", "VirtualAugment", "EpochSampler", "prepare_data", "is_rank_zero"]


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


@dataclass(frozen=True)
class VirtualAugment:
    """``--augment virtual``: each sample, each epoch, with probability ``prob``, becomes its road-plane
    virtual view (:func:`freespace.geometry.virtual_view`) from a pose drawn uniformly in ±``shift``
    (dx, dy, dz metres) and ±``rotate`` (roll, pitch, yaw degrees), from (seed, epoch, i) only.

    ``planes`` maps a dataset frame index to its intrinsics (3×3, pixels of the frame's own size) and
    road plane; frames without one are never warped.
    """

    planes: dict[int, tuple[np.ndarray, Any]]
    shift: tuple[float, float, float] = (0.5, 0.2, 0.0)
    rotate: tuple[float, float, float] = (3.0, 3.0, 3.0)
    prob: float = 0.5

    def pose(self, seed: int, epoch: int, i: int):  # -> VirtualPose | None
        """The pose of sample ``i`` in ``epoch`` (None: keep the sample as it is)."""
        from freespace.geometry import VirtualPose

        rng = np.random.default_rng([seed, epoch, i, 29])
        if rng.random() >= self.prob:
            return None
        s = rng.uniform(-1, 1, 3) * np.asarray(self.shift)
        r = rng.uniform(-1, 1, 3) * np.asarray(self.rotate)
        return VirtualPose(shift=(float(s[0]), float(s[1]), float(s[2])), roll=float(r[0]), pitch=float(r[1]),
                           yaw=float(r[2]))


def _resized_K(K: np.ndarray, src: tuple[int, int], dst: tuple[int, int]) -> np.ndarray:
    """Intrinsics after resizing an image from ``src`` to ``dst`` (H, W), pixel centres kept (as cv2.resize)."""
    sx, sy = dst[1] / src[1], dst[0] / src[0]
    S = np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])
    return S @ K


class RoadFrames(torch.utils.data.Dataset):
    """Samples of a dataset resized to ``size`` (H, W); with ``augment``, keys are ``(epoch, i)`` pairs and
    the augmentation of sample i in an epoch depends only on (seed, epoch, i). ``virtual`` adds the
    road-plane virtual views (before the conventional augmentation)."""

    def __init__(self, dataset: StereoRoadDataset, items: list[Item], size: tuple[int, int], augment: bool,
                 seed: int, virtual: VirtualAugment | None = None) -> None:
        self.dataset, self.items, self.size, self.augment, self.seed = dataset, items, size, augment, seed
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._aug = _augmenter() if augment else None
        self.virtual = virtual if augment else None
        self._K: dict[int, np.ndarray] = {}  # intrinsics at ``size`` of items with a road plane

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
            if self.virtual is not None and item.index in self.virtual.planes:
                self._K[i] = _resized_K(self.virtual.planes[item.index][0], image.shape[:2], (h, w))
            if image.shape[:2] != (h, w):
                image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
                label = cv2.resize(label, (w, h), interpolation=cv2.INTER_NEAREST)  # labels: never bilinear
            self._cache[i] = (image, label)
        return self._cache[i]

    def __getitem__(self, key: int | tuple[int, int]) -> dict[str, Any]:
        epoch, i = key if isinstance(key, tuple) else (0, key)
        image, label = self.decoded(i)
        if self.virtual is not None and i in self._K:
            pose = self.virtual.pose(self.seed, epoch, i)
            if pose is not None:
                from freespace.geometry import virtual_view

                plane = self.virtual.planes[self.items[i].index][1]
                image, label, _ = virtual_view(image, label, self._K[i], plane, pose, ignore=IGNORE_INDEX)
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

    With ``--augment virtual`` it finds the road plane of every training frame (:class:`VirtualAugment`).

    Returns ``{"dataset", "train", "val", "test"}`` (lists of :class:`Item`), ``"size"`` (H, W) and
    ``"virtual"`` (a :class:`VirtualAugment`, or None).
    """
    ds = get_dataset(config.dataset, config.root, config.split, disparity=config.disparity, cache_dir=config.cache_dir)
    labelled = [f for f in ds.frames if f.label is not None]
    if config.max_frames is not None:
        labelled = labelled[: config.max_frames]
    if len(labelled) < 3:
        raise DatasetError(f"{config.dataset} at {config.root} has {len(labelled)} labelled frames; training needs ≥ 3")
    names = [f.name for f in labelled]
    split_dir = run_dir / "splits"
    if config.splits:
        splits = read_splits(config.splits, known=names)
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
    augments = parse_augment(config.augment)
    if "homography" in augments:
        items["train"] += _generated_views(ds, [index[n] for n in splits["train"]], run_dir / "generated")
    virtual = None
    if "virtual" in augments:
        virtual = VirtualAugment(_road_planes(ds, [index[n] for n in splits["train"]]),
                                 shift=parse_ranges(config.virtual_shift, "--virtual-shift"),
                                 rotate=parse_ranges(config.virtual_rotate, "--virtual-rotate"), prob=config.virtual_prob)
    size = config.image_size or tuple(int(x) for x in ds.load(index[names[0]], right=False, disparity=False).left.shape[:2])
    return {"dataset": ds, **items, "size": size, "virtual": virtual}


def _road_planes(ds: StereoRoadDataset, indices: list[int]) -> dict[int, tuple[np.ndarray, Any]]:
    """Intrinsics and road plane of each frame, for ``--augment virtual``: the calibration's plane (KITTI
    ``Tr_cam_to_road``, or the camera height and pitch of ``freespace.yaml``), else the road fit of the
    frame's disparity (file, depth or SGBM) with the rig's focal length and baseline."""
    from freespace.errors import FreespaceError
    from freespace.geometry import RoadPlane, fit_road_model

    planes: dict[int, tuple[np.ndarray, Any]] = {}
    reasons: dict[str, str] = {}
    for i in indices:
        frame = ds.frames[i]
        try:
            calib = ds.calibration(frame)
            if calib is None:
                raise DatasetError("no camera (calibration file or `camera:` in freespace.yaml)")
            if calib.road_normal is not None:
                plane = RoadPlane.from_calibration(calib)
            else:
                sample = ds.load(i)
                if sample.disparity is None or sample.label is None or not calib.baseline > 0:
                    raise DatasetError("no road plane in the calibration and no disparity (and baseline) to fit one")
                model = fit_road_model(sample.disparity, sample.label.road & sample.label.valid)
                plane = RoadPlane.from_road_model(model, calib.fx, calib.baseline, calib.cx, calib.cy, fy=calib.fy)
            planes[i] = (calib.K, plane)
        except FreespaceError as exc:
            reasons[frame.name] = str(exc)
    if not planes:
        first = next(iter(reasons.items()), ("", ""))
        raise DatasetError(f"--augment virtual needs each frame's camera and road plane; none of the {len(indices)} "
                           f"training frames has one ({first[0]}: {first[1]}); give a KITTI calibration with "
                           f"Tr_cam_to_road, `camera: {{height: .., pitch: ..}}` in freespace.yaml, or disparities")
    if reasons:
        log.warning("%d of %d training frames have no road plane and get no virtual views: %s", len(reasons),
                    len(indices), "; ".join(f"{k}: {v}" for k, v in list(reasons.items())[:3]))
    log.info("virtual views: road planes of %d training frames", len(planes))
    return planes


def _generated_views(ds: StereoRoadDataset, indices: list[int], folder: Path) -> list[Item]:
    """DS-Generator views of the given frames (made once, resumable), as items with the frames' labels."""
    from freespace.generate import generate_dataset

    sub = copy.copy(ds)
    sub.frames = [ds.frames[i] for i in indices if ds.frames[i].right is not None]
    if not sub.frames:
        raise DatasetError("--augment homography needs right images; this dataset has none")
    if is_rank_zero():
        summary = generate_dataset(sub, folder)
        if summary["failed"]:
            log.warning("%d of %d frames gave no generated view (skipped): %s", len(summary["failed"]),
                        len(sub.frames), "; ".join(f"{k}: {v}" for k, v in list(summary["failed"].items())[:3]))
    return [Item(ds.index(f.name), f.name, str(folder / f"{f.name}.png")) for f in sub.frames
            if (folder / f"{f.name}.png").is_file()]
