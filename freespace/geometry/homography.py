"""Plane-induced homographies and the stereo road model from calibration.

Conventions
-----------
Pixels are 0-based, ``u`` right, ``v`` down. Camera frames are right-handed with x right, y down,
z forward. ``R_tr, t_tr`` map reference-camera coordinates to target-camera coordinates:
``X_t = R_tr X_r + t_tr``. The road is the plane ``{X : nᵀ X + D = 0}`` in the reference frame, with
``n`` the unit normal pointing from the road towards the camera (≈ (0, −1, 0) for a level rig) and
``D > 0`` the distance from the reference camera centre to the road. Homographies map homogeneous
reference pixels to target pixels (``H_tr``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from freespace.errors import InvalidOptionError
from freespace.geometry.road_model import RoadModel

__all__ = ["homography_from_pose", "StereoCalibration"]


def _as_matrix(x: np.ndarray, shape: tuple[int, ...], name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != shape or not np.isfinite(arr).all():
        raise InvalidOptionError(f"{name} must be a finite array of shape {shape}, got shape {arr.shape}")
    return arr


def homography_from_pose(K_r: np.ndarray, K_t: np.ndarray, R_tr: np.ndarray, t_tr: np.ndarray,
                         n: np.ndarray, D: float) -> np.ndarray:
    """The homography induced by the road plane between two views (the paper's eq. H1).

    ``H_tr = K_t (R_tr − t_tr nᵀ / D) K_r⁻¹``, normalised so that ``H[2, 2] = 1`` when possible.

    Args:
        K_r, K_t: 3×3 intrinsics of the reference and target cameras.
        R_tr: 3×3 rotation, t_tr: 3-vector (metres): ``X_t = R_tr X_r + t_tr``.
        n: 3-vector, road normal in the reference frame pointing towards the camera (normalised here).
        D: distance in metres from the reference camera centre to the road plane ``nᵀX + D = 0``.

    Returns:
        ``H_tr`` (3×3 float64) mapping homogeneous reference pixels to target pixels of road points.
    """
    K_r = _as_matrix(K_r, (3, 3), "K_r")
    K_t = _as_matrix(K_t, (3, 3), "K_t")
    R_tr = _as_matrix(R_tr, (3, 3), "R_tr")
    t_tr = _as_matrix(np.ravel(t_tr), (3,), "t_tr")
    n = _as_matrix(np.ravel(n), (3,), "n")
    norm = float(np.linalg.norm(n))
    if norm == 0 or not (math.isfinite(D) and D > 0):
        raise InvalidOptionError(f"the road normal must be non-zero and the distance D > 0 (got |n| = {norm}, "
                                 f"D = {D})")
    n = n / norm
    H = K_t @ (R_tr - np.outer(t_tr, n) / D) @ np.linalg.inv(K_r)
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 else H


@dataclass(frozen=True)
class StereoCalibration:
    """A rectified stereo rig (reference = left camera) and, optionally, its road plane.

    Attributes:
        fx, fy: focal lengths in pixels. cx, cy: principal point in pixels (0-based).
        baseline: distance between the camera centres in metres (> 0, target to the right; 0 for a
            monocular camera, which has no disparity).
        road_normal: unit road normal in the reference frame pointing to the camera, or None.
        road_distance: reference camera centre to road plane in metres, or None.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    baseline: float
    road_normal: tuple[float, float, float] | None = None
    road_distance: float | None = None

    @property
    def K(self) -> np.ndarray:
        """3×3 intrinsic matrix of both (rectified) cameras."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_kitti(cls, calib: dict[str, np.ndarray], left: str = "P2", right: str = "P3") -> StereoCalibration:
        """Build from a parsed KITTI calibration (:func:`freespace.io.kitti.read_kitti_calib`).

        Focal length and principal point come from ``P2``; the baseline from the difference of the
        4th columns of ``P2`` and ``P3``. When ``Tr_cam_to_road`` (camera 0 → road frame, applied before ``R0_rect`` as in the devkit,
        road plane ``Y = 0``) is present, the road plane is moved into the ``P2`` camera's frame.
        """
        P_l, P_r = calib[left], calib[right]
        fx, fy, cx, cy = P_l[0, 0], P_l[1, 1], P_l[0, 2], P_l[1, 2]
        K = P_l[:, :3]
        # camera centre offsets relative to rectified camera 0: P = K [I | t]
        t_l = np.linalg.solve(K, P_l[:, 3])
        t_r = np.linalg.solve(K, P_r[:, 3])
        baseline = float(t_l[0] - t_r[0])
        if not baseline > 0:
            raise InvalidOptionError(f"calibration gives a baseline of {baseline:.4g} m between {left} and {right}; "
                                     f"the reference must be the left camera")
        normal = distance = None
        if "Tr_cam_to_road" in calib:
            R0 = calib.get("R0_rect", calib.get("R_rect", np.eye(3)))
            tr = np.asarray(calib["Tr_cam_to_road"])
            # Tr_cam_to_road maps unrectified camera-0 coordinates X0 to the road frame (road: Y = 0);
            # rectified X_rect = R0 X0, so road Y = (R0 row)·X_rect + offset.
            row = R0 @ tr[1, :3]
            offset = float(tr[1, 3])
            s = float(np.linalg.norm(row))
            n0, d0 = -row / s, -offset / s  # nᵀX_rect + d0 = 0 with n pointing up, towards the camera
            # left camera frame: X_2 = X_rect + t_l, so nᵀ(X_2 − t_l) + d0 = 0
            distance = d0 - float(n0 @ t_l)
            normal = tuple(float(x) for x in n0)
        return cls(fx=float(fx), fy=float(fy), cx=float(cx), cy=float(cy), baseline=baseline,
                   road_normal=normal, road_distance=distance)

    def road_model(self) -> RoadModel:
        """The road disparity model this calibration predicts (needs ``road_normal`` and ``road_distance``).

        A road point satisfies ``nᵀX + D = 0`` with ``X = Z K⁻¹ p̃``, so ``d = fx B / Z =
        −(fx B / D) nᵀ K⁻¹ p̃``, an affine function of (u, v).
        """
        if self.road_normal is None or self.road_distance is None:
            raise InvalidOptionError("this calibration has no road plane; give road_normal and road_distance")
        n = np.asarray(self.road_normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        scale = -self.fx * self.baseline / self.road_distance
        a = scale * n[0] / self.fx
        b = scale * n[1] / self.fy
        c = scale * (n[2] - n[0] * self.cx / self.fx - n[1] * self.cy / self.fy)
        return RoadModel.from_affine(a, b, c)

    def homography(self) -> np.ndarray:
        """The road homography ``H_tr`` from the pose: left → right camera, ``t_tr = (−B, 0, 0)``."""
        if self.road_normal is None or self.road_distance is None:
            raise InvalidOptionError("this calibration has no road plane; give road_normal and road_distance")
        return homography_from_pose(self.K, self.K, np.eye(3), np.array([-self.baseline, 0.0, 0.0]),
                                    np.asarray(self.road_normal), self.road_distance)
