"""KITTI road: frame listing and pairing (torch-free).

Expected tree (``ROOT`` is the folder that holds ``data_road``)::

    ROOT/data_road/{training,testing}/image_2/<cat>_<id>.png          left images (cat: um, umm, uu)
    ROOT/data_road/training/gt_image_2/<cat>_road_<id>.png           road ground truth (KITTI colours)
    ROOT/data_road/{training,testing}/calib/<cat>_<id>.txt           calibration (optional here)
    ROOT/data_road/{training,testing}/disparity/<cat>_<id>.png       left disparity, KITTI uint16 (optional)
    ROOT/data_road_right/{training,testing}/image_3/<cat>_<id>.png   right images

Files are paired by frame name from a sorted listing of ``image_2``; ``*_lane_*`` ground truth is
ignored. A user-supplied disparity folder (``<frame>.png|.npy|.pfm``) replaces ``disparity/``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from freespace.errors import DatasetError, InputFileError, InvalidOptionError
from freespace.io import DISPARITY_SUFFIXES, PathLike

__all__ = ["KittiRoadFrame", "list_kitti_road_frames", "SPLITS"]

SPLITS = ("training", "testing")
_FRAME = re.compile(r"^(um|umm|uu)_(\d{6})$")


@dataclass(frozen=True)
class KittiRoadFrame:
    """Paths of one KITTI road frame; ``None`` where the file does not exist."""

    name: str
    category: str
    left: Path
    right: Path | None
    label: Path | None
    calib: Path | None
    disparity: Path | None


def _find_disparity(folder: Path | None, name: str) -> Path | None:
    if folder is None:
        return None
    for suffix in DISPARITY_SUFFIXES:
        path = folder / f"{name}{suffix}"
        if path.is_file():
            return path
    return None


def list_kitti_road_frames(root: PathLike, split: str = "training",
                           disparity_dir: PathLike | None = None) -> list[KittiRoadFrame]:
    """List the frames of a KITTI road split, sorted by name, with their partner files.

    Args:
        root: folder holding ``data_road`` (and ``data_road_right``).
        split: ``training`` or ``testing``.
        disparity_dir: folder of ``<frame>.png|.npy|.pfm`` disparities to use instead of the tree's own
            ``disparity/`` folder.

    Raises:
        InputFileError: ``root`` or its ``image_2`` folder is missing. DatasetError: no frames.
    """
    if split not in SPLITS:
        raise InvalidOptionError(f"unknown KITTI road split {split!r}; choose one of {', '.join(SPLITS)}")
    root = Path(root)
    if not root.is_dir():
        raise InputFileError(f"dataset root not found: {root} (give the folder that holds data_road/)")
    base = root / "data_road" / split
    image_dir = base / "image_2"
    if not image_dir.is_dir():
        raise InputFileError(f"{image_dir} not found; a KITTI road root holds data_road/{split}/image_2")
    right_dir = root / "data_road_right" / split / "image_3"
    if disparity_dir is not None:
        disp_dir: Path | None = Path(disparity_dir)
        if not disp_dir.is_dir():
            raise InputFileError(f"disparity folder not found: {disp_dir}")
    else:
        disp_dir = base / "disparity" if (base / "disparity").is_dir() else None
    frames = []
    for left in sorted(image_dir.glob("*.png")):
        match = _FRAME.match(left.stem)
        if not match:
            continue
        cat, idx = match.groups()
        right = right_dir / left.name
        label = base / "gt_image_2" / f"{cat}_road_{idx}.png"
        calib = base / "calib" / f"{left.stem}.txt"
        frames.append(KittiRoadFrame(
            name=left.stem, category=cat, left=left,
            right=right if right.is_file() else None,
            label=label if label.is_file() else None,
            calib=calib if calib.is_file() else None,
            disparity=_find_disparity(disp_dir, left.stem)))
    if not frames:
        raise DatasetError(f"no KITTI road frames (<um|umm|uu>_<6 digits>.png) in {image_dir}")
    return frames
