"""`freespace reproduce`: every run, the table (mean ± std, HA gain), figures, index; reruns skip."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.io import read_image
from freespace.data.synthetic import SynthConfig, write_dataset


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("rep")
    write_dataset(root, 16, seed=3, config=SynthConfig(width=128, height=96, frames_per_scenario=2), progress=False)
    return root


def test_reproduce(data: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "exp"
    args = ["reproduce", "--dataset", "synth", "--root", str(data), "--models", "segnet", "--seeds", "2",
            "--epochs", "1", "--batch-size", "4", "--no-progress", "--out", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "| HA-segnet |" in printed and "HA gain" in printed
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [r["network"] for r in rows] == ["segnet", "HA-segnet"] and all(r["seeds"] == "2" for r in rows)
    assert rows[0]["gain_f_score"] == "" and rows[1]["gain_f_score"] != ""
    index = json.loads((out / "index.json").read_text())
    assert [(r["variant"], r["seed"]) for r in index] == [("none", 0), ("none", 1), ("homography", 0), ("homography", 1)]
    for entry in index:  # the index holds each run's own test metrics, from one set of counts
        m = json.loads((out / entry["run"] / "metrics.json").read_text())
        assert entry["status"] == "done" and entry["metrics"] == {k: m[k] for k in entry["metrics"]}
        assert m["iou"] == pytest.approx(m["f_score"] / (2 - m["f_score"]), abs=1e-12)  # IoU = F/(2−F)
        assert 0.2 < m["f_score"] <= 1 and 0 < m["precision"] <= 1 and 0 < m["recall"] <= 1
    for row, variant in zip(rows, ("none", "homography")):  # mean ± std (in %) over the seeds of the index
        for k in ("accuracy", "f_score", "iou"):
            values = 100 * np.array([e["metrics"][k] for e in index if e["variant"] == variant])
            assert float(row[k]) == pytest.approx(values.mean(), abs=1e-4)
            assert float(row[f"{k}_std"]) == pytest.approx(values.std(ddof=1), abs=1e-4)
    md = (out / "results.md").read_text()
    assert f"| HA-segnet | 2 | {float(rows[1]['accuracy']):.2f} ± {float(rows[1]['accuracy_std']):.2f} |" in md
    # three test frames of seed 0: image, X, HA-X side by side at the data's size (96×128)
    assert read_image(out / "figures" / "segnet.png").shape == (3 * 96, 3 * 128, 3)
    gain = float(rows[1]["f_score"]) - float(rows[0]["f_score"])
    assert float(rows[1]["gain_f_score"]) == pytest.approx(gain, abs=1e-3)
    # both variants of a seed share the split
    assert (out / "runs/segnet-orig-s0/splits/test.txt").read_text() == (out / "runs/segnet-ha-s0/splits/test.txt").read_text()
    assert main(args) == 0  # finished runs are skipped
    assert all(r["status"] == "done (skipped)" for r in json.loads((out / "index.json").read_text()))


def test_reproduce_mistakes(data: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["reproduce", "--dataset", "synth", "--root", str(data), "--models", "fcn", "--out", str(tmp_path)]) == 2
    assert "unknown models" in capsys.readouterr().err
    assert main(["reproduce", "--dataset", "synth", "--root", str(data), "--seeds", "0", "--out", str(tmp_path)]) == 2
    assert "--seeds must be in 1…1000" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # rejected before any work
