"""The dataset interface shared by every layout (torch-free).

A dataset lists its frames (:class:`FrameRef`: paths only, cheap) and loads them on demand
(:class:`Sample`: arrays). Layouts differ only in how they list frames and decode labels and depth;
the rest — disparity resolution (file → depth + calibration → cached SGBM), integrity checks,
registry — lives here.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from freespace.errors import DatasetError, FreespaceError, InputFileError, InvalidOptionError, ShapeMismatchError
from freespace.geometry import StereoCalibration, compute_disparity
from freespace.io import PathLike, RoadLabel, atomic_write_bytes, read_disparity, read_image, read_raw

log = logging.getLogger(__name__)

__all__ = ["FrameRef", "Sample", "Problem", "StereoRoadDataset", "DisparityCache", "register_dataset",
           "get_dataset", "list_datasets", "DISPARITY_MODES", "image_size"]

DISPARITY_MODES = ("auto", "file", "sgbm", "none")


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


@dataclass
class Sample:
    """One loaded frame.

    Attributes:
        name, category, scenario: identifiers (see :class:`FrameRef`).
        left: ``H×W×3 uint8`` RGB reference image; right: the target image or None.
        label: road label with don't-care (``valid``), or None (unlabelled split).
        disparity: ``float32 H×W`` left disparity in pixels (NaN invalid), or None.
        disparity_source: ``file``, ``depth``, ``sgbm`` or ``none``.
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


def image_size(path: Path) -> tuple[int, int]:
    """``(H, W)`` of an image file; decodes it fully so corrupt files are caught.

    Raises:
        InputFileError, CorruptFileError.
    """
    img = read_raw(path)
    return int(img.shape[0]), int(img.shape[1])


class DisparityCache:
    """SGBM disparities on disk, keyed by the frame's image files (path, size, mtime) and the matcher
    settings, so a second run costs one ``.npy`` read. Default folder: ``$XDG_CACHE_HOME/freespace/sgbm``
    (``~/.cache/freespace/sgbm``)."""

    def __init__(self, folder: PathLike | None = None, **settings: Any) -> None:
        base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "freespace" / "sgbm"
        self.folder = Path(folder) if folder is not None else base
        self.settings = dict(sorted(settings.items()))

    def path(self, frame: FrameRef) -> Path:
        """Cache file of ``frame`` under the current settings."""
        parts = [self.settings]
        for p in (frame.left, frame.right):
            st = Path(p).stat()  # type: ignore[arg-type]
            parts.append([str(Path(p).resolve()), st.st_size, st.st_mtime_ns])  # type: ignore[arg-type]
        key = hashlib.sha1(json.dumps(parts, default=str).encode()).hexdigest()[:16]
        return self.folder / f"{frame.name}-{key}.npy"

    def get(self, frame: FrameRef, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """The cached disparity, computing and storing it on a miss."""
        path = self.path(frame)
        if path.is_file():
            try:
                return np.load(path, allow_pickle=False)
            except (OSError, ValueError):
                log.warning("unreadable cache file %s: recomputing", path)
        disp = compute_disparity(left, right, **self.settings)
        import io as _io

        buf = _io.BytesIO()
        np.save(buf, disp)
        atomic_write_bytes(path, buf.getvalue())
        return disp


class StereoRoadDataset(ABC):
    """Base class of every dataset layout.

    Args:
        root: dataset folder.
        split: the layout's on-disk split (``training``/``testing`` for KITTI road; layouts without
            on-disk splits accept only ``all``).
        disparity: where disparities come from: ``auto`` (file, else depth + calibration, else SGBM),
            ``file`` (file or depth only), ``sgbm`` (always SGBM), ``none``.
        cache_dir: folder of the SGBM cache (see :class:`DisparityCache`).
        max_disparity: SGBM search range in pixels.
    """

    name: ClassVar[str] = ""
    splits: ClassVar[tuple[str, ...]] = ("all",)

    def __init__(self, root: PathLike, split: str | None = None, *, disparity: str = "auto",
                 cache_dir: PathLike | None = None, max_disparity: int = 128) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise InputFileError(f"dataset root not found: {self.root} (give the folder that holds the "
                                 f"{self.name} dataset)")
        self.split = split or self.splits[0]
        if self.split not in self.splits:
            raise InvalidOptionError(f"unknown split {self.split!r} for {self.name}; choose one of "
                                     f"{', '.join(self.splits)}")
        if disparity not in DISPARITY_MODES:
            raise InvalidOptionError(f"unknown disparity source {disparity!r}; choose one of {', '.join(DISPARITY_MODES)}")
        self.disparity_mode = disparity
        self.cache = DisparityCache(cache_dir, max_disparity=max_disparity)
        self.frames: list[FrameRef] = self._list()
        if not self.frames:
            raise DatasetError(f"no frames found for {self.name} split {self.split!r} under {self.root}; "
                               f"see `freespace datasets info` and the expected tree in the docs")
        names = [f.name for f in self.frames]
        if len(set(names)) != len(names):
            raise DatasetError(f"{self.name}: frame names are not unique under {self.root}")

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

    @property
    def has_right(self) -> bool:
        """Whether any frame has a right image (needed for the augmentation)."""
        return any(f.right is not None for f in self.frames)

    def load(self, i: int, *, right: bool = True, label: bool = True, disparity: bool = True) -> Sample:
        """Load frame ``i`` (what is not asked for, or not there, is None)."""
        frame = self.frames[i]
        left_img = read_image(frame.left, what="left image")
        right_img = read_image(frame.right, what="right image") if right and frame.right else None
        if right_img is not None and right_img.shape != left_img.shape:
            raise ShapeMismatchError(f"{frame.name}: right image is {right_img.shape[1]}×{right_img.shape[0]} but the "
                                     f"left is {left_img.shape[1]}×{left_img.shape[0]}")
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
        mode = self.disparity_mode
        if mode in ("auto", "file"):
            if frame.disparity is not None:
                return read_disparity(frame.disparity), "file"
            if frame.depth is not None and calib is not None and calib.baseline > 0:  # 0: monocular
                return depth_to_disparity(self.read_depth(frame), calib), "depth"
        if mode in ("auto", "sgbm") and right is not None:
            return self.cache.get(frame, left, right), "sgbm"
        return None, "none"

    def check(self, progress: bool = False) -> list[Problem]:
        """Open every file of every frame; return every problem found (missing partners, sizes that
        disagree, unreadable files, files without a left image)."""
        return self.scan(progress)[0]

    def scan(self, progress: bool = False) -> tuple[list[Problem], dict[str, tuple[int, int]]]:
        """:meth:`check`, plus the ``(H, W)`` of every readable left image by frame name."""
        from tqdm import tqdm

        problems = list(self.orphans())
        left_sizes: dict[str, tuple[int, int]] = {}
        expect = self.expected_partners()
        for frame in tqdm(self.frames, desc="check", unit="frame", disable=not progress):
            sizes: dict[str, tuple[int, int]] = {}
            for kind in ("left", "right", "label", "disparity", "depth"):
                path = getattr(frame, kind)
                if path is None:
                    if kind in expect:
                        problems.append(Problem(frame.name, f"missing {kind} file"))
                    continue
                try:
                    if kind == "disparity" and Path(path).suffix.lower() != ".png":
                        sizes[kind] = read_disparity(path).shape  # type: ignore[assignment]
                    else:
                        sizes[kind] = image_size(path)
                except FreespaceError as exc:
                    problems.append(Problem(frame.name, str(exc)))
            if frame.calib is None and "calib" in expect:
                problems.append(Problem(frame.name, "missing calib file"))
            elif frame.calib is not None:
                try:
                    self.calibration(frame)
                except (FreespaceError, KeyError, ValueError) as exc:
                    problems.append(Problem(frame.name, f"bad calibration {frame.calib}: {exc}"))
            ref = sizes.get("left")
            if ref is not None:
                left_sizes[frame.name] = ref
            for kind, size in sizes.items():
                if ref is not None and size != ref:
                    problems.append(Problem(frame.name, f"{kind} is {size[1]}×{size[0]} but left is {ref[1]}×{ref[0]}"))
        return problems, left_sizes

    def expected_partners(self) -> set[str]:
        """Kinds of file every frame should have, given which folders exist (a missing one is a problem)."""
        kinds = set()
        for kind in ("right", "label", "disparity", "depth", "calib"):
            if any(getattr(f, kind) is not None for f in self.frames):
                kinds.add(kind)
        return kinds


def depth_to_disparity(depth: np.ndarray, calib: StereoCalibration) -> np.ndarray:
    """Disparity ``d = fx·B / Z`` (pixels) from depth along the optical axis ``Z`` (metres); invalid
    depth (≤ 0, NaN, inf) gives NaN."""
    depth = np.asarray(depth, np.float32)
    out = np.full(depth.shape, np.nan, np.float32)
    ok = np.isfinite(depth) & (depth > 0)
    out[ok] = np.float32(calib.fx * calib.baseline) / depth[ok]
    return out


# --- registry ----------------------------------------------------------------------------------------

_REGISTRY: dict[str, type[StereoRoadDataset]] = {}


def register_dataset(*names: str):
    """Class decorator: make a layout available under ``names`` (first = canonical)."""
    def wrap(cls: type[StereoRoadDataset]) -> type[StereoRoadDataset]:
        cls.name = names[0]
        for n in names:
            _REGISTRY[n] = cls
        return cls
    return wrap


def list_datasets() -> list[str]:
    """Registered dataset names."""
    _load_layouts()
    return sorted(_REGISTRY)


def get_dataset(name: str, root: PathLike, split: str | None = None, **options: Any) -> StereoRoadDataset:
    """Open the dataset layout called ``name`` at ``root`` (options: see :class:`StereoRoadDataset`)."""
    _load_layouts()
    if name not in _REGISTRY:
        raise InvalidOptionError(f"unknown dataset {name!r}; choose one of {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name](root, split, **options)


def _load_layouts() -> None:
    import freespace.data.folder  # noqa: F401  (registers synthia, carla, generic)
    import freespace.data.kitti_road  # noqa: F401  (registers kitti)


