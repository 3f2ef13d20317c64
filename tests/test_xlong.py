"""X-long is X's own run continued: its cell starts from X's run folder of the same network and seed (config,
splits, per-epoch record, checkpoints) and extends it with twice the cap and patience, so its epochs up to X's
stop are X's byte for byte, and it ends as an X-long trained from scratch on the same machine would."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from freespace.cli import main
from freespace.data.synthetic import SynthConfig, write_dataset


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("xlong")
    write_dataset(root, 16, seed=3, config=SynthConfig(width=128, height=96, frames_per_scenario=2), progress=False)
    return root


def _cell(data: Path, out: Path, variant: str, *extra: str) -> int:
    # least improvement 0.5: no epoch improves on the first, so X stops after 1 + patience epochs
    return main(["reproduce", "--dataset", "synth", "--root", str(data), "--seeds", "1", "--epochs", "3",
                 "--patience", "1", "--min-delta", "0.5", "--image-size", "64x96", "--batch-size", "4",
                 "--no-progress", "--out", str(out), "--only", f"segnet,{variant},0", *extra])


@pytest.fixture(scope="module")
def x_out(data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A reproduce folder holding segnet's X cell of seed 0 (tests copy it before writing)."""
    out = tmp_path_factory.mktemp("x") / "out"
    assert _cell(data, out, "X") == 0
    return out


def _files(run: Path) -> dict[str, bytes]:
    return {p.relative_to(run).as_posix(): p.read_bytes() for p in sorted(run.rglob("*"))
            if p.is_file() and ".freespace" not in p.parts}


def _rows(run: Path) -> list[dict[str, str]]:
    return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader((run / "metrics.csv").open())]


def test_x_long_is_x_continued(data: Path, x_out: Path, tmp_path: Path) -> None:
    out, fresh = tmp_path / "out", tmp_path / "fresh"
    shutil.copytree(x_out, out)
    x, long = out / "runs/segnet-orig-s0", out / "runs/segnet-long-s0"
    stop = json.loads((x / "metrics.json").read_text())["epochs_run"]
    assert stop == 2  # stopped by patience, before its cap (3)
    before = _files(x)
    assert _cell(data, out, "X-long") == 0
    assert _files(x) == before  # X's folder is read, never written
    ours = (x / "metrics.csv").read_text().splitlines()
    theirs = (long / "metrics.csv").read_text().splitlines()
    assert theirs[:1 + stop] == ours  # header and X's epochs, byte for byte (the seconds too)
    assert len(theirs) - 1 == json.loads((long / "metrics.json").read_text())["epochs_run"] == 3  # it went on
    assert (long / "splits").is_dir() and all((long / "splits" / n).read_bytes() == (x / "splits" / n).read_bytes()
                                              for n in ("train.txt", "val.txt", "test.txt"))
    config = (long / "config.yaml").read_text()
    assert "epochs: 6" in config and "patience: 2" in config and "segnet-long-s0" in config
    # the protocol's X-long, trained from scratch here: the same epochs and the same end
    assert _cell(data, fresh, "X-long") == 0
    assert _rows(fresh / "runs/segnet-long-s0") == _rows(long)
    ends = [json.loads((r / "metrics.json").read_text()) for r in (long, fresh / "runs/segnet-long-s0")]
    for m in ends:
        m.pop("seconds_per_frame")
    assert ends[0] == ends[1]
    assert _cell(data, out, "X-long") == 0  # finished: skipped, nothing copied again
    assert (long / "metrics.csv").read_text().splitlines() == theirs


@pytest.mark.parametrize("damage, message", [
    ("metrics.json", "segnet-orig-s0's run, which is unfinished"),
    ("checkpoints", "segnet-orig-s0's run, which has no checkpoints/last.ckpt"),
    ("lr", "segnet-orig-s0 was started with other settings (lr"),
])
def test_x_long_refuses_an_x_it_cannot_continue(data: Path, x_out: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture, damage: str, message: str) -> None:
    """An X that is unfinished (running, or cut off), whose checkpoints were not kept, or that was started with
    other settings is not continued, and X-long does not silently train from scratch beside it."""
    out = tmp_path / "out"
    shutil.copytree(x_out, out)
    x = out / "runs/segnet-orig-s0"
    if damage == "lr":  # X's recorded settings: another learning rate
        (x / "config.yaml").write_text((x / "config.yaml").read_text().replace("lr: 0.001", "lr: 0.01"))
    elif damage == "metrics.json":
        (x / "metrics.json").unlink()
    elif damage == "checkpoints":
        shutil.rmtree(x / "checkpoints")
    capsys.readouterr()
    assert _cell(data, out, "X-long") == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (out / "runs/segnet-long-s0").exists()
