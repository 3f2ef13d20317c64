"""Prediction with test-time augmentation (``predict --tta``, ``Predictor(tta=True)``): each frame seen with its
light normalised (adapt's teacher's view) and averaged with its mirror image; recorded where it was used."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.data.photometry import normalise_light
from freespace.errors import InvalidOptionError
from freespace.inference.predictor import Predictor

from helpers import refused, road_folders, road_frame, tiny_road_checkpoint

SIZE = (32, 96)


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_road_checkpoint(tmp_path_factory.mktemp("tta") / "model.ckpt", SIZE, width=0.25)


def test_tta_is_the_mean_of_the_normalised_frame_and_its_mirror(ckpt: Path) -> None:
    frame = road_frame((64, 192), 3)[0]  # twice the network's size: resized first, then normalised
    plain, tta = Predictor(checkpoint=ckpt), Predictor(checkpoint=ckpt, tta=True)
    small = normalise_light(cv2.resize(frame, (SIZE[1], SIZE[0]), interpolation=cv2.INTER_AREA))
    direct = plain.infer([small.transpose(2, 0, 1).astype(np.float32) / 255])[0]
    mirrored = plain.infer([np.ascontiguousarray(small[:, ::-1]).transpose(2, 0, 1).astype(np.float32) / 255])[0]
    expected = plain.restore((direct + mirrored[:, ::-1]) / 2, frame.shape[:2])
    got = tta.predict(frame)[0]
    assert got.shape == frame.shape[:2]
    np.testing.assert_allclose(got, expected, atol=1e-5)
    assert not np.allclose(got, plain.predict(frame)[0], atol=1e-3)  # it changes something
    # the same for a float frame in [0, 1] (resized in float, then to 8 bits for the normaliser: the masks agree)
    assert ((tta.predict(frame.astype(np.float32) / 255)[0] >= 0.5) == (got >= 0.5)).mean() > 0.99
    with pytest.raises(InvalidOptionError, match="tta is True or False"):
        Predictor(checkpoint=ckpt, tta="yes")  # type: ignore[arg-type]


def test_predict_records_tta_and_refuses_to_mix(ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    frames, labels = road_folders(tmp_path, SIZE)
    out = tmp_path / "out"
    assert main(["predict", "--checkpoint", str(ckpt), "--input", str(frames), "--out", str(out), "--tta",
                 "--no-overlays", "--shard", "1/2"]) == 0
    records = [json.loads(p.read_text()) for p in out.glob("*.json") if "tta" in p.read_text()]
    assert records and all(r["tta"] is True for r in records), list(out.iterdir())
    refused(capsys, ["predict", "--checkpoint", str(ckpt), "--input", str(frames), "--out", str(out),
                     "--no-overlays", "--shard", "2/2"], match="tta True → False")
    ev = tmp_path / "eval"
    assert main(["evaluate", "--checkpoint", str(ckpt), "--images", str(frames), "--labels", str(labels),
                 "--label-format", "binary", "--out", str(ev), "--tta", "--no-overlays"]) == 0
    assert json.loads((ev / "metrics.json").read_text())["tta"] is True
