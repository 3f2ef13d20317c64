"""Road labels that reach the whole road: carry what later frames of a drive saw near the car back into earlier ones.

A single frame's autolabel (:mod:`freespace.datagen.labeller`) is sure of the road only where the disparity is
good: near the car. Far lanes, the road beyond parked cars and across junctions stay don't care. A few seconds
later the car is there, and the same road lies near the camera, well labelled. This module carries those labels
back along the drive:

1. **Ego-motion** between consecutive frames (:func:`ego_motion`): ORB features of the earlier left image with a
   disparity (SGBM or LiDAR) are points in 3-D; their matches in the next left image give the camera's motion by
   PnP (RANSAC, then Levenberg–Marquardt on the inliers). Motions are chained along the drive.
2. **The road plane** of the earlier frame ``t`` (its autolabel's fitted road model,
   :meth:`~freespace.geometry.RoadPlane.from_road_model`) and the motion ``X_s = R X_t + t`` to a later frame ``s``
   give the plane-induced homography ``H_st = K (R + t nᵀ/h) K⁻¹`` (:func:`~freespace.geometry.homography_from_pose`):
   where a road pixel of ``t`` lies in ``s``.
3. **Votes** (:func:`propagate_frame`): each pixel of ``t`` below its horizon takes, from each source frame ``s``,
   the label ``s`` gives its image point — only where ``s`` is sure of it (labelled, within
   :attr:`PropagateOptions.near_depth` metres of ``s``'s camera) and where the two images agree there (the blurred
   grey levels differ by at most :attr:`PropagateOptions.max_grey_difference`: a car that stood on that road in
   ``t`` and has moved on by ``s`` is not taken for road).
4. **The label**: a don't-care pixel of ``t`` becomes road when at least one source says road and none says
   non-road; a labelled pixel keeps its label unless a source contradicts it and more sources contradict than
   agree — then it becomes don't care (a conflict is not resolved by guessing). Non-road votes never create
   non-road: they only veto.

Conventions: pixels 0-based (``u`` column, ``v`` row); camera frame x right, y down, z forward, metres;
``Motion`` maps points of the earlier camera into the later one. NumPy and OpenCV only, never torch.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from freespace.data.base import StereoRoadDataset
from freespace.data.label_tree import check_label_tree, confidence_path, write_label_files
from freespace.errors import CorruptFileError, DatasetError, InvalidOptionError, param
from freespace.geometry import RoadModel
from freespace.geometry.homography import homography_from_pose
from freespace.geometry.plane import RoadPlane
from freespace.io.codecs import read_image, read_road_label
from freespace.io.files import (
    PathLike,
    check_outputs,
    check_writable,
    write_csv,
    write_json,
)
from freespace.io.outdir import claim_folder
from freespace.labels import RoadLabel

log = logging.getLogger(__name__)

__all__ = ["PropagateOptions", "Motion", "ego_motion", "compose", "source_frames", "propagate_frame",
           "propagate_dataset"]


@dataclass(frozen=True)
class PropagateOptions:
    """Settings of the propagation (see the module docstring).

    Attributes:
        window: how many later frames may be sources (default 40: 4 s of KITTI's 10 Hz).
        min_travel, max_travel: metres the camera moved between ``t`` and a source (defaults 4 and 40): nearer
            sources add nothing, farther ones drift.
        sources: at most this many sources per frame, spread over the travel range (default 4).
        near_depth: metres; a source's label is taken only within this depth of its camera (default 20).
        max_grey_difference: grey levels (0–255, after a 5-pixel Gaussian blur) by which a pixel may differ from its
            image in the source (default 30).
        max_depth: metres; features farther than this do not enter the ego-motion (default 50).
        min_inliers: PnP inliers a motion needs to be trusted (default 40).
    """

    window: int = 40
    min_travel: float = 4.0
    max_travel: float = 40.0
    sources: int = 4
    near_depth: float = 20.0
    max_grey_difference: float = 30.0
    max_depth: float = 50.0
    min_inliers: int = 40

    def check(self) -> None:
        """Raise :class:`InvalidOptionError` (one line) for a value out of range."""
        if not 1 <= self.window <= 1000 or not 1 <= self.sources <= 32:
            raise InvalidOptionError(f"{param('window')} must be 1–1000 frames and {param('sources')} 1–32, got "
                                     f"{self.window} and {self.sources}")
        if not 0 <= self.min_travel < self.max_travel < math.inf:
            raise InvalidOptionError(f"the travel range must be 0 ≤ min < max metres, got {self.min_travel}–"
                                     f"{self.max_travel}")
        for name in ("near_depth", "max_grey_difference", "max_depth"):
            if not 0 < getattr(self, name) < math.inf:
                raise InvalidOptionError(f"{param(name)} must be a finite number > 0, got {getattr(self, name)}")
        if self.min_inliers < 6:
            raise InvalidOptionError(f"{param('min_inliers')} must be at least 6 (PnP), got {self.min_inliers}")

    def to_dict(self) -> dict[str, float]:
        """JSON-ready settings."""
        return asdict(self)


@dataclass(frozen=True)
class Motion:
    """A rigid motion of the camera: points of the earlier camera frame in the later one, ``X_s = R X_t + t``.

    Attributes:
        R: 3×3 rotation. t: 3-vector, metres. inliers: PnP inliers it rests on (0 for a composed motion).
    """

    R: np.ndarray
    t: np.ndarray
    inliers: int = 0

    @property
    def travel(self) -> float:
        """The distance the camera centre moved, metres."""
        return float(np.linalg.norm(self.R.T @ self.t))


def compose(first: Motion, then: Motion) -> Motion:
    """``then ∘ first``: the motion from ``first``'s earlier frame to ``then``'s later one (inliers: the fewer)."""
    return Motion(then.R @ first.R, then.R @ first.t + then.t, min(first.inliers, then.inliers))


def _grey(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image


def ego_motion(earlier: np.ndarray, later: np.ndarray, disparity: np.ndarray, K: np.ndarray, baseline: float, *,
               options: PropagateOptions = PropagateOptions(), features: int = 3000) -> Motion | None:
    """The camera's motion from the earlier left image to the later one, or None when it cannot be trusted.

    Args:
        earlier, later: ``H×W×3`` RGB (or ``H×W`` grey) ``uint8`` left images of one camera.
        disparity: ``float32 H×W`` disparity of ``earlier`` in pixels (NaN or ≤ 0: none; sparse LiDAR is enough).
        K: 3×3 intrinsics (pixels). baseline: metres (> 0), for the depth of a disparity.
        options: ``max_depth`` and ``min_inliers``. features: ORB features detected per image.

    Returns:
        ``Motion`` with ``X_later = R X_earlier + t`` (metres) and its PnP inlier count, or None with fewer than
        ``options.min_inliers`` inliers (a blank image, a stopped frame that matched nothing, a scene cut).
    """
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    orb = cv2.ORB_create(features)
    ga, gb = _grey(earlier), _grey(later)
    with np.errstate(invalid="ignore"):
        has_depth = np.isfinite(disparity) & (disparity >= fx * baseline / options.max_depth)
    kp_a, des_a = orb.detectAndCompute(ga, (cv2.dilate(has_depth.astype(np.uint8), np.ones((5, 5))) > 0)
                                       .astype(np.uint8) * 255)
    kp_b, des_b = orb.detectAndCompute(gb, None)
    if des_a is None or des_b is None or len(kp_a) < options.min_inliers:
        return None
    matches = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(des_a, des_b, k=2)
    good = [m[0] for m in matches if len(m) == 2 and m[0].distance < 0.8 * m[1].distance]
    obj, img = [], []
    for m in good:
        u, v = kp_a[m.queryIdx].pt
        d = _nearest_disparity(disparity, has_depth, u, v)
        if d is None:
            continue
        z = fx * baseline / d
        obj.append(((u - cx) * z / fx, (v - cy) * z / fy, z))
        img.append(kp_b[m.trainIdx].pt)
    if len(obj) < options.min_inliers:
        return None
    obj_a, img_b = np.asarray(obj, np.float64), np.asarray(img, np.float64)
    ok, rvec, tvec, inliers = cv2.solvePnPRansac(obj_a, img_b, K, None, iterationsCount=300, reprojectionError=2.0,
                                                 confidence=0.999, flags=cv2.SOLVEPNP_EPNP)
    if not ok or inliers is None or len(inliers) < options.min_inliers:
        return None
    idx = inliers.ravel()
    rvec, tvec = cv2.solvePnPRefineLM(obj_a[idx], img_b[idx], K, None, rvec, tvec)
    return Motion(cv2.Rodrigues(rvec)[0], tvec.ravel(), int(len(idx)))


def _nearest_disparity(disparity: np.ndarray, has: np.ndarray, u: float, v: float, radius: int = 2) -> float | None:
    """The disparity at (u, v), or the median of those within ``radius`` pixels (sparse LiDAR), or None."""
    h, w = disparity.shape
    c, r = int(round(u)), int(round(v))
    if 0 <= r < h and 0 <= c < w and has[r, c]:
        return float(disparity[r, c])
    r0, r1, c0, c1 = max(r - radius, 0), min(r + radius + 1, h), max(c - radius, 0), min(c + radius + 1, w)
    near = disparity[r0:r1, c0:c1][has[r0:r1, c0:c1]]
    return float(np.median(near)) if near.size else None


def source_frames(motions: list[Motion | None], t: int, options: PropagateOptions = PropagateOptions()
                  ) -> list[tuple[int, Motion]]:
    """The later frames that frame ``t`` takes labels from, with the motion from ``t`` to each.

    Args:
        motions: ``motions[i]`` from frame ``i`` to ``i + 1`` of one drive (None: not trusted — the chain stops).
        t: the frame.

    Returns:
        Up to ``options.sources`` pairs ``(s, motion)`` with ``t < s ≤ t + window`` and a travel within
        ``[min_travel, max_travel]``, spread evenly over the candidates (nearest and farthest included).
    """
    candidates, motion = [], None
    for s in range(t + 1, min(t + options.window, len(motions)) + 1):
        step = motions[s - 1]
        if step is None:
            break
        motion = step if motion is None else compose(motion, step)
        if motion.travel > options.max_travel:
            break
        if motion.travel >= options.min_travel:
            candidates.append((s, motion))
    if len(candidates) <= options.sources:
        return candidates
    picks = np.unique(np.round(np.linspace(0, len(candidates) - 1, options.sources)).astype(int))
    return [candidates[i] for i in picks]


def _blur(image: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(_grey(image).astype(np.float32), (5, 5), 0)


def propagate_frame(image: np.ndarray, label: RoadLabel, model: RoadModel, K: np.ndarray, baseline: float,
                    sources: list[tuple[np.ndarray, RoadLabel, RoadModel, Motion]], *,
                    options: PropagateOptions = PropagateOptions()) -> tuple[RoadLabel, np.ndarray]:
    """Frame ``t``'s label with the road its later frames saw (steps 2–4 of the module docstring).

    Args:
        image: ``H×W×3`` RGB ``uint8`` left image of ``t``. label: its own autolabel. model: its fitted road model.
        K: 3×3 intrinsics (pixels). baseline: metres.
        sources: per source frame ``s``: its left image, autolabel, road model, and the motion from ``t`` to ``s``.

    Returns:
        The new label and a ``uint8 H×W`` map of what changed: 0 unchanged, 1 don't care → road, 2 → don't care
        (a conflict).
    """
    h, w = label.shape
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    plane = RoadPlane.from_road_model(model, fx, baseline, cx, cy, fy)
    below_horizon = model.disparity((h, w)) > 0
    grey_t = _blur(image)
    road_votes = np.zeros((h, w), np.int16)
    other_votes = np.zeros((h, w), np.int16)
    near_disparity = fx * baseline / options.near_depth
    for src_image, src_label, src_model, motion in sources:
        H = homography_from_pose(K, K, motion.R, motion.t, plane)  # t's road pixels → s's pixels
        sure = src_label.valid & (src_model.disparity((h, w)) >= near_disparity)
        code = np.where(sure, np.where(src_label.road, 2, 1), 0).astype(np.uint8)
        flags = cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP
        code_t = cv2.warpPerspective(code, H, (w, h), flags=flags, borderValue=0)
        grey_s = cv2.warpPerspective(_blur(src_image), H, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                     borderValue=-1000.0)
        agree = (np.abs(grey_s - grey_t) <= options.max_grey_difference) & below_horizon
        road_votes += (code_t == 2) & agree
        other_votes += (code_t == 1) & agree
    road, valid = label.road.copy(), label.valid.copy()
    gained = ~label.valid & (road_votes > 0) & (other_votes == 0)
    against = np.where(label.road, other_votes, road_votes)
    support = np.where(label.road, road_votes, other_votes)
    conflict = label.valid & (against > 0) & (against > support)
    road[gained], valid[gained] = True, True
    road[conflict], valid[conflict] = False, False
    change = np.zeros((h, w), np.uint8)
    change[gained], change[conflict] = 1, 2
    return RoadLabel(road=road, valid=valid), change


# --- a whole dataset: an autolabel tree in, a propagated tree out ---------------------------------------------------


def _read_tree_settings(tree: Path, dataset: StereoRoadDataset) -> dict[str, Any]:
    """The settings of the autolabel tree ``tree``, checked to label ``dataset`` and not to be propagated already."""
    check_label_tree(tree, dataset.name, dataset.root, dataset.split, option="propagate_from")
    try:
        made = json.loads((tree / "settings.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        made = None
    if not isinstance(made, dict):
        raise DatasetError(f"{param('propagate_from')} {tree} has no readable settings.json, so it is no tree that "
                           f"`freespace autolabel` wrote; label the dataset first (`freespace autolabel --out TREE`)")
    if "propagation" in made:
        raise DatasetError(f"{param('propagate_from')} {tree} is already propagated; give the single-frame tree it "
                           f"was made from ({made.get('source_labels')})")
    return made


def _frame_label(tree: Path, name: str) -> tuple[RoadLabel, RoadModel, dict[str, Any]] | None:
    """A frame's autolabel, road model and report from ``tree``, or None when the tree has none for it."""
    label_path, report_path = tree / f"{name}.png", tree / "reports" / f"{name}.json"
    if not (label_path.is_file() and report_path.is_file()):
        return None
    try:
        report = json.loads(report_path.read_text())
        model = RoadModel.from_affine(*report["affine"])
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError):
        raise CorruptFileError(f"the report {report_path} of {param('propagate_from')} is unreadable; label the "
                               f"dataset again with `freespace autolabel`") from None
    return read_road_label(label_path), model, report


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
    """Propagate one drive's frames (``indices``, in time order) from ``tree`` into ``staging``; the rows."""
    motions, K, baseline = _drive_motions(dataset, indices, options)
    cache: dict[int, tuple[np.ndarray, tuple[RoadLabel, RoadModel, dict[str, Any]] | None]] = {}

    def frame(k: int) -> tuple[np.ndarray, tuple[RoadLabel, RoadModel, dict[str, Any]] | None]:
        if k not in cache:
            name = dataset.frames[indices[k]].name
            cache[k] = (dataset.load(indices[k], right=False, label=False, disparity=False).left,
                        _frame_label(tree, name))
        return cache[k]

    rows = []
    for k, index in enumerate(indices):
        for old in [c for c in cache if c < k]:
            del cache[old]
        image, own = frame(k)
        name = dataset.frames[index].name
        if own is None:
            continue
        label, model, report = own
        sources = [(frame(s)[0], *frame(s)[1][:2], m) for s, m in source_frames(motions, k, options)
                   if frame(s)[1] is not None]
        new, change = propagate_frame(image, label, model, K, baseline, sources, options=options)
        row = {"frame": name, "sources": len(sources), "coverage_before": round(float(label.valid.mean()), 4),
               "coverage": round(float(new.valid.mean()), 4), "road_before": round(float(label.road.mean()), 4),
               "road_fraction": round(float(new.road.mean()), 4), "gained": round(float((change == 1).mean()), 4),
               "conflicts": round(float((change == 2).mean()), 4)}
        confidence = read_image(confidence_path(tree, name), what="confidence") \
            if confidence_path(tree, name).is_file() else np.zeros(label.shape, np.uint8)
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
    settings = _read_tree_settings(tree, dataset)
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
