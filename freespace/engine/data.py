"""Training data: splits, the DS-Generator views (``augment`` with ``"homography"``), the road planes of the
road-plane virtual views (``"virtual"``) and an epoch-seeded sampler (exact resumes, DDP sharding). The
samples themselves (resizing, paired conventional augmentation, the virtual views drawn on the fly,
decoded-image caching) are :class:`freespace.data.torch_dataset.RoadSegmentationDataset`."""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np
import torch

from freespace.data.base import StereoRoadDataset
from freespace.data.label_tree import apply_label_tree, label_tree_pixels, tree_labels
from freespace.data.registry import get_dataset
from freespace.data.splits import make_splits, read_splits, write_splits
from freespace.data.torch_dataset import Item, VirtualAugment
from freespace.engine.config import TrainConfig
from freespace.engine.labelled import labelled_frames
from freespace.engine.option_values import ranges_text
from freespace.errors import DatasetError, InvalidOptionError, param

log = logging.getLogger(__name__)

__all__ = ["EpochSampler", "prepare_data", "is_rank_zero", "loader_context"]


def is_rank_zero() -> bool:
    """True in the launching process (DDP children have LOCAL_RANK/RANK > 0)."""
    return int(os.environ.get("LOCAL_RANK", os.environ.get("RANK", "0"))) == 0


#: signals blocked in the trainer while it forks a loader process (see :class:`_LoaderProcess`)
_FORK_BLOCKED = {signal.SIGINT, signal.SIGTERM}


class _LoaderProcess(multiprocessing.context.ForkProcess):
    """A DataLoader worker that stops at once with the command and never outlives it.

    In the trainer, Ctrl-C and ``SIGTERM`` are blocked while it forks the worker: a signal that came during
    ``fork`` would otherwise run its handler inside Python's at-fork hooks, which swallow the handler's
    exception ("Exception ignored in _releaseLock"), and the command would go on as if no signal had come; blocked,
    the signal reaches the trainer just after the fork. In the worker, ``SIGTERM`` ends the process at once and
    silently (the default action: a forked worker would otherwise run the command's handler and print a
    traceback), the worker ends with its parent even on ``SIGKILL``
    (:func:`~freespace.runtime.parallel.die_with_parent`), and then the signals are unblocked. A thread of the
    worker that fails because the trainer hung up (the thread that hands batches' shared memory to the trainer,
    when the trainer stopped half-way through taking one) ends silently too (:func:`_quiet_when_trainer_gone`)."""

    def start(self) -> None:
        self._freespace_parent = os.getpid()
        old = signal.pthread_sigmask(signal.SIG_BLOCK, _FORK_BLOCKED)
        try:
            super().start()
        finally:  # a Ctrl-C or SIGTERM that came meanwhile is raised here, in the trainer
            signal.pthread_sigmask(signal.SIG_SETMASK, old)

    def run(self) -> None:
        from freespace.runtime.parallel import die_with_parent

        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        threading.excepthook = _quiet_when_trainer_gone
        die_with_parent(self._freespace_parent)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _FORK_BLOCKED)
        super().run()


def _quiet_when_trainer_gone(args: threading.ExceptHookArgs) -> None:
    """A loader worker's thread hook: a lost connection (the trainer stopped, on Ctrl-C or ``SIGTERM``, while it
    took a batch's shared memory from the worker's ``multiprocessing`` resource sharer) is not reported: the
    worker ends with the trainer, and the command's one-line message is the report. Anything else is."""
    if not issubclass(args.exc_type, (ConnectionError, EOFError)):
        threading.__excepthook__(args)


class _LoaderContext(multiprocessing.context.ForkContext):
    Process = _LoaderProcess


def loader_context() -> multiprocessing.context.BaseContext | None:
    """The ``multiprocessing_context`` of the training DataLoaders: forked workers (:class:`_LoaderProcess`)
    that stop at once with the command and leave no process behind; None (PyTorch's default) where processes
    are not forked or signals cannot be blocked (not Linux)."""
    if not sys.platform.startswith("linux") or not hasattr(signal, "pthread_sigmask"):
        return None
    return _LoaderContext()


class EpochSampler(torch.utils.data.Sampler):
    """Yields ``(epoch, i)``: a permutation drawn from (seed, epoch) when shuffling, this rank's share
    under DDP (training shares are padded to equal length; evaluation shares are disjoint)."""

    def __init__(self, n: int, seed: int, shuffle: bool) -> None:
        self.n, self.seed, self.shuffle, self.epoch = n, seed, shuffle, 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def _order(self) -> list[int]:
        order = (np.random.default_rng([self.seed, self.epoch]).permutation(self.n) if self.shuffle
                 else np.arange(self.n))
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
    """Open the dataset, decide the subsets (their lists in ``run_dir/splits``) and, when ``config.augment``
    holds ``"homography"``, make the DS-Generator views of the training frames (``run_dir/generated``).
    ``"duplicate"`` (the control of ``homography``) makes them too, only to know which frames have one, and
    adds those frames once more with their own left images: the same frames, labels and number of training
    samples (so of steps per epoch) as ``homography``, without the views' content.

    With ``"virtual"`` it finds the road plane of every training frame (:class:`VirtualAugment`).

    Returns ``{"dataset", "train", "val", "test"}`` (lists of :class:`Item`; ``train`` starts with the
    training frames themselves, ``"frames"`` of them, and the views or duplicates follow), ``"size"``
    (H, W: ``config.image_size``, or the first labelled frame's for
    :data:`~freespace.engine.option_values.FIRST_FRAME_SIZE`: :meth:`TrainConfig.with_size`) and ``"virtual"`` (a
    :class:`VirtualAugment`, or None).
    """
    plan = plan_data(config, run_dir)
    ds, splits, index, stereo = plan["dataset"], plan["splits"], plan["index"], plan["stereo"]
    virtual = None
    if "virtual" in config.augment:  # before the DS-Generator views: a virtual_shift no frame allows is refused first
        virtual = VirtualAugment(_road_planes(ds, [index[n] for n in splits["train"]], config.virtual_shift),
                                 shift=config.virtual_shift, rotate=config.virtual_rotate, prob=config.virtual_prob)
    if is_rank_zero():
        write_splits(run_dir / "splits", splits)
    items = {k: [Item(index[n], n) for n in v] for k, v in splits.items()}
    if "homography" in config.augment:
        items["train"] += _generated_views(ds, [index[n] for n in stereo], run_dir / "generated")
    elif "duplicate" in config.augment:  # the control: the same frames again, their own left images
        views = _generated_views(ds, [index[n] for n in stereo], run_dir / "generated")
        items["train"] += [Item(it.index, it.name) for it in views]
    first = next(iter(index.values()))
    size = config.with_size(lambda: ds.load(first, right=False, disparity=False).left.shape[:2]).image_size
    return {"dataset": ds, **items, "frames": len(splits["train"]), "size": size, "virtual": virtual,
            "labelled": plan.get("labelled")}


def plan_data(config: TrainConfig, run_dir: Path, warn: bool = True) -> dict[str, Any]:
    """What :func:`prepare_data` trains on, decided and checked without writing anything: the dataset (with the
    label tree's labels), the splits, each labelled frame's index and the training frames with a right image.
    ``reproduce`` calls it for every cell before the first trains. ``warn``: log what it leaves out or reads
    in place of the dataset's labels (after every check, so that a refusal stays one line).

    Returns ``{"dataset", "splits", "index", "stereo"}``.

    Raises:
        DatasetError: fewer than 3 labelled frames, a split left empty, a label tree without the training
            frames, no labelled pixel, no right image for ``augment`` homography or duplicate.
        InvalidOptionError: ``human_share`` on a dataset without labels of its own.
    """
    if config.images is not None:
        return _plan_folder(config)
    ds = get_dataset(config.dataset, config.root, config.split, disparity_source=config.disparity_source,
                     cache_dir=config.cache_dir)
    labelled = ds.labelled().frames
    notes: list[str] = []
    if not labelled and config.labels is not None:  # a layout without labels (KITTI raw): the tree labels every split
        if config.human_share:
            raise InvalidOptionError(f"{param('human_share')} needs frames labelled by people; {config.dataset} at "
                                     f"{config.root} has none: leave it at 0")
        ds = apply_label_tree(ds, config.labels, tree_labels(config.labels, [f.name for f in ds.frames]))
        labelled = ds.labelled().frames
        notes.append(f"labels: {config.dataset} at {config.root} has no labels of its own: validation and test use "
                     f"{config.labels} as well (measure the model on human labels with freespace evaluate)")
    if config.max_frames is not None:
        labelled = labelled[: config.max_frames]
    if len(labelled) < 3:
        raise DatasetError(f"{config.dataset} at {config.root} has {len(labelled)} labelled frames; training needs ≥ 3")
    splits = _splits(config, ds, labelled, run_dir / "splits")
    if config.labels is not None:  # the training frames' labels from a label tree; val and test keep their own
        human = _human_drives(labelled, splits["train"], config.human_share, config.seed)
        tree = set(tree_labels(config.labels, splits["train"]))
        train = [n for n in splits["train"] if n in human or n in tree]
        if not train:
            raise DatasetError(f"{param('labels')} {config.labels} has no label of any of the {len(splits['train'])} "
                               f"training frames (<frame>.png); label them with `freespace autolabel`")
        if len(train) < len(splits["train"]):
            notes.append(f"labels: {len(splits['train']) - len(train)} of {len(splits['train'])} training frames have "
                         f"no label in {config.labels} and are left out")
        ds = apply_label_tree(ds, config.labels, [n for n in train if n not in human])
        splits = {**splits, "train": train}
    _check_labelled(ds, splits["train"], config.labels)
    index = {f.name: ds.index(f.name) for f in labelled}
    stereo = [n for n in splits["train"] if ds.frames[index[n]].right is not None]
    needs_right = [a for a in ("homography", "duplicate") if a in config.augment]
    if needs_right and not stereo:  # checked before anything is written
        why = {"homography": "the DS-Generator warps them", "duplicate": "it repeats the frames that have a "
               "DS-Generator view"}[needs_right[0]]
        raise DatasetError(f"{param('augment')} {needs_right[0]} needs right images ({why}); none of the "
                           f"{len(splits['train'])} training frames has one")
    for note in notes if warn else ():
        log.warning("%s", note)
    return {"dataset": ds, "splits": splits, "index": index, "stereo": stereo}


def _plan_folder(config: TrainConfig) -> dict[str, Any]:
    """:func:`plan_data` of a labelled folder (:func:`~freespace.engine.labelled.labelled_frames`): train on its
    training frames, validate on the validation frames, and test on them too (a labelled folder has no test set
    of its own: measure the model on frames apart with ``freespace evaluate``)."""
    found = labelled_frames(config)
    ds = found.dataset()
    splits = {"train": [f.name for f in found.groups["train"]], "val": [f.name for f in found.groups["val"]]}
    splits["test"] = splits["val"]
    index = {f.name: i for i, f in enumerate(ds.frames)}
    return {"dataset": ds, "splits": splits, "index": index, "stereo": [], "labelled": found}


def _splits(config: TrainConfig, ds: StereoRoadDataset, labelled: list[Any], split_dir: Path) -> dict[str, list[str]]:
    """The train/val/test frame names: ``config.splits_dir``'s lists, else the run's own (``split_dir``, a
    resumed run), else a split of the ``labelled`` frames by scenario.

    Raises:
        DatasetError: a listed frame of the dataset that has no label (named with its cause: a label tree
            that lacks it, such as one shard's part, or ``max_frames``), or a split left empty (named with its
            cause: lists without frames there, or too few scenarios to split whole).
    """
    names = {f.name for f in labelled}
    lists = config.splits_dir or (split_dir if (split_dir / "train.txt").is_file() else None)
    if lists is None:
        splits = make_splits([(f.name, f.scenario) for f in labelled], seed=config.seed)
    else:
        splits = read_splits(lists, known=[f.name for f in ds.frames])
        missing = [n for k in ("train", "val", "test") for n in splits[k] if n not in names]
        if missing:
            raise DatasetError(f"{len(missing)} frames of the subset lists {lists} have no label (first: "
                               f"{missing[0]}): {_why_unlabelled(config, ds, missing[0])}")
    if not all(splits.values()):
        counts = ", ".join(f"{k} {len(v)}" for k, v in splits.items())
        if lists is not None:
            raise DatasetError(f"the subset lists {lists} leave a subset empty ({counts}); list labelled frames in "
                               f"each of train.txt, val.txt and test.txt")
        scenarios = len({f.scenario for f in labelled})
        raise DatasetError(f"a split is empty ({counts}): the {len(labelled)} labelled frames are {scenarios} "
                           f"scenarios (drives), and each scenario goes whole into one split; use frames of more "
                           f"scenarios, or give {param('splits_dir')}")
    return splits


def _why_unlabelled(config: TrainConfig, ds: StereoRoadDataset, name: str) -> str:
    """Why the dataset's frame ``name`` is not among the labelled frames training uses, and the fix: ``max_frames``
    cut it, the dataset has no label of it, or (a dataset without labels of its own) the label tree has none."""
    if ds.has_label(ds.frames[ds.index(name)]):
        return f"{param('max_frames')} {config.max_frames} leaves it out; raise it or list fewer frames"
    if config.labels is None or any(f.label is not None for f in ds.frames):
        return f"{config.dataset} at {config.root} has no label of it; list labelled frames only"
    shards = sorted(p.name for p in Path(config.labels).glob("summary.shard-*.json"))
    part = (f"it holds shards' parts ({', '.join(shards)}): label the other shards into it (`freespace autolabel` "
            f"with each shard K/N), or " if shards else "label those frames or ")
    return f"the label tree {param('labels')} {config.labels} has no {name}.png; {part}list only the frames it labels"


def _check_labelled(ds: StereoRoadDataset, train: list[str], labels: str | None) -> None:
    """Refuse a training set in which no pixel is labelled (every label all don't care: the loss would be 0 and
    nothing learnt), before any training. Reads the training labels until one has a labelled pixel (the
    first, unless something is wrong); a label tree's files are read once per process."""
    from freespace.io.codecs import read_road_label

    tree = label_tree_pixels(labels) if labels is not None else {}
    for name in train:
        path = ds.label_files.get(name)
        if path is not None and labels is not None and Path(path).parent.resolve() == Path(labels).resolve() \
                and name in tree:
            if tree[name]:
                return
            continue
        label = read_road_label(path) if path is not None else ds.read_label(ds.frames[ds.index(name)])
        if label.valid.any():
            return
    where = f"{param('labels')} {labels}" if labels is not None else f"the dataset's labels ({ds.root})"
    raise DatasetError(f"none of the {len(train)} training frames has a labelled pixel in {where}: every pixel is "
                       f"don't care, so training would learn nothing (loss 0); give labels with road and non-road")


def _human_drives(frames: list[Any], train: list[str], share: float, seed: int) -> set[str]:
    """The training frames that keep their own labels with ``human_share``: every frame of
    ``round(share · drives)`` training drives (scenarios), drawn from ``seed``."""
    scenario = {f.name: f.scenario for f in frames}
    drives = sorted({scenario[n] for n in train})
    keep = {drives[i] for i in np.random.default_rng([seed, 29]).permutation(len(drives))[:round(share * len(drives))]}
    return {n for n in train if scenario[n] in keep}


def _road_planes(ds: StereoRoadDataset, indices: list[int], shift: Any) -> dict[int, tuple[np.ndarray, Any]]:
    """Intrinsics and road plane of each frame, for the virtual views: the calibration's plane (KITTI
    ``Tr_cam_to_road``, or the camera height and pitch of ``freespace.yaml``), else the road fit of the
    frame's disparity (file, depth, LiDAR or SGBM, as ``disparity_source`` allows) with the rig's focal
    length and baseline; a fit no real rig gives (:meth:`~freespace.geometry.RoadModel.check_plausible`)
    leaves its frame without views.

    Raises:
        InvalidOptionError: a camera move within ``shift`` (``virtual_shift``, metres) can take a frame's
            camera closer than :data:`~freespace.geometry.road_model.CAMERA_HEIGHT_RANGE_M`'s lowest height
            to its road plane (or through it), checked here, before any training.
    """
    from freespace.errors import FreespaceError, InvalidOptionError
    from freespace.geometry import RoadPlane, fit_road_model, pose_ranges
    from freespace.geometry.road_model import CAMERA_HEIGHT_RANGE_M

    planes: dict[int, tuple[np.ndarray, Any]] = {}
    reasons: dict[str, str] = {}
    for i in indices:
        frame = ds.frames[i]
        try:
            calib = ds.calibration(frame)
            if calib is None:
                raise DatasetError("no camera (calibration file or `camera:` in freespace.yaml)")
            if calib.road_plane is not None:
                plane = calib.road_plane
            else:
                sample = ds.load(i)
                if sample.disparity is None or sample.label is None or not calib.baseline > 0:
                    scan = (f" (it has a LiDAR scan: {param('disparity_source')} lidar or fused fits one to it)"
                            if frame.velodyne is not None and ds.disparity_source not in ("lidar", "fused") else "")
                    raise DatasetError(f"no road plane in the calibration and no disparity (and baseline) to fit "
                                       f"one{scan}")
                model = fit_road_model(sample.disparity, sample.label.road & sample.label.valid)
                plane = RoadPlane.from_road_model(model, calib.fx, calib.baseline, calib.cx, calib.cy, fy=calib.fy)
                model.check_plausible(plane.height)
            planes[i] = (calib.K, plane)
        except FreespaceError as exc:
            reasons[frame.name] = str(exc)
    if not planes:
        first = next(iter(reasons.items()), ("", ""))
        raise DatasetError(f"{param('augment')} virtual needs each frame's camera and road plane; none of the "
                           f"{len(indices)} training frames has one ({first[0]}: {first[1]}); give a KITTI calibration "
                           f"with Tr_cam_to_road, `camera: {{height: .., pitch: ..}}` in freespace.yaml, or "
                           f"disparities")
    lowest = min(planes, key=lambda i: planes[i][1].clearance(shift))
    plane, least = planes[lowest][1], CAMERA_HEIGHT_RANGE_M[0]
    if plane.clearance(shift) < least:
        # the largest move down (DY) that keeps every frame's camera `least` above its road (DX, DZ kept)
        dy = min((p.clearance((shift[0], 0.0, shift[2])) - least) / max(abs(p.n[1]), 1e-9) for _, p in planes.values())
        fix = (f"a DY that moves it down by at most {dy:.2f} m: {dy:.2f} (±), or LO:{dy:.2f} (raised by up to -LO m)"
               if dy > 0 else "smaller DX and DZ")
        raise InvalidOptionError(
            f"{param('virtual_shift')} {ranges_text(pose_ranges(shift))} can move the camera through the road: frame "
            f"{ds.frames[lowest].name}'s camera is {plane.height:.2f} m above its road, and a move within those "
            f"ranges brings it {plane.height - plane.clearance(shift):.2f} m closer; to keep it ≥ {least:g} m above "
            f"the road give {fix}")
    if reasons:
        log.warning("%d of %d training frames have no road plane and get no virtual views: %s", len(reasons),
                    len(indices), "; ".join(f"{k}: {v}" for k, v in list(reasons.items())[:3]))
    log.info("virtual views: road planes of %d training frames", len(planes))
    return planes


def _generated_views(ds: StereoRoadDataset, indices: list[int], folder: Path) -> list[Item]:
    """DS-Generator views of the given frames (which have right images; made once, resumable), as items with
    the frames' labels."""
    from freespace.datagen.generate import generate_dataset

    sub = ds.subset(ds.frames[i].name for i in indices)
    if is_rank_zero():
        summary = generate_dataset(sub, folder)
        if summary["failed"]:
            log.warning("%d of %d frames gave no generated view (skipped): %s", len(summary["failed"]),
                        len(sub.frames), "; ".join(f"{k}: {v}" for k, v in list(summary["failed"].items())[:3]))
    return [Item(ds.index(f.name), f.name, str(folder / f"{f.name}.png")) for f in sub.frames
            if (folder / f"{f.name}.png").is_file()]
