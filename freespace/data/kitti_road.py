"""KITTI road (and the built-in renderer's output, which uses the same tree).

Expected tree (``ROOT`` holds ``data_road``)::

    ROOT/data_road/{training,testing}/image_2/<cat>_<id>.png          left images (cat: um, umm, uu)
    ROOT/data_road/training/gt_image_2/<cat>_road_<id>.png           road ground truth (KITTI colours)
    ROOT/data_road/{training,testing}/calib/<cat>_<id>.txt           calibration (P0–P3, R0_rect,
                                                                     Tr_velo_to_cam, Tr_cam_to_road)
    ROOT/data_road/{training,testing}/disparity/<cat>_<id>.png       left disparity, KITTI uint16 (optional)
    ROOT/data_road/{training,testing}/depth_u16/<cat>_<id>.png       left depth, SNE-RoadSeg's uint16 millimetres,
                                                                     0 and 65535 = none; or .npy/.pfm metres
                                                                     (optional)
    ROOT/data_road/{training,testing}/velodyne/<cat>_<id>.bin        Velodyne scan, KITTI float32 x, y, z, r
      or ROOT/data_road_velodyne/{training,testing}/velodyne/...     (optional; KITTI's data_road_velodyne.zip)
    ROOT/data_road_right/{training,testing}/image_3/<cat>_<id>.png   right images (optional)

Files are paired by frame name from a sorted listing of ``image_2``; ``*_lane_*`` ground truth is
ignored. Without right images the frames load without them (no augmentation then). A user-supplied
disparity folder (``<frame>.png|.npy|.pfm``, e.g. a learned matcher's KITTI uint16 output) replaces the
tree's own ``disparity/``. Depth becomes disparity ``d = f·B/Z`` and a scan is projected through
``Tr_velo_to_cam``, ``R0_rect`` and ``P2`` (nearest point per pixel), with f and B from the frame's
calibration (P2/P3; a virtual right camera 0.54 m to the right when it has no P3:
:func:`freespace.geometry.depth.rig_from_kitti`). KITTI road has no drive ids, so every frame is its own
scenario — unless ``ROOT/index.csv`` (written by ``freespace synth``) gives a ``scenario`` per ``frame``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from freespace.data.base import FrameRef, Problem, StereoRoadDataset
from freespace.data.registry import register_dataset
from freespace.errors import DatasetError, InvalidOptionError, param
from freespace.geometry import StereoCalibration
from freespace.geometry.depth import rig_from_kitti
from freespace.geometry.lidar import velodyne_to_disparity
from freespace.io.codecs import DEPTH_SUFFIXES, DISPARITY_SUFFIXES, read_depth, read_road_label
from freespace.io.files import PathLike, missing_input
from freespace.io.kitti import read_kitti_calib, read_velodyne
from freespace.labels import RoadLabel

__all__ = ["KittiRoad", "CATEGORIES"]

CATEGORIES = ("um", "umm", "uu")
_FRAME = re.compile(r"^(um|umm|uu)_(\d{6})$")
_LABEL = re.compile(r"^(um|umm|uu)_road_(\d{6})$")


def _find(folder: Path | None, name: str, suffixes: tuple[str, ...]) -> Path | None:
    if folder is None:
        return None
    for suffix in suffixes:
        path = folder / f"{name}{suffix}"
        if path.is_file():
            return path
    return None


@register_dataset("kitti", "kitti_road", "synth")
class KittiRoad(StereoRoadDataset):
    """KITTI road (``training``/``testing``); see the module docstring for the tree.

    Args:
        disparity_dir: folder of ``<frame>.png|.npy|.pfm`` disparities to use instead of ``disparity/``.
        lidar_densify: 0 (default) keeps a scan's sparse disparity (``disparity_source="lidar"``); ``k > 0``
            fills every empty pixel within ``k`` pixels of a point with that point's disparity
            (:func:`freespace.geometry.lidar.densify_nearest`).
        Other arguments: :class:`~freespace.data.base.StereoRoadDataset`.
    """

    splits = ("training", "testing")

    def __init__(self, root: PathLike, split: str | None = None, *, disparity_dir: PathLike | None = None,
                 lidar_densify: float = 0, **options) -> None:
        self.disparity_dir = Path(disparity_dir) if disparity_dir is not None else None
        if self.disparity_dir is not None and not self.disparity_dir.is_dir():
            raise missing_input(self.disparity_dir, "disparity folder", "folder")
        if isinstance(lidar_densify, bool) or not (isinstance(lidar_densify, (int, float))
                                                   and math.isfinite(lidar_densify) and lidar_densify >= 0):
            raise InvalidOptionError(f"{param('lidar_densify')} must be a number of pixels ≥ 0, got "
                                     f"{lidar_densify!r}")
        self.lidar_densify = float(lidar_densify)
        super().__init__(root, split, **options)

    @property
    def base(self) -> Path:
        return self.root / "data_road" / self.split

    def _list(self) -> list[FrameRef]:
        image_dir = self.base / "image_2"
        if not image_dir.is_dir():
            raise missing_input(image_dir, "image folder", "folder",
                                hint=f"a KITTI road root holds data_road/{self.split}/image_2")
        right_dir = self.root / "data_road_right" / self.split / "image_3"
        disp_dir = self.disparity_dir or (self.base / "disparity" if (self.base / "disparity").is_dir() else None)
        depth_dir = self.base / "depth_u16"
        velo_dirs = [d for d in self._velodyne_dirs() if d.is_dir()]
        scenarios = self._scenarios()
        frames = []
        for left in sorted(image_dir.glob("*.png")):
            match = _FRAME.match(left.stem)
            if not match:
                continue
            cat, idx = match.groups()
            right = right_dir / left.name
            label = self.base / "gt_image_2" / f"{cat}_road_{idx}.png"
            calib = self.base / "calib" / f"{left.stem}.txt"
            frames.append(FrameRef(
                name=left.stem, category=cat, scenario=scenarios.get(left.stem, left.stem), left=left,
                right=right if right.is_file() else None,
                label=label if label.is_file() else None,
                calib=calib if calib.is_file() else None,
                disparity=_find(disp_dir, left.stem, DISPARITY_SUFFIXES),
                depth=_find(depth_dir if depth_dir.is_dir() else None, left.stem, DEPTH_SUFFIXES),
                velodyne=next((p for d in velo_dirs if (p := d / f"{left.stem}.bin").is_file()), None)))
        return frames

    def _velodyne_dirs(self) -> list[Path]:
        """Where scans are looked for, in order: beside ``image_2``, then KITTI's ``data_road_velodyne``."""
        return [self.base / "velodyne", self.root / "data_road_velodyne" / self.split / "velodyne"]

    def _scenarios(self) -> dict[str, str]:
        """Frame → scenario from ``ROOT/index.csv`` when there is one (the renderer's output)."""
        path = self.root / "index.csv"
        if not path.is_file():
            return {}
        import csv

        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
        if not rows or not {"frame", "scenario"} <= set(rows[0]):
            raise DatasetError(f"{path} must have 'frame' and 'scenario' columns")
        return {r["frame"]: f"scenario_{r['scenario']}" for r in rows}

    def read_label(self, frame: FrameRef) -> RoadLabel:
        return read_road_label(frame.label)  # type: ignore[arg-type]

    def calibration(self, frame: FrameRef) -> StereoCalibration | None:
        """Focal length, principal point and baseline from P2/P3 (a virtual right camera 0.54 m to the right
        without P3); the road plane from Tr_cam_to_road."""
        return rig_from_kitti(read_kitti_calib(frame.calib)) if frame.calib else None

    def read_depth(self, frame: FrameRef) -> np.ndarray:
        """``depth_u16/<frame>.png`` (uint16 millimetres, 0 and 65535 = none) or ``.npy``/``.pfm`` (metres)
        as ``float32 H×W`` metres, NaN = none (:func:`freespace.io.codecs.read_depth`)."""
        if frame.depth is None:
            raise DatasetError(f"{frame.name} has no depth map (data_road/{self.split}/depth_u16/{frame.name}.png)")
        return read_depth(frame.depth)

    def read_lidar(self, frame: FrameRef, shape: tuple[int, int]) -> np.ndarray:
        """The frame's Velodyne scan projected through its calibration into the left (P2) image: sparse
        ``float32 H×W`` disparity in pixels, NaN = no point (densified by ``lidar_densify``)."""
        if frame.velodyne is None:
            raise DatasetError(f"{frame.name} has no Velodyne scan (data_road/{self.split}/velodyne/{frame.name}.bin "
                               f"or data_road_velodyne/{self.split}/velodyne/{frame.name}.bin)")
        if frame.calib is None:
            raise DatasetError(f"{frame.name} has no calibration file; projecting its Velodyne scan needs "
                               f"Tr_velo_to_cam, R0_rect and P2 from data_road/{self.split}/calib/{frame.name}.txt")
        return velodyne_to_disparity(read_velodyne(frame.velodyne), read_kitti_calib(frame.calib), shape,
                                     densify_gap=self.lidar_densify)

    def orphans(self) -> list[Problem]:
        names = {f.name for f in self.frames}
        problems = []
        for path in sorted((self.root / "data_road_right" / self.split / "image_3").glob("*.png")):
            if path.stem not in names:
                problems.append(Problem(path.stem, f"right image {path} has no left image"))
        for kind, paths in (("depth", (self.base / "depth_u16").glob("*.*")),
                            ("Velodyne scan", (p for d in self._velodyne_dirs() for p in d.glob("*.bin")))):
            for path in sorted(paths):
                if _FRAME.match(path.stem) and path.stem not in names:
                    problems.append(Problem(path.stem, f"{kind} {path} has no left image"))
        for path in sorted((self.base / "gt_image_2").glob("*_road_*.png")):
            m = _LABEL.match(path.stem)
            if m and f"{m.group(1)}_{m.group(2)}" not in names:
                problems.append(Problem(f"{m.group(1)}_{m.group(2)}", f"label {path} has no left image"))
        return problems

    def expected_partners(self) -> set[str]:
        kinds = super().expected_partners()
        if self.split == "training" and (self.base / "gt_image_2").is_dir():
            kinds.add("label")
        return kinds
