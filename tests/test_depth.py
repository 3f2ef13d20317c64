"""Disparity from depth: d = f·B/Z, the depth readers, the rig from a KITTI calibration (real or
virtual baseline), and road fits on three real KITTI road frames with LiDAR depth.

The real frames (../shared/data/kitti_road_depth, skipped when absent) have no road label: the road
regions are polygons drawn by hand on the images (lower central road, clear of cars, curbs and the
parked cars' shadows' edges).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, ShapeMismatchError
from freespace.evaluation.real_frames import KITTI_ROAD_POLYGONS
from freespace.geometry import fit_road_model
from freespace.geometry.depth import (
    DEFAULT_VIRTUAL_BASELINE_M,
    depth_to_disparity,
    rig_from_kitti,
)
from freespace.io.codecs import read_depth, write_disparity
from freespace.io.kitti import read_kitti_calib

from helpers import disparity_from_depth_file, shared_path

# --- d = f·B/Z ---------------------------------------------------------------------------------------


def test_depth_to_disparity_values_and_invalid() -> None:
    depth = np.array([[10.0, 20.0, 0.0], [-1.0, np.nan, np.inf]])
    d = depth_to_disparity(depth, 721.5377, 0.54)
    assert d.dtype == np.float32 and d.shape == (2, 3)
    assert d[0, 0] == pytest.approx(721.5377 * 0.54 / 10, rel=1e-6)
    assert d[0, 1] == pytest.approx(721.5377 * 0.54 / 20, rel=1e-6)
    assert np.isnan(d[0, 2]) and np.isnan(d[1]).all()


@pytest.mark.parametrize("focal, baseline", [(0.0, 0.5), (-700.0, 0.5), (700.0, 0.0), (700.0, float("nan")),
                                             (float("inf"), 0.5)])
def test_depth_to_disparity_rejects_bad_rig(focal: float, baseline: float) -> None:
    with pytest.raises(InvalidOptionError, match="positive"):
        depth_to_disparity(np.ones((2, 2)), focal, baseline)


# --- readers -----------------------------------------------------------------------------------------


def _file_bytes(suffix: str, raw: np.ndarray) -> bytes:
    """``raw`` as the content of a ``.png`` (OpenCV's encoding, 16-bit kept) or a ``.npy`` file."""
    if suffix == ".npy":
        buf = io.BytesIO()
        np.save(buf, raw)
        return buf.getvalue()
    ok, png = cv2.imencode(suffix, raw)
    assert ok
    return png.tobytes()


def _png16(path: Path, raw: np.ndarray) -> Path:
    path.write_bytes(_file_bytes(".png", raw))
    return path


def test_read_depth_u16_millimetres(tmp_path: Path) -> None:
    raw = np.array([[0, 1000, 65535], [12345, 65534, 1]], np.uint16)
    depth = read_depth(_png16(tmp_path / "d.png", raw))
    assert depth.dtype == np.float32
    np.testing.assert_allclose(depth[~np.isnan(depth)], [1.0, 12.345, 65.534, 0.001], rtol=1e-6)
    assert np.isnan(depth[0, 0]) and np.isnan(depth[0, 2])          # 0 and 65535 = no depth
    assert read_depth(tmp_path / "d.png", png_scale=0.01)[0, 1] == pytest.approx(10.0)   # e.g. centimetres


def test_read_depth_float_files_in_metres(tmp_path: Path) -> None:
    depth = np.array([[5.5, 0.0], [-2.0, 80.25]], np.float32)
    np.save(tmp_path / "d.npy", depth)
    write_disparity(tmp_path / "d.pfm", np.where(depth > 0, depth, np.nan))   # same PFM layout
    for name in ("d.npy", "d.pfm"):
        out = read_depth(tmp_path / name)
        assert out[0, 0] == 5.5 and out[1, 1] == 80.25
        assert np.isnan(out[0, 1]) and np.isnan(out[1, 0])


#: what read_depth refuses: test id → (file name, its bytes or None for no file, read_depth's keywords, the error
#: and its message)
DEPTH_ERRORS = {
    "8-bit-png": ("eight.png", _file_bytes(".png", np.full((4, 5), 7, np.uint8)), {}, CorruptFileError,
                  "8-bit image with 1 channel.*16-bit one-channel depth PNG"),
    "colour-png": ("rgb16.png", _file_bytes(".png", np.zeros((4, 5, 3), np.uint16)), {}, CorruptFileError, "3 channel"),
    "truncated-png": ("corrupt.png", b"\x89PNG\r\n\x1a\n-truncated", {}, CorruptFileError, "cannot decode depth"),
    "3-d-npy": ("cube.npy", _file_bytes(".npy", np.zeros((2, 3, 4))), {}, CorruptFileError,
                "2-D float array in metres"),
    "bad-pfm": ("bad.pfm", b"P6\n1 1\n-1\nxxxx", {}, CorruptFileError, "cannot decode depth .*PFM"),
    "wrong-size": ("ok.png", _file_bytes(".png", np.ones((4, 5), np.uint16)), {"shape": (4, 6)},
                   ShapeMismatchError, "5×4 but its image is 6×4"),
    "unknown-suffix": ("d.exr", b"v/1\x01", {}, InvalidOptionError, "unknown depth format '.exr'"),
    "missing": ("missing.png", None, {}, InputFileError, "not found"),
    "zero-png-scale": ("ok.png", _file_bytes(".png", np.ones((4, 5), np.uint16)), {"png_scale": 0},
                       InvalidOptionError, "PNG scale"),
}


@pytest.mark.parametrize("name, content, kwargs, error, match", DEPTH_ERRORS.values(), ids=list(DEPTH_ERRORS))
def test_read_depth_errors(tmp_path: Path, name: str, content: bytes | None, kwargs: dict[str, Any],
                           error: type[Exception], match: str) -> None:
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(error, match=match):
        read_depth(path, **kwargs)


# --- the rig from a calibration ----------------------------------------------------------------------

KITTI_P2 = np.array([[721.5377, 0, 609.5593, 44.85728], [0, 721.5377, 172.854, 0.2163791], [0, 0, 1, 0.002745884]])
KITTI_P3 = np.array([[721.5377, 0, 609.5593, -339.5242], [0, 721.5377, 172.854, 2.199936], [0, 0, 1, 0.002729905]])


def test_rig_from_kitti_real_and_virtual() -> None:
    real = rig_from_kitti({"P2": KITTI_P2, "P3": KITTI_P3})
    # the shared data's README: B = (P2[0,3] − P3[0,3]) / f (the principal-point terms move it by 2e-5 m)
    assert real.fx == 721.5377 and real.baseline == pytest.approx((44.85728 + 339.5242) / 721.5377, abs=1e-4)
    assert real.baseline == pytest.approx(0.5327, abs=1e-4)
    no_p3 = rig_from_kitti({"P2": KITTI_P2})
    assert no_p3.baseline == pytest.approx(DEFAULT_VIRTUAL_BASELINE_M, abs=1e-12)
    assert (no_p3.fx, no_p3.cx, no_p3.cy) == (real.fx, real.cx, real.cy)
    forced = rig_from_kitti({"P2": KITTI_P2, "P3": KITTI_P3}, baseline=0.3)
    assert forced.baseline == pytest.approx(0.3, abs=1e-12)
    with pytest.raises(InvalidOptionError, match="baseline"):
        rig_from_kitti({"P2": KITTI_P2}, baseline=-0.5)
    with pytest.raises(CorruptFileError, match="no P2"):
        rig_from_kitti({"P3": KITTI_P3})


# --- real KITTI road frames with LiDAR depth ---------------------------------------------------------

# (split folder, frame) → road polygon (u, v) drawn on the left image (freespace/evaluation/real_frames.py)
ROAD_POLYGONS = KITTI_ROAD_POLYGONS


@pytest.fixture(params=sorted(ROAD_POLYGONS), ids=lambda k: k[1])
def real_frame(request: pytest.FixtureRequest):
    split, name = request.param
    root = shared_path("kitti_road_depth", split)
    depth_path = root / "depth_u16" / f"{name}.png"
    calib = read_kitti_calib(root / "calib" / f"{name}.txt")
    road = np.zeros((375, 1242), np.uint8)
    cv2.fillPoly(road, [np.array(ROAD_POLYGONS[request.param], np.int32)], 1)
    return name, depth_path, calib, road.astype(bool)


def test_real_depth_gives_a_sane_road_fit(real_frame) -> None:
    name, depth_path, calib, road = real_frame
    disparity, rig = disparity_from_depth_file(depth_path, calib, shape=road.shape)
    assert rig.baseline == pytest.approx(0.5327, abs=1e-4)              # the real P2/P3 baseline
    model = fit_road_model(disparity, road)
    assert model.num_valid == road.sum()                               # the interpolated depth covers the road
    # measured: inliers 100 / 88 / 85 %, rms 0.24 / 0.44 / 0.45 px
    assert model.num_inliers > 0.8 * model.num_valid
    assert model.rms < 0.6
    # the calibration's own road plane (Tr_cam_to_road), independent of the depth:
    # measured roll −0.65 vs −1.23°, −2.73 vs −2.29°, −1.24 vs −1.34°; ϰ̂ 4.3 / 3.2 / 0.7 % apart
    expected = rig.road_model()
    assert abs(model.roll_deg) < 4
    assert abs(model.roll_deg - expected.roll_deg) < 1.0
    assert model.kappa_hat == pytest.approx(expected.kappa_hat, rel=0.06)


def test_virtual_baseline_scales_only_kappa_hat(real_frame) -> None:
    """With a virtual right camera, Φ and κ do not depend on B; ϰ̂ (and the homography) scale with it."""
    name, depth_path, calib, road = real_frame
    real_disp, real_rig = disparity_from_depth_file(depth_path, calib)
    virt_disp, virt_rig = disparity_from_depth_file(depth_path, {k: v for k, v in calib.items() if k != "P3"})
    assert virt_rig.baseline == DEFAULT_VIRTUAL_BASELINE_M
    real = fit_road_model(real_disp, road, robust=False)
    virt = fit_road_model(virt_disp, road, robust=False)
    assert virt.roll_deg == pytest.approx(real.roll_deg, abs=1e-6)
    assert virt.kappa == pytest.approx(real.kappa, abs=1e-4)
    assert virt.kappa_hat / real.kappa_hat == pytest.approx(DEFAULT_VIRTUAL_BASELINE_M / real_rig.baseline, rel=1e-5)
    # the robust fit's inlier threshold is in pixels, so its inlier set — and the roll — move a little:
    # measured 0.000 / 0.014 / 0.021°
    assert abs(fit_road_model(virt_disp, road).roll_deg - fit_road_model(real_disp, road).roll_deg) < 0.05
    # the virtual right camera's homography: every coefficient of d = a·u + b·v + c scales by B'/B
    ratio = DEFAULT_VIRTUAL_BASELINE_M / real_rig.baseline
    np.testing.assert_allclose(np.array(virt.affine), ratio * np.array(real.affine), rtol=1e-5)
    np.testing.assert_allclose(virt.homography[0], [1 - virt.affine[0], -virt.affine[1], -virt.affine[2]], rtol=1e-12)


def test_new_modules_never_import_torch() -> None:
    import subprocess
    import sys

    code = ("import sys, freespace.geometry.depth, freespace.geometry.lidar, freespace.io.video, "
            "freespace.runtime.shard; print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
