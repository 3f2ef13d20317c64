"""The dataset interface shared by every layout (torch-free).

A dataset lists its frames (:class:`FrameRef`: paths only, cheap) and loads them on demand
(:class:`Sample`: arrays). Layouts differ only in how they list frames and decode labels and depth.
Disparity sources live in :mod:`freespace.data.disparity`, the registry in :mod:`freespace.data.registry`
and the integrity scan in :mod:`freespace.data.info`.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from freespace.data.disparity import DisparityCache, check_disparity_source, resolve_disparity
from freespace.errors import DatasetError, InputFileError, InvalidOptionError, ShapeMismatchError, param
from freespace.geometry import SGBM_MAX_DISPARITY, StereoCalibration
from freespace.io.codecs import describe_image, read_image, read_road_label
from freespace.io.files import PathLike
from freespace.labels import RoadLabel

__all__ = ["FrameRef", "Sample", "Problem", "StereoRoadDataset", "check_dataset_root"]


@dataclass(frozen=True)
class FrameRef:
    """Where one frame's files are. Paths are None when the file does not exist.

    ``scenario`` groups frames of one drive/sequence (splits never separate them); ``category`` is the
    KITTI road category (um/umm/uu) or the layout's own grouping.
    """

    name: str
    category: str
    scenario: str
    left: Path
    right: Path | None = None
    label: Path | None = None
    disparity: Path | None = None
    depth: Path | None = None
    calib: Path | None = None
    velodyne: Path | None = None


@dataclass
class Sample:
    """One loaded frame.

    Attributes:
        name, category, scenario: identifiers (see :class:`FrameRef`).
        left: ``H×W×3 uint8`` RGB reference image; right: the target image or None.
        label: road label with don't-care (``valid``), or None (unlabelled split).
        disparity: ``float32 H×W`` left disparity in pixels (NaN invalid), or None.
        disparity_source: ``file``, ``depth``, ``lidar``, ``sgbm``, ``fused`` or ``none``.
        calibration: the rig (and road plane when known), or None.
    """

    name: str
    category: str
    scenario: str
    left: np.ndarray
    right: np.ndarray | None = None
    label: RoadLabel | None = None
    disparity: np.ndarray | None = None
    disparity_source: str = "none"
    calibration: StereoCalibration | None = None


@dataclass(frozen=True)
class Problem:
    """One integrity problem of a dataset: the frame (or file) and what is wrong."""

    frame: str
    message: str

    def __str__(self) -> str:
        return f"{self.frame}: {self.message}"


def check_dataset_root(root: PathLike, layout: str) -> Path:
    """``root`` as a Path if it is a folder; InputFileError (the same everywhere) if it is not."""
    root = Path(root)
    if not root.is_dir():
        what = f"dataset root {root} is a file" if root.exists() else f"dataset root not found: {root}"
        raise InputFileError(f"{what} (give the folder that holds the {layout} dataset)")
    return root


class StereoRoadDataset(ABC):
    """Base class of every dataset layout.

    Args:
        root: dataset folder.
        split: the layout's on-disk split (``training``/``testing`` for KITTI road; layouts without
            on-disk splits accept only ``all``).
        disparity_source: where disparities come from: ``auto`` (file, else depth + calibration, else
            SGBM), ``file`` (file or depth only), ``depth`` (depth only), ``lidar`` (Velodyne scans
            only), ``sgbm`` (always SGBM), ``none`` (:func:`~freespace.data.disparity.resolve_disparity`).
            ``depth`` and ``lidar`` refuse a dataset without any depth map or scan.
        cache_dir: folder of the SGBM cache (see :class:`~freespace.data.disparity.DisparityCache`).
        max_disparity: SGBM search range in pixels.
    """

    name: ClassVar[str] = ""
    splits: ClassVar[tuple[str, ...]] = ("all",)
    #: frame name → a KITTI-colour label file read instead of the layout's own label (a label tree's:
    #: :func:`freespace.data.label_tree.apply_label_tree`)
    label_files: dict[str, Path] = {}

    def __init__(self, root: PathLike, split: str | None = None, *, disparity_source: str = "auto",
                 cache_dir: PathLike | None = None, max_disparity: int = SGBM_MAX_DISPARITY) -> None:
        self.root = check_dataset_root(root, self.name)
        self.split = split or self.splits[0]
        if self.split not in self.splits:
            raise InvalidOptionError(f"unknown split {self.split!r} for {self.name}; choose one of "
                                     f"{', '.join(self.splits)}")
        self.disparity_source = check_disparity_source(disparity_source)
        self.cache = DisparityCache(cache_dir, max_disparity=max_disparity)
        self.frames: list[FrameRef] = self._list()
        if not self.frames:
            raise DatasetError(f"no frames found for {self.name} split {self.split!r} under {self.root}; "
                               f"see `freespace datasets info` and the expected tree in the docs")
        names = [f.name for f in self.frames]
        if len(set(names)) != len(names):
            raise DatasetError(f"{self.name}: frame names are not unique under {self.root}")
        if self.disparity_source == "fused" and not any(f.velodyne is not None or f.right is not None
                                                         for f in self.frames):
            raise DatasetError(f"{param('disparity_source')} fused: no frame of {self.name} split {self.split!r} under "
                               f"{self.root} has a Velodyne scan or a right image; see the layout's tree in the docs")
        kind = {"depth": "depth", "lidar": "velodyne"}.get(self.disparity_source)
        if kind is not None and not any(getattr(f, kind) is not None for f in self.frames):
            raise DatasetError(f"{param('disparity_source')} {self.disparity_source}: no frame of {self.name} split "
                               f"{self.split!r} under {self.root} has a "
                               f"{'depth map' if kind == 'depth' else 'Velodyne scan'}; see the layout's tree in the "
                               f"docs")

    # --- what a layout provides ---------------------------------------------------------------------
    @abstractmethod
    def _list(self) -> list[FrameRef]:
        """Frames of ``self.split``, sorted by name, with their partner files."""

    @abstractmethod
    def read_label(self, frame: FrameRef) -> RoadLabel:
        """Decode the frame's road label."""

    def calibration(self, frame: FrameRef) -> StereoCalibration | None:
        """The frame's rig, or None when unknown."""
        return None

    def read_depth(self, frame: FrameRef) -> np.ndarray:
        """Decode the frame's depth map (``float32 H×W`` metres along the optical axis, NaN invalid)."""
        raise DatasetError(f"{self.name} has no depth maps")

    def read_lidar(self, frame: FrameRef, shape: tuple[int, int]) -> np.ndarray:
        """The frame's Velodyne scan projected into the left image: ``float32 H×W`` disparity in pixels
        (``shape`` = ``(H, W)``), NaN where no point landed. Layouts with scans override."""
        raise DatasetError(f"{self.name} has no Velodyne scans")

    def orphans(self) -> list[Problem]:
        """Files without a left image (mispaired names); layouts override."""
        return []

    # --- shared behaviour -----------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self) -> Iterator[FrameRef]:
        return iter(self.frames)

    def index(self, name: str) -> int:
        """Position of the frame called ``name``."""
        for i, f in enumerate(self.frames):
            if f.name == name:
                return i
        raise DatasetError(f"frame {name!r} is not in {self.name} {self.split}")

    def subset(self, names: Iterable[str]) -> StereoRoadDataset:
        """This dataset (layout, split, disparity options) restricted to the frames called ``names``, in
        that order; positions (:meth:`index`, :meth:`load`) are those of the subset.

        Raises:
            DatasetError: a name is not a frame of this dataset.
        """
        by_name = {f.name: f for f in self.frames}
        frames = []
        for name in names:
            if name not in by_name:
                raise DatasetError(f"frame {name!r} is not in {self.name} {self.split}")
            frames.append(by_name[name])
        view = copy.copy(self)
        view.frames = frames
        return view

    def has_label(self, frame: FrameRef) -> bool:
        """Whether ``frame`` has a road label: its own, or one from a label tree
        (:func:`~freespace.data.label_tree.apply_label_tree`)."""
        return frame.label is not None or frame.name in self.label_files

    def labelled(self) -> StereoRoadDataset:
        """The frames that have a road label (:meth:`has_label`; :meth:`subset`), in order."""
        return self.subset(f.name for f in self.frames if self.has_label(f))

    def load(self, i: int, *, right: bool = True, label: bool = True, disparity: bool = True) -> Sample:
        """Load frame ``i`` (what is not asked for, or not there, is None)."""
        frame = self.frames[i]
        left_img = read_image(frame.left, what="left image")
        right_img = read_image(frame.right, what="right image") if right and frame.right else None
        if right_img is not None and right_img.shape != left_img.shape:
            raise ShapeMismatchError(f"{frame.name}: right image {frame.right} is {describe_image(right_img.shape)} "
                                     f"but the left is {describe_image(left_img.shape)}; a stereo pair has two images "
                                     f"of one size and kind")
        if label and frame.name in self.label_files:
            lab = read_road_label(self.label_files[frame.name])
        else:
            lab = self.read_label(frame) if label and frame.label else None
        if lab is not None and lab.shape != left_img.shape[:2]:
            raise ShapeMismatchError(f"{frame.name}: label is {lab.shape[1]}×{lab.shape[0]} but the image is "
                                     f"{left_img.shape[1]}×{left_img.shape[0]}")
        calib = self.calibration(frame)
        disp, source = (self._disparity(frame, left_img, right_img, calib) if disparity else (None, "none"))
        if disp is not None and disp.shape != left_img.shape[:2]:
            raise ShapeMismatchError(f"{frame.name}: disparity is {disp.shape[1]}×{disp.shape[0]} but the image is "
                                     f"{left_img.shape[1]}×{left_img.shape[0]}")
        return Sample(name=frame.name, category=frame.category, scenario=frame.scenario, left=left_img,
                      right=right_img, label=lab, disparity=disp, disparity_source=source, calibration=calib)

    def _disparity(self, frame: FrameRef, left: np.ndarray, right: np.ndarray | None,
                   calib: StereoCalibration | None) -> tuple[np.ndarray | None, str]:
        return resolve_disparity(frame, left, right, calib, mode=self.disparity_source, cache=self.cache,
                                 read_depth=lambda: self.read_depth(frame),
                                 read_lidar=lambda: self.read_lidar(frame, left.shape[:2]))

    def expected_partners(self) -> set[str]:
        """Kinds of file every frame should have, given which folders exist (a missing one is a problem for
        :func:`freespace.data.info.check_dataset`)."""
        kinds = set()
        for kind in ("right", "label", "disparity", "depth", "calib", "velodyne"):
            if any(getattr(f, kind) is not None for f in self.frames):
                kinds.add(kind)
        return kinds

