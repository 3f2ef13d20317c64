"""Disparity from depth: ``d = f·B / Z``, with f and B from a KITTI calibration or a virtual baseline.

Conventions
-----------
Depth ``Z`` is the distance in metres along the reference (left) camera's optical axis — not the
distance along the ray. Disparity is in pixels of the rectified reference image, ``float32 H×W``, NaN
for "no value"; ``d = fx · B / Z`` with ``fx`` the focal length in pixels and ``B`` the baseline in
metres (target camera ``B`` metres to the right of the reference one).

RGB-D data and virtual baselines
--------------------------------
A depth camera (or LiDAR) without a second camera has no baseline: choose one, a *virtual* right camera
``B`` metres to the right (default :data:`DEFAULT_VIRTUAL_BASELINE_M`, KITTI's 0.54 m). The road fit on
``f·B/Z`` then gives:

* the roll Φ and κ independent of ``B`` (scaling every disparity by a factor scales a and b of the
  plane ``d = a·u + b·v + c`` together, and Φ = atan2(−a, b), κ = c/ϰ);
* ϰ, the affine coefficients and the road homography ``H_tr`` those of the *virtual* right camera:
  ``H_tr`` maps left pixels to where that camera would see the road. A DS-Generator view needs a real
  target image, so with RGB-D data the fitted model serves the road geometry, virtual views of a
  chosen pose, and disparity-based training inputs, not the warp of a right image that does not exist.

Only NumPy is imported here; never torch. Depth files are read by :func:`freespace.io.codecs.read_depth`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace

import numpy as np

from freespace.errors import CorruptFileError, InvalidOptionError
from freespace.geometry.homography import StereoCalibration

__all__ = [
    "DEFAULT_VIRTUAL_BASELINE_M",
    "depth_to_disparity",
    "rig_from_kitti",
]

log = logging.getLogger(__name__)

DEFAULT_VIRTUAL_BASELINE_M = 0.54
"""Baseline (metres) of the virtual right camera when a calibration has none: KITTI's stereo rig."""


def _check_rig(focal_px: float, baseline_m: float) -> None:
    if not (math.isfinite(focal_px) and focal_px > 0):
        raise InvalidOptionError(f"the focal length must be a positive number of pixels, got {focal_px}")
    if not (math.isfinite(baseline_m) and baseline_m > 0):
        raise InvalidOptionError(f"the baseline must be a positive number of metres, got {baseline_m}")


def depth_to_disparity(depth_m: np.ndarray, focal_px: float, baseline_m: float) -> np.ndarray:
    """Disparity ``d = f·B / Z`` from depth.

    Args:
        depth_m: ``H×W`` depth ``Z`` in metres along the optical axis (any float or integer dtype).
        focal_px: focal length ``fx`` in pixels (> 0).
        baseline_m: baseline ``B`` in metres (> 0), real or virtual.

    Returns:
        ``float32 H×W`` disparity in pixels; NaN where the depth is ≤ 0, NaN or inf.

    Raises:
        InvalidOptionError: a non-positive or non-finite focal length or baseline.

    Example:
        >>> depth_to_disparity(np.array([[10.0, 0.0]]), 700.0, 0.5)
        array([[35., nan]], dtype=float32)
    """
    _check_rig(focal_px, baseline_m)
    depth = np.asarray(depth_m, dtype=np.float64)
    out = np.full(depth.shape, np.nan, np.float32)
    ok = np.isfinite(depth) & (depth > 0)
    out[ok] = (focal_px * baseline_m / depth[ok]).astype(np.float32)
    return out


def rig_from_kitti(calib: dict[str, np.ndarray], *, baseline: float | None = None, left: str = "P2",
                   right: str = "P3") -> StereoCalibration:
    """The stereo rig of a parsed KITTI calibration (:func:`freespace.io.kitti.read_kitti_calib`), with a
    virtual right camera when needed.

    * ``baseline`` None and ``right`` (P3) present: the real rig, as
      :meth:`StereoCalibration.from_kitti` (f = P2[0, 0], B from the 4th columns of P2 and P3).
    * ``baseline`` given: a virtual right camera ``baseline`` metres to the right of ``left`` (P3, if
      any, is ignored).
    * neither: a virtual right camera at :data:`DEFAULT_VIRTUAL_BASELINE_M` (logged).

    The road plane (``Tr_cam_to_road``) is kept when the file has one. See the module docstring for
    what a virtual baseline means for the fitted road model.

    Raises:
        CorruptFileError: no ``left`` projection matrix. InvalidOptionError: a baseline ≤ 0, or P3 left
        of P2.

    Example:
        >>> P2 = np.array([[700.0, 0, 600, 0], [0, 700, 180, 0], [0, 0, 1, 0]])
        >>> rig = rig_from_kitti({"P2": P2}, baseline=0.5)  # no P3 needed: a virtual right camera 0.5 m to the right
        >>> rig.fx, rig.baseline, rig.road_plane is None
        (700.0, 0.5, True)
    """
    if left not in calib:
        raise CorruptFileError(f"the calibration has no {left} (3×4 projection of the reference camera)")
    if baseline is None and right not in calib:
        baseline = DEFAULT_VIRTUAL_BASELINE_M
        log.info("calibration has no %s: using a virtual right camera %.2f m to the right", right, baseline)
    if baseline is not None:
        P = np.asarray(calib[left], np.float64)
        _check_rig(float(P[0, 0]), float(baseline))
        virtual = P.copy()
        virtual[0, 3] -= P[0, 0] * baseline  # P = K [I | t]: the camera centre moved by +B along x
        rig = StereoCalibration.from_kitti({**calib, right: virtual}, left=left, right=right)
        return replace(rig, baseline=float(baseline))  # exactly the chosen value, not a round trip through P
    return StereoCalibration.from_kitti(calib, left=left, right=right)
