"""A run's record of where it ran: the package commit, the data root and the torch version in its metrics.json
(never in config.yaml, so that a resume with another commit is not refused)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest
import torch
import yaml

from freespace.cli import main
from freespace.engine.record import UNKNOWN, package_commit

from helpers import TRAINED_ARGS


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t", *args],
                          check=True, capture_output=True, text=True).stdout.strip()


def test_a_run_records_commit_data_root_and_torch(trained: dict[str, Path]) -> None:
    record = json.loads((trained["run"] / "metrics.json").read_text())["record"]
    assert record == {"commit": package_commit(), "data_root": str(trained["data"].resolve()),
                      "torch": torch.__version__}
    assert re.fullmatch(r"[0-9a-f]{40}(-dirty)?|unknown", record["commit"])
    assert Path(record["data_root"]).is_absolute()
    config = yaml.safe_load((trained["run"] / "config.yaml").read_text())
    assert not {"record", "commit", "torch", "data_root"} & set(config)  # not a training option


def test_the_commit_of_a_package_source(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    repo = tmp_path / "repo"
    (repo / "pkg").mkdir(parents=True)
    (repo / "pkg" / "__init__.py").write_text("x = 1\n")
    (repo / "other.txt").write_text("a\n")
    _git(repo, "init", "-q")
    assert package_commit(repo / "pkg") == UNKNOWN  # not yet tracked: no commit to name
    _git(repo, "add", ".")
    _git(repo, "commit", "-q", "-m", "one")
    head = _git(repo, "rev-parse", "HEAD")
    assert package_commit(repo / "pkg") == head
    (repo / "other.txt").write_text("b\n")  # a change outside the package does not make it dirty
    (repo / "pkg" / "new.py").write_text("")  # nor an untracked file
    assert package_commit(repo / "pkg") == head
    (repo / "pkg" / "__init__.py").write_text("x = 2\n")
    assert package_commit(repo / "pkg") == head + "-dirty"
    monkeypatch.setenv("GIT_DIR", str(tmp_path / "elsewhere"))  # a caller's git variables name another repo
    assert package_commit(repo / "pkg") == head + "-dirty"
    untracked = repo / "venv" / "pkg"  # a package installed inside a work tree, not tracked by it
    untracked.mkdir(parents=True)
    (untracked / "__init__.py").write_text("")
    assert package_commit(untracked) == UNKNOWN
    assert package_commit(tmp_path / "nowhere") == UNKNOWN


def test_a_resume_is_not_refused_for_another_commit(trained: dict[str, Path], tmp_path: Path) -> None:
    """The record is not compared: a run finished by another commit on another data path resumes, and its new
    record is this session's."""
    run = tmp_path / "run"
    shutil.copytree(trained["run"], run)
    metrics = json.loads((run / "metrics.json").read_text())
    metrics["record"] = {"commit": "0" * 40, "data_root": "/elsewhere", "torch": "0.0"}
    (run / "metrics.json").write_text(json.dumps(metrics))
    args = [a if a != "1" else "2" for a in TRAINED_ARGS]  # --epochs 1 → 2: an extension
    assert main(["train", "--dataset", "synth", "--root", str(trained["data"]), *args, "--out", str(run),
                 "--resume"]) == 0
    after = json.loads((run / "metrics.json").read_text())
    assert after["epochs_run"] == 2
    assert after["record"] == {"commit": package_commit(), "data_root": str(trained["data"].resolve()),
                               "torch": torch.__version__}


def test_a_run_resumes_from_its_folder_alone(trained: dict[str, Path], tmp_path: Path) -> None:
    """``train --out RUN --resume`` reads the run's own config.yaml: no dataset, root or options again; a flag
    given as well is an extension the resume check allows (here a larger --epochs)."""
    run = tmp_path / "run"
    shutil.copytree(trained["run"], run)
    assert main(["train", "--out", str(run), "--resume", "--epochs", "2", "--no-progress"]) == 0
    assert json.loads((run / "metrics.json").read_text())["epochs_run"] == 2


def test_the_reproduce_index_holds_each_runs_record(trained: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "out"
    shutil.copytree(trained["run"], out / "runs" / "segnet-orig-s0")
    old = out / "runs" / "segnet-orig-s1"  # a run of a version that recorded nothing: no record, no error
    shutil.copytree(trained["run"], old)
    metrics = json.loads((old / "metrics.json").read_text())
    del metrics["record"]
    (old / "metrics.json").write_text(json.dumps(metrics))
    from freespace.experiments.tables import collect as _collect  # the index's entries

    index = {e["run"]: e for e in _collect(out)[0]}
    assert index["runs/segnet-orig-s0"]["record"]["data_root"] == str(trained["data"].resolve())
    assert index["runs/segnet-orig-s0"]["record"]["commit"] == package_commit()
    assert "record" not in index["runs/segnet-orig-s1"]
