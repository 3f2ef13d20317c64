"""Plane-induced homographies and the stereo road model from calibration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from freespace.errors import InvalidOptionError
from freespace.geometry import RoadModel, RoadPlane, StereoCalibration, homography_from_pose
from freespace.io.kitti import read_kitti_calib

from helpers import shared_path


def _rot(rx: float, ry: float, rz: float) -> np.ndarray:
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _project(K: np.ndarray, X: np.ndarray) -> np.ndarray:
    p = (K @ X.T).T
    return p[:, :2] / p[:, 2:]


def _road_points(n: np.ndarray, D: float, count: int = 200, seed: int = 0) -> np.ndarray:
    """Random 3D points of the plane nᵀX + D = 0 in front of the camera (z 5…40 m)."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-8, 8, count)
    z = rng.uniform(5, 40, count)
    y = -(D + n[0] * x + n[2] * z) / n[1]
    return np.stack([x, y, z], axis=1)


def test_general_pose_maps_road_points() -> None:
    K_r = np.array([[700.0, 0, 620], [0, 705.0, 180], [0, 0, 1]])
    K_t = np.array([[690.0, 0, 600], [0, 690.0, 190], [0, 0, 1]])
    R = _rot(0.02, -0.05, 0.01)
    t = np.array([-0.5, 0.03, 0.2])
    n = np.array([0.02, -0.99, 0.05])
    n = n / np.linalg.norm(n)
    D = 1.6
    X = _road_points(n, D)
    H = homography_from_pose(K_r, K_t, R, t, RoadPlane(tuple(-n), D))  # n·X = h with n towards the road
    p_r = _project(K_r, X)
    p_t = _project(K_t, (R @ X.T).T + t)
    q = (H @ np.c_[p_r, np.ones(len(p_r))].T).T
    np.testing.assert_allclose(q[:, :2] / q[:, 2:], p_t, atol=1e-8)


def test_stereo_road_model_from_calibration() -> None:
    roll = math.radians(2.0)
    n = _rot(0.03, 0.0, roll) @ np.array([0.0, -1.0, 0.0])
    calib = StereoCalibration(fx=720.0, fy=720.0, cx=610.0, cy=175.0, baseline=0.54,
                              road_plane=RoadPlane(tuple(-n), 1.65))
    model = calib.road_model()
    # the model's disparity equals f·B/Z at the projections of road points
    X = _road_points(n, 1.65)
    p = _project(calib.K, X)
    a, b, c = model.affine
    np.testing.assert_allclose(a * p[:, 0] + b * p[:, 1] + c, 720.0 * 0.54 / X[:, 2], rtol=1e-9)
    # the pose homography (left → right, t = (−B, 0, 0)) is the model's affine homography
    np.testing.assert_allclose(calib.homography(), model.homography, atol=1e-9)
    # rolling the rig by Φ about the optical axis rolls the disparity plane by Φ
    assert model.roll_deg == pytest.approx(2.0, abs=1e-9)


def test_kitti_calibration_parsed() -> None:
    calib = StereoCalibration.from_kitti(read_kitti_calib(shared_path("kitti_road_calib", "um_000000.txt")))
    assert calib.fx == pytest.approx(721.5377)
    assert calib.baseline == pytest.approx(0.5327, abs=1e-3)  # (P2[0,3] − P3[0,3]) / fx
    assert 1.5 < calib.road_plane.height < 1.8  # camera height above the road
    assert calib.road_plane.normal[1] > 0.99  # pointing down, to the road
    model = calib.road_model()
    assert abs(model.roll_deg) < 1.0
    # the KITTI road horizon: disparity 0 near the principal row, ~0.33 px per row below
    assert model.kappa_hat == pytest.approx(calib.baseline / calib.road_plane.height, rel=0.02)


@pytest.mark.parametrize("name", ["um_000000", "umm_000000", "uu_000000", "uu_000001"])
def test_kitti_road_plane_consistent_with_devkit_transform(name: str) -> None:
    """Road points made with the devkit's Tr = P2·R0·inv(Tr_cam_to_road) land on our road model."""
    raw = read_kitti_calib(shared_path("kitti_road_calib", f"{name}.txt"))
    calib = StereoCalibration.from_kitti(raw)
    R0 = np.eye(4)
    R0[:3, :3] = raw["R0_rect"]
    T = np.eye(4)
    T[:3] = raw["Tr_cam_to_road"]
    rng = np.random.default_rng(0)
    road = np.stack([rng.uniform(-10, 10, 50), np.zeros(50), rng.uniform(6, 46, 50), np.ones(50)])
    cam = R0 @ np.linalg.inv(T) @ road  # rectified camera-0 coordinates
    a, b, c = calib.road_model().affine
    p2 = raw["P2"] @ cam
    u2, v2 = p2[0] / p2[2], p2[1] / p2[2]
    # an ideal rectified right camera: P2 shifted by the baseline along x only
    P3 = raw["P2"].copy()
    P3[0, 3] -= calib.fx * calib.baseline
    p3 = P3 @ cam
    np.testing.assert_allclose(a * u2 + b * v2 + c, u2 - p3[0] / p3[2], atol=1e-6)
    # the real P3 also has mm-scale y/z offsets (2011-10-03 rig: 3.5 mm, 1.1 mm): < 0.2 px of disparity
    p3 = raw["P3"] @ cam
    np.testing.assert_allclose(a * u2 + b * v2 + c, u2 - p3[0] / p3[2], atol=0.2)


def test_bad_pose_arguments() -> None:
    K = np.eye(3)
    with pytest.raises(InvalidOptionError, match="shape"):
        homography_from_pose(np.eye(2), K, np.eye(3), np.zeros(3), RoadPlane((0, 1, 0), 1.0))
    with pytest.raises(InvalidOptionError, match="height > 0"):
        homography_from_pose(K, K, np.eye(3), np.zeros(3), RoadPlane((0, 1, 0), 0.0))
    with pytest.raises(InvalidOptionError, match="no road plane"):
        StereoCalibration(fx=1, fy=1, cx=0, cy=0, baseline=1).road_model()
    assert isinstance(StereoCalibration(1, 1, 0, 0, 1, RoadPlane((0, 1, 0), 1.0)).road_model(), RoadModel)


def test_kitti_road_frame_either_way_up_gives_one_plane() -> None:
    """The calibration's plane always has n pointing from the camera to the road: a road frame whose Y points
    up (Tr_cam_to_road's Y row negated) describes the same plane, and a camera on the plane is refused."""
    raw = read_kitti_calib(shared_path("kitti_road_calib", "um_000000.txt"))
    plane = StereoCalibration.from_kitti(raw).road_plane
    flipped = dict(raw, Tr_cam_to_road=raw["Tr_cam_to_road"] * np.array([[1.0], [-1.0], [1.0]]))
    same = StereoCalibration.from_kitti(flipped).road_plane
    assert same is not None and same.normal == plane.normal and same.height == plane.height
    assert plane.normal[1] > 0.99 and 1.5 < plane.height < 1.8
    on_road = raw["Tr_cam_to_road"].copy()
    t_l = np.linalg.solve(raw["P2"][:, :3], raw["P2"][:, 3])  # the P2 camera's centre is −t_l (rectified)
    on_road[1, 3] = float((raw["R0_rect"] @ on_road[1, :3]) @ t_l)  # road Y = 0 through that centre
    with pytest.raises(InvalidOptionError, match="on the road plane"):
        StereoCalibration.from_kitti(dict(raw, Tr_cam_to_road=on_road))
