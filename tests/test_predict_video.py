"""`freespace predict` on videos, folders and globs (checkpoint and ONNX), frame by frame, and `--shard K/N`.

The network is an untrained SegNet (⅛ width, batch-norm statistics from the test frames) saved as a
training checkpoint: these tests check what `predict` writes (frame counts, names, sizes, the overlay of
the predicted road), not the road it finds.
"""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.evaluation.metrics import to_confidence
from freespace.evaluation.viz import overlay_road
from freespace.inference.predict import predict_video
from freespace.io.codecs import read_image, write_image
from freespace.io.video import VideoWriter, open_frames

from helpers import textured_image

SHAPE = (96, 128)


def _frames(n: int, shape: tuple[int, int] = SHAPE) -> list[np.ndarray]:
    base = textured_image(shape, seed=1)
    return [np.roll(base, 3 * i, axis=1) for i in range(n)]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    import torch

    from freespace.models import create_model

    base = tmp_path_factory.mktemp("predict_video")
    torch.manual_seed(0)
    net = create_model("segnet", num_classes=2, width=0.125)
    # an untrained network's road probability is the same everywhere (its activations fade through the
    # decoder): batch-norm statistics from the frames and a classifier bias at the median make it vary
    # with the texture, road on about half of each frame (measured 45–50 %)
    frames = torch.from_numpy(np.stack(_frames(13))).permute(0, 3, 1, 2).float() / 255
    frames = torch.nn.functional.interpolate(frames, (64, 96))
    with torch.no_grad():
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.momentum = None
                m.reset_running_stats()
        net.train()(frames)
        logits = net.eval()(frames[:1])
        net.classifier.bias[1] -= (logits[:, 1] - logits[:, 0]).median()
    ckpt = base / "model.ckpt"
    hyper = {"model": "segnet", "model_options": {"num_classes": 2, "width": 0.125}, "image_size": [64, 96]}
    torch.save({"hyper_parameters": hyper,
                "state_dict": {f"net.{k}": v for k, v in net.state_dict().items()}}, ckpt)
    video = base / "in" / "drive.mp4"
    with VideoWriter(video, fps=12.0) as writer:
        for frame in _frames(13):
            writer.write(frame)
    for i, frame in enumerate(_frames(7)):
        write_image(base / "frames" / f"f{i}.png", frame)
    return {"base": base, "ckpt": ckpt, "video": video, "frames": base / "frames"}


def _predict(files: dict[str, Path], *args: str) -> int:
    return main(["predict", "--checkpoint", str(files["ckpt"]), "--no-progress", *args])


def test_video_round_trip(files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "out" / "drive_road.mp4"
    assert _predict(files, "--input", str(files["video"]), "--out", str(out), "--batch-size", "5") == 0
    printed = capsys.readouterr().out
    assert printed.startswith("13 frames") and "frames per second end to end" in printed
    assert sorted(p.name for p in out.parent.iterdir()) == ["drive_road.mp4"]      # nothing else, no temporary file
    source, result = open_frames(files["video"]), open_frames(out)
    assert (result.kind, result.fps, result.size) == ("video", 12.0, SHAPE)
    decoded = list(result)
    assert len(decoded) == len(list(source)) == 13                                 # the same frame count
    # every output frame is the overlay of the prediction of its input frame. MPEG-4 blurs the fine mask of
    # an untrained network, so frames are compared in 8×8-pixel block means: measured 2.2 grey levels from
    # the expected overlay, 15–17 from the inverted mask's, 25–31 from no overlay, 13–14 from the next frame's
    from freespace.inference.predictor import Predictor

    def blocks(image: np.ndarray) -> np.ndarray:
        return cv2.resize(image.astype(np.float32), (SHAPE[1] // 8, SHAPE[0] // 8), interpolation=cv2.INTER_AREA)

    predictor = Predictor(checkpoint=files["ckpt"])
    frames = list(source)
    for i in (0, 4, 8, 12):
        road = to_confidence(predictor.predict([frames[i].image])[0]) >= 128
        assert 0.2 < road.mean() < 0.8
        got = blocks(decoded[i].image)
        err = {name: float(np.abs(got - blocks(image)).mean()) for name, image in (
            ("expected", overlay_road(frames[i].image, road)), ("inverted", overlay_road(frames[i].image, ~road)),
            ("none", frames[i].image), ("neighbour", overlay_road(frames[i - 1 if i else 1].image, road)))}
        assert err["expected"] < 4 and min(v for k, v in err.items() if k != "expected") > 3 * err["expected"], err
    # the ONNX model writes the same video
    onnx = tmp_path / "m.onnx"
    assert main(["export", "--checkpoint", str(files["ckpt"]), "--format", "onnx", "--out", str(onnx)]) == 0
    out_onnx = tmp_path / "onnx.mp4"
    assert main(["predict", "--onnx", str(onnx), "--input", str(files["video"]), "--out", str(out_onnx),
                 "--no-progress"]) == 0
    via_onnx = list(open_frames(out_onnx))
    assert len(via_onnx) == 13
    assert max(np.abs(a.image.astype(int) - b.image.astype(int)).mean() for a, b in zip(decoded, via_onnx)) < 2


def test_folder_and_glob_inputs(files: dict[str, Path], tmp_path: Path) -> None:
    names = [f"f{i}" for i in range(7)]
    assert _predict(files, "--input", str(files["frames"]), "--out", str(tmp_path / "a")) == 0
    assert sorted(p.stem for p in (tmp_path / "a").glob("*.png")) == names
    assert sorted(p.stem for p in (tmp_path / "a" / "overlays").glob("*.png")) == names
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["frames"] == 7 and summary["frames_per_second"] > 0 and summary["seconds_per_frame"] > 0
    assert _predict(files, "--input", str(files["frames"] / "f[1-3].png"), "--out", str(tmp_path / "g")) == 0
    assert sorted(p.stem for p in (tmp_path / "g").glob("*.png")) == ["f1", "f2", "f3"]
    for name in ("f1", "f3"):
        a, g = read_image(tmp_path / "a" / f"{name}.png"), read_image(tmp_path / "g" / f"{name}.png")
        assert a.shape == SHAPE and np.abs(a.astype(int) - g.astype(int)).max() <= 1
    # frames into a video, and a video into per-frame PNGs
    assert _predict(files, "--input", str(files["frames"]), "--out", str(tmp_path / "frames.mp4")) == 0
    assert len(list(open_frames(tmp_path / "frames.mp4"))) == 7
    assert _predict(files, "--input", str(files["video"]), "--out", str(tmp_path / "v")) == 0
    assert sorted(p.name for p in (tmp_path / "v").glob("*.png"))[:2] == ["drive_000000.png", "drive_000001.png"]
    assert len(list((tmp_path / "v").glob("*.png"))) == 13


def test_predict_shards_cover_every_frame_once(files: dict[str, Path], tmp_path: Path) -> None:
    whole, shared = tmp_path / "whole", tmp_path / "shared"
    assert _predict(files, "--input", str(files["frames"]), "--out", str(whole)) == 0
    counts = []
    for k in (1, 2, 3):
        before = set(p.name for p in shared.glob("*.png")) if shared.is_dir() else set()
        assert _predict(files, "--input", str(files["frames"]), "--out", str(shared), "--shard", f"{k}/3") == 0
        mine = set(p.name for p in shared.glob("*.png")) - before
        summary = json.loads((shared / f"summary.shard-{k}-of-3.json").read_text())
        assert summary["shard"] == f"{k}/3" and summary["frames"] == len(mine)   # each shard writes only its frames
        counts.append(len(mine))
    assert counts == [3, 2, 2]
    assert sorted(p.name for p in shared.glob("*.png")) == sorted(p.name for p in whole.glob("*.png"))
    overlays = [sorted(p.name for p in (folder / "overlays").iterdir()) for folder in (shared, whole)]
    assert overlays[0] == overlays[1]
    for path in whole.glob("*.png"):
        assert np.abs(read_image(path).astype(int) - read_image(shared / path.name).astype(int)).max() <= 1
    assert json.loads((shared / "summary.json").read_text())["frames"] == 7  # the third shard completed the run
    # a shard past the end writes its (empty) summary; an unsharded run then replaces the folder whole
    few = tmp_path / "few"
    assert _predict(files, "--input", str(files["frames"]), "--out", str(few), "--shard", "9/9") == 0
    assert json.loads((few / "summary.shard-9-of-9.json").read_text())["frames"] == 0
    assert _predict(files, "--input", str(files["frames"]), "--out", str(few)) == 0
    assert sorted(p.name for p in few.glob("*.json")) == ["predict.json", "summary.json"]


def test_predict_mistakes_are_one_line(files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    video = files["video"]
    cases = [
        (["--input", str(video), "--out", str(video)], "is the input --input"),
        (["--input", str(video), "--out", str(tmp_path / "o.avi")], "must end in .mp4"),
        (["--input", str(video), "--out", str(tmp_path / "s"), "--shard", "1/2"], "a video is one output"),
        (["--input", str(files["frames"]), "--out", str(tmp_path / "o.mp4"), "--shard", "1/2"], "leave out --shard"),
        (["--input", str(files["frames"]), "--out", str(tmp_path / "s"), "--shard", "3/2"], "K/N with whole numbers"),
        (["--input", str(files["frames"]), "--out", str(files["frames"] / "o.mp4")], "lies inside the input"),
        (["--input", str(files["frames"] / "*.png"), "--out", str(files["frames"] / "p")], "lies inside the input"),
        (["--input", str(tmp_path / "none" / "*.png"), "--out", str(tmp_path / "p")], "no image file matches"),
        (["--input", str(video), "--out", str(tmp_path / "o.mp4"), "--batch-size", "0"],
         "--batch-size must be an integer in [1, 1024], got 0"),
    ]
    for args, message in cases:
        assert _predict(files, *args) == 2, args
        err = capsys.readouterr().err
        assert err.startswith("freespace: error:") and err.count("\n") == 1 and message in err, (args, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == []                        # no partial output anywhere
    assert sorted(p.name for p in files["frames"].iterdir()) == [f"f{i}.png" for i in range(7)]
    # frames of different sizes cannot make one video: one line, and no video is left
    mixed = tmp_path / "mixed"
    write_image(mixed / "a.png", _frames(1)[0])
    write_image(mixed / "b.png", _frames(1, (64, 64))[0])
    assert _predict(files, "--input", str(mixed), "--out", str(tmp_path / "m.mp4")) == 2
    assert "resize the frames to one size" in capsys.readouterr().err and not (tmp_path / "m.mp4").exists()


class _Threshold:
    """A stand-in network (no torch): road = bright pixels."""

    name, resize_to = "threshold", None

    def predict(self, images: list[np.ndarray]) -> list[np.ndarray]:
        return [(im.mean(axis=2) > 128).astype(np.float32) for im in images]


def test_video_memory_does_not_grow_with_length(tmp_path: Path) -> None:
    shape = (120, 160)
    frame_bytes = shape[0] * shape[1] * 3
    peaks = {}
    for n in (4, 20, 160):  # the first run (4 frames) imports what predict needs: not measured
        video = tmp_path / f"v{n}.mp4"
        with VideoWriter(video, fps=30) as writer:
            for frame in _frames(n, shape):
                writer.write(frame)
        tracemalloc.start()
        try:
            summary = predict_video(_Threshold(), video, tmp_path / f"o{n}.mp4", batch_size=4, progress=False)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        assert summary["frames"] == n
        peaks[n] = peak
    # measured (six runs each): peaks of 21.9–25.6 frames' size for 20 frames and 25.3–27.9 for 160 (a few
    # batches of 4 frames and their overlays in the reader's, the network's and the writer's bounded queues).
    # The threads fill those queues in an order that varies from run to run, so 160 frames (8× as many) meet a
    # fuller pipeline more often than 20: up to 1.20× the 20 frames' peak in CI on a clean clone. Memory that
    # grew with length would be several times it.
    assert peaks[160] < 40 * frame_bytes < 160 * frame_bytes
    assert peaks[160] < 1.5 * peaks[20]
