"""KITTI raw: rectified stereo drives with calibration and Velodyne scans, no labels.

Expected tree (KITTI raw's own layout, as its ``*_sync.zip`` and ``*_calib.zip`` unpack)::

    ROOT/<date>/calib_cam_to_cam.txt                             S_rect_02, R_rect_00, P_rect_02, P_rect_03
    ROOT/<date>/calib_velo_to_cam.txt                            R, T: Velodyne → camera 0 (needed with scans)
    ROOT/<date>/<date>_drive_<nnnn>_sync/image_02/data/<frame>.png     left colour camera, rectified
    ROOT/<date>/<date>_drive_<nnnn>_sync/image_03/data/<frame>.png     right colour camera (optional)
    ROOT/<date>/<date>_drive_<nnnn>_sync/velodyne_points/data/<frame>.bin
                                                                 Velodyne scan, float32 x, y, z, reflectance
                                                                 (optional)

``<date>`` is ``YYYY_MM_DD``, ``<frame>`` the ten-digit frame number. Any number of days and drives may
sit under ``ROOT``; ``root`` may also be one date folder or one drive folder (the calibration is then
read from the drive's parent). Other folders (``image_00``/``image_01``: the grey cameras, ``oxts``,
``*_extract``: the unrectified recording) are ignored.

Frames are named ``<drive>/<frame>`` (``2011_09_26_drive_0001_sync/0000000045``); the scenario is the
drive (splits by scenario never separate one; :func:`freespace.data.splits.make_block_splits` splits a
drive into contiguous time blocks) and the category the date. There are no road labels: label the drives
with ``freespace autolabel`` and train on that tree.

The rig of every frame comes from its day's ``P_rect_02`` (focal length, principal point) and
``P_rect_03`` (baseline, about 0.53 m; a virtual right camera 0.54 m to the right without ``P_rect_03``:
:func:`freespace.geometry.depth.rig_from_kitti`). A scan maps into the left image as KITTI's raw devkit
maps it: ``P_rect_02 · R_rect_00 · [R | T]`` (:mod:`freespace.geometry.lidar`). Images must have the size
``S_rect_02`` (1242×375 for 2011_09_26).

A drive without ``image_03`` supports what needs no right image (the ``lidar`` disparity source and
autolabel from it; loading for training, prediction and virtual views); the DS-Generator and SGBM refuse it up
front (:meth:`KittiRaw.require_right`). The tree's problems —
a missing calibration file, an empty drive folder, left and right frame lists that differ, images of
another size than ``S_rect_02``, and (with ``disparity_source="lidar"``) a scan whose size is not a
multiple of 16 bytes — stop the dataset from opening with one line naming the file;
``freespace datasets info`` opens it with ``strict=False`` and lists every one.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from freespace.data.base import FrameRef, Problem, Sample, StereoRoadDataset
from freespace.data.registry import register_dataset
from freespace.errors import (
    CorruptFileError,
    DatasetError,
    FreespaceError,
    InputFileError,
    InvalidOptionError,
    ShapeMismatchError,
    param,
)
from freespace.geometry import StereoCalibration
from freespace.geometry.depth import rig_from_kitti
from freespace.geometry.lidar import velodyne_to_disparity
from freespace.io.files import PathLike
from freespace.io.kitti import VELODYNE_POINT_BYTES, read_kitti_raw_calib, read_velodyne
from freespace.labels import RoadLabel

__all__ = ["KittiRaw", "CAM_TO_CAM", "VELO_TO_CAM"]

CAM_TO_CAM = "calib_cam_to_cam.txt"
VELO_TO_CAM = "calib_velo_to_cam.txt"
LEFT_DIR, RIGHT_DIR, VELODYNE_DIR = "image_02/data", "image_03/data", "velodyne_points/data"
_DATE = re.compile(r"^\d{4}_\d{2}_\d{2}$")
_DRIVE = re.compile(r"^(\d{4}_\d{2}_\d{2})_drive_(\d{4})_sync$")
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_header(path: Path) -> tuple[int, int, bool] | None:
    """``(W, H, grey)`` from a PNG file's header (26 bytes read; ``grey``: its colour type is grey, with or
    without alpha, as :func:`~freespace.io.codecs.read_image` reads it: ``H×W``), or None when it is no PNG
    (decoded later)."""
    try:
        with path.open("rb") as f:
            head = f.read(26)
    except OSError:
        return None
    if len(head) < 26 or not head.startswith(_PNG_SIGNATURE) or head[12:16] != b"IHDR":
        return None
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big"), head[25] in (0, 4)


def _png_size(path: Path) -> tuple[int, int] | None:
    """``(W, H)`` from a PNG file's header, or None when it is no PNG."""
    header = _png_header(path)
    return header[:2] if header is not None else None


def _size_problems(name: str, cam_file: Path, calib: dict[str, np.ndarray], lefts: dict[str, Path],
                   rights: dict[str, Path]) -> list[_TreeProblem]:
    """The drive ``name``'s images (left, and right ones with a left) whose size (from the PNG header) is not the
    calibration's rectified size ``S_rect_02``: one problem naming the first and counting them, or none."""
    width, height = (int(x) for x in calib["S_rect_02"])
    wrong = []
    for stem, path in list(lefts.items()) + [(s, p) for s, p in rights.items() if s in lefts]:
        size = _png_size(path)
        if size is not None and size != (width, height):
            wrong.append((stem, path, size))
    if not wrong:
        return []
    stem, path, (w, h) = wrong[0]
    return [_TreeProblem(f"{name}/{stem}", f"{path} is {w}×{h} but {cam_file} gives S_rect_02 "
                         f"{width}×{height} ({len(wrong)} image{'s' if len(wrong) > 1 else ''} of "
                         f"drive {name}); give the rectified images of the _sync zip (not _extract) "
                         f"and the calibration of their day", ShapeMismatchError)]


def _mixed_kinds(name: str, lefts: dict[str, Path], rights: dict[str, Path]) -> _TreeProblem | None:
    """One problem for the pairs of drive ``name`` whose left and right PNGs differ in kind (grey or colour), or
    None."""
    mixed = []
    for stem in sorted(set(lefts) & set(rights)):
        left, right = _png_header(lefts[stem]), _png_header(rights[stem])
        if left is not None and right is not None and left[2] != right[2]:
            mixed.append((stem, left[2]))
    if not mixed:
        return None
    stem, grey = mixed[0]
    kinds = ("grey", "colour") if grey else ("colour", "grey")
    return _TreeProblem(f"{name}/{stem}", f"{rights[stem]} is {kinds[1]} but its left image {lefts[stem]} is "
                                          f"{kinds[0]} ({len(mixed)} pair{'s' if len(mixed) > 1 else ''} of drive "
                                          f"{name}); give the colour cameras' images (image_02, image_03) to both "
                                          f"sides", ShapeMismatchError)


def _files(folder: Path, suffix: str) -> dict[str, Path]:
    """Frame stem → file of ``folder`` with ``suffix`` (hidden files left out); empty when no folder."""
    if not folder.is_dir():
        return {}
    return {p.stem: p for p in sorted(folder.glob(f"*{suffix}")) if p.is_file() and not p.name.startswith(".")}


class _TreeProblem(Exception):
    """Internal: one problem of the tree and the error class it raises when the dataset opens strictly."""

    def __init__(self, where: str, message: str, error: type[FreespaceError] = DatasetError) -> None:
        super().__init__(message)
        self.problem = Problem(where, message)
        self.error = error



def _unpaired(name: str, stems: list[str], side: tuple[str, Path], partner: tuple[str, Path], fix: str) -> _TreeProblem:
    """The images ``stems`` of drive ``name`` on one ``side`` (``("left", folder)``) whose ``partner`` image (the
    other side's, in its folder) is missing; ``fix``: what to do."""
    n, first = len(stems), stems[0]
    return _TreeProblem(f"{name}/{first}", f"{partner[1] / (first + '.png')} not found: {n} {side[0]} "
                                           f"image{'s' if n > 1 else ''} of {side[1]} {'have' if n > 1 else 'has'} no "
                                           f"{partner[0]} image (first {first}); {fix}")

@register_dataset("kitti-raw", "kitti_raw")
class KittiRaw(StereoRoadDataset):
    """KITTI raw drives (``*_sync``: rectified, synchronised); see the module docstring for the tree.

    Args:
        root: the folder holding date folders, one date folder, or one drive folder.
        split: ``all`` (KITTI raw has no on-disk split; split with ``freespace datasets split``).
        lidar_densify: 0 (default) keeps a scan's sparse disparity (``disparity_source="lidar"``); ``k > 0``
            fills every empty pixel within ``k`` pixels of a point with that point's disparity
            (:func:`freespace.geometry.lidar.densify_nearest`).
        strict: True (default): a problem of the tree (module docstring) raises, naming its file;
            False: the frames are listed anyway and :meth:`orphans` returns every problem (what
            ``freespace datasets info`` reports).
        Other arguments: :class:`~freespace.data.base.StereoRoadDataset`.

    Raises:
        InputFileError: no ``*_sync`` drive under ``root``, or a drive's ``calib_cam_to_cam.txt`` is missing.
        DatasetError, CorruptFileError, ShapeMismatchError: the other problems of the tree (``strict``).
    """

    splits = ("all",)
    #: KITTI raw has no labels of its own: splits are made of every frame (the labels come from autolabel)
    has_labels: ClassVar[bool] = False
    #: how ``freespace datasets info`` opens the layout: listing every problem instead of stopping at the first
    info_options: ClassVar[dict[str, Any]] = {"strict": False}

    def __init__(self, root: PathLike, split: str | None = None, *, lidar_densify: float = 0, strict: bool = True,
                 **options: Any) -> None:
        if isinstance(lidar_densify, bool) or not (isinstance(lidar_densify, (int, float))
                                                   and math.isfinite(lidar_densify) and lidar_densify >= 0):
            raise InvalidOptionError(f"{param('lidar_densify')} must be a number of pixels ≥ 0, got "
                                     f"{lidar_densify!r}")
        self.lidar_densify = float(lidar_densify)
        self.strict = bool(strict)
        self._problems: list[Problem] = []
        self._calib: dict[Path, dict[str, np.ndarray]] = {}
        self._missing_right: list[Path] = []  # image_03/data folders of drives that have none
        super().__init__(root, split, **options)

    # --- the tree ---------------------------------------------------------------------------------------
    def drives(self) -> list[Path]:
        """The drive folders under ``root`` (``<date>_drive_<nnnn>_sync``), sorted by name.

        Raises:
            InputFileError: there is none.
        """
        root = self.root
        if _DRIVE.match(root.name) or (root / "image_02").is_dir():
            return [root]
        drives = sorted(p for p in root.iterdir() if p.is_dir() and _DRIVE.match(p.name))
        if not drives:
            for day in sorted(p for p in root.iterdir() if p.is_dir() and _DATE.match(p.name)):
                drives += sorted(p for p in day.iterdir() if p.is_dir() and _DRIVE.match(p.name))
        if not drives:
            raise InputFileError(f"no KITTI raw drive under {root}: expected <date>/<date>_drive_<nnnn>_sync/"
                                 f"image_02/data/*.png (give the folder holding the date folders, one date "
                                 f"folder or one drive folder)")
        return sorted(drives, key=lambda p: p.name)

    def _list(self) -> list[FrameRef]:
        frames: list[FrameRef] = []
        problems: list[_TreeProblem] = []
        for drive in self.drives():
            try:
                frames += self._list_drive(drive, problems)
            except _TreeProblem as exc:  # the drive cannot be used at all
                problems.append(exc)
        self._problems = [p.problem for p in problems]
        if problems and (self.strict or not frames):
            first = problems[0]
            more = (f" ({len(problems) - 1} more problem{'s' if len(problems) > 2 else ''}: `freespace datasets info "
                    f"--dataset kitti-raw --root {self.root}` lists every one)" if len(problems) > 1 else "")
            raise first.error(f"{first.problem.message}{more}")
        if self.disparity_source == "sgbm" and self._missing_right:
            self.require_right(f"{param('disparity_source')} sgbm matches the right image",
                               f"use the Velodyne scans ({param('disparity_source')} lidar)")
        return sorted(frames, key=lambda f: f.name)

    def _list_drive(self, drive: Path, problems: list[_TreeProblem]) -> list[FrameRef]:
        """The frames of one drive; problems that spoil single frames go to ``problems``, a problem that
        spoils the drive raises :class:`_TreeProblem`."""
        name, day = drive.name, drive.parent
        lefts = _files(drive / LEFT_DIR, ".png")
        if not lefts:
            raise _TreeProblem(name, f"drive folder {drive} holds no left image ({LEFT_DIR}/*.png): unpack the "
                                     f"drive's _sync zip into it, or remove the empty folder")
        calib = self._drive_calib(drive, problems)
        cam_file = day / CAM_TO_CAM
        scans = _files(drive / VELODYNE_DIR, ".bin")
        if scans and calib is not None and "Tr_velo_to_cam" not in calib:
            problem = _TreeProblem(name, f"{day / VELO_TO_CAM} not found: drive {name} has Velodyne scans, and "
                                         f"projecting them needs the Velodyne calibration; unpack KITTI raw's "
                                         f"{day.name}_calib.zip into {day}", InputFileError)
            if self.disparity_source == "lidar" or not self.strict:
                problems.append(problem)
        rights = self._pair_rights(drive, lefts, problems)
        mixed = _mixed_kinds(name, lefts, rights) if self.strict else None  # datasets info: the scan, per drive
        if mixed is not None:
            problems.append(mixed)
        if calib is not None:
            problems.extend(_size_problems(name, cam_file, calib, lefts, rights))
        problems.extend(self._scan_problems(drive, lefts, scans))
        match = _DRIVE.match(name)
        return [FrameRef(name=f"{name}/{stem}", category=match.group(1) if match else day.name, scenario=name,
                         left=left, right=rights.get(stem), calib=cam_file if calib is not None else None,
                         velodyne=scans.get(stem)) for stem, left in lefts.items()]

    def _drive_calib(self, drive: Path, problems: list[_TreeProblem]) -> dict[str, np.ndarray] | None:
        """The calibration of the day of ``drive`` (its cameras, and its Velodyne when that file is there); None
        when the cameras' file is missing, which goes to ``problems`` (raised when ``strict``: the frames are
        still listed, and counted, by datasets info). An unreadable file raises :class:`_TreeProblem`."""
        name, day = drive.name, drive.parent
        cam_file, velo_file = day / CAM_TO_CAM, day / VELO_TO_CAM
        if not cam_file.is_file():
            missing = _TreeProblem(name, f"{cam_file} not found: drive {name} needs its day's camera calibration; "
                                         f"unpack KITTI raw's {day.name}_calib.zip into {day}", InputFileError)
            if self.strict:
                raise missing
            problems.append(missing)
            return None
        try:
            return self._read_calib(cam_file, velo_file if velo_file.is_file() else None)
        except FreespaceError as exc:
            raise _TreeProblem(name, exc.render(param), type(exc)) from None

    def _pair_rights(self, drive: Path, lefts: dict[str, Path], problems: list[_TreeProblem]) -> dict[str, Path]:
        """The right images of ``drive`` by stem; a drive without any is noted (:meth:`require_right`), and left
        images without a right one, or right images without a left one, go to ``problems``."""
        name, right_dir = drive.name, drive / RIGHT_DIR
        rights = _files(right_dir, ".png")
        if not right_dir.is_dir() or not rights:
            self._missing_right.append(right_dir)
        elif set(rights) != set(lefts):
            no_right = sorted(set(lefts) - set(rights))
            no_left = sorted(set(rights) - set(lefts))
            if no_right:
                problems.append(_unpaired(name, no_right, ("left", drive / LEFT_DIR), ("right", right_dir),
                                          "copy the missing right images, or move image_03 away to use the drive "
                                          "without them"))
            if no_left:
                problems.append(_unpaired(name, no_left, ("right", right_dir), ("left", drive / LEFT_DIR),
                                          "copy the missing left images or delete those right images"))
        return rights

    def _scan_problems(self, drive: Path, lefts: dict[str, Path], scans: dict[str, Path]) -> list[_TreeProblem]:
        """The problems of the Velodyne scans of ``drive``: with the lidar source (``strict``) a scan of a size no
        point cloud has; for datasets info (not ``strict``) a scan without a left image and left images without
        a scan (which the lidar source fails on)."""
        name, problems = drive.name, []
        if self.disparity_source == "lidar" and self.strict:  # datasets info (not strict) reads every scan itself
            for stem, path in scans.items():
                size = path.stat().st_size
                if size == 0 or size % VELODYNE_POINT_BYTES:
                    problems.append(_TreeProblem(f"{name}/{stem}", f"Velodyne scan {path} has {size} bytes, not a "
                                                 f"non-empty multiple of {VELODYNE_POINT_BYTES} (float32 x, y, z, "
                                                 f"reflectance per point): a truncated copy? copy it again or "
                                                 f"delete it", CorruptFileError))
        if self.strict:
            return problems
        for stem, path in scans.items():
            if stem not in lefts:
                problems.append(_TreeProblem(f"{name}/{stem}", f"Velodyne scan {path} has no left image "
                                             f"({drive / LEFT_DIR / (stem + '.png')} not found)"))
        unscanned = sorted(set(lefts) - set(scans)) if scans else []
        if unscanned:  # those frames fail alone under disparity_source lidar
            problems.append(_TreeProblem(f"{name}/{unscanned[0]}", f"{drive / VELODYNE_DIR / (unscanned[0] + '.bin')} "
                                         f"not found: {len(unscanned)} left "
                                         f"image{'s' if len(unscanned) > 1 else ''}"
                                         f" of drive {name} {'have' if len(unscanned) > 1 else 'has'} no Velodyne "
                                         f"scan (first {unscanned[0]}); the lidar disparity source fails on them"))
        return problems

    def _read_calib(self, cam_file: Path, velo_file: Path | None) -> dict[str, np.ndarray]:
        """A day's calibration (:func:`freespace.io.kitti.read_kitti_raw_calib`), read once."""
        if cam_file not in self._calib:
            self._calib[cam_file] = read_kitti_raw_calib(cam_file, velo_file)
        return self._calib[cam_file]

    def _frame_calib(self, frame: FrameRef) -> dict[str, np.ndarray]:
        if frame.calib is None:
            raise InputFileError(f"{frame.left.parents[2].parent / CAM_TO_CAM} not found: frame {frame.name} "
                                 f"needs its day's camera calibration")
        velo = frame.calib.parent / VELO_TO_CAM
        return self._read_calib(frame.calib, velo if velo.is_file() else None)

    def require_right(self, why: str, alternative: str | None = None) -> None:
        """Refuse, in one line naming the first drive's missing ``image_03/data`` folder, a dataset with a
        drive that has no right images, for a command that needs them.

        Args:
            why: what needs the right images (``"the DS-Generator warps the right image"``).
            alternative: another way to run without them, appended to the advice, or None.

        Raises:
            DatasetError: some drive has no right images.
        """
        if not self._missing_right:
            return
        folder = self._missing_right[0]
        more = f" (and {len(self._missing_right) - 1} more drives)" if len(self._missing_right) > 1 else ""
        other = f", or {alternative}" if alternative else ""
        state = "holds no .png" if folder.is_dir() else "is a file" if folder.exists() else "not found"
        raise DatasetError(f"{folder} {state}: drive "
                           f"{folder.parents[1].name} has no right images{more}, and {why}; give {param('root')} "
                           f"drives with image_03/data{other}")

    # --- what the base class asks ---------------------------------------------------------------------------
    def calibration(self, frame: FrameRef) -> StereoCalibration | None:
        """The left colour camera's intrinsics from ``P_rect_02`` and the baseline from ``P_rect_02`` and
        ``P_rect_03`` (a virtual 0.54 m one without ``P_rect_03``); no road plane (KITTI raw gives none)."""
        return rig_from_kitti(self._frame_calib(frame))

    def read_label(self, frame: FrameRef) -> RoadLabel:
        raise DatasetError(f"KITTI raw has no road labels ({frame.name}); make them with `freespace autolabel "
                           f"--dataset kitti-raw` and train with their tree as labels")

    def kitti_calib(self, frame: FrameRef) -> dict[str, np.ndarray]:
        """The frame's calibration in KITTI road's keys (``P2``, ``P3``, ``R0_rect``, ``Tr_velo_to_cam``,
        ``S_rect_02``: :func:`freespace.io.kitti.read_kitti_raw_calib`)."""
        return self._frame_calib(frame)

    def read_lidar(self, frame: FrameRef, shape: tuple[int, int]) -> np.ndarray:
        """The frame's Velodyne scan projected into the left image through ``[R | T]``, ``R_rect_00`` and
        ``P_rect_02``: sparse ``float32 H×W`` disparity in pixels (``shape`` = ``(H, W)``), NaN = no point;
        densified by ``lidar_densify``."""
        if frame.velodyne is None:
            raise DatasetError(f"{frame.name} has no Velodyne scan "
                               f"({frame.left.parents[2] / VELODYNE_DIR / frame.left.stem}.bin not found)")
        calib = self._frame_calib(frame)
        if "Tr_velo_to_cam" not in calib:
            raise InputFileError(f"{frame.calib.parent / VELO_TO_CAM} not found: projecting the Velodyne scan of "  # type: ignore[union-attr]
                                 f"{frame.name} needs it")
        return velodyne_to_disparity(read_velodyne(frame.velodyne), calib, shape, densify_gap=self.lidar_densify)

    def load(self, i: int, *, right: bool = True, label: bool = True, disparity: bool = True) -> Sample:
        """:meth:`StereoRoadDataset.load`, refusing first an image of another size than ``S_rect_02``."""
        frame = self.frames[i]
        width, height = (int(x) for x in self._frame_calib(frame)["S_rect_02"])
        for path in (frame.left, frame.right if right else None):
            size = _png_size(path) if path is not None else None
            if size is not None and size != (width, height):
                raise ShapeMismatchError(f"{path} is {size[0]}×{size[1]} but {frame.calib} gives S_rect_02 "
                                         f"{width}×{height}; give the rectified images of the _sync zip and the "
                                         f"calibration of their day")
        return super().load(i, right=right, label=label, disparity=disparity)

    def orphans(self) -> list[Problem]:
        """Every problem of the tree found while listing it (with ``strict=False``; a strict dataset has none)."""
        return list(self._problems)

    def expected_partners(self) -> set[str]:
        """None across the whole tree: right images and scans are optional per drive, and a drive's missing
        calibration is one problem of :meth:`orphans`, not one per frame."""
        return set()
