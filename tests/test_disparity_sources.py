"""`--disparity-source depth` and `--disparity-source lidar` in the data layer and in `generate`.

Depth: three real KITTI road frames with SNE-RoadSeg-style ``depth_u16`` (../shared/data/kitti_road_depth,
skipped when absent) laid out as a KITTI road tree. LiDAR: Velodyne scans made from the renderer's exact
disparity (every sampled pixel back-projected and moved into the Velodyne frame through the frame's own
calibration), so the projected disparity is known exactly.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.data import get_dataset
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.errors import DatasetError
from freespace.geometry.lidar import velodyne_to_disparity
from freespace.io.codecs import read_disparity
from freespace.io.kitti import read_kitti_calib, read_velodyne

from helpers import disparity_from_depth_file, shared_path, write_velodyne

# --- depth_u16 beside image_2 (real KITTI frames) ------------------------------------------------------


@pytest.fixture(scope="module")
def kitti_depth_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shared frames as a KITTI road tree: testing (um_000000) and, for the two frames of unknown
    split, training."""
    src = shared_path("kitti_road_depth")
    root = tmp_path_factory.mktemp("kitti_depth")
    for split, folder in (("testing", "testing"), ("training", "unknown_split")):
        for sub in ("image_2", "depth_u16", "calib"):
            shutil.copytree(src / folder / sub, root / "data_road" / split / sub)
    return root


@pytest.mark.parametrize("split, frames", [("training", ["uu_000000", "uu_000001"]), ("testing", ["um_000000"])])
def test_kitti_depth_u16_is_the_frames_disparity(kitti_depth_root: Path, split: str, frames: list[str]) -> None:
    ds = get_dataset("kitti", kitti_depth_root, split, disparity_source="depth")
    assert [f.name for f in ds.frames] == frames
    for i, frame in enumerate(ds.frames):
        sample = ds.load(i)
        expected, rig = disparity_from_depth_file(frame.depth, frame.calib)
        assert sample.disparity_source == "depth"
        np.testing.assert_array_equal(sample.disparity, expected)
        assert sample.calibration.baseline == pytest.approx(rig.baseline) == pytest.approx(0.5327, abs=1e-4)
        # the interpolated depth covers about half the image (below the horizon); 65535 and 0 are none
        assert 0.4 < np.isfinite(sample.disparity).mean() < 0.7
        raw = cv2.imread(str(frame.depth), cv2.IMREAD_UNCHANGED)
        assert np.isnan(sample.disparity[(raw == 0) | (raw == 65535)]).all()
        # auto takes depth + camera when there is no disparity file
        assert get_dataset("kitti", kitti_depth_root, split).load(i).disparity_source == "depth"


def test_kitti_depth_without_p3_uses_the_virtual_baseline(kitti_depth_root: Path, tmp_path: Path) -> None:
    root = tmp_path / "k"
    shutil.copytree(kitti_depth_root / "data_road" / "testing", root / "data_road" / "testing")
    calib = root / "data_road/testing/calib/um_000000.txt"
    calib.write_text("".join(line for line in calib.read_text().splitlines(True) if not line.startswith("P3")))
    sample = get_dataset("kitti", root, "testing", disparity_source="depth").load(0)
    assert sample.calibration.baseline == 0.54
    expected, _ = disparity_from_depth_file(root / "data_road/testing/depth_u16/um_000000.png", calib)
    np.testing.assert_array_equal(sample.disparity, expected)


def test_datasets_info_counts_depth(kitti_depth_root: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["datasets", "info", "--dataset", "kitti", "--root", str(kitti_depth_root), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "depth 2/2, velodyne 0/2" in out and "depth 1/1, velodyne 0/1" in out and "0 problems" in out


# --- Velodyne scans made from the renderer's exact disparity -------------------------------------------

FRAMES = 3


def _h(M: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[: M.shape[0], : M.shape[1]] = M
    return out


def make_scan(disparity: np.ndarray, calib: dict[str, np.ndarray],
              step: tuple[int, int] = (3, 2)) -> tuple[np.ndarray, np.ndarray]:
    """A Velodyne scan (N×4) whose points project onto every ``step``-th pixel of ``disparity`` with exactly
    its value, and the bool mask of those pixels. Camera-2 coordinates are X2 = R0·(Tr·p) + t2 with
    P2 = K [I | K⁻¹P2₄]."""
    P2 = calib["P2"]
    K = P2[:, :3]
    fx, baseline = K[0, 0], float(np.linalg.solve(K, P2[:, 3])[0] - np.linalg.solve(K, calib["P3"][:, 3])[0])
    grid = np.zeros(disparity.shape, bool)
    grid[:: step[0], :: step[1]] = True
    sampled = grid & np.isfinite(disparity) & (disparity > 0)
    v, u = np.nonzero(sampled)
    z = fx * baseline / disparity[v, u].astype(np.float64)
    cam = np.stack([(u - K[0, 2]) / fx * z, (v - K[1, 2]) / K[1, 1] * z, z, np.ones_like(z)], axis=1)
    t2 = np.linalg.solve(K, P2[:, 3])
    cam_from_velo = (_h(np.hstack([np.eye(3), t2[:, None]])) @ _h(calib.get("R0_rect", np.eye(3)))
                     @ _h(calib["Tr_velo_to_cam"]))
    velo = cam @ np.linalg.inv(cam_from_velo).T
    return np.hstack([velo[:, :3], np.full((len(velo), 1), 0.5)]), sampled


@pytest.fixture(scope="module")
def lidar_root(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, np.ndarray]]:
    """A rendered KITTI tree (exact disparity files) with ``velodyne/<frame>.bin`` made from them; returns
    the root and each frame's sampled-pixel mask."""
    root = tmp_path_factory.mktemp("lidar")
    write_dataset(root, FRAMES, seed=3, config=SynthConfig(width=320, height=240, frames_per_scenario=1),
                  progress=False)
    base = root / "data_road" / "training"
    masks = {}
    for path in sorted((base / "image_2").glob("*.png")):
        calib = read_kitti_calib(base / "calib" / f"{path.stem}.txt")
        scan, masks[path.stem] = make_scan(read_disparity(base / "disparity" / path.name), calib)
        write_velodyne(base / "velodyne" / f"{path.stem}.bin", scan)
    return root, masks


def test_lidar_mode_loads_the_projected_scan(lidar_root) -> None:
    root, masks = lidar_root
    ds = get_dataset("kitti", root, "training", disparity_source="lidar")
    exact = get_dataset("kitti", root, "training", disparity_source="file")
    assert len(ds) == FRAMES
    for i, frame in enumerate(ds.frames):
        sample = ds.load(i)
        assert sample.disparity_source == "lidar"
        projected = velodyne_to_disparity(read_velodyne(frame.velodyne), read_kitti_calib(frame.calib),
                                          sample.left.shape[:2])
        np.testing.assert_array_equal(sample.disparity, projected)
        have = np.isfinite(sample.disparity)
        np.testing.assert_array_equal(have, masks[frame.name])          # one point per sampled pixel, no other
        truth = exact.load(i).disparity
        np.testing.assert_allclose(sample.disparity[have], truth[have], rtol=1e-5, atol=1e-4)
    # auto never takes the scan: the tree's disparity file wins, and without it SGBM, not LiDAR
    assert get_dataset("kitti", root, "training").load(0).disparity_source == "file"
    densified = get_dataset("kitti", root, "training", disparity_source="lidar", lidar_densify=2).load(0).disparity
    assert np.isfinite(densified).sum() > 2 * np.isfinite(ds.load(0).disparity).sum()


def test_kitti_road_velodyne_folder_is_found(lidar_root, tmp_path: Path) -> None:
    src, _ = lidar_root
    root = tmp_path / "k"
    shutil.copytree(src / "data_road", root / "data_road")
    shutil.copytree(src / "data_road_right", root / "data_road_right")
    shutil.move(root / "data_road/training/velodyne", root / "data_road_velodyne/training/velodyne")
    ds = get_dataset("kitti", root, "training", disparity_source="lidar")
    assert all(f.velodyne is not None and "data_road_velodyne" in str(f.velodyne) for f in ds.frames)
    assert ds.load(1).disparity_source == "lidar"


def test_generate_from_lidar_matches_the_exact_fit(lidar_root, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root, _ = lidar_root
    exact, lidar = tmp_path / "exact", tmp_path / "lidar"
    base = ["generate", "--dataset", "kitti", "--root", str(root)]
    assert main(base + ["--disparity-source", "file", "--out", str(exact)]) == 0
    assert main(base + ["--disparity-source", "lidar", "--out", str(lidar)]) == 0
    rolls = []
    for path in sorted((exact / "reports").glob("*.json")):
        e = json.loads(path.read_text())
        li = json.loads((lidar / "reports" / path.name).read_text())
        assert (e["disparity_source"], li["disparity_source"]) == ("file", "lidar")
        assert li["num_valid"] < 0.25 * e["num_valid"]                   # sparse: every 6th road pixel
        rolls.append(abs(li["roll_deg"] - e["roll_deg"]))
        assert li["kappa_hat"] == pytest.approx(e["kappa_hat"], rel=1e-3)
    assert len(rolls) == FRAMES and max(rolls) < 0.05                   # measured: below 1e-3°
    settings = json.loads((lidar / "settings.json").read_text())
    assert settings["disparity_source"] == "lidar" and settings["lidar_densify"] == 0
    # densification changes what was generated: refused in the same folder, like any other setting
    capsys.readouterr()
    assert main(base + ["--disparity-source", "lidar", "--lidar-densify", "2", "--out", str(lidar)]) == 2
    assert "lidar_densify 0.0 → 2.0" in capsys.readouterr().err


def test_lidar_and_depth_mistakes(lidar_root, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    src, _ = lidar_root
    root = tmp_path / "k"
    shutil.copytree(src / "data_road", root / "data_road")
    shutil.copytree(src / "data_road_right", root / "data_road_right")
    missing = sorted((root / "data_road/training/velodyne").glob("*.bin"))[1]
    missing.unlink()
    out = tmp_path / "out"
    base = ["generate", "--dataset", "kitti", "--root", str(root)]
    assert main(base + ["--disparity-source", "lidar", "--out", str(out)]) == 1   # that frame fails, the others go on
    summary = json.loads((out / "summary.json").read_text())
    assert summary["generated"] == FRAMES - 1
    assert "has no Velodyne scan" in summary["failed"][missing.stem]
    capsys.readouterr()
    # a dataset without any depth map: one line, exit 2, no output
    assert main(base + ["--disparity-source", "depth", "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "has a depth map" in err and not (tmp_path / "d").exists()
    assert main(base + ["--disparity-source", "lidar", "--lidar-densify", "-1", "--out", str(tmp_path / "d")]) == 2
    assert "--lidar-densify must be in [0, 1000], got -1" in capsys.readouterr().err
    assert main(base + ["--lidar-densify", "2", "--out", str(tmp_path / "d")]) == 2
    assert "--lidar-densify is for --disparity-source lidar" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
    ds = get_dataset("kitti", root, "training")
    with pytest.raises(DatasetError, match="has no Velodyne scan"):
        ds.read_lidar(ds.frames[1], (240, 320))
    assert main(["datasets", "info", "--dataset", "kitti", "--root", str(root), "--no-progress"]) == 1
    out_text = capsys.readouterr().out
    assert f"velodyne {FRAMES - 1}/{FRAMES}" in out_text and f"{missing.stem}: missing velodyne file" in out_text


# --- generic layout: png16 depth, 65535 = none ---------------------------------------------------------


def test_generic_png16_depth_65535_is_none(tmp_path: Path) -> None:
    h, w = 40, 60
    rng = np.random.default_rng(0)
    mm = rng.integers(2000, 60000, (h, w)).astype(np.uint16)
    mm[:5] = 65535
    mm[5:8] = 0
    (tmp_path / "rgb").mkdir()
    cv2.imwrite(str(tmp_path / "rgb" / "a.png"), np.zeros((h, w, 3), np.uint8))
    (tmp_path / "depth_u16").mkdir()
    cv2.imwrite(str(tmp_path / "depth_u16" / "a.png"), mm)
    (tmp_path / "freespace.yaml").write_text(
        "left: rgb\ndepth: depth_u16\ndepth_encoding: png16\ndepth_scale: 0.001\n"
        "camera: {fx: 700.0, fy: 700.0, cx: 30.0, cy: 20.0, baseline: 0.54}\n")
    sample = get_dataset("generic", tmp_path, disparity_source="depth").load(0, label=False)
    assert sample.disparity_source == "depth"
    assert np.isnan(sample.disparity[:8]).all()                         # 65535 (saturated) and 0: no depth
    np.testing.assert_allclose(sample.disparity[8:], 700.0 * 0.54 / (mm[8:] * 0.001), rtol=1e-5)
