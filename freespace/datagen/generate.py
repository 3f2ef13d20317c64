"""The DS-Generator over files: one stereo pair (:func:`generate_pair`), or every labelled frame of a dataset
(:func:`generate_dataset`, through the per-frame runner :mod:`freespace.datagen.runner`; fitted to a label tree's
labels: :func:`generate_with_labels`). One reference image
seen from a virtual camera pose: :mod:`freespace.datagen.virtual`.

This is what ``freespace generate`` runs. It imports NumPy and OpenCV only (never torch), reads and
checks every input before it writes anything, and writes every output atomically.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.base import StereoRoadDataset
from freespace.data.label_tree import hold_labels_record, labelled_from_tree
from freespace.datagen.inputs import check_sgbm_range, dataset_settings
from freespace.datagen.runner import FrameCommand, check_run, run_dataset
from freespace.errors import DatasetError, FreespaceError, InvalidOptionError, RoadFitError, ShapeMismatchError, param
from freespace.geometry import (
    SGBM_MAX_DISPARITY,
    RoadModel,
    RoadPlane,
    StereoCalibration,
    compute_disparity,
    fit_road_model,
    generate_view,
)
from freespace.io.codecs import (
    OUTPUT_IMAGE_SUFFIXES,
    describe_image,
    encode_image,
    read_disparity,
    read_image,
    read_road_label,
)
from freespace.io.files import (
    PathLike,
    atomic_write_bytes,
    check_outputs,
    check_writable_files,
    encode_json,
    write_files_together,
)
from freespace.labels import RoadLabel

log = logging.getLogger(__name__)

__all__ = ["FitOptions", "GenerateResult", "generate_arrays", "generate_pair", "generate_dataset",
           "generate_with_labels", "road_to_fit", "check_output_image_path"]


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
    if path.suffix.lower() not in OUTPUT_IMAGE_SUFFIXES:
        raise InvalidOptionError(f"{param(name)} {path} must end in one of {', '.join(OUTPUT_IMAGE_SUFFIXES)} (PNG is "
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
        raise ShapeMismatchError(f"reference is {describe_image(reference.shape)} but target is "
                                 f"{describe_image(target.shape)}; give the two images of one rectified stereo pair")
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
# whole datasets


def _process_frame(dataset: StereoRoadDataset, index: int, out: Path, report: Path, options: FitOptions,
                   settings: dict[str, Any]) -> dict[str, Any]:
    """Generate frame ``index`` of ``dataset`` into ``out`` (the image) and ``report`` (its JSON); never raises
    (the reason of a failure goes into the record). ``settings`` (the run's, :func:`_settings`) are kept in the
    frame's report, so a resumed run redoes a frame made with other settings."""
    t0 = time.perf_counter()
    frame = dataset.frames[index]
    record: dict[str, Any] = {"frame": frame.name}
    try:
        if frame.right is None:
            raise DatasetError("missing right image")
        if not dataset.has_label(frame):  # its own label, or one of a label tree (a dataset without labels)
            raise DatasetError("missing road label")
        sample = dataset.load(index)
        result = generate_arrays(sample.left, sample.right, road_to_fit(sample.label), sample.disparity, options,
                                 disparity_source=sample.disparity_source, calibration=sample.calibration)
        atomic_write_bytes(out, encode_image(result.image, ".png"))
        record.update(status="done", **result.report(), settings=settings)
        record["seconds"]["total"] = time.perf_counter() - t0
        atomic_write_bytes(report, encode_json(record))
    except FreespaceError as exc:
        record.update(status="failed", reason=str(exc))
    except Exception as exc:  # a bad frame must not stop the run; the reason is reported
        log.debug("frame %s failed", frame.name, exc_info=True)
        record.update(status="failed", reason=f"{type(exc).__name__}: {exc}")
    return record


def _means(ok: list[dict[str, Any]]) -> dict[str, Any]:
    """The mean fit statistics of the frames that did not fail (None without any)."""

    def mean(key: str) -> float | None:
        vals = [r[key] for r in ok if r.get(key) is not None]
        return float(np.mean(vals)) if vals else None

    return {"mean_roll_deg": mean("roll_deg"), "mean_rms_px": mean("rms_px"),
            "mean_inlier_fraction": float(np.mean([r["num_inliers"] / r["num_valid"] for r in ok])) if ok else None}


#: ``freespace generate --dataset``, for the per-frame runner
GENERATE = FrameCommand(name="generate", verb="generate", work=_process_frame, done="generated", means=_means,
                        fields=("frame", "status", "roll_deg", "kappa_hat", "kappa", "num_valid", "num_inliers",
                                "rms_px", "disparity_source", "seconds", "reason"))


def _settings(dataset: StereoRoadDataset, options: FitOptions) -> dict[str, Any]:
    """What a generated dataset depends on (written to ``OUT/settings.json``; never the shard, so that the
    shards of one run share an output folder)."""
    return {**dataset_settings(dataset), "robust": options.robust, "inlier_threshold": options.inlier_threshold,
            "max_disparity": options.max_disparity}


def generate_dataset(dataset: StereoRoadDataset, out_dir: PathLike, *, workers: int = 1,
                     options: FitOptions = FitOptions(), progress: bool = True,
                     overwrite: bool = False, shard: tuple[int, int] | None = None) -> dict[str, Any]:
    """Generate the augmented image of every frame of a dataset and write a report.

    Args:
        dataset: any layout; its disparity setting decides where disparities come from (file, depth,
            cached SGBM).
        out_dir: output folder. Writes ``<frame>.png`` (the frame's own file name), ``reports/<frame>.json``
            (model, inliers, residual, seconds, the run's settings), ``report.csv`` (one row per frame),
            ``summary.json`` and ``settings.json``.
        workers: processes; 1 runs in this process.
        options: fit options.
        shard: ``(K, N)``: only the K-th of N disjoint parts of the frames (1-based,
            :func:`freespace.runtime.shard.select_shard`), with its totals in ``summary.shard-K-of-N.json``
            and ``report.shard-K-of-N.csv``; the shards of one run share ``out_dir`` (``settings.json`` holds
            no shard). A run without ``shard`` afterwards skips every frame and writes the totals.

    Resumable, sharded and refusing a folder made with other settings (unless ``overwrite`` replaces what
    was generated there; a shard's ``overwrite``: only its own frames) as every per-frame command
    (:mod:`freespace.datagen.runner`). A failing frame (missing partner, unreadable file, too little road,
    ...) is recorded with its reason and does not stop the run. ``out_dir`` may not lie inside the
    dataset's root (nor hold it).

    Returns:
        The summary (also written to ``summary.json``): counts, ``failed`` (frame → reason), means.
    """
    options.check()
    out_dir = check_run(dataset, out_dir, workers)
    check_sgbm_range(dataset, options.max_disparity, labelled=True)
    summary, _ = run_dataset(dataset, out_dir, GENERATE, options=options, settings=_settings(dataset, options),
                             workers=workers, progress=progress, overwrite=overwrite, shard=shard,
                             summary={"options": {"robust": options.robust,
                                                  "inlier_threshold": options.inlier_threshold,
                                                  "max_disparity": options.max_disparity,
                                                  "disparity_source": dataset.disparity_source}})
    return summary


def generate_with_labels(dataset: StereoRoadDataset, out_dir: PathLike, labels: PathLike | None, *, name: str,
                         root: PathLike, split: str | None = None, **run: Any) -> dict[str, Any]:
    """``freespace generate --dataset``: :func:`generate_dataset` (``run``: its keyword arguments) of the road labels
    the frames have. With ``labels`` (a label tree, ``freespace autolabel``'s output) the frames of ``dataset``
    that have a label there, labelled from it (:func:`~freespace.data.label_tree.labelled_from_tree`; ``name``,
    ``root`` and ``split`` as the user gave them, checked against the tree's record); without, the dataset's own
    labels. ``OUT/labels.json`` records which (:func:`~freespace.data.label_tree.hold_labels_record`: an ``out_dir``
    fitted to other labels is refused unless ``run["overwrite"]``).

    Raises:
        DatasetError: no ``labels`` and no frame of ``dataset`` has a road label (the message says how to make
            some), or the tree labels none of its frames.
        InvalidOptionError: ``out_dir`` holds frames fitted to other labels.
    """
    tree = None
    if labels is not None:
        dataset, tree = labelled_from_tree(dataset, labels, name, root, split)
    elif not any(dataset.has_label(f) for f in dataset.frames):
        autolabel = "freespace autolabel --dataset {} --root {} --out TREE".format(name, root)  # a command: flags
        raise DatasetError(f"{name} at {root} has no road labels, which the DS-Generator fits the road model to; "
                           f"label it with `{autolabel}` and give {param('labels')} TREE")
    with hold_labels_record(out_dir, tree, dataset.root, labels, run.get("overwrite", False)):
        return generate_dataset(dataset, out_dir, **run)
