"""Folder layouts: SYNTHIA stereo sequences, SYN-Stereo/CARLA exports and a generic stereo layout.

All three pair files by frame stem across folders and decode labels and depth as a
:class:`FolderSpec` says. Each reads an optional ``freespace.yaml`` at the dataset root (loaded with
``yaml.safe_load``) whose keys override the layout's documented defaults, e.g.::

    road_ids: [1, 24]          # class ids that are road (CARLA ≥ 0.9.14: Roads, RoadLines)
    ignore_ids: [0]            # class ids that are don't-care
    label_encoding: class_id   # class_id | kitti (KITTI colours) | mask (non-zero = road)
    label_channel: 0           # channel holding the class id in a colour label, RGB order
    depth_encoding: png16      # png16 (integer × depth_scale; 0 and, in 16-bit PNGs, 65535 = none)
                               # | carla_rgb | float (.npy/.pfm × depth_scale)
    depth_channel: 0
    depth_scale: 0.01          # metres per stored unit
    camera: {fx: 320, fy: 320, cx: 320, cy: 240, baseline: 1.5}   # pixels, metres

The camera may also give the road plane, for the virtual-view augmentation on datasets without a right image or
disparity: ``height`` (metres of the camera centre above a flat road, > 0), ``pitch`` (degrees, positive
= the camera looks down at the road) and ``roll`` (degrees, about the optical axis), both default 0, as
in :meth:`freespace.geometry.RoadPlane.from_camera`. With ``height`` the ``baseline`` may be left out
(a monocular camera: no disparity from depth then), e.g.
``camera: {fx: 720, cx: 640, cy: 360, height: 1.6, pitch: 2.5}``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.base import FrameRef, Problem, StereoRoadDataset
from freespace.data.registry import register_dataset
from freespace.errors import CorruptFileError, DatasetError, InputFileError, InvalidOptionError
from freespace.geometry import RoadPlane, StereoCalibration
from freespace.io.codecs import DISPARITY_SUFFIXES, IMAGE_SUFFIXES, read_disparity, read_raw, read_road_label
from freespace.io.files import PathLike, missing_input
from freespace.labels import RoadLabel
from freespace.limits import MAX_BASELINE_M, MAX_FOCAL_PX, MIN_BASELINE_M
from freespace.runtime.patterns import check_pattern, search_names

__all__ = ["FolderSpec", "GenericStereo", "SynthiaStereo", "CarlaStereo", "CONFIG_NAME"]

CONFIG_NAME = "freespace.yaml"
LABEL_ENCODINGS = ("class_id", "kitti", "mask")
DEPTH_ENCODINGS = ("png16", "carla_rgb", "float")


@dataclass(frozen=True)
class FolderSpec:
    """How a folder layout encodes labels, depth and the camera (see the module docstring)."""

    label_encoding: str = "class_id"
    label_channel: int = 0
    road_ids: tuple[int, ...] = (1,)
    ignore_ids: tuple[int, ...] = ()
    depth_encoding: str = "png16"
    depth_channel: int = 0
    depth_scale: float = 1.0
    camera: dict[str, float] | None = None
    folders: dict[str, str] = field(default_factory=dict)
    scenario_pattern: str | None = None

    def updated(self, path: Path) -> FolderSpec:
        """This spec with the keys of the YAML file at ``path`` (if it exists) applied."""
        if not path.is_file():
            return self
        from freespace.io.codecs import load_yaml

        data = load_yaml(path) or {}  # a key given twice is refused
        if not isinstance(data, dict):
            raise CorruptFileError(f"{path} must hold a mapping of options")
        known = {f.name for f in fields(self)}
        folder_keys = {"left", "right", "label", "disparity", "depth"}
        unknown = set(data) - known - folder_keys
        if unknown:
            raise InvalidOptionError(f"{path}: unknown keys {sorted(unknown)}; allowed: {sorted(known | folder_keys)}")
        folders = dict(self.folders)
        folders.update({k: str(data.pop(k)) for k in list(data) if k in folder_keys})
        for key in ("road_ids", "ignore_ids"):
            if key in data:
                ids = data[key] if isinstance(data[key], list) else [data[key]]
                if not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in ids):
                    raise InvalidOptionError(f"{path}: {key} must be a list of class ids (integers ≥ 0), "
                                             f"got {data[key]!r}")
                data[key] = tuple(ids)
        for key in ("label_channel", "depth_channel"):
            if key in data and (not isinstance(data[key], int) or isinstance(data[key], bool)
                                or not 0 <= data[key] <= 3):
                raise InvalidOptionError(f"{path}: {key} must be a channel index 0…3 (RGB order, 3 = alpha), "
                                         f"got {data[key]!r}")
        if "depth_scale" in data and (isinstance(data["depth_scale"], bool)
                                      or not isinstance(data["depth_scale"], (int, float))
                                      or not 0 < data["depth_scale"] < float("inf")):
            raise InvalidOptionError(f"{path}: depth_scale must be a positive number (metres per stored unit), "
                                     f"got {data['depth_scale']!r}")
        for key in ("label_encoding", "depth_encoding", "scenario_pattern"):
            if key in data and not isinstance(data[key], str):
                raise InvalidOptionError(f"{path}: {key} must be a string, got {data[key]!r}")
        if "camera" in data and (not isinstance(data["camera"], dict) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in data["camera"].values())):
            raise InvalidOptionError(f"{path}: camera must be a mapping of numbers (fx, fy, cx, cy, baseline, "
                                     f"height, pitch, roll), got {data['camera']!r}")
        spec = replace(self, folders=folders, **data)
        spec.check(path)
        return spec

    def check(self, where: Path | str = "options") -> None:
        if self.label_encoding not in LABEL_ENCODINGS:
            raise InvalidOptionError(f"{where}: label_encoding must be one of {LABEL_ENCODINGS}")
        if self.depth_encoding not in DEPTH_ENCODINGS:
            raise InvalidOptionError(f"{where}: depth_encoding must be one of {DEPTH_ENCODINGS}")
        if self.scenario_pattern is not None:
            check_pattern(self.scenario_pattern, f"{where}: scenario_pattern")  # bounded: no nested quantifiers
        if self.camera is not None:
            if not isinstance(self.camera, dict):
                raise InvalidOptionError(f"{where}: camera must be a mapping (fx, fy, cx, cy, baseline, height, "
                                         f"pitch, roll)")
            missing = ({"fx", "cx", "cy"} | ({"baseline"} if "height" not in self.camera else set())) - set(self.camera)
            if missing:
                raise InvalidOptionError(f"{where}: camera needs fx, cx, cy and baseline (or height, for a monocular "
                                         f"camera) (missing {sorted(missing)})")
            for key in ("fx", "fy", "cx", "cy", "baseline", "height", "pitch", "roll"):
                value = self.camera.get(key)
                if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                          or not math.isfinite(value)):
                    raise InvalidOptionError(f"{where}: camera {key} must be a number, got {value!r}")
            _check_rig(where, self.camera)
            if "height" in self.camera and not self.camera["height"] > 0:
                raise InvalidOptionError(f"{where}: camera height must be > 0 metres above the road, got "
                                         f"{self.camera['height']}")
            if "pitch" in self.camera and not abs(self.camera["pitch"]) < 90:
                raise InvalidOptionError(f"{where}: camera pitch must be within ±90 degrees, got "
                                         f"{self.camera['pitch']}")


def _check_rig(where: Path | str, camera: dict[str, float]) -> None:
    """Refuse a camera no rig has: a focal length not in (0, MAX_FOCAL_PX] px, a principal point left of or above
    the image (< 0), a baseline outside MIN_BASELINE_M…MAX_BASELINE_M m (0 only for a monocular camera, which
    gives its ``height``)."""
    for key in ("fx", "fy"):
        if key in camera and not 0 < camera[key] <= MAX_FOCAL_PX:
            raise InvalidOptionError(f"{where}: camera {key} must be a focal length in (0, {MAX_FOCAL_PX:g}] pixels, "
                                     f"got {camera[key]}")
    for key in ("cx", "cy"):
        if key in camera and camera[key] < 0:
            raise InvalidOptionError(f"{where}: camera {key} must be a principal point inside the image (≥ 0 px), got "
                                     f"{camera[key]}")
    baseline = camera.get("baseline")
    if baseline is not None and not (MIN_BASELINE_M <= baseline <= MAX_BASELINE_M
                                     or (baseline == 0 and "height" in camera)):
        raise InvalidOptionError(f"{where}: camera baseline must be {MIN_BASELINE_M:g}–{MAX_BASELINE_M:g} metres "
                                 f"(0 only for a monocular camera, with its height), got {baseline}")


def _channel(img: np.ndarray, channel: int) -> np.ndarray:
    return img if img.ndim == 2 else img[:, :, channel]


class FolderDataset(StereoRoadDataset):
    """Shared behaviour of the folder layouts: decode labels and depth by :class:`FolderSpec`."""

    default_spec: FolderSpec = FolderSpec()

    def __init__(self, root: PathLike, split: str | None = None, *, spec: FolderSpec | None = None, **options) -> None:
        self.spec = spec or self.default_spec.updated(Path(root) / CONFIG_NAME)
        super().__init__(root, split, **options)

    def read_label(self, frame: FrameRef) -> RoadLabel:
        spec = self.spec
        if spec.label_encoding == "kitti":
            return read_road_label(frame.label)  # type: ignore[arg-type]
        ids = _channel(read_raw(frame.label, what="label"), spec.label_channel)  # type: ignore[arg-type]
        if spec.label_encoding == "mask":
            return RoadLabel(road=ids > 0, valid=np.ones(ids.shape, bool))
        valid = ~np.isin(ids, spec.ignore_ids) if spec.ignore_ids else np.ones(ids.shape, bool)
        return RoadLabel(road=np.isin(ids, spec.road_ids) & valid, valid=valid)

    def read_depth(self, frame: FrameRef) -> np.ndarray:
        spec = self.spec
        path = frame.depth
        if spec.depth_encoding == "float":
            return read_disparity(path) * np.float32(spec.depth_scale)  # type: ignore[arg-type]
        img = read_raw(path, what="depth")  # type: ignore[arg-type]
        if spec.depth_encoding == "carla_rgb":
            if img.ndim != 3:
                raise CorruptFileError(f"depth {path} is not a CARLA RGB-encoded depth image (3 channels)")
            rgb = img[:, :, :3].astype(np.float64)
            metres = (rgb[..., 0] + rgb[..., 1] * 256 + rgb[..., 2] * 65536) / (256 ** 3 - 1) * 1000.0
            depth = metres.astype(np.float32)
        else:
            raw = _channel(img, spec.depth_channel)
            depth = raw.astype(np.float32) * np.float32(spec.depth_scale)
            if raw.dtype == np.uint16:
                depth[raw == 65535] = np.nan  # saturated: "no depth" in SNE-RoadSeg's depth_u16
        depth[depth <= 0] = np.nan
        return depth

    def calibration(self, frame: FrameRef) -> StereoCalibration | None:
        cam = self._camera(frame)
        if cam is None:
            return None
        plane = None
        if cam.get("height") is not None:  # the road plane of a camera height and pitch (and roll)
            plane = RoadPlane.from_camera(float(cam["height"]), float(cam.get("pitch", 0.0)),
                                          float(cam.get("roll", 0.0)))
        return StereoCalibration(fx=float(cam["fx"]), fy=float(cam.get("fy", cam["fx"])), cx=float(cam["cx"]),
                                 cy=float(cam["cy"]), baseline=float(cam.get("baseline", 0.0)), road_plane=plane)

    def _camera(self, frame: FrameRef) -> dict[str, float] | None:
        return self.spec.camera

    def _pair(self, name: str, category: str, scenario: str, left: Path, folders: dict[str, Path | None],
              stem: str) -> FrameRef:
        def find(kind: str, suffixes: tuple[str, ...]) -> Path | None:
            folder = folders.get(kind)
            if folder is None:
                return None
            for s in suffixes:
                if (folder / f"{stem}{s}").is_file():
                    return folder / f"{stem}{s}"
            return None

        return FrameRef(name=name, category=category, scenario=scenario, left=left,
                        right=find("right", IMAGE_SUFFIXES), label=find("label", IMAGE_SUFFIXES),
                        disparity=find("disparity", DISPARITY_SUFFIXES), depth=find("depth", (".png", ".npy", ".pfm")))

    def _orphans_in(self, folders: dict[str, Path | None], stems: set[str], prefix: str) -> list[Problem]:
        problems = []
        for kind, folder in folders.items():
            if kind == "left" or folder is None or not folder.is_dir():
                continue
            for path in sorted(folder.iterdir()):
                if path.is_file() and path.stem not in stems and not path.name.startswith("."):
                    problems.append(Problem(f"{prefix}{path.stem}", f"{kind} file {path} has no left image"))
        return problems


def _left_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith("."))


@register_dataset("generic")
class GenericStereo(FolderDataset):
    """A generic stereo layout described by ``ROOT/freespace.yaml``.

    Expected tree (folder names are set in the YAML; ``left`` is required)::

        ROOT/freespace.yaml
        ROOT/<left>/<frame>.png          left images
        ROOT/<right>/<frame>.png         right images (optional)
        ROOT/<label>/<frame>.png         labels (optional): class ids, KITTI colours or a road mask
        ROOT/<disparity>/<frame>.png     left disparity (optional): KITTI uint16 .png, .npy or .pfm
        ROOT/<depth>/<frame>.png         left depth (optional, used without disparity; needs ``camera``)

    Besides the spec keys (module docstring): ``left``, ``right``, ``label``, ``disparity``, ``depth``
    (folder names) and ``scenario_pattern``, a regex on the frame name whose group ``scenario`` names the
    frame's scenario (default: each frame is its own scenario).
    """

    def __init__(self, root: PathLike, split: str | None = None, **options) -> None:
        config = Path(root) / CONFIG_NAME
        if Path(root).is_dir() and not config.is_file():
            if config.exists():
                raise missing_input(config, "the generic layout's description", "file")
            raise InputFileError(f"{config} not found; the generic layout is described by a YAML file there naming "
                                 f"its folders, at least `left: <folder of left images>` (every key: docs/datasets.md)")
        super().__init__(root, split, **options)

    def _folders(self) -> dict[str, Path | None]:
        folders: dict[str, Path | None] = {k: None for k in ("left", "right", "label", "disparity", "depth")}
        for kind, name in self.spec.folders.items():
            folders[kind] = self.root / name
        if folders["left"] is not None and folders["left"].exists() and not folders["left"].is_dir():
            raise missing_input(folders["left"], "left image folder", "folder")
        if folders["left"] is None or not folders["left"].is_dir():  # type: ignore[union-attr]
            raise InputFileError(f"left image folder {folders['left']} not found; "
                                 f"set `left:` in {self.root / CONFIG_NAME}")
        return folders

    def _list(self) -> list[FrameRef]:
        folders = self._folders()
        lefts = _left_files(folders["left"])  # type: ignore[arg-type]
        scenarios: list[str | None] = [left.stem for left in lefts]
        pattern = self.spec.scenario_pattern
        if pattern:
            where = f"{self.root / CONFIG_NAME}: scenario_pattern"
            if "scenario" not in check_pattern(pattern, where).groupindex:
                raise DatasetError(f"{where} has no (?P<scenario>...) group, which names a frame's scenario; add one")
            found = search_names(pattern, [left.stem for left in lefts], where, "scenario")  # in bounded time
            miss = next((left.stem for left, (_, group) in zip(lefts, found) if group is None), None)
            if miss is not None:
                raise DatasetError(f"{where} does not match frame {miss!r} (or its scenario group matches nothing "
                                   f"there); write one that matches every frame name")
            scenarios = [scenario for _, scenario in found]
        return [self._pair(left.stem, "all", scenario, left, folders, left.stem)
                for left, scenario in zip(lefts, scenarios)]

    def orphans(self) -> list[Problem]:
        return self._orphans_in(self._folders(), {f.name for f in self.frames}, "")


class SequenceDataset(FolderDataset):
    """Layouts made of sequence folders (``ROOT/<sequence>/...``, or ``ROOT`` is one sequence).

    Frame names are ``<sequence>_<stem>``; the scenario is the sequence.
    """

    marker: str = ""  # a folder, relative to a sequence, whose presence makes a sequence

    def _sequences(self) -> list[Path]:
        if (self.root / self.marker).is_dir():
            return [self.root]
        seqs = sorted(p for p in self.root.iterdir() if (p / self.marker).is_dir())
        if not seqs:
            raise InputFileError(f"no {self.name} sequence under {self.root}: expected <sequence>/{self.marker}")
        return seqs

    def _folders(self, seq: Path) -> dict[str, Path | None]:
        raise NotImplementedError

    def _category(self, seq: Path) -> str:
        return seq.name

    def _list(self) -> list[FrameRef]:
        frames = []
        for seq in self._sequences():
            folders = self._folders(seq)
            if not folders["left"].is_dir():  # type: ignore[union-attr]
                continue
            for left in _left_files(folders["left"]):  # type: ignore[arg-type]
                frames.append(self._pair(f"{seq.name}_{left.stem}", self._category(seq), seq.name, left, folders,
                                         left.stem))
        return frames

    def orphans(self) -> list[Problem]:
        problems = []
        for seq in self._sequences():
            stems = {f.name[len(seq.name) + 1:] for f in self.frames if f.scenario == seq.name}
            problems += self._orphans_in(self._folders(seq), stems, f"{seq.name}_")
        return problems


@register_dataset("synthia")
class SynthiaStereo(SequenceDataset):
    """SYNTHIA stereo video sequences (SYNTHIA-SEQS).

    Expected tree (``ROOT`` holds one or more sequence folders, or is one)::

        ROOT/<SEQUENCE>/RGB/Stereo_Left/Omni_F/<id>.png         left images
        ROOT/<SEQUENCE>/RGB/Stereo_Right/Omni_F/<id>.png        right images
        ROOT/<SEQUENCE>/GT/LABELS/Stereo_Left/Omni_F/<id>.png   class ids (16-bit, first channel)
        ROOT/<SEQUENCE>/Depth/Stereo_Left/Omni_F/<id>.png       depth (16-bit, first channel, centimetres)

    Defaults (override in ``ROOT/freespace.yaml``): road = class 3 (road) and 12 (lane marking), class 0
    (void) is don't-care; depth in centimetres; camera fx = fy = 532.74 px, principal point (640, 380),
    baseline 0.8 m (SYNTHIA's 1280×760 stereo rig). Frame names are ``<SEQUENCE>_<id>``; the scenario is
    the sequence and the category its last dash-separated word (SPRING, NIGHT, ...).
    """

    default_spec = FolderSpec(label_encoding="class_id", label_channel=0, road_ids=(3, 12), ignore_ids=(0,),
                              depth_encoding="png16", depth_channel=0, depth_scale=0.01,
                              camera={"fx": 532.740352, "fy": 532.740352, "cx": 640.0, "cy": 380.0, "baseline": 0.8})
    view = "Omni_F"
    marker = "RGB/Stereo_Left"

    def _folders(self, seq: Path) -> dict[str, Path | None]:
        v = self.view
        return {"left": seq / "RGB" / "Stereo_Left" / v, "right": seq / "RGB" / "Stereo_Right" / v,
                "label": seq / "GT" / "LABELS" / "Stereo_Left" / v, "depth": seq / "Depth" / "Stereo_Left" / v,
                "disparity": None}

    def _category(self, seq: Path) -> str:
        return seq.name.rsplit("-", 1)[-1]


@register_dataset("carla", "syn-stereo")
class CarlaStereo(SequenceDataset):
    """SYN-Stereo-style CARLA exports (the paper's SYN-Stereo: 640×480, baseline 1.5 m).

    Expected tree (``ROOT`` holds sequence folders, or is one)::

        ROOT/<sequence>/left/<id>.png        left images
        ROOT/<sequence>/right/<id>.png       right images
        ROOT/<sequence>/semantic/<id>.png    CARLA semantic segmentation (class id in the red channel)
        ROOT/<sequence>/depth/<id>.png       CARLA depth ((R + 256 G + 65536 B) / (256³ − 1) · 1000 m)
        ROOT/<sequence>/disparity/<id>.png   left disparity, KITTI uint16 (optional; preferred to depth)
        ROOT/<sequence>/camera.yaml          fx, fy, cx, cy (px), baseline (m) (optional, else the default)

    Defaults (override in ``ROOT/freespace.yaml``): road = CARLA classes 7 (road) and 6 (road line) as
    in CARLA ≤ 0.9.13 (use ``road_ids: [1, 24]`` for CARLA ≥ 0.9.14); camera for 640×480 with a 90° field
    of view (fx = fy = 320, principal point (320, 240)) and a 1.5 m baseline. Frame names are
    ``<sequence>_<id>``; the scenario and the category are the sequence.
    """

    default_spec = FolderSpec(label_encoding="class_id", label_channel=0, road_ids=(7, 6), ignore_ids=(),
                              depth_encoding="carla_rgb",
                              camera={"fx": 320.0, "fy": 320.0, "cx": 320.0, "cy": 240.0, "baseline": 1.5})

    marker = "left"

    def _folders(self, seq: Path) -> dict[str, Path | None]:
        return {k: seq / d for k, d in (("left", "left"), ("right", "right"), ("label", "semantic"),
                                         ("depth", "depth"), ("disparity", "disparity"))}

    def _camera(self, frame: FrameRef) -> dict[str, Any] | None:
        own = frame.left.parent.parent / "camera.yaml"
        return self._camera_file(own) if own.is_file() else self.spec.camera

    @staticmethod
    def _camera_file(path: Path) -> dict[str, Any]:
        from freespace.io.codecs import load_yaml

        cam = load_yaml(path)  # a key given twice is refused
        if not isinstance(cam, dict) or not {"fx", "cx", "cy", "baseline"} <= set(cam):
            raise CorruptFileError(f"{path} must give fx, cx, cy (pixels) and baseline (metres)")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in cam.values()):
            raise CorruptFileError(f"{path}: every value must be a finite number, got {cam!r}")
        _check_rig(path, cam)
        return cam
