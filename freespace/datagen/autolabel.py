"""Road labels without people from files: one left image (:func:`autolabel_pair`) or every frame of a dataset
(:func:`autolabel_dataset`, through the per-frame runner :mod:`freespace.datagen.runner`, into a label tree:
:mod:`freespace.data.label_tree`); what ``freespace autolabel`` runs. The method itself, :func:`autolabel` of a
disparity map, is :mod:`freespace.datagen.labeller` (its names are importable from here too).

Every input is read and checked before anything is written; outputs are written atomically. This module
imports NumPy and OpenCV only, never torch.
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data import label_tree
from freespace.data.base import StereoRoadDataset
from freespace.datagen.inputs import check_sgbm_range, dataset_settings, may_use_sgbm
from freespace.datagen.labeller import AutolabelOptions, AutolabelResult, autolabel
from freespace.datagen.runner import FrameCommand, check_run, run_dataset
from freespace.errors import (
    CorruptFileError,
    DatasetError,
    FreespaceError,
    InvalidOptionError,
    RoadFitError,
    ShapeMismatchError,
    param,
)
from freespace.geometry import compute_disparity
from freespace.io.codecs import describe_image, read_disparity, read_image
from freespace.io.files import PathLike, check_outputs, check_writable_files
from freespace.io.kitti import read_kitti_calib

log = logging.getLogger(__name__)

__all__ = ["AutolabelOptions", "AutolabelResult", "autolabel", "autolabel_pair", "autolabel_dataset",
           "write_label_files", "implausible_pair", "MIN_MATCHED", "MIN_ROAD"]


#: a rectified stereo pair's left image matches on far more of its pixels than this share (SGBM); a swapped
#: pair (the right image as reference) or two unrelated images match on a few per cent
MIN_MATCHED = 0.15
#: a road label with less road than this share of the image comes from a pair or disparity that is wrong more
#: often than from a frame without road in its lower centre (which autolabel assumes)
MIN_ROAD = 0.01


def implausible_pair(matched: float | None, result: AutolabelResult | None) -> str | None:
    """Why a stereo pair (or its disparity) looks wrong for a road label, or None: SGBM matched less than
    :data:`MIN_MATCHED` of the pixels (``matched``: the share of valid disparities, None when no SGBM ran), or
    the label has less than :data:`MIN_ROAD` road (``result``)."""
    if matched is not None and matched < MIN_MATCHED:
        return f"SGBM matched only {100 * matched:.1f} % of the pixels"
    if result is not None and result.stats["road_fraction"] < MIN_ROAD:
        return f"only {100 * result.stats['road_fraction']:.1f} % of the image is road"
    return None


def _matched(disparity: np.ndarray) -> float:
    with np.errstate(invalid="ignore"):
        return float((np.isfinite(disparity) & (disparity > 0)).mean())


def _size(shape: tuple[int, ...]) -> str:
    return f"{shape[1]}×{shape[0]}"


def _lossless_png(path: PathLike, name: str) -> Path:
    path = Path(path)
    if path.suffix.lower() != ".png" or path.is_dir():
        raise InvalidOptionError(f"{param(name)} {path} must be a .png file name (labels and confidences must "
                                 f"stay exact)")
    return path


def _baseline_from_calib(calib: PathLike) -> float:
    from freespace.geometry.depth import rig_from_kitti

    try:
        return float(rig_from_kitti(read_kitti_calib(calib)).baseline)
    except KeyError as exc:
        raise CorruptFileError(f"calibration file {calib} has no {exc.args[0]}; it needs P2 and P3 (KITTI)") from None


def write_label_files(result: AutolabelResult, out: PathLike, confidence: PathLike | None = None,
                      report: PathLike | None = None, extra: dict[str, Any] | None = None) -> list[Path]:
    """Write the label (KITTI colours PNG), its confidence (8-bit grey PNG, ``round(255·c)``) and a JSON
    report (:meth:`AutolabelResult.report` plus ``extra``), all or nothing (when one cannot be written, the
    files there before stay as they were), as a label tree holds them
    (:func:`freespace.data.label_tree.write_label_files`). Returns the paths written."""
    return label_tree.write_label_files(result.label, out, result.confidence_u8(), confidence,
                                        {**result.report(), **(extra or {})}, report)


def autolabel_pair(reference: PathLike, target: PathLike | None = None, disparity: PathLike | None = None, *,
                   out: PathLike, confidence: PathLike | None = None, calib: PathLike | None = None,
                   baseline: float | None = None, model_json: PathLike | None = None,
                   options: AutolabelOptions = AutolabelOptions()) -> AutolabelResult:
    """Autolabel one left image from files (``freespace autolabel`` with one image)).

    Args:
        reference: the left image (its size is checked against the disparity; SGBM input with ``target``).
        target: the right image: the disparity is computed with SGBM (``options.max_disparity``). Exactly
            one of ``target`` and ``disparity``.
        disparity: the left disparity (KITTI uint16 .png, .npy, .pfm).
        out: the label, KITTI colours (.png). confidence: its confidence, 8-bit grey (.png), optional.
        calib: a KITTI calibration (the baseline from P2/P3), or ``baseline`` in metres; with neither,
            the camera height is ``options.camera_height``.
        model_json: optional JSON report (road model, noise, coverage, ...).

    Every input is read and the label computed before anything is written; outputs are written
    atomically, all or nothing, and may not be any input.
    """
    options.check()
    if (target is None) == (disparity is None):
        raise InvalidOptionError(f"give the right image ({param('target')}) or the left disparity "
                                 f"({param('disparity')}), one of them")
    if calib is not None and baseline is not None:
        raise InvalidOptionError(f"give the baseline once: {param('calib')} or {param('baseline')}, not both")
    _lossless_png(out, "out")
    if confidence is not None:
        _lossless_png(confidence, "confidence")
    check_outputs({"out": out, "confidence": confidence, "model_json": model_json},
                  {"reference": reference, "target": target, "disparity": disparity, "calib": calib})
    check_writable_files({"out": out, "confidence": confidence, "model_json": model_json})
    t0 = time.perf_counter()
    left = read_image(reference, what="reference image")
    if calib is not None:
        baseline = _baseline_from_calib(calib)
    if target is not None:
        if Path(os.path.realpath(reference)) == Path(os.path.realpath(target)):
            raise InvalidOptionError(f"{param('reference')} and {param('target')} are the same file; give the left "
                                     f"and the right image of one rectified stereo pair")
        right = read_image(target, what="target image")
        if right.shape != left.shape:
            raise ShapeMismatchError(f"reference is {describe_image(left.shape)} but target is "
                                     f"{describe_image(right.shape)}; give the two images of one rectified stereo pair")
        disp = compute_disparity(left, right, max_disparity=options.max_disparity)
        source = "sgbm"
    else:
        disp = read_disparity(disparity)  # type: ignore[arg-type]
        source = "file"
        if disp.shape != left.shape[:2]:
            raise ShapeMismatchError(f"disparity is {_size(disp.shape)} but the reference image is "
                                     f"{_size(left.shape)}; give the disparity of the reference image")
    if not np.isfinite(disp).any():
        raise RoadFitError("the disparity map has no valid value (all 0, NaN or inf); check the "
                           + ("stereo pair" if source == "sgbm" else "disparity file"))
    matched = _matched(disp) if source == "sgbm" else None
    try:
        result = autolabel(disp, baseline=baseline, options=options)
    except RoadFitError as exc:
        why = implausible_pair(matched, None)
        if why is None:
            raise
        raise RoadFitError(f"{exc.render(param)} ({why}: {_pair_question()})") from None
    result.stats.update(disparity_source=source, seconds=round(time.perf_counter() - t0, 4))
    why = implausible_pair(matched, result)
    if why is not None:
        log.warning("the label is implausible: %s; %s", why, "are the reference and target images swapped? The "
                    "reference is the left image, the target the right one of one rectified pair" if source == "sgbm"
                    else "is the disparity the reference (left) image's?")
    write_label_files(result, out, confidence, model_json)
    return result


def _pair_question() -> str:
    return (f"are {param('reference')} and {param('target')} swapped? {param('reference')} is the left image, "
            f"{param('target')} the right one of one rectified pair")


def _settings(dataset: StereoRoadDataset, options: AutolabelOptions) -> dict[str, Any]:
    """What an autolabel tree depends on (``OUT/settings.json``; never the shard)."""
    return {**dataset_settings(dataset), **options.to_dict()}


def _label_frame(dataset: StereoRoadDataset, index: int, out: Path, report: Path, options: AutolabelOptions,
                 settings: dict[str, Any]) -> dict[str, Any]:
    """Autolabel frame ``index`` of ``dataset`` into ``out`` (+ ``confidence/``, ``report``); never raises
    (a failure's reason goes into the record)."""
    t0 = time.perf_counter()
    frame = dataset.frames[index]
    record: dict[str, Any] = {"frame": frame.name}
    matched = None
    try:
        sample = dataset.load(index, label=False)
        if sample.disparity is None:
            wanted = {"sgbm": "right image for SGBM", "file": "disparity file or depth map"}.get(
                dataset.disparity_source, "disparity file, depth map or right image for SGBM")
            raise DatasetError(f"no {wanted} ({param('disparity_source')} {dataset.disparity_source})")
        matched = _matched(sample.disparity) if sample.disparity_source == "sgbm" else None
        calib = sample.calibration
        baseline = calib.baseline if calib is not None and calib.baseline > 0 else None
        result = autolabel(sample.disparity, baseline=baseline, options=options)
        result.stats.update(disparity_source=sample.disparity_source, seconds={"total": time.perf_counter() - t0})
        why = implausible_pair(matched, result)
        record.update(status="done", **result.report(), settings=settings, **({"implausible": why} if why else {}))
        root = out.parents[len(Path(frame.name).parts) - 1]  # OUT: out is OUT/<frame>.png, a frame may hold folders
        write_label_files(result, out, label_tree.confidence_path(root, frame.name), report, record)
    except FreespaceError as exc:
        why = implausible_pair(matched, None) if isinstance(exc, RoadFitError) else None
        text = exc.render(param) + (f" ({why}: are the left and right images swapped?)" if why else "")
        # the reason as the files record it (parameters by name), and the error, whose parameters the command
        # line writes as its flags (kept in memory only: no file records it)
        record.update(status="failed", reason=FreespaceError(text).render(), error=text)
    except Exception as exc:  # a bad frame must not stop the run; the reason is reported
        log.debug("frame %s failed", frame.name, exc_info=True)
        record.update(status="failed", reason=f"{type(exc).__name__}: {exc}")
    return record


def _means(ok: list[dict[str, Any]]) -> dict[str, Any]:
    """The mean coverage and road fraction of the frames labelled (None without any)."""
    return {"mean_coverage": float(np.mean([r["coverage"] for r in ok])) if ok else None,
            "mean_road_fraction": float(np.mean([r["road_fraction"] for r in ok])) if ok else None}


#: ``freespace autolabel --dataset``, for the per-frame runner
AUTOLABEL = FrameCommand(name="autolabel", verb="label", work=_label_frame, done="labelled", means=_means,
                         fields=("frame", "status", "coverage", "road_fraction", "noise_px", "roughness_m",
                                 "camera_height_m", "roll_deg", "num_inliers", "rms_px", "disparity_source",
                                 "seconds", "reason"), extra=("confidence",))


def autolabel_dataset(dataset: StereoRoadDataset, out_dir: PathLike, *, workers: int = 1,
                      options: AutolabelOptions = AutolabelOptions(), progress: bool = True,
                      overwrite: bool = False, shard: tuple[int, int] | None = None) -> dict[str, Any]:
    """Autolabel every frame of a dataset (labelled or not) into a label tree that training reads as its ``labels``.

    Writes ``OUT/<frame>.png`` (KITTI colours), ``OUT/confidence/<frame>.png`` (8-bit), ``OUT/reports/
    <frame>.json`` (road model, noise, coverage, settings), ``OUT/report.csv`` and ``OUT/summary.json``
    (``.shard-K-of-N`` names with ``shard``), and ``OUT/settings.json``. Disparities come from the
    dataset's disparity setting (file, depth, LiDAR or cached SGBM); the baseline from each frame's
    calibration. Resumable, sharded and refusing a folder made with other settings (unless
    ``overwrite``) as every per-frame command (:mod:`freespace.datagen.runner`).

    Returns:
        The summary: counts, ``failed`` (frame → reason), mean coverage and road fraction; and ``errors``
        (frame → :class:`~freespace.errors.FreespaceError`, this run's failures, whose parameters an interface
        writes its own way: :meth:`~freespace.errors.FreespaceError.render`).
    """
    options.check()
    out_dir = check_run(dataset, out_dir, workers)
    _check_disparity_inputs(dataset, out_dir, options)
    settings = _settings(dataset, options)
    summary, records = run_dataset(dataset, out_dir, AUTOLABEL, options=options, settings=settings, workers=workers,
                                   progress=progress, overwrite=overwrite, shard=shard,
                                   summary={"settings": settings})
    ok = [r for r in records if r["status"] != "failed"]
    odd = [r for r in ok if r.get("implausible")]
    if odd:
        log.warning("%d of %d labelled frames look implausible (e.g. %s: %s); are the left and right images "
                    "swapped, or the disparities not the left images'?", len(odd), len(ok), odd[0]["frame"],
                    odd[0]["implausible"])
    return {**summary, "errors": {r["frame"]: FreespaceError(r["error"]) for r in records if "error" in r}}


def _check_disparity_inputs(dataset: StereoRoadDataset, out_dir: Path, options: AutolabelOptions) -> None:
    """Refuse, before any work, a disparity setting under which frames cannot be labelled or files land where
    they must not:

    * ``disparity_source`` ``none`` (no frame could be labelled);
    * a folder of disparity files (``disparity_dir``) with a source that never reads them (``sgbm``, ``depth``,
      ``lidar``): it would be ignored;
    * ``sgbm`` on a tree without right images, ``file`` on one without disparity files or depth maps
      (``depth`` and ``lidar`` are checked when the dataset opens);
    * an SGBM search range (``max_disparity``) not smaller than the images' width;
    * an SGBM cache (``cache_dir``) inside the dataset (its ``.npy`` files would land among the images) or
      that is, holds or lies in ``out_dir`` (its files would lie outside the label tree's manifest).
    """
    source = dataset.disparity_source
    if source == "none":
        raise InvalidOptionError(f"{param('disparity_source')} none gives no disparity, and a label needs one; "
                                 f"choose auto, file, depth, lidar or sgbm")
    if getattr(dataset, "disparity_dir", None) is not None and source not in ("auto", "file"):
        raise InvalidOptionError(f"{param('disparity_dir')} is read with {param('disparity_source')} auto or file; "
                                 f"with {source} it would be ignored: leave one of them out")
    if source == "sgbm" and not any(f.right is not None for f in dataset.frames):
        raise DatasetError(f"{param('disparity_source')} sgbm matches left and right images, and no frame under "
                           f"{dataset.root} has a right image; give disparities ({param('disparity_source')} file, "
                           f"depth or lidar)")
    if source == "file" and not any(f.disparity is not None or f.depth is not None for f in dataset.frames):
        raise DatasetError(f"{param('disparity_source')} file reads disparity files (or depth maps), and no frame "
                           f"under {dataset.root} has one; give {param('disparity_dir')}, or choose "
                           f"{param('disparity_source')} sgbm, depth or lidar")
    if not may_use_sgbm(dataset):
        return
    check_sgbm_range(dataset, options.max_disparity)
    cache = Path(dataset.cache.folder)
    check_outputs({"cache_dir": cache}, {"root": dataset.root})
    real_cache, real_out = Path(os.path.realpath(cache)), Path(os.path.realpath(out_dir))
    if real_cache.is_relative_to(real_out) or real_out.is_relative_to(real_cache):
        raise InvalidOptionError(f"{param('cache_dir')} {cache} and {param('out')} {out_dir} overlap: the SGBM cache's "
                                 f"files would lie in the label tree, outside what it records (or the tree in the "
                                 f"cache); give them two separate folders")
