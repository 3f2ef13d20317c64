"""The built-in stereo road scene renderer: exact geometry, determinism, the KITTI tree it writes."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.data.kitti_road import KittiRoad
from freespace.data.synthetic import SynthConfig, render_sample, sample_frame, write_dataset
from freespace.geometry import StereoCalibration, fit_road_model
from freespace.io.codecs import read_disparity, read_road_label
from freespace.io.kitti import read_kitti_calib

SMALL = SynthConfig(width=320, height=240)


@pytest.fixture(scope="module")
def samples():
    return [render_sample(i, seed=11, config=SMALL) for i in (0, 13, 27, 41)]


def test_sample_contents(samples) -> None:
    for s in samples:
        assert s.left.shape == s.right.shape == (240, 320, 3) and s.left.dtype == np.uint8
        assert s.disparity.shape == (240, 320) and s.disparity.dtype == np.float32
        road = s.label.road
        assert 0.05 < road.mean() < 0.7
        assert np.isfinite(s.disparity[road]).all()  # the road is always hit
        assert s.name.startswith(s.category + "_") and s.scenario == s.index // SMALL.frames_per_scenario
        assert not np.array_equal(s.left, s.right)


def test_right_image_warped_with_true_disparity_reproduces_left(samples) -> None:
    """Non-occluded pixels: left(u, v) ≈ gain · right(u − d, v) + bias, up to noise and vignetting."""
    for s in samples:
        h, w = s.disparity.shape
        d = np.nan_to_num(s.disparity, nan=0.0)
        map_x = (np.arange(w, dtype=np.float32)[None, :] - d).astype(np.float32)
        map_y = np.repeat(np.arange(h, dtype=np.float32)[:, None], w, axis=1)
        warped = cv2.remap(s.right, map_x, map_y, cv2.INTER_LINEAR).astype(np.float64)
        ok = s.noc.copy()
        ok[:, :2] = ok[:, -2:] = False
        left = s.left.astype(np.float64)
        errors = []
        for shift in (0.0, 2.0):  # the true correspondence, and one 2 px off
            wp = cv2.remap(s.right, map_x - shift, map_y, cv2.INTER_LINEAR).astype(np.float64) if shift else warped
            err = []
            for c in range(3):
                A = np.stack([wp[..., c][ok], np.ones(ok.sum())], 1)
                coef, *_ = np.linalg.lstsq(A, left[..., c][ok], rcond=None)
                err.append(np.abs(A @ coef - left[..., c][ok]))
            errors.append(float(np.mean(err)))
        assert errors[0] < 6.0, (s.name, s.meta["weather"], errors)
        assert errors[1] > 1.5 * errors[0]


def test_planar_road_disparity_lies_on_the_known_road_plane(samples) -> None:
    for s in samples:
        road = s.label.road
        model = s.calibration.road_model()
        np.testing.assert_allclose(s.disparity[road], model.disparity(road.shape)[road], atol=2e-3, rtol=1e-4)
        fitted = fit_road_model(s.disparity, road)
        assert fitted.num_inliers == fitted.num_valid
        assert fitted.roll_deg == pytest.approx(s.meta["roll_deg"], abs=1e-3)
        assert fitted.kappa_hat == pytest.approx(s.meta["baseline_m"] / s.meta["camera_height_m"]
                                                 * np.cos(np.radians(s.meta["pitch_deg"])), rel=1e-3)


def test_non_planar_roads_depart_from_a_plane() -> None:
    cfg = SynthConfig(width=320, height=240, planar=False)
    rms = [fit_road_model(s.disparity, s.label.road).rms for s in (render_sample(i, 5, cfg) for i in (0, 10, 20))]
    assert max(rms) > 0.02


def test_frame_depends_only_on_seed_and_index(tmp_path: Path) -> None:
    a = render_sample(7, seed=3, config=SMALL)
    b = render_sample(7, seed=3, config=SMALL)
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right, b.right)
    assert not np.array_equal(a.left, render_sample(7, seed=4, config=SMALL).left)
    write_dataset(tmp_path / "three", 3, seed=3, config=SMALL, progress=False)
    write_dataset(tmp_path / "five", 5, seed=3, config=SMALL, progress=False)
    for path in (tmp_path / "three").rglob("*.png"):
        assert path.read_bytes() == (tmp_path / "five" / path.relative_to(tmp_path / "three")).read_bytes()


def test_scenarios_keep_their_rig_and_vary_between_each_other() -> None:
    cfg = SynthConfig(width=64, height=48, frames_per_scenario=4)
    rigs = [(f.scenario.index, f.scenario.baseline, f.scenario.roll)
            for f in (sample_frame(cfg, 0, i) for i in range(8))]
    assert len({r for r in rigs[:4]}) == 1 and len({r for r in rigs[4:]}) == 1 and rigs[0] != rigs[4]
    assert all(abs(np.degrees(sample_frame(cfg, 0, i * 4).scenario.roll)) <= 3 for i in range(30))


def test_synth_writes_a_kitti_road_tree(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "syn"
    assert main(["synth", "--out", str(out), "--num", "4", "--width", "160", "--height", "120",
                 "--frames-per-scenario", "2", "--seed", "9", "--workers", "2"]) == 0
    assert "4 stereo frames in 2 scenarios" in capsys.readouterr().out
    frames = KittiRoad(out).frames
    assert len(frames) == 4 and all(f.right and f.label and f.calib and f.disparity for f in frames)
    rows = list(csv.DictReader((out / "index.csv").open()))
    assert [r["frame"] for r in rows] == [f.name for f in sorted(frames, key=lambda f: f.name[-6:])]
    assert [int(r["scenario"]) for r in rows] == [0, 0, 1, 1]
    assert json.loads((out / "synth.json").read_text())["seed"] == 9
    assert [f.scenario for f in frames] == [f"scenario_{r['scenario']}" for r in sorted(rows, key=lambda r: r["frame"])]
    for f in frames:
        label = read_road_label(f.label)
        disp = read_disparity(f.disparity)
        calib = StereoCalibration.from_kitti(read_kitti_calib(f.calib))
        road = label.road
        # files agree: disparity on the label's road = the calibration's road plane (1/256 px PNG steps)
        np.testing.assert_allclose(disp[road], calib.road_model().disparity(road.shape)[road], atol=4e-3)
        row = next(r for r in rows if r["frame"] == f.name)
        assert calib.baseline == pytest.approx(float(row["baseline_m"]), rel=1e-5)
    # and the DS-Generator runs on it
    assert main(["generate", "--dataset", "kitti", "--root", str(out), "--out", str(tmp_path / "gen")]) == 0


def test_synth_stores_disparities_beyond_the_png_range_as_invalid(tmp_path: Path,
                                                                  caplog: pytest.LogCaptureFixture) -> None:
    """A wide baseline at a large width gives near disparities above KITTI's 255.996 px: they are stored as
    invalid (never clipped), and synth says so in one line, not in one warning per frame."""
    out = tmp_path / "syn"
    config = SynthConfig(width=640, height=240, baselines=(4.0, 4.0))
    with caplog.at_level("WARNING", logger="freespace"):
        write_dataset(out, 2, seed=0, config=config, progress=False)
    lines = [r.getMessage() for r in caplog.records if "exceed the 255.996 px" in r.getMessage()]
    assert len(lines) == 1 and " of 2 frames" in lines[0], [r.getMessage() for r in caplog.records]
    for f in KittiRoad(out).frames:
        exact = render_sample(int(f.name[-6:]), 0, config).disparity
        stored = read_disparity(f.disparity)
        assert (exact > 256).any()
        assert np.isnan(stored[exact > 256]).all() and np.nanmax(stored) < 256
        kept = exact < 255
        np.testing.assert_allclose(stored[kept], exact[kept], atol=1 / 512)


def test_synth_user_mistakes(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    for args, message in ((["--num", "0"], "--num"), (["--num", "2", "--width", "8"], "--width"),
                          (["--num", "2", "--weather", "snow"], "weather"),
                          (["--num", "2", "--baseline", "-1"], "baseline")):
        assert main(["synth", "--out", str(tmp_path / "x"), *args]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    (tmp_path / "file").write_text("")
    assert main(["synth", "--out", str(tmp_path / "file"), "--num", "1"]) == 2
