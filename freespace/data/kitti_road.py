"""KITTI road (and the built-in renderer's output, which uses the same tree).

Expected tree (``ROOT`` holds ``data_road``)::

    ROOT/data_road/{training,testing}/image_2/<cat>_<id>.png          left images (cat: um, umm, uu)
    ROOT/data_road/training/gt_image_2/<cat>_road_<id>.png           road ground truth (KITTI colours)
    ROOT/data_road/{training,testing}/calib/<cat>_<id>.txt           calibration (P0–P3, R0_rect,
                                                                     Tr_velo_to_cam, Tr_cam_to_road)
    ROOT/data_road/{training,testing}/disparity/<cat>_<id>.png       left disparity, KITTI uint16 (optional)
    ROOT/data_road_right/{training,testing}/image_3/<cat>_<id>.png   right images (optional)

Files are paired by frame name from a sorted listing of ``image_2``; ``*_lane_*`` ground truth is
ignored. Without right images the frames load without them (no augmentation then). A user-supplied
disparity folder (``<frame>.png|.npy|.pfm``, e.g. a learned matcher's KITTI uint16 output) replaces the
tree's own ``disparity/``. KITTI road has no drive ids, so every frame is its own scenario — unless
``ROOT/index.csv`` (written by ``freespace synth``) gives a ``scenario`` per ``frame``.
"""

from __future__ import annotations

import re
from pathlib import Path

from freespace.data.base import FrameRef, Problem, StereoRoadDataset
from freespace.data.registry import register_dataset
from freespace.errors import DatasetError, InputFileError
from freespace.geometry import StereoCalibration
from freespace.io import DISPARITY_SUFFIXES, PathLike, RoadLabel, read_kitti_calib, read_road_label

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
        Other arguments: :class:`~freespace.data.base.StereoRoadDataset`.
    """

    splits = ("training", "testing")

    def __init__(self, root: PathLike, split: str | None = None, *, disparity_dir: PathLike | None = None,
                 **options) -> None:
        self.disparity_dir = Path(disparity_dir) if disparity_dir is not None else None
        if self.disparity_dir is not None and not self.disparity_dir.is_dir():
            raise InputFileError(f"disparity folder not found: {self.disparity_dir}")
        super().__init__(root, split, **options)

    @property
    def base(self) -> Path:
        return self.root / "data_road" / self.split

    def _list(self) -> list[FrameRef]:
        image_dir = self.base / "image_2"
        if not image_dir.is_dir():
            raise InputFileError(f"{image_dir} not found; a KITTI road root holds data_road/{self.split}/image_2")
        right_dir = self.root / "data_road_right" / self.split / "image_3"
        disp_dir = self.disparity_dir or (self.base / "disparity" if (self.base / "disparity").is_dir() else None)
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
                disparity=_find(disp_dir, left.stem, DISPARITY_SUFFIXES)))
        return frames

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
        """Focal length, principal point and baseline from P2/P3; the road plane from Tr_cam_to_road."""
        return StereoCalibration.from_kitti(read_kitti_calib(frame.calib)) if frame.calib else None

    def orphans(self) -> list[Problem]:
        names = {f.name for f in self.frames}
        problems = []
        for path in sorted((self.root / "data_road_right" / self.split / "image_3").glob("*.png")):
            if path.stem not in names:
                problems.append(Problem(path.stem, f"right image {path} has no left image"))
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
