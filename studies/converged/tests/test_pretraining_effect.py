"""The converged run's control of pretraining (studies/converged/pretraining.py): X with ImageNet weights
against X from scratch, paired by seed over the seeds both finished, beside HA's gains."""

from __future__ import annotations

import csv
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from freespace.experiments.stats import paired_gain

SCRIPT = Path(__file__).resolve().parents[1] / "pretraining.py"
spec = importlib.util.spec_from_file_location("pretraining", SCRIPT)
pretraining = importlib.util.module_from_spec(spec)
spec.loader.exec_module(pretraining)


def _entry(model: str, variant: str, seed: int, f: float, shifted: float, status: str = "done") -> dict:
    return {"run": f"runs/{model}-{variant}-s{seed}", "model": model, "variant": variant, "seed": seed,
            "status": status, "metrics": {"f_score": f / 100}, "test_sets": {"shifted": {"f_score": shifted / 100}}}


def _folder(path: Path, entries: list[dict], gains: list[dict] | None = None) -> Path:
    path.mkdir()
    (path / "index.json").write_text(json.dumps(entries))
    if gains is not None:
        with (path / "gains.csv").open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=["network", "versus", "metric", "test_set", "mean", "ci_low",
                                              "ci_high", "n", "excludes_zero"])
            w.writeheader()
            w.writerows(gains)
    return path


def test_the_effect_pairs_seeds_both_finished(tmp_path: Path) -> None:
    pre = [90.0, 92.5, 91.0, 93.0]
    scr = [85.0, 88.0, 89.5, 70.0]  # seed 3 of the control did not finish: it must not be paired
    res = _folder(tmp_path / "res", [_entry("unet", "X", s, f, f - 5) for s, f in enumerate(pre)]
                  + [_entry("unet", "HA-X", 0, 95.0, 90.0)],
                  [{"network": "unet", "versus": "HA-X - X-dup", "metric": "f_score", "test_set": "shifted",
                    "mean": "0.5", "ci_low": "-0.5", "ci_high": "1.5", "n": "4", "excludes_zero": "false"}])
    scratch = _folder(tmp_path / "scr", [_entry("unet", "X", s, f, f - 8, "done" if s < 3 else "running")
                                         for s, f in enumerate(scr)]
                      + [_entry("segnet", "X", 0, 80.0, 70.0)])
    rows = pretraining.pretraining_table(res, scratch)
    assert [(r["network"], r["test set"]) for r in rows] == [("unet", "test"), ("unet", "shifted")]
    test, shifted = rows
    g = paired_gain(pre[:3], scr[:3])
    assert test["seeds"] == "0,1,2" and test["X ImageNet"] == f"{sum(pre[:3]) / 3:.2f}"
    assert test["ImageNet − scratch"] == f"{g.mean:+.2f} [{g.ci_low:+.2f}, {g.ci_high:+.2f}] (n = 3)"
    assert test["HA-X − X-dup"] == ""  # no such gain in gains.csv for this test set
    assert shifted["ImageNet − scratch"].startswith(f"{g.mean + 3:+.2f} ")
    assert shifted["HA-X − X-dup"] == "+0.50 [-0.50, +1.50] (n = 4)"


def test_a_folder_without_tables_is_one_line(tmp_path: Path) -> None:
    res = _folder(tmp_path / "res", [_entry("unet", "X", 0, 90.0, 85.0)])  # no gains.csv
    scratch = _folder(tmp_path / "scr", [_entry("unet", "X", 0, 85.0, 80.0)])
    out = subprocess.run([sys.executable, str(SCRIPT), str(res), str(scratch)], capture_output=True, text=True)
    assert out.returncode != 0 and "holds no gains.csv" in out.stderr and "Traceback" not in out.stderr


@pytest.mark.parametrize("csv_out", [False, True])
def test_the_table_is_printed_and_written(tmp_path: Path, csv_out: bool) -> None:
    res = _folder(tmp_path / "res", [_entry("unet", "X", s, 90.0 + s, 85.0) for s in range(2)], [])
    scratch = _folder(tmp_path / "scr", [_entry("unet", "X", s, 88.0, 84.0 + s) for s in range(2)])
    extra = ["--csv", str(tmp_path / "t.csv")] if csv_out else []
    out = subprocess.run([sys.executable, str(SCRIPT), str(res), str(scratch), *extra], capture_output=True,
                         text=True, check=True)
    assert out.stdout.splitlines()[0].startswith("| network | test set | seeds |")
    assert "| unet | test | 0,1 | 90.50 | 88.00 | +2.50 [" in out.stdout
    assert (tmp_path / "t.csv").is_file() == csv_out


def test_the_table_never_overwrites_an_input(tmp_path: Path) -> None:
    res = _folder(tmp_path / "res", [_entry("unet", "X", s, 90.0 + s, 85.0) for s in range(2)], [])
    scratch = _folder(tmp_path / "scr", [_entry("unet", "X", s, 88.0, 84.0 + s) for s in range(2)])
    before = (res / "gains.csv").read_bytes()
    out = subprocess.run([sys.executable, str(SCRIPT), str(res), str(scratch), "--csv", str(res / "gains.csv")],
                         capture_output=True, text=True)
    assert out.returncode != 0 and "is one of the inputs" in out.stderr
    assert (res / "gains.csv").read_bytes() == before
