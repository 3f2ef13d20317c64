"""Road labels that reach the whole road: carry what later frames of a drive saw near the car back into earlier ones.

A single frame's autolabel (:mod:`freespace.datagen.labeller`) is sure of the road only where the disparity is
good: near the car. Far lanes, the road beyond parked cars and across junctions stay don't care. A few seconds
later the car is there, and the same road lies near the camera, well labelled. This module carries those labels
back along the drive:

1. **Ego-motion** between consecutive frames (:func:`ego_motion`, in :mod:`freespace.datagen.ego_motion`): ORB
   features of the earlier left image with a disparity (SGBM or LiDAR) are points in 3-D; their matches in the next
   left image give the camera's motion by PnP (RANSAC, then Levenberg–Marquardt on the inliers). Motions are
   chained along the drive.
2. **The road plane** of the earlier frame ``t`` (its autolabel's fitted road model,
   :meth:`~freespace.geometry.RoadPlane.from_road_model`) and the motion ``X_s = R X_t + t`` to a later frame ``s``
   give the plane-induced homography ``H_st = K (R + t nᵀ/h) K⁻¹`` (:func:`~freespace.geometry.homography_from_pose`):
   where a road pixel of ``t`` lies in ``s``.
3. **Votes** (:func:`propagate_frame`, in :mod:`freespace.datagen.road_votes`): each pixel of ``t`` below its
   horizon takes, from each source frame ``s``, the label ``s`` gives its image point — only where ``s`` is sure of
   it (labelled, within
   :attr:`PropagateOptions.near_depth` metres of ``s``'s camera) and where the two images agree there (the blurred
   grey levels differ by at most :attr:`PropagateOptions.max_grey_difference`: a car that stood on that road in
   ``t`` and has moved on by ``s`` is not taken for road).
4. **The label**: a don't-care pixel of ``t`` becomes road when at least one source says road and none says
   non-road; a labelled pixel keeps its label unless a source contradicts it and more sources contradict than
   agree — then it becomes don't care (a conflict is not resolved by guessing). Non-road votes never create
   non-road: they only veto.

Conventions: pixels 0-based (``u`` column, ``v`` row); camera frame x right, y down, z forward, metres;
``Motion`` maps points of the earlier camera into the later one. NumPy and OpenCV only, never torch.

This module runs it over a dataset: an autolabel tree in, a propagated tree out (:func:`propagate_dataset`); the
settings are :class:`PropagateOptions` (:mod:`freespace.datagen.options`). Every name above is importable from here.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.base import StereoRoadDataset
from freespace.data.label_tree import check_label_tree, confidence_path, write_label_files
from freespace.datagen.ego_motion import Motion, compose, ego_motion, source_frames
from freespace.datagen.options import PropagateOptions
from freespace.datagen.road_votes import propagate_frame
from freespace.errors import CorruptFileError, DatasetError, ShapeMismatchError, param
from freespace.geometry import RoadModel
from freespace.io.codecs import read_image, read_road_label
from freespace.io.files import PathLike, check_outputs, check_writable, write_csv, write_json
from freespace.io.outdir import claim_folder
from freespace.labels import RoadLabel

log = logging.getLogger(__name__)

__all__ = ["PropagateOptions", "Motion", "ego_motion", "compose", "source_frames", "propagate_frame",
           "propagate_dataset"]


# --- a whole dataset: an autolabel tree in, a propagated tree out ---------------------------------------------------


#: what a tree is called once a pass has made it (the key of the pass's settings in settings.json)
_DONE = {"propagation": "propagated", "look": "look-checked"}


def read_tree_settings(tree: Path, dataset: StereoRoadDataset, option: str = "propagate_from",
                       done: str = "propagation") -> dict[str, Any]:
    """The settings of the autolabel tree ``tree`` (given as ``option``), checked to label ``dataset`` and not to
    have been through the pass whose settings key is ``done`` already (``propagation``, or ``look``)."""
    check_label_tree(tree, dataset.name, dataset.root, dataset.split, option=option)
    try:
        made = json.loads((tree / "settings.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        made = None
    if not isinstance(made, dict):
        raise DatasetError(f"{param(option)} {tree} has no readable settings.json, so it is no tree that "
                           f"`freespace autolabel` wrote; label the dataset first (`freespace autolabel --out TREE`)")
    if done in made:
        source = made.get("look_source_labels" if done == "look" else "source_labels")
        raise DatasetError(f"{param(option)} {tree} is already {_DONE[done]}; give the tree it was made from "
                           f"({source})")
    return made


#: a frame of a drive as propagation reads it: its left image, and from the tree its label, road model, report and
#: confidence (None: the tree has no label for it)
_Frame = tuple[np.ndarray, "tuple[RoadLabel, RoadModel, dict[str, Any], np.ndarray] | None"]


def _size(array: np.ndarray) -> str:
    """``W×H`` (``W×H×C`` for a colour image) of an image array, as the messages write sizes."""
    return "×".join(str(n) for n in (array.shape[1], array.shape[0], *array.shape[2:]))


def frame_label(tree: Path, name: str, image: np.ndarray, image_path: Path, option: str = "propagate_from"
                ) -> tuple[RoadLabel, RoadModel, dict[str, Any], np.ndarray] | None:
    """A frame's autolabel, road model, report and confidence (``uint8 H×W``; zeros when the tree has none) from
    ``tree``, or None when the tree has no label for it; ``image`` is the frame's left image (``image_path``).

    Raises:
        CorruptFileError: an unreadable report, a confidence map that is no grey image. ShapeMismatchError: the label
        is not the size of the image, or the confidence map not the size of the label (both files and sizes named).
    """
    label_path, report_path = tree / f"{name}.png", tree / "reports" / f"{name}.json"
    if not (label_path.is_file() and report_path.is_file()):
        return None
    try:
        report = json.loads(report_path.read_text())
        model = RoadModel.from_affine(*report["affine"])
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError):
        raise CorruptFileError(f"the report {report_path} of {param(option)} is unreadable; label the "
                               f"dataset again with `freespace autolabel`") from None
    label = read_road_label(label_path)
    if label.shape != image.shape[:2]:
        raise ShapeMismatchError(f"{param(option)} {tree}: the label {label_path} is {_size(label.road)} but "
                                 f"the frame's image {image_path} is {_size(image)}; label the dataset again with "
                                 f"`freespace autolabel` (a tree's labels are the size of its images)")
    conf_path = confidence_path(tree, name)
    if not conf_path.is_file():
        return label, model, report, np.zeros(label.shape, np.uint8)
    confidence = read_image(conf_path, what="confidence")
    if confidence.ndim != 2:
        raise CorruptFileError(f"{param(option)} {tree}: the confidence map {conf_path} is a colour image "
                               f"({_size(confidence)}), not a grey one; label the dataset again with `freespace "
                               f"autolabel`")
    if confidence.shape != label.shape:
        raise ShapeMismatchError(f"{param(option)} {tree}: the confidence map {conf_path} is "
                                 f"{_size(confidence)} but the label {label_path} is {_size(label.road)}; label the "
                                 f"dataset again with `freespace autolabel` (or remove the confidence map)")
    return label, model, report, confidence


def _drive_motions(dataset: StereoRoadDataset, indices: list[int], options: PropagateOptions
                   ) -> tuple[list[Motion | None], np.ndarray, float]:
    """The motions between consecutive frames ``indices`` of one drive, its intrinsics and baseline."""
    motions: list[Motion | None] = []
    earlier = dataset.load(indices[0], right=True, label=False)
    calib = earlier.calibration
    if calib is None or not calib.baseline > 0:
        raise DatasetError(f"{earlier.scenario} has no calibration with a baseline; propagation needs the rig's "
                           f"focal length and baseline")
    for i in indices[1:]:
        later = dataset.load(i, right=True, label=False)
        motion = None
        if earlier.disparity is not None:
            motion = ego_motion(earlier.left, later.left, earlier.disparity, calib.K, calib.baseline, options=options)
        motions.append(motion)
        earlier = later
    return motions, calib.K, calib.baseline


def _propagate_drive(dataset: StereoRoadDataset, indices: list[int], tree: Path, staging: Path,
                     options: PropagateOptions) -> list[dict[str, Any]]:
    """Propagate one drive's frames (``indices``, in time order) from ``tree`` into ``staging``; the rows.

    Raises:
        ShapeMismatchError: a label or confidence map of another size than its frame (:func:`frame_label`), or two
        frames of the drive with images of other sizes.
    """
    motions, K, baseline = _drive_motions(dataset, indices, options)
    cache: dict[int, _Frame] = {}
    first: list[tuple[Path, np.ndarray]] = []  # the drive's first image: every other is of its size

    def frame(k: int) -> _Frame:
        if k not in cache:
            ref = dataset.frames[indices[k]]
            image = dataset.load(indices[k], right=False, label=False, disparity=False).left
            if not first:
                first.append((ref.left, image))
            if image.shape[:2] != first[0][1].shape[:2]:
                raise ShapeMismatchError(f"{ref.left} is {_size(image)} but {first[0][0]}, of the same drive "
                                         f"{ref.scenario}, is {_size(first[0][1])}; propagation carries labels "
                                         f"between the frames of one camera: give frames of one size")
            cache[k] = (image, frame_label(tree, ref.name, image, ref.left))
        return cache[k]

    rows = []
    for k, index in enumerate(indices):
        for old in [c for c in cache if c < k]:
            del cache[old]
        image, own = frame(k)
        name = dataset.frames[index].name
        if own is None:
            continue
        label, model, report, confidence = own
        sources = [(frame(s)[0], *frame(s)[1][:2], m) for s, m in source_frames(motions, k, options)
                   if frame(s)[1] is not None]
        new, change = propagate_frame(image, label, model, K, baseline, sources, options=options)
        row = {"frame": name, "sources": len(sources), "coverage_before": round(float(label.valid.mean()), 4),
               "coverage": round(float(new.valid.mean()), 4), "road_before": round(float(label.road.mean()), 4),
               "road_fraction": round(float(new.road.mean()), 4), "gained": round(float((change == 1).mean()), 4),
               "conflicts": round(float((change == 2).mean()), 4)}
        confidence = np.where(change == 1, 128, np.where(change == 2, 0, confidence)).astype(np.uint8)
        write_label_files(new, staging / f"{name}.png", confidence, confidence_path(staging, name),
                          {**report, "propagation": row}, staging / "reports" / f"{name}.json")
        rows.append(row)
    return rows


def propagate_dataset(dataset: StereoRoadDataset, labels: PathLike, out: PathLike, *,
                      options: PropagateOptions = PropagateOptions(), progress: bool = True) -> dict[str, Any]:
    """Carry the road that later frames of each drive saw near the car back into the autolabel tree ``labels``.

    Args:
        dataset: the drives (frames in time order within each scenario; disparities for the ego-motion).
        labels: the tree ``freespace autolabel`` wrote for ``dataset`` (single-frame labels and their reports).
        out: the new label tree: ``<frame>.png`` (KITTI colours), ``confidence/`` (propagated road 0.5, conflicts 0),
            ``reports/`` (each frame's report with its ``propagation`` row), ``report.csv``, ``summary.json`` and
            ``settings.json`` (the tree's, with ``propagation`` and ``source_labels``): written all or nothing.
        options: :class:`PropagateOptions`. progress: a progress bar on a terminal.

    Returns:
        The summary: frames, mean coverage and road fraction before and after, mean gained and conflict shares.
    """
    from freespace.runtime.log import progress_bar

    options.check()
    tree, out = Path(labels), Path(out)
    settings = read_tree_settings(tree, dataset)
    check_writable(out, folder=True)
    check_outputs({"out": out}, {"propagate_from": tree, "root": dataset.root})
    drives: dict[str, list[int]] = {}
    for i, f in enumerate(dataset.frames):
        drives.setdefault(f.scenario, []).append(i)
    t0, rows = time.perf_counter(), []
    with claim_folder(out, "autolabel") as folder, folder.staged() as staging:
        for scenario in progress_bar(sorted(drives), desc="propagate", unit="drive", enabled=progress):
            indices = sorted(drives[scenario], key=lambda i: dataset.frames[i].name)
            rows += _propagate_drive(dataset, indices, tree, staging, options)
            log.info("propagated %s: %d frames", scenario, len(drives[scenario]))
        if not rows:
            raise DatasetError(f"{param('propagate_from')} {tree} labels none of the frames of {dataset.root}")
        summary = {"frames": len(rows), "seconds": round(time.perf_counter() - t0, 1),
                   **{f"mean_{k}": round(float(np.mean([r[k] for r in rows])), 4)
                      for k in ("coverage_before", "coverage", "road_before", "road_fraction", "gained", "conflicts")}}
        write_csv(staging / "report.csv", list(rows[0]), rows)
        write_json(staging / "summary.json", summary)
        write_json(staging / "settings.json", {**settings, "propagation": options.to_dict(),
                                               "source_labels": str(tree.resolve())})
    return summary
