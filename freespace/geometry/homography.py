"""Plane-induced homographies and the stereo road model from calibration.

Conventions
-----------
Pixels are 0-based, ``u`` right, ``v`` down. Camera frames are right-handed with x right, y down,
z forward. ``R_tr, t_tr`` map reference-camera coordinates to target-camera coordinates:
``X_t = R_tr X_r + t_tr``. The road is a :class:`~freespace.geometry.plane.RoadPlane`, ``{X : n·X = h}``
in the reference frame, with ``n`` the unit normal pointing from the camera down to the road (≈ (0, 1, 0)
for a level rig) and ``h > 0`` the reference camera centre's height above it. Homographies map
homogeneous reference pixels to target pixels (``H_tr``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from freespace.errors import InvalidOptionError
from freespace.geometry.plane import RoadPlane
from freespace.geometry.road_model import RoadModel

__all__ = ["homography_from_pose", "StereoCalibration"]


def _as_matrix(x: np.ndarray, shape: tuple[int, ...], name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.shape != shape or not np.isfinite(arr).all():
        raise InvalidOptionError(f"{name} must be a finite array of shape {shape}, got shape {arr.shape}")
    return arr


def homography_from_pose(K_r: np.ndarray, K_t: np.ndarray, R_tr: np.ndarray, t_tr: np.ndarray,
                         plane: RoadPlane) -> np.ndarray:
    """The homography induced by the road plane between two views (the paper's eq. H1).

    ``H_tr = K_t (R_tr + t_tr nᵀ / h) K_r⁻¹`` for the plane ``n·X = h`` (the paper writes it
    ``K_t (R_tr − t_tr n'ᵀ / D) K_r⁻¹`` with ``n' = −n`` pointing to the camera and ``D = h``), normalised so
    that ``H[2, 2] = 1`` when possible.

    Args:
        K_r, K_t: 3×3 intrinsics of the reference and target cameras.
        R_tr: 3×3 rotation, t_tr: 3-vector (metres): ``X_t = R_tr X_r + t_tr``.
        plane: the road plane in the reference frame (unit ``n`` towards the road, ``h > 0`` metres).

    Returns:
        ``H_tr`` (3×3 float64) mapping homogeneous reference pixels to target pixels of road points.

    Example:
        A level camera 1.5 m up, B = 0.5 m: 150 rows below the horizon, d = 50.

        >>> K = np.array([[700.0, 0, 600], [0, 700, 180], [0, 0, 1]])
        >>> H = homography_from_pose(K, K, np.eye(3), [-0.5, 0, 0], RoadPlane((0, 1, 0), 1.5))
        >>> (H @ [600, 330, 1]).round(6).tolist()
        [550.0, 330.0, 1.0]
    """
    K_r = _as_matrix(K_r, (3, 3), "K_r")
    K_t = _as_matrix(K_t, (3, 3), "K_t")
    R_tr = _as_matrix(R_tr, (3, 3), "R_tr")
    t_tr = _as_matrix(np.ravel(t_tr), (3,), "t_tr")
    H = K_t @ (R_tr + np.outer(t_tr, plane.n) / plane.height) @ np.linalg.inv(K_r)
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 else H


@dataclass(frozen=True)
class StereoCalibration:
    """A rectified stereo rig (reference = left camera) and, optionally, its road plane.

    Attributes:
        fx, fy: focal lengths in pixels. cx, cy: principal point in pixels (0-based).
        baseline: distance between the camera centres in metres (> 0, target to the right; 0 for a
            monocular camera, which has no disparity).
        road_plane: the road plane in the reference (left) camera's frame, or None.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    baseline: float
    road_plane: RoadPlane | None = None

    @property
    def K(self) -> np.ndarray:
        """3×3 intrinsic matrix of both (rectified) cameras."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_kitti(cls, calib: dict[str, np.ndarray], left: str = "P2", right: str = "P3") -> StereoCalibration:
        """Build from a parsed KITTI calibration (:func:`freespace.io.kitti.read_kitti_calib`).

        Focal length and principal point come from ``P2``; the baseline from the difference of the
        4th columns of ``P2`` and ``P3``. When ``Tr_cam_to_road`` (camera 0 → road frame, applied before
        ``R0_rect`` as in the devkit, road plane ``Y = 0``) is present, the road plane is moved into the ``P2``
        camera's frame; its normal is the one pointing from the camera to the road, whichever way the road frame's Y
        points.

        Raises:
            InvalidOptionError: ``P3`` is not to the right of ``P2``, or ``Tr_cam_to_road`` puts the
                camera on the road plane.

        Example:
            >>> P2 = np.array([[700.0, 0, 600, 0], [0, 700, 180, 0], [0, 0, 1, 0]])
            >>> P3 = P2 - [[0, 0, 0, 350.0], [0, 0, 0, 0], [0, 0, 0, 0]]  # P3 = K [I | −B·e₁] with B = 0.5 m
            >>> StereoCalibration.from_kitti({"P2": P2, "P3": P3})
            StereoCalibration(fx=700.0, fy=700.0, cx=600.0, cy=180.0, baseline=0.5, road_plane=None)
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
        plane = None
        if "Tr_cam_to_road" in calib:
            R0 = calib.get("R0_rect", calib.get("R_rect", np.eye(3)))
            tr = np.asarray(calib["Tr_cam_to_road"])
            # Tr_cam_to_road maps unrectified camera-0 coordinates X0 to the road frame (road: Y = 0);
            # rectified X_rect = R0 X0, so road Y = (R0 row)·X_rect + offset.
            row = R0 @ tr[1, :3]
            offset = float(tr[1, 3])
            s = float(np.linalg.norm(row))
            n, h0 = row / s, -offset / s  # n·X_rect = h0
            # left camera frame: X_2 = X_rect + t_l, so n·X_2 = h0 + n·t_l
            height = h0 + float(n @ t_l)
            if abs(height) < 1e-9:  # metres
                raise InvalidOptionError(f"Tr_cam_to_road puts the {left} camera on the road plane; give the "
                                         f"calibration's real road transform or leave the Tr_cam_to_road line out")
            # n towards the road: the camera is on the side of the plane the normal points away from
            plane = RoadPlane(tuple(float(x) for x in n), height) if height > 0 else \
                RoadPlane(tuple(-float(x) for x in n), -height)  # type: ignore[arg-type]
        return cls(fx=float(fx), fy=float(fy), cx=float(cx), cy=float(cy), baseline=baseline, road_plane=plane)

    def road_model(self) -> RoadModel:
        """The road disparity model this calibration predicts (needs ``road_plane``).

        A road point satisfies ``n·X = h`` with ``X = Z K⁻¹ p̃``, so ``d = fx B / Z =
        (fx B / h) nᵀ K⁻¹ p̃``, an affine function of (u, v).

        Example:
            >>> rig = StereoCalibration(700.0, 700.0, 600.0, 180.0, 0.5, RoadPlane((0, 1, 0), 1.5))
            >>> [round(x, 6) for x in rig.road_model().affine]  # d = (v − 180) / 3: zero on the horizon's row
            [0.0, 0.333333, -60.0]
        """
        if self.road_plane is None:
            raise InvalidOptionError("this calibration has no road plane; give road_plane")
        n = self.road_plane.n
        scale = self.fx * self.baseline / self.road_plane.height
        a = scale * n[0] / self.fx
        b = scale * n[1] / self.fy
        c = scale * (n[2] - n[0] * self.cx / self.fx - n[1] * self.cy / self.fy)
        return RoadModel.from_affine(a, b, c)

    def homography(self) -> np.ndarray:
        """The road homography ``H_tr`` from the pose: left → right camera, ``t_tr = (−B, 0, 0)``.

        Example:
            >>> rig = StereoCalibration(700.0, 700.0, 600.0, 180.0, 0.5, RoadPlane((0, 1, 0), 1.5))
            >>> rig.homography().round(6).tolist()  # the road model's [[1 − a, −b, −c], [0, 1, 0], [0, 0, 1]]
            [[1.0, -0.333333, 60.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        """
        if self.road_plane is None:
            raise InvalidOptionError("this calibration has no road plane; give road_plane")
        return homography_from_pose(self.K, self.K, np.eye(3), np.array([-self.baseline, 0.0, 0.0]), self.road_plane)
