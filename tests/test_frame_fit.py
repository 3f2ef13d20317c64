"""Frames at their own aspect (issue 70, item 2): ``train --resize letterbox`` fits each frame to the input with its
aspect kept (the border don't care), the checkpoint and the ONNX file record it, and prediction fits frames the
same way; the default stays ``stretch``, as every earlier model was trained."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from freespace.cli import main
from freespace.io.frame_fit import content_box, fit, unfit
from freespace.labels import IGNORE_INDEX
from test_own_data import make_folder

from helpers import refused


def test_a_letterbox_keeps_the_aspect_and_comes_back() -> None:
    frame = np.zeros((360, 480, 3), np.uint8)
    frame[180:] = 200  # the lower half: road
    boxed = fit(frame, (192, 640), "letterbox")
    assert boxed.shape == (192, 640, 3) and content_box((360, 480), (192, 640)) == (0, 192, 192, 256)
    assert not boxed[:, :192].any() and not boxed[:, 448:].any()  # black borders
    assert (boxed[96:, 192:448] == 200).all() and not boxed[:95, 192:448].any()  # the horizon on the same row
    label = fit(np.ones((360, 480), np.uint8), (192, 640), "letterbox", label=True, fill=IGNORE_INDEX)
    assert (label[:, :192] == IGNORE_INDEX).all() and (label[:, 192:448] == 1).all()
    prob = (boxed[..., 0] / 255).astype(np.float32)
    back = unfit(prob, (360, 480), "letterbox")
    assert back.shape == (360, 480) and abs(back[200:].mean() - 200 / 255) < 1e-3 and back[:170].max() < 1e-3
    stretched = fit(frame, (192, 640), "stretch")
    assert stretched.shape == (192, 640, 3) and (stretched[100:] == 200).all()  # squeezed: every column is road
    assert unfit(prob, (192, 640), "letterbox") is prob  # nothing to do at the input's size


@pytest.mark.parametrize("size", [(64, 64), (64, 192), (100, 37)])
def test_content_box_fits_inside(size: tuple[int, int]) -> None:
    for src in ((375, 1242), (360, 480), (1080, 1920), (7, 500)):
        y0, x0, h, w = content_box(src, size)
        assert 0 <= y0 and 0 <= x0 and y0 + h <= size[0] and x0 + w <= size[1] and h >= 1 and w >= 1
        assert h == size[0] or w == size[1]  # one side fills the input


def test_letterbox_trains_records_and_predicts_so(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, labels = make_folder(tmp_path / "data", 6, "binary")  # 64×96 frames
    run = tmp_path / "run"
    assert main(["train", "--images", str(images), "--labels", str(labels), "--label-format", "binary", "--out",
                 str(run), "--model", "segnet", "--batch-size", "2", "--epochs", "1", "--image-size", "64x64",
                 "--resize", "letterbox", "--no-progress"]) == 0
    ckpt = run / "checkpoints" / "best.ckpt"
    assert torch.load(ckpt, weights_only=True)["hyper_parameters"]["resize"] == "letterbox"
    from freespace.inference.predictor import Predictor

    frame = np.random.default_rng(0).integers(0, 255, (64, 96, 3), dtype=np.uint8)
    predictor = Predictor(checkpoint=ckpt)
    assert predictor.resize == "letterbox"
    expected = unfit(predictor.infer([fit(frame, (64, 64), "letterbox").transpose(2, 0, 1).astype(np.float32)
                                      / 255])[0], (64, 96), "letterbox")
    np.testing.assert_allclose(predictor.predict(frame)[0], expected, atol=1e-6)
    onnx = tmp_path / "model.onnx"
    assert main(["export", "--checkpoint", str(ckpt), "--format", "onnx", "--out", str(onnx)]) == 0
    exported = Predictor(onnx=onnx)
    assert exported.resize == "letterbox"
    assert ((exported.predict(frame)[0] >= 0.5) == (expected >= 0.5)).mean() > 0.99
    # fine-tuning from it keeps its way
    ft = tmp_path / "ft"
    assert main(["train", "--images", str(images), "--labels", str(labels), "--label-format", "binary", "--out",
                 str(ft), "--batch-size", "2", "--epochs", "1", "--init", str(ckpt), "--no-progress"]) == 0
    assert yaml.safe_load((ft / "config.yaml").read_text())["resize"] == "letterbox"
    assert torch.load(ft / "checkpoints" / "best.ckpt", weights_only=True)["hyper_parameters"]["resize"] == "letterbox"
    assert json.loads((ft / "metrics.json").read_text())["init"]["path"] == str(ckpt.resolve())


def test_letterbox_refuses_what_it_cannot_do(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    refused(capsys, ["train", "--dataset", "kitti", "--root", str(tmp_path), "--out", str(tmp_path / "o"),
                     "--augment", "virtual", "--resize", "letterbox"], match="virtual takes stretched frames")
    refused(capsys, ["train", "--dataset", "kitti", "--root", str(tmp_path), "--out", str(tmp_path / "o"),
                     "--resize", "crop"], match="resize")
