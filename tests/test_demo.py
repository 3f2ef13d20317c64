"""The built-in demo and the pictures it draws."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.data.synthetic import SynthConfig
from freespace.demo import run_demo
from freespace.evaluation.viz import caption, colorize_disparity, grid, overlay_road
from freespace.io.codecs import read_image


def test_demo_end_to_end(tmp_path: Path) -> None:
    result = run_demo(tmp_path, num_frames=3, seed=4, config=SynthConfig(width=320, height=240, frames_per_scenario=1),
                      train=False)
    assert len(result["frames"]) == 3 and not result["generate_failed"]
    assert result["max_roll_error_deg"] < 0.01
    assert result["max_sgbm_roll_error_deg"] < 0.5
    assert result["mean_road_mae_generated"] < result["mean_road_mae_right"]
    assert len(list((tmp_path / "figures").glob("*.jpg"))) == 3
    assert json.loads((tmp_path / "demo_summary.json").read_text())["frames"][0]["frame"]


@pytest.mark.slow
def test_demo_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The whole `freespace demo` (about 2 minutes here): DS-Generator, U-Net with and without HA, table."""
    assert main(["demo", "--out", str(tmp_path), "--num", "24", "--epochs", "2"]) == 0
    out = capsys.readouterr().out
    assert "generated view differs" in out and "| unet | HA-X | test |" in out and "figures:" in out
    assert "HA-X − X above is one seed" in out and "X-dup" in out  # the gain printed is said to be the steps'
    summary = json.loads((tmp_path / "demo_summary.json").read_text())
    # the DS-Generator part: the exact-disparity fit recovers the rendered roll, the generated view is
    # closer to the left image on the road than the raw right image
    assert summary["max_roll_error_deg"] < 0.01 and not summary["generate_failed"]
    assert summary["mean_road_mae_generated"] < summary["mean_road_mae_right"]
    assert len(list((tmp_path / "figures").glob("*.jpg"))) == 4
    # the training part: both variants trained and tested, the table and its CSV agree
    rows = list(csv.DictReader((tmp_path / "experiment" / "results.csv").open()))
    assert [r["variant"] for r in rows] == ["X", "HA-X"] and all(r["n"] == "1" for r in rows)
    assert [r["variant"] for r in summary["results"]] == ["X", "HA-X"]
    for row, result in zip(rows, summary["results"]):
        assert float(row["f_score_mean"]) == pytest.approx(result["f_score_mean"], abs=1e-4)
        assert 20 < result["f_score_mean"] <= 100 and 0 < result["iou_mean"] <= result["f_score_mean"]  # %, alive
    assert f"| unet | HA-X | test | 1 | {float(rows[1]['accuracy_mean']):.2f} | " in out  # one seed: no std
    assert read_image(tmp_path / "experiment" / "figures" / "unet.png").shape[0] == 3 * 128


def test_demo_mistake(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["demo", "--out", str(tmp_path), "--num", "0"]) == 2
    assert "--num must be an integer in [1, " in capsys.readouterr().err and list(tmp_path.iterdir()) == []
    assert main(["demo", "--out", str(tmp_path), "--num", "5"]) == 2  # a number, but too few frames to train
    assert "--num must be in 16…" in capsys.readouterr().err and list(tmp_path.iterdir()) == []


def test_viz() -> None:
    d = np.array([[np.nan, 1.0], [2.0, 4.0]], np.float32)
    rgb = colorize_disparity(d)
    assert rgb.shape == (2, 2, 3) and rgb[0, 0].tolist() == [0, 0, 0] and rgb[1, 1].any()
    img = np.full((40, 60, 3), 100, np.uint8)
    road = np.zeros((40, 60), bool)
    road[20:] = True
    over = overlay_road(img, road)
    assert (over[30, 5] != img[30, 5]).any() and (over[5, 5] == img[5, 5]).all()
    assert caption(img, "x").shape == img.shape
    assert grid([[img, img], [img, img]], width=30).shape == (40, 60, 3)
