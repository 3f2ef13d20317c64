"""One reference image and its road label seen from a virtual camera pose, from files
(``freespace generate --shift/--rotate``): :func:`generate_virtual_pair`.

The road plane comes from a road fit (the DS-Generator's, :mod:`freespace.datagen.generate`) or from the
calibration; the view itself is :func:`freespace.geometry.virtual_view`. It imports NumPy and OpenCV only
(never torch), reads and checks every input before it writes anything, and writes every output atomically.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from freespace.datagen.generate import FitOptions, check_output_image_path, road_to_fit
from freespace.errors import CorruptFileError, InvalidOptionError, ShapeMismatchError, param
from freespace.geometry import (
    RoadModel,
    RoadPlane,
    StereoCalibration,
    VirtualPose,
    fit_road_model,
    virtual_homography,
    virtual_view,
)
from freespace.io.codecs import (
    OUTPUT_IMAGE_SUFFIXES,
    encode_image,
    read_disparity,
    read_image,
    read_road_label,
    road_label_to_kitti,
)
from freespace.io.files import PathLike, check_outputs, check_writable_files, encode_json, write_files_together
from freespace.io.kitti import read_kitti_calib
from freespace.labels import RoadLabel

__all__ = ["VirtualResult", "generate_virtual_pair"]


def _size(shape: tuple[int, ...]) -> str:
    return f"{shape[1]}×{shape[0]}"


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
    lossless = tuple(x for x in OUTPUT_IMAGE_SUFFIXES if x not in (".jpg", ".jpeg"))
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
