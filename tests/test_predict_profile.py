"""``predict --profile`` (issue 71): where a frame's time goes — decode, preprocess, network, postprocess, write —
printed on request and always recorded in ``summary.json``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from freespace.cli import main
from freespace.inference.predict import STAGES
from freespace.io.codecs import write_image

from helpers import road_frame, tiny_road_checkpoint

SIZE = (32, 96)


@pytest.mark.parametrize("pipeline_out", ["folder", "video"])
def test_the_profile_names_every_stage(tmp_path: Path, capsys: pytest.CaptureFixture, pipeline_out: str) -> None:
    ckpt = tiny_road_checkpoint(tmp_path / "m.ckpt", SIZE, width=0.25)
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(5):
        write_image(frames / f"f{i}.png", road_frame((64, 192), i)[0])
    out = tmp_path / ("out" if pipeline_out == "folder" else "out.mp4")
    capsys.readouterr()
    assert main(["predict", "--checkpoint", str(ckpt), "--input", str(frames), "--out", str(out), "--profile",
                 "--no-progress"]) == 0
    printed = capsys.readouterr().out.strip().splitlines()
    assert len(printed) == 2 and printed[1].startswith("profile, ms per frame")
    assert all(f"{stage} " in printed[1] for stage in STAGES)
    if pipeline_out == "folder":
        profile = json.loads((out / "summary.json").read_text())["profile_ms_per_frame"]
        assert set(profile) == {*STAGES, "end_to_end"} and all(v >= 0 for v in profile.values())
        assert profile["network"] > 0 and profile["decode"] > 0 and profile["write"] > 0


def test_jpeg_overlays_are_asked_for_and_recorded(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from helpers import refused

    ckpt = tiny_road_checkpoint(tmp_path / "m.ckpt", SIZE, width=0.25)
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(4):
        write_image(frames / f"f{i}.png", road_frame((64, 192), i)[0])
    out = tmp_path / "out"
    base = ["predict", "--checkpoint", str(ckpt), "--input", str(frames), "--no-progress"]
    assert main([*base, "--out", str(out), "--overlay-format", "jpg", "--shard", "1/2"]) == 0
    assert sorted(p.suffix for p in (out / "overlays").iterdir()) == [".jpg", ".jpg"]
    assert json.loads((out / "predict.json").read_text())["overlay_format"] == "jpg"
    refused(capsys, [*base, "--out", str(out), "--shard", "2/2"], match="overlay_format 'jpg' → 'png'")
    refused(capsys, [*base, "--out", str(tmp_path / "v.mp4"), "--overlay-format", "jpg"], match="a video is one file")
    refused(capsys, [*base, "--out", str(tmp_path / "o2"), "--overlay-format", "jpg", "--no-overlays"],
            match="they are left out")
