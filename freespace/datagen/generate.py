"""The DS-Generator over files: one stereo pair, or every labelled frame of a dataset; and one reference
image seen from a virtual camera pose (:func:`generate_virtual_pair`).

This is what ``freespace generate`` runs. It imports NumPy and OpenCV only (never torch), reads and
checks every input before it writes anything, and writes every output atomically.
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from collections.abc import Iterator
from concurrent.futures import as_completed
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np

from freespace.errors import (
    CorruptFileError,
    DatasetError,
    FreespaceError,
    InvalidOptionError,
    RoadFitError,
    ShapeMismatchError,
    param,
)
from freespace.geometry import (
    SGBM_MAX_DISPARITY,
    RoadModel,
    RoadPlane,
    StereoCalibration,
    VirtualPose,
    compute_disparity,
    fit_road_model,
    generate_view,
    virtual_homography,
    virtual_view,
)
from freespace.data.disparity import SGBM_SOURCES
from freespace.geometry.stereo import SGBM_VERSION, check_search_range
from freespace.io.codecs import (IMAGE_SUFFIXES, encode_image, read_disparity, read_image, read_road_label,
    road_label_to_kitti)
from freespace.io.files import (PathLike, check_outputs, check_writable, check_writable_files, encode_json,
    atomic_write_bytes, write_csv, write_json, write_files_together)
from freespace.io.kitti import read_kitti_calib
from freespace.io.outdir import check_settings, claim_folder
from freespace.labels import RoadLabel
from freespace.runtime.shard import select_shard

log = logging.getLogger(__name__)

__all__ = ["FitOptions", "GenerateResult", "VirtualResult", "generate_pair", "generate_virtual_pair",
           "generate_dataset", "road_to_fit"]


@dataclass(frozen=True)
class FitOptions:
    """Options of the road fit and of the stereo matcher used when no disparity is given."""

    robust: bool = True
    inlier_threshold: float = 1.0
    max_disparity: int = SGBM_MAX_DISPARITY

    def check(self) -> None:
        """Raise InvalidOptionError for out-of-range values."""
        if not 0 < self.inlier_threshold < math.inf:
            raise InvalidOptionError(f"{param('inlier_threshold')} must be a finite number of pixels > 0, got "
                                     f"{self.inlier_threshold}")
        if not 1 <= self.max_disparity <= 1024:
            raise InvalidOptionError(f"{param('max_disparity')} must be in 1..1024 pixels, got {self.max_disparity}")


@dataclass
class GenerateResult:
    """What generating one frame produced: the model, the image and timings (seconds)."""

    model: RoadModel
    image: np.ndarray
    disparity_source: str
    timings: dict[str, float] = field(default_factory=dict)

    def report(self) -> dict[str, Any]:
        """JSON-ready model and statistics (``roll_deg``, ``kappa_hat``, ``kappa``, ``affine``,
        ``homography``, ``num_inliers``, ``rms_px``, ...)."""
        return {**self.model.to_dict(), "disparity_source": self.disparity_source,
                "seconds": {k: round(v, 6) for k, v in self.timings.items()}}


def check_output_image_path(path: PathLike, name: str = "out") -> Path:
    """Reject output names whose suffix is not an image format, before any work is done (``name``: the
    parameter that gave it, for the message)."""
    path = Path(path)
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        raise InvalidOptionError(f"{param(name)} {path} must end in one of {', '.join(IMAGE_SUFFIXES)} (PNG is "
                                 f"lossless)")
    if path.is_dir():
        raise InvalidOptionError(f"{param(name)} {path} is a folder; give an image file name")
    return path


def _size(shape: tuple[int, ...]) -> str:
    return f"{shape[1]}×{shape[0]}"


def road_to_fit(label: RoadLabel) -> np.ndarray:
    """The road pixels of ``label`` the fit uses (``bool H×W``: road and evaluated), or a RoadFitError that
    says why there are none: no evaluated pixel at all (an all-black KITTI ground truth), or no road."""
    if not label.valid.any():
        raise RoadFitError("empty road mask: the label has no evaluated pixel (all black: don't care everywhere "
                           "in KITTI colours); give the frame's road ground truth")
    road = label.road & label.valid
    if not road.any():
        raise RoadFitError("empty road mask: the label marks no road pixel; give a label with road (magenta in "
                           "KITTI colours, non-zero in a single-channel mask)")
    return road


#: what to check when a disparity has no valid value, by where it came from
_NO_DISPARITY_HINT = {
    "file": "check the disparity file",
    "depth": "check the depth map (0 and 65535 mean no depth) and the camera's focal length and baseline",
    "lidar": "no point of the LiDAR scan lands in the image: check the Velodyne scan and the calibration "
             "(Tr_velo_to_cam, R0_rect, P2)",
    "sgbm": "the stereo matcher found no match: check that the images are one rectified pair",
}


def generate_arrays(reference: np.ndarray, target: np.ndarray, road: np.ndarray, disparity: np.ndarray | None,
                    options: FitOptions = FitOptions(), *, disparity_source: str = "file",
                    calibration: StereoCalibration | None = None) -> GenerateResult:
    """Fit the road model and generate the view from arrays.

    Args:
        reference, target: ``H×W×3`` RGB (or ``H×W``) uint8 left and right images.
        road: ``bool H×W`` road pixels of the reference label (don't-care pixels excluded).
        disparity: ``float32 H×W`` left disparity (NaN invalid), or None to compute it with SGBM.
        disparity_source: where ``disparity`` came from (``file``, ``depth``, ``lidar``, ``sgbm``), for
            the report and the messages.
        calibration: the rig, when known: with a baseline the fit's camera height is checked too.

    Raises:
        RoadFitError: no road, no valid disparity, or a fit no real rig gives
            (:meth:`RoadModel.check_plausible`).
    """
    timings: dict[str, float] = {}
    if reference.shape != target.shape:
        raise ShapeMismatchError(f"reference is {_size(reference.shape)} but target is {_size(target.shape)}; "
                                 f"give the two images of one rectified stereo pair")
    if road.shape != reference.shape[:2]:
        raise ShapeMismatchError(f"road mask is {_size(road.shape)} but the images are {_size(reference.shape)}; "
                                 f"give the label of the reference image")
    if not road.any():
        raise RoadFitError("empty road mask: it marks no road pixel; give a label with road (magenta in KITTI "
                           "colours, non-zero in a single-channel mask)")
    source = disparity_source
    if disparity is None:
        t0 = time.perf_counter()
        disparity = compute_disparity(reference, target, max_disparity=options.max_disparity)
        timings["disparity"] = time.perf_counter() - t0
        source = "sgbm"
    elif disparity.shape != reference.shape[:2]:
        raise ShapeMismatchError(f"disparity is {_size(disparity.shape)} but the images are "
                                 f"{_size(reference.shape)}; give the disparity of the reference image")
    if not np.isfinite(disparity).any():
        raise RoadFitError(f"the disparity map (from {source}) has no valid value (all 0, NaN or inf); "
                           f"{_NO_DISPARITY_HINT.get(source, _NO_DISPARITY_HINT['file'])}")
    t0 = time.perf_counter()
    model = fit_road_model(disparity, road, robust=options.robust, inlier_threshold=options.inlier_threshold)
    timings["fit"] = time.perf_counter() - t0
    model.check_plausible(_camera_height(model, calibration))
    if model.num_inliers < 0.5 * model.num_valid:
        log.warning("only %d of %d road pixels (%.0f%%) agree with the fitted plane: check that the images are "
                    "one rectified pair and the label marks a planar road", model.num_inliers, model.num_valid,
                    100.0 * model.num_inliers / model.num_valid)
    t0 = time.perf_counter()
    image = generate_view(reference, target, model)
    timings["warp"] = time.perf_counter() - t0
    return GenerateResult(model=model, image=image, disparity_source=source, timings=timings)


def _camera_height(model: RoadModel, rig: StereoCalibration | None) -> float | None:
    """The camera height (metres) of a fitted model on ``rig``, or None without a rig or a baseline."""
    if rig is None or not rig.baseline > 0:
        return None
    return RoadPlane.from_road_model(model, rig.fx, rig.baseline, rig.cx, rig.cy, fy=rig.fy).height


def generate_pair(reference: PathLike, target: PathLike, road_mask: PathLike, disparity: PathLike | None = None,
                  *, out: PathLike | None = None, model_json: PathLike | None = None,
                  options: FitOptions = FitOptions()) -> GenerateResult:
    """Generate the augmented image of one stereo pair from files.

    Reads every input and computes the result before anything is written; then writes ``out`` (the
    generated image) and ``model_json`` (the model, :meth:`GenerateResult.report`) atomically.
    """
    options.check()
    if out is not None:
        check_output_image_path(out)
    check_writable_files({"out": out, "model_json": model_json})
    check_outputs({"out": out, "model_json": model_json},
                  {"reference": reference, "target": target, "road_mask": road_mask, "disparity": disparity})
    t_start = time.perf_counter()
    ref = read_image(reference, what="reference image")
    tgt = read_image(target, what="target image")
    label = read_road_label(road_mask)
    disp = read_disparity(disparity) if disparity is not None else None
    result = generate_arrays(ref, tgt, road_to_fit(label), disp, options)
    files: dict[PathLike, bytes] = {}
    if out is not None:
        files[out] = encode_image(result.image, Path(out).suffix.lower())
    result.timings["total"] = time.perf_counter() - t_start
    if model_json is not None:
        files[model_json] = encode_json(result.report())
    write_files_together(files)  # all or nothing; earlier files stay when it fails
    return result


# ---------------------------------------------------------------------------------------------------
# one reference image from another camera pose


@dataclass
class VirtualResult:
    """What :func:`generate_virtual_pair` made: the view, its label, the plane and where it came from."""

    image: np.ndarray
    label: RoadLabel
    valid: np.ndarray
    plane: RoadPlane
    plane_source: str  # "calibration" (Tr_cam_to_road) or "fit" (the disparity's road fit + P2/P3)
    pose: VirtualPose
    homography: np.ndarray
    model: RoadModel | None = None
    timings: dict[str, float] = field(default_factory=dict)

    def report(self) -> dict[str, Any]:
        """JSON-ready pose, plane, homography (reference → virtual pixels), valid fraction, fit."""
        out: dict[str, Any] = {"pose": self.pose.to_dict(), "plane_source": self.plane_source,
                               "plane": {"normal": list(self.plane.normal), "height_m": self.plane.height},
                               "homography": self.homography.tolist(), "valid_fraction": float(self.valid.mean()),
                               "seconds": {k: round(v, 6) for k, v in self.timings.items()}}
        if self.model is not None:
            out["road_model"] = self.model.to_dict()
        return out

    def summary(self) -> str:
        """One line for the command's output."""
        p = self.pose
        return (f"shift ({p.shift[0]:+.3f}, {p.shift[1]:+.3f}, {p.shift[2]:+.3f}) m  roll/pitch/yaw "
                f"({p.roll:+.2f}, {p.pitch:+.2f}, {p.yaw:+.2f})°  plane from {self.plane_source}: camera "
                f"{self.plane.height:.3f} m above the road  valid {100 * self.valid.mean():.1f}%")


def generate_virtual_pair(reference: PathLike, road_mask: PathLike, calib: PathLike, disparity: PathLike | None = None,
                          *, shift: str | None = None, rotate: str | None = None, out: PathLike, label_out: PathLike,
                          model_json: PathLike | None = None, options: FitOptions = FitOptions()) -> VirtualResult:
    """The reference image and its road label seen from a virtual camera pose.

    The road plane comes from the road fit of ``disparity`` (on the road pixels of ``road_mask``) and the
    calibration's ``P2``/``P3`` (:meth:`RoadPlane.from_road_model`) when a disparity is given, else from
    the calibration's ``Tr_cam_to_road``. The pose follows :mod:`freespace.geometry.virtual`.

    Args:
        reference, road_mask, calib, disparity: input files (left image, its label, KITTI calibration,
            optional left disparity: KITTI uint16 .png, .npy, .pfm).
        shift: ``"DX,DY,DZ"`` (metres), rotate: ``"ROLL,PITCH,YAW"`` (degrees); None = 0.
        out: the virtual image. label_out: its label in KITTI colours (road magenta, non-road red,
            don't care black: outside the reference image or don't care there).
        model_json: optional JSON report (:meth:`VirtualResult.report`).

    Every input is read and every check made before anything is written; outputs are written
    atomically, all or nothing, and may not be any input file.
    """
    options.check()
    pose = VirtualPose.parse(shift, rotate)
    lossless = tuple(x for x in IMAGE_SUFFIXES if x not in (".jpg", ".jpeg"))
    if Path(label_out).suffix.lower() not in lossless or Path(label_out).is_dir():
        raise InvalidOptionError(f"{param('label_out')} {label_out} must be a lossless image file name ending in "
                                 f"one of "
                                 f"{', '.join(lossless)} (labels must stay exact)")
    check_output_image_path(out)
    check_writable_files({"out": out, "label_out": label_out, "model_json": model_json})
    check_outputs({"out": out, "label_out": label_out, "model_json": model_json},
                  {"reference": reference, "road_mask": road_mask, "calib": calib, "disparity": disparity})
    t_start = time.perf_counter()
    image = read_image(reference, what="reference image")
    label = read_road_label(road_mask)
    if label.shape != image.shape[:2]:
        raise ShapeMismatchError(f"road mask is {_size(label.shape)} but the image is {_size(image.shape)}; give the "
                                 f"label of the reference image")
    try:
        rig = StereoCalibration.from_kitti(read_kitti_calib(calib))
    except KeyError as exc:
        raise CorruptFileError(f"calibration file {calib} has no {exc.args[0]}; it needs P2 and P3 (KITTI)") from None
    model = None
    if disparity is not None:
        disp = read_disparity(disparity)
        if disp.shape != image.shape[:2]:
            raise ShapeMismatchError(f"disparity is {_size(disp.shape)} but the image is {_size(image.shape)}; give "
                                     f"the disparity of the reference image")
        t0 = time.perf_counter()
        model = fit_road_model(disp, road_to_fit(label), robust=options.robust,
                               inlier_threshold=options.inlier_threshold)
        plane = RoadPlane.from_road_model(model, rig.fx, rig.baseline, rig.cx, rig.cy, fy=rig.fy)
        model.check_plausible(plane.height)
        timings = {"fit": time.perf_counter() - t0}
        source = "fit"
    else:
        if rig.road_plane is None:
            raise InvalidOptionError("the calibration has no road plane (no Tr_cam_to_road); give a disparity to fit "
                                     "the road, or the camera height and pitch")
        plane = rig.road_plane
        timings = {}
        source = "calibration"
    t0 = time.perf_counter()
    view, view_label, valid = virtual_view(image, label, rig.K, plane, pose)
    timings["warp"] = time.perf_counter() - t0
    result = VirtualResult(image=view, label=view_label, valid=valid, plane=plane, plane_source=source, pose=pose,
                           homography=virtual_homography(rig.K, plane, pose), model=model, timings=timings)
    data = [encode_image(view, Path(out).suffix.lower()), encode_image(road_label_to_kitti(view_label),
                                                                          Path(label_out).suffix.lower())]
    result.timings["total"] = time.perf_counter() - t_start
    files: dict[PathLike, bytes] = {out: data[0], label_out: data[1]}
    if model_json is not None:
        files[model_json] = encode_json(result.report())
    write_files_together(files)  # all or nothing; earlier files stay when it fails
    return result


# ---------------------------------------------------------------------------------------------------
# whole datasets


_DATASET: Any = None  # the dataset of this worker process (set by _init_worker)


def _process_frame(dataset: Any, index: int, out: Path, report: Path, options: FitOptions,
                   settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """Generate one frame of ``dataset``; never raises (the reason of a failure goes into the record).
    ``settings`` (the run's, :func:`_settings`) are kept in the frame's report, so a resumed run redoes a
    frame made with other settings."""
    t0 = time.perf_counter()
    frame = dataset.frames[index]
    record: dict[str, Any] = {"frame": frame.name}
    try:
        if frame.right is None:
            raise DatasetError("missing right image")
        if frame.label is None:
            raise DatasetError("missing road label")
        sample = dataset.load(index)
        result = generate_arrays(sample.left, sample.right, road_to_fit(sample.label), sample.disparity, options,
                                 disparity_source=sample.disparity_source, calibration=sample.calibration)
        atomic_write_bytes(out, encode_image(result.image, ".png"))
        record.update(status="done", **result.report())
        if settings is not None:
            record["settings"] = settings
        record["seconds"]["total"] = time.perf_counter() - t0
        write_json(report, record)
    except FreespaceError as exc:
        record.update(status="failed", reason=str(exc))
    except Exception as exc:  # a bad frame must not stop the run; the reason is reported
        log.debug("frame %s failed", frame.name, exc_info=True)
        record.update(status="failed", reason=f"{type(exc).__name__}: {exc}")
    return record


def _init_worker(dataset: Any, parent: int) -> None:
    import cv2

    from freespace.runtime.parallel import init_worker

    init_worker(parent)
    global _DATASET
    _DATASET = dataset
    cv2.setNumThreads(1)


SETTINGS_NAME = "settings.json"


def dataset_settings(dataset: Any) -> dict[str, Any]:
    """What a per-frame output depends on in the dataset: its layout, root, split and where its
    disparities come from (the source, its folder of disparity files, LiDAR densification)."""
    disparity_dir = getattr(dataset, "disparity_dir", None)
    spec = getattr(dataset, "spec", None)
    settings = {"dataset": dataset.name, "root": str(Path(dataset.root).resolve()), "split": dataset.split,
                "disparity_source": dataset.disparity_source,
                "disparity_dir": str(Path(disparity_dir).resolve()) if disparity_dir is not None else None,
                "layout": json.loads(json.dumps(asdict(spec), default=str)) if is_dataclass(spec) else None}
    if dataset.disparity_source == "lidar":
        settings["lidar_densify"] = getattr(dataset, "lidar_densify", 0.0)
    if _may_use_sgbm(dataset):
        settings["sgbm_version"] = SGBM_VERSION
    return settings


def _may_use_sgbm(dataset: Any) -> bool:
    """Whether a frame's disparity may come from SGBM: always with source ``sgbm``; with ``auto`` when a
    frame with a right image has neither a disparity file nor a depth map."""
    if dataset.disparity_source not in SGBM_SOURCES:
        return False
    return dataset.disparity_source == "sgbm" or any(
        f.disparity is None and f.depth is None and f.right is not None for f in dataset.frames)


def recorded_settings(recorded: dict[str, Any]) -> dict[str, Any]:
    """Settings recorded by an earlier version under the names of today's (``disparity``: ``disparity_source``)."""
    return {("disparity_source" if k == "disparity" else k): v for k, v in recorded.items()}


def _settings(dataset: Any, options: FitOptions) -> dict[str, Any]:
    """What a generated dataset depends on (written to ``OUT/settings.json``; never the shard, so that the
    shards of one run share an output folder)."""
    return {**dataset_settings(dataset), "robust": options.robust, "inlier_threshold": options.inlier_threshold,
            "max_disparity": options.max_disparity}


def _totals_names(shard: tuple[int, int] | None) -> tuple[str, str]:
    """``(summary, report)`` file names: ``summary.json``/``report.csv``, or for the shard ``(K, N)``
    ``summary.shard-K-of-N.json``/``report.shard-K-of-N.csv`` (shards never overwrite each other's)."""
    if shard is None:
        return "summary.json", "report.csv"
    return f"summary.shard-{shard[0]}-of-{shard[1]}.json", f"report.shard-{shard[0]}-of-{shard[1]}.csv"


def generate_dataset(dataset: Any, out_dir: PathLike, *, workers: int = 1,
                     options: FitOptions = FitOptions(), progress: bool = True,
                     overwrite: bool = False, shard: tuple[int, int] | None = None) -> dict[str, Any]:
    """Generate the augmented image of every frame of a dataset and write a report.

    Args:
        dataset: a :class:`freespace.data.base.StereoRoadDataset` (any layout); its disparity setting
            decides where disparities come from (file, depth, cached SGBM).
        out_dir: output folder. Writes ``<frame>.png`` (the frame's own file name), ``reports/<frame>.json``
            (model, inliers, residual, seconds), ``report.csv`` (one row per frame) and ``summary.json``.
        workers: processes; 1 runs in this process.
        options: fit options.
        shard: ``(K, N)``: only the K-th of N disjoint parts of the frames (1-based,
            :func:`freespace.runtime.shard.select_shard`), with its totals in ``summary.shard-K-of-N.json`` and
            ``report.shard-K-of-N.csv``; the shards of one run share ``out_dir`` (``settings.json`` holds
            no shard). A run without ``shard`` afterwards skips every frame and writes the totals.

    Frames whose image and report already exist, made with these settings, are skipped (resumable;
    every report keeps the run's settings). A failing frame (missing
    partner, unreadable file, too little road, ...) is recorded with its reason and does not stop the run.
    The settings (dataset, fit and disparity options) are recorded in ``settings.json``: a folder made
    with other settings is refused, unless ``overwrite`` replaces what was generated there (a shard's
    ``overwrite``: only its own frames). ``out_dir``
    may not lie inside the dataset's root (nor hold it).

    Returns:
        The summary (also written to ``summary.json``): counts, ``failed`` (frame → reason), means.
    """
    options.check()
    if workers < 1:
        raise InvalidOptionError(f"{param('workers')} must be ≥ 1, got {workers}")
    out_dir = Path(out_dir)
    check_writable(out_dir, folder=True)
    check_outputs({"out": out_dir}, {"root": dataset.root})
    _check_sgbm_width(dataset, options)
    settings = _settings(dataset, options)
    if shard is not None:
        dataset = dataset.subset(select_shard((f.name for f in dataset.frames), *shard))
    with frames_folder(out_dir, "generate", settings, overwrite, [f.name for f in dataset.frames], shard):
        return _generate_frames(dataset, out_dir, settings, options, workers, progress, shard)


@contextmanager
def frames_folder(out_dir: Path, command: str, settings: dict[str, Any], overwrite: bool, names: list[str],
                  shard: tuple[int, int] | None, extra: tuple[str, ...] = ()) -> Iterator[None]:
    """Hold ``out_dir`` for a per-frame dataset output of ``command`` (``generate``, ``autolabel``): the
    folder rule of :mod:`freespace.io.outdir` (shards share it), the recorded ``settings`` (a folder made with
    other ones is refused unless ``overwrite``, which first removes what this run or shard would write),
    and every file of the frames ``names`` listed in the manifest before it is written: ``<frame>.png``,
    ``reports/<frame>.json``, ``<extra>/<frame>.png``, the totals and ``settings.json``."""
    summary_name, report_name = _totals_names(shard)
    mine = {SETTINGS_NAME, "summary.json", "report.csv", summary_name, report_name,
            *(f"{n}.png" for n in names), *(f"reports/{n}.json" for n in names),
            *(f"{e}/{n}.png" for e in extra for n in names)}
    with claim_folder(out_dir, command, shared=shard is not None) as folder:
        check_settings(out_dir / SETTINGS_NAME, settings, overwrite, f"frames made by freespace {command}",
                       recorded_as=recorded_settings)
        if overwrite:  # only what this run (or shard) would write, and the whole run's totals, now stale
            folder.forget(mine & folder.entries())
        folder.record(mine)
        write_json(out_dir / SETTINGS_NAME, settings)
        yield


def _generate_frames(dataset: Any, out_dir: Path, settings: dict[str, Any], options: FitOptions, workers: int,
                     progress: bool, shard: tuple[int, int] | None) -> dict[str, Any]:
    """Generate the frames of ``dataset`` not yet done into ``out_dir`` and write the totals."""
    t0 = time.perf_counter()
    ordered = run_frames(dataset, out_dir, options, settings, shard, workers, progress)
    summary = {"dataset": dataset.name, "root": str(dataset.root),
               **({"shard": f"{shard[0]}/{shard[1]}"} if shard is not None else {}),
               **_totals(ordered), "wall_seconds": round(time.perf_counter() - t0, 3), "workers": workers,
               "options": {"robust": options.robust, "inlier_threshold": options.inlier_threshold,
                           "max_disparity": options.max_disparity, "disparity_source": dataset.disparity_source}}
    write_json(out_dir / _totals_names(shard)[0], summary)
    return summary


def run_frames(dataset: Any, out_dir: Path, options: Any, settings: dict[str, Any], shard: tuple[int, int] | None,
               workers: int, progress: bool, *, process: Any = None, desc: str = "generate", verb: str = "generate",
               fields: list[str] | None = None) -> list[dict[str, Any]]:
    """Process the frames of ``dataset`` that ``out_dir`` lacks (:func:`_plan`: resumable, redone when made
    with other settings) with ``process`` (default :func:`_process_frame`; ``desc`` names the progress bar,
    ``verb`` the work in the log), log each failure and write the run's (or shard's) report CSV with
    ``fields`` (default: generate's columns). Returns the frames' records in frame order."""
    frames = dataset.frames
    records, jobs = _plan(frames, out_dir, options, settings)
    log.info("%d frames: %d to %s, %d already done", len(frames), len(jobs), verb, len(records))
    records.update(_run_jobs(dataset, jobs, workers, progress, process=process or _process_frame, desc=desc))
    ordered = [records[f.name] for f in frames]
    for record in ordered:
        if record["status"] == "failed":
            log.warning("frame %s failed: %s", record["frame"], record["reason"])
    _write_report_csv(out_dir / _totals_names(shard)[1], ordered, fields or _CSV_FIELDS)
    return ordered


def _check_sgbm_width(dataset: Any, options: FitOptions) -> None:
    """Refuse, once and before any work, a ``max_disparity`` that SGBM cannot use on the dataset's images:
    checked on the first frame that would be matched (no disparity or depth file, or the disparity source
    ``sgbm``); frames of other sizes still fail one by one."""
    if dataset.disparity_source not in ("auto", "sgbm"):
        return
    frame = next((f for f in dataset.frames if f.right is not None and f.label is not None
                  and (dataset.disparity_source == "sgbm" or (f.disparity is None and f.depth is None))), None)
    if frame is None:
        return
    try:
        width = read_image(frame.left, what="left image").shape[1]
    except FreespaceError:
        return  # the frame fails with its own reason
    check_search_range(options.max_disparity, width, f"give disparities ({param('disparity_dir')}, or depth maps "
                                                     f"with {param('disparity_source')} depth)")


def _plan(frames: list[Any], out_dir: Path, options: FitOptions,
          settings: dict[str, Any]) -> tuple[dict[str, dict[str, Any]], list[tuple]]:
    """The records of frames already generated with these settings, and the jobs of the others."""
    records: dict[str, dict[str, Any]] = {}
    jobs = []
    for i, frame in enumerate(frames):
        image_path = out_dir / f"{frame.name}.png"
        report_path = out_dir / "reports" / f"{frame.name}.json"
        if image_path.is_file() and report_path.is_file():
            try:
                report = json.loads(report_path.read_text())
                if recorded_settings(report.get("settings", settings)) == settings:  # (older runs' have none)
                    records[frame.name] = {**report, "status": "skipped"}
                    continue
                log.info("%s was generated with other settings: generating it again", frame.name)
            except (OSError, ValueError, AttributeError):
                pass  # unreadable report: do the frame again
        jobs.append((i, image_path, report_path, options, settings))
    return records, jobs


def _in_worker(process: Any, *job: Any) -> dict[str, Any]:
    """``process(dataset, *job)`` with this worker process's dataset."""
    return process(_DATASET, *job)


def _run_jobs(dataset: Any, jobs: list[tuple], workers: int, progress: bool, process: Any = _process_frame,
              desc: str = "generate") -> dict[str, dict[str, Any]]:
    """Run ``process(dataset, *job)`` (a module-level function returning the frame's record, default
    :func:`_process_frame`) over ``jobs`` in this process or in ``workers`` processes."""
    from freespace.runtime.log import progress_bar

    records: dict[str, dict[str, Any]] = {}
    bar = progress_bar(None, total=len(jobs), desc=desc, unit="frame", enabled=progress and bool(jobs))
    if workers == 1 or len(jobs) <= 1:
        for job in jobs:
            record = process(dataset, *job)
            records[record["frame"]] = record
            bar.update()
    else:
        from freespace.runtime.parallel import worker_pool

        with worker_pool(workers, _init_worker, (dataset, os.getpid())) as pool:  # ends at once on Ctrl-C
            for future in as_completed([pool.submit(_in_worker, process, *job) for job in jobs]):
                record = future.result()
                records[record["frame"]] = record
                bar.update()
    bar.close()
    return records


def _totals(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Counts, failures by frame and the mean fit statistics of a run's frame records."""
    ok = [r for r in records if r["status"] != "failed"]

    def mean(key: str) -> float | None:
        vals = [r[key] for r in ok if r.get(key) is not None]
        return float(np.mean(vals)) if vals else None

    return {"frames": len(records),
            "generated": sum(r["status"] == "done" for r in records),
            "skipped": sum(r["status"] == "skipped" for r in records),
            "failed": {r["frame"]: r["reason"] for r in records if r["status"] == "failed"},
            "mean_roll_deg": mean("roll_deg"), "mean_rms_px": mean("rms_px"),
            "mean_inlier_fraction": float(np.mean([r["num_inliers"] / r["num_valid"] for r in ok])) if ok else None}


_CSV_FIELDS = ["frame", "status", "roll_deg", "kappa_hat", "kappa", "num_valid", "num_inliers", "rms_px",
               "disparity_source", "seconds", "reason"]


def _write_report_csv(path: Path, records: list[dict[str, Any]], fields: list[str] = _CSV_FIELDS) -> None:
    rows = []
    for record in records:
        row = dict(record)
        seconds = record.get("seconds") or {}
        row["seconds"] = round(seconds.get("total", math.nan), 4) if seconds else ""
        rows.append(row)
    write_csv(path, fields, rows, extra="ignore")
