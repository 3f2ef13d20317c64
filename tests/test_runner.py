"""freespace.datagen.runner: the per-frame dataset runner, with a per-frame command of the test's own (the
runner knows no command: its work, report fields and totals are what the command gives)."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest

from freespace.data.base import StereoRoadDataset
from freespace.data.registry import get_dataset
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.datagen.runner import FrameCommand, check_run, run_dataset
from freespace.errors import InvalidOptionError
from freespace.io.files import write_json


def _work(dataset: StereoRoadDataset, index: int, out: Path, report: Path, options: Any,
          settings: dict[str, Any]) -> dict[str, Any]:
    """A frame's work: its left image's size, written as the image's bytes and the report; frame 1 fails."""
    frame = dataset.frames[index]
    if index == 1:
        return {"frame": frame.name, "status": "failed", "reason": "the test's failure"}
    record = {"frame": frame.name, "status": "done", "width": options["scale"] * int(frame.left.stat().st_size > 0),
              "settings": settings, "seconds": {"total": 0.5}}
    out.write_bytes(b"image")
    write_json(report, record)
    return record


def _means(ok: list[dict[str, Any]]) -> dict[str, Any]:
    return {"mean_width": sum(r["width"] for r in ok) / len(ok) if ok else None}


COMMAND = FrameCommand(name="test-cmd", verb="test", work=_work, fields=("frame", "status", "width", "seconds"),
                       done="tested", means=_means)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> StereoRoadDataset:
    root = tmp_path_factory.mktemp("synth")
    write_dataset(root, 5, seed=0, config=SynthConfig(width=64, height=48, frames_per_scenario=5), progress=False)
    return get_dataset("synth", root)


def _run(dataset: StereoRoadDataset, out: Path, **kwargs: Any) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    settings = kwargs.pop("settings", {"what": 1})
    options = {"scale": kwargs.pop("scale", 2)}
    kwargs = {"workers": 1, "progress": False, "overwrite": False, "shard": None, **kwargs}
    return run_dataset(dataset, check_run(dataset, out, kwargs["workers"]), COMMAND, options=options,
                       settings=settings, summary={"tail": True}, **kwargs)


def test_a_command_of_its_own_runs_resumes_and_shards(dataset: StereoRoadDataset, tmp_path: Path) -> None:
    names = [f.name for f in dataset.frames]
    summary, records = _run(dataset, tmp_path / "out")
    assert list(summary) == ["dataset", "root", "frames", "tested", "skipped", "failed", "mean_width", "wall_seconds",
                             "workers", "tail"]
    assert (summary["frames"], summary["tested"], summary["skipped"]) == (5, 4, 0)
    assert summary["failed"] == {names[1]: "the test's failure"} and summary["mean_width"] == 2
    assert [r["frame"] for r in records] == names
    assert json.loads((tmp_path / "out" / "summary.json").read_text()) == summary
    assert json.loads((tmp_path / "out" / "settings.json").read_text()) == {"what": 1}
    with open(tmp_path / "out" / "report.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["frame", "status", "width", "seconds"] and rows[0]["seconds"] == "0.5"
    assert [r["status"] for r in rows] == ["done", "failed", "done", "done", "done"]
    # again: the frames done are skipped (even with other options: settings decide), the failed one redone
    summary, _ = _run(dataset, tmp_path / "out", scale=3)
    assert (summary["tested"], summary["skipped"], summary["mean_width"]) == (0, 4, 2)
    # other settings: refused, unless overwrite, which redoes every frame
    with pytest.raises(InvalidOptionError, match="settings"):
        _run(dataset, tmp_path / "out", settings={"what": 2})
    summary, _ = _run(dataset, tmp_path / "out", settings={"what": 2}, overwrite=True, scale=3)
    assert (summary["tested"], summary["skipped"], summary["mean_width"]) == (4, 0, 3)
    # shards: their own totals, in one folder; in two worker processes
    summary, records = _run(dataset, tmp_path / "sharded", shard=(2, 2), workers=2)
    assert summary["shard"] == "2/2" and [r["frame"] for r in records] == sorted(names)[1::2]
    assert {p.name for p in (tmp_path / "sharded").iterdir()} >= {"summary.shard-2-of-2.json",
                                                                  "report.shard-2-of-2.csv", "settings.json"}
    assert not (tmp_path / "sharded" / "summary.json").exists()


def test_the_folder_is_checked_before_any_work(dataset: StereoRoadDataset, tmp_path: Path) -> None:
    with pytest.raises(InvalidOptionError, match="workers must be ≥ 1"):
        check_run(dataset, tmp_path / "out", 0)
    (tmp_path / "file").write_text("x")
    with pytest.raises(InvalidOptionError, match="is a file"):
        check_run(dataset, tmp_path / "file", 1)
    with pytest.raises(InvalidOptionError):
        check_run(dataset, dataset.root / "inside", 1)
    assert not (tmp_path / "out").exists() and not (dataset.root / "inside").exists()
