"""Prediction with a region of interest (``predict --crop-top F``, ``Predictor(crop_top=F)``): the top F of each
frame left out of the network's input and scored not road; recorded where it was used."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.errors import InvalidOptionError
from freespace.inference.predictor import Predictor

from helpers import refused, road_folders, road_frame, tiny_road_checkpoint

SIZE = (32, 96)


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_road_checkpoint(tmp_path_factory.mktemp("crop") / "model.ckpt", SIZE, width=0.25)


def test_crop_top_feeds_the_rest_of_the_frame_and_scores_the_top_not_road(ckpt: Path) -> None:
    frame = road_frame((64, 192), 3)[0]
    plain, cut = Predictor(checkpoint=ckpt), Predictor(checkpoint=ckpt, crop_top=0.25)  # 16 rows left out
    rest = cv2.resize(frame[16:], (SIZE[1], SIZE[0]), interpolation=cv2.INTER_AREA)
    direct = plain.infer([rest.transpose(2, 0, 1).astype(np.float32) / 255])[0]
    expected = cv2.resize(direct, (192, 48), interpolation=cv2.INTER_LINEAR)
    got = cut.predict(frame)[0]
    assert got.shape == frame.shape[:2] and not got[:16].any()
    np.testing.assert_allclose(got[16:], expected, atol=1e-5)
    assert not np.allclose(got[16:], plain.predict(frame)[0][16:], atol=1e-3)  # the rest is seen larger
    np.testing.assert_allclose(cut.restore(direct, frame.shape[:2]), got, atol=1e-6)  # prepare/infer/restore apart
    assert cut.prepare(frame).shape == (3, *SIZE)
    assert Predictor(checkpoint=ckpt, crop_top=0.69).predict(road_frame((2, 8), 0)[0])[0][1:].shape == (1, 8)
    for bad in (-0.1, 0.7, True, "0.3"):
        with pytest.raises(InvalidOptionError, match="crop_top is a fraction"):
            Predictor(checkpoint=ckpt, crop_top=bad)  # type: ignore[arg-type]


def test_predict_records_crop_top_and_refuses_to_mix(ckpt: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture) -> None:
    frames, labels = road_folders(tmp_path, SIZE)
    out = tmp_path / "out"
    assert main(["predict", "--checkpoint", str(ckpt), "--input", str(frames), "--out", str(out), "--crop-top",
                 "0.3", "--no-overlays", "--shard", "1/2"]) == 0
    records = [json.loads(p.read_text()) for p in out.glob("*.json") if "crop_top" in p.read_text()]
    assert records and all(r["crop_top"] == 0.3 for r in records), list(out.iterdir())
    refused(capsys, ["predict", "--checkpoint", str(ckpt), "--input", str(frames), "--out", str(out),
                     "--no-overlays", "--shard", "2/2"], match="crop_top 0.3 → 0.0")
    refused(capsys, ["predict", "--checkpoint", str(ckpt), "--input", str(frames), "--out", str(tmp_path / "bad"),
                     "--crop-top", "0.8"], match="--crop-top must be in [0, 0.7)")
    assert not (tmp_path / "bad").exists()
    ev = tmp_path / "eval"
    assert main(["evaluate", "--checkpoint", str(ckpt), "--images", str(frames), "--labels", str(labels),
                 "--label-format", "binary", "--out", str(ev), "--crop-top", "0.3", "--no-overlays"]) == 0
    assert json.loads((ev / "metrics.json").read_text())["crop_top"] == 0.3
