"""Disparity from KITTI Velodyne scans, made here from the renderer's exact depth.

Every sampled pixel of a rendered frame is back-projected with its exact depth, moved into the
Velodyne frame through the inverse of P2's camera offset, R0_rect and Tr_velo_to_cam (KITTI-like,
non-trivial matrices, composed so the left camera stays the rendered one), written as a ``.bin`` scan,
read and projected back. Hidden points (farther along a sampled ray), points behind the camera and
points outside the image are added to check that only the nearest visible point lands.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.data.synthetic import SynthConfig, format_kitti_calib, render_sample
from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError
from freespace.geometry import fit_road_model
from freespace.geometry.lidar import (
    densify_nearest,
    project_velodyne,
    velodyne_to_disparity,
)
from freespace.io.kitti import read_kitti_calib, read_velodyne

from helpers import disparity_from_depth_file, write_velodyne

# a real KITTI R0_rect (rotation of about 0.7°) and camera-2 offset (P2 = K [I | t2])
R0_RECT = np.array([[0.9999239, 0.00983776, -0.007445048], [-0.009869795, 0.9999421, -0.004278459],
                    [0.007402527, 0.004351614, 0.9999631]])
T2 = np.array([0.06, -0.0003, 0.0027])


def _orthonormal(R: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(R)
    return u @ vt


def _h(M: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[: M.shape[0], : M.shape[1]] = M
    return out


@pytest.fixture(scope="module")
def scene():
    sample = render_sample(3, seed=5, config=SynthConfig(width=320, height=240))
    rig = sample.calibration
    K = rig.K
    R0 = _orthonormal(R0_RECT)
    calib = {
        "P2": K @ np.hstack([np.eye(3), T2[:, None]]),
        "P3": K @ np.hstack([np.eye(3), (T2 - [rig.baseline, 0, 0])[:, None]]),
        "R0_rect": R0,
    }
    # camera-2 coordinates X2 = R0 · X0 + t2 must equal the rendered left camera's: Tr' = R0ᵀ·([I|−t2]·Tr)
    tr = (_h(np.linalg.inv(_h(R0))[:3]) @ _h(np.hstack([np.eye(3), -T2[:, None]]))
          @ _h(sample.kitti_calib["Tr_velo_to_cam"]))
    calib["Tr_velo_to_cam"] = tr[:3]
    return sample, calib


def _cam_points(sample, v: np.ndarray, u: np.ndarray, scale: float | np.ndarray = 1.0) -> np.ndarray:
    """Left-camera 3-D points of pixels (u, v) at their exact depth × scale (N×3, metres)."""
    rig = sample.calibration
    z = rig.fx * rig.baseline / sample.disparity[v, u].astype(np.float64) * scale
    return np.stack([(u - rig.cx) / rig.fx * z, (v - rig.cy) / rig.fy * z, z], axis=1)


def _to_velo(points_cam: np.ndarray, calib: dict) -> np.ndarray:
    cam_from_velo = _h(np.hstack([np.eye(3), T2[:, None]])) @ _h(calib["R0_rect"]) @ _h(calib["Tr_velo_to_cam"])
    pts = np.hstack([points_cam, np.ones((len(points_cam), 1))]) @ np.linalg.inv(cam_from_velo).T
    return pts[:, :3]


@pytest.fixture(scope="module")
def scan(scene, tmp_path_factory: pytest.TempPathFactory):
    sample, calib = scene
    h, w = sample.disparity.shape
    grid = np.zeros((h, w), bool)
    grid[::3, ::2] = True                                        # scan-line-like: every 3rd row, 2nd column
    sampled = grid & np.isfinite(sample.disparity)
    v, u = np.nonzero(sampled)
    seen = _cam_points(sample, v, u)
    rng = np.random.default_rng(0)
    pick = rng.choice(len(v), len(v) // 5, replace=False)
    hidden = _cam_points(sample, v[pick], u[pick], scale=rng.uniform(1.05, 3.0, len(pick)))   # same pixel, farther
    free_v, free_u = np.nonzero(~grid & np.isfinite(sample.disparity))
    pick = rng.choice(len(free_v), 500, replace=False)
    behind = -_cam_points(sample, free_v[pick], free_u[pick])    # Z < 0: mirrored through the camera centre
    outside = np.array([[-50.0, 1.0, 10.0], [60.0, 1.0, 10.0], [0.0, -40.0, 10.0], [0.0, 0.0, 0.05]])
    points = np.vstack([seen, hidden, behind, outside])
    points = points[rng.permutation(len(points))]                # the order must not matter
    velo = _to_velo(points, calib)
    path = write_velodyne(tmp_path_factory.mktemp("velodyne") / "frame.bin",
                          np.hstack([velo, rng.uniform(0, 1, (len(velo), 1))]))
    return path, sampled


def test_projected_disparity_equals_the_exact_one(scene, scan) -> None:
    sample, calib = scene
    path, sampled = scan
    points = read_velodyne(path)
    assert points.dtype == np.float32 and points.shape[1] == 4
    disparity = velodyne_to_disparity(points, calib, sample.disparity.shape)
    assert disparity.dtype == np.float32
    have = np.isfinite(disparity)
    np.testing.assert_array_equal(have, sampled)                 # no hidden, behind or outside point landed
    np.testing.assert_allclose(disparity[sampled], sample.disparity[sampled], rtol=2e-5, atol=1e-4)
    depth = project_velodyne(points, calib, sample.disparity.shape)
    np.testing.assert_array_equal(np.isfinite(depth), sampled)
    assert (depth[sampled] > 0).all()
    # the same through the files: a KITTI calibration text file and the .bin scan
    calib_file = path.parent / "calib.txt"
    calib_file.write_text(format_kitti_calib(calib))
    from_files = velodyne_to_disparity(read_velodyne(path), read_kitti_calib(calib_file), sample.disparity.shape)
    np.testing.assert_allclose(from_files, disparity, rtol=1e-6, equal_nan=True)


def test_road_from_depth_and_lidar_matches_exact_fit(scene, scan, tmp_path: Path) -> None:
    sample, calib = scene
    path, _ = scan
    road = sample.label.road
    exact = fit_road_model(sample.disparity, road)
    # depth as SNE-RoadSeg stores it: uint16 millimetres, 0 = none
    z = sample.calibration.fx * sample.calibration.baseline / sample.disparity.astype(np.float64)
    raw = np.where(np.isfinite(z), np.clip(np.rint(z * 1000), 1, 65534), 0).astype(np.uint16)
    ok, buf = cv2.imencode(".png", raw)
    (tmp_path / "depth_u16.png").write_bytes(buf.tobytes())
    from_depth, rig = disparity_from_depth_file(tmp_path / "depth_u16.png", calib)
    assert rig.baseline == pytest.approx(sample.calibration.baseline, rel=1e-9)
    from_depth_fit = fit_road_model(from_depth, road)
    lidar = velodyne_to_disparity(read_velodyne(path), calib, road.shape)
    lidar_fit = fit_road_model(lidar, road)
    assert lidar_fit.num_valid < 0.2 * exact.num_valid          # sparse: every 6th road pixel
    truth = sample.meta["roll_deg"]
    # measured: roll from depth 8e-5°, from LiDAR 1e-6° from the exact fit
    for fit in (from_depth_fit, lidar_fit):
        assert abs(fit.roll_deg - exact.roll_deg) < 0.05
        assert abs(fit.roll_deg - truth) < 0.05
        assert fit.kappa_hat == pytest.approx(exact.kappa_hat, rel=1e-3)
        diff = np.abs(fit.disparity(road.shape) - exact.disparity(road.shape))[road]
        assert diff.max() < 0.01


def test_densified_lidar(scene, scan) -> None:
    sample, calib = scene
    path, sampled = scan
    sparse = velodyne_to_disparity(read_velodyne(path), calib, sample.disparity.shape)
    dense = velodyne_to_disparity(read_velodyne(path), calib, sample.disparity.shape, densify_gap=2)
    np.testing.assert_array_equal(dense[sampled], sparse[sampled])      # measured values untouched
    seen = np.isfinite(sample.disparity)
    assert np.isfinite(dense[seen]).mean() > 0.99                       # gaps ≤ 2 px are closed
    road = sample.label.road
    fit = fit_road_model(dense, road)
    # nearest-neighbour copies are up to a row off: measured rms 0.69 px (sparse: 0), roll 0.001° off
    assert abs(fit.roll_deg - fit_road_model(sample.disparity, road).roll_deg) < 0.05


def test_densify_nearest_respects_the_gap() -> None:
    d = np.full((7, 9), np.nan, np.float32)
    d[1, 1], d[5, 7], d[3, 4] = 1, 2, 3
    out = densify_nearest(d, 2.0)
    assert out[1, 1] == 1 and out[5, 7] == 2 and out[3, 4] == 3
    assert out[1, 3] == 1 and out[3, 6] == 3 and out[3, 7] == 2      # nearest (2 vs √5, 2 vs 3)
    assert np.isnan(out[0, 3]) and np.isnan(out[6, 0])              # farther than 2 px from every value
    np.testing.assert_array_equal(np.isnan(densify_nearest(d, 0)), np.isnan(d))
    with pytest.raises(InvalidOptionError, match="gap"):
        densify_nearest(d, -1)


def test_velodyne_reader_errors(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="not found"):
        read_velodyne(tmp_path / "missing.bin")
    (tmp_path / "odd.bin").write_bytes(np.zeros(7, "<f4").tobytes())
    with pytest.raises(CorruptFileError, match="28 bytes; expected a non-empty multiple of 16"):
        read_velodyne(tmp_path / "odd.bin")
    (tmp_path / "empty.bin").write_bytes(b"")
    with pytest.raises(CorruptFileError, match="0 bytes"):
        read_velodyne(tmp_path / "empty.bin")
    (tmp_path / "nan.bin").write_bytes(np.array([[1, 2, 3, 0], [np.nan, 0, 0, 0]], "<f4").tobytes())
    with pytest.raises(CorruptFileError, match="1 points with NaN or inf"):
        read_velodyne(tmp_path / "nan.bin")
    pts = np.array([[1.5, -2.0, 0.25, 0.5]], np.float32)
    np.testing.assert_array_equal(read_velodyne(write_velodyne(tmp_path / "ok.bin", pts)), pts)


def test_projection_needs_tr_velo_to_cam(scene) -> None:
    sample, calib = scene
    no_tr = {k: v for k, v in calib.items() if k != "Tr_velo_to_cam"}
    with pytest.raises(CorruptFileError, match="no Tr_velo_to_cam"):
        project_velodyne(np.zeros((1, 4), np.float32), no_tr, (10, 10))
