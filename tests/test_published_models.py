"""Publishing a real-road model (issue 45 §4): the float16 ONNX export (``freespace export --fp16``) and the
demo's last stage, which runs every published model (``models/<name>/model.onnx``) on the real example frames
shipped with it, as ``freespace predict --onnx`` does.

The network is a Fast-SCNN at half width trained for a few CPU seconds on generated frames at 32×96 (road: a
dark noisy band under a random horizon, below a bright texture): confident enough that its masks say
something, and large enough that its weights, not the graph, make most of its file (so float16 halves it).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.io.codecs import read_image, write_image

from helpers import road_frame, tiny_road_checkpoint

ort = pytest.importorskip("onnxruntime")

TRAIN_SIZE = (32, 96)
FRAME = (75, 250)



@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The checkpoint, its float32 and float16 ONNX exports (through the command) and the export's output."""
    base = tmp_path_factory.mktemp("published")
    ckpt = tiny_road_checkpoint(base / "model.ckpt", TRAIN_SIZE, width=0.5)
    f32, f16 = base / "f32.onnx", base / "f16.onnx"
    assert main(["export", "--checkpoint", str(ckpt), "--format", "onnx", "--out", str(f32)]) == 0
    assert main(["export", "--checkpoint", str(ckpt), "--format", "onnx", "--fp16", "--out", str(f16)]) == 0
    return {"base": base, "ckpt": ckpt, "f32": f32, "f16": f16}


# --- export --fp16 ---------------------------------------------------------------------------------------


def test_fp16_export_is_half_the_size_and_agrees_with_float32(files: dict[str, Path], capsys) -> None:
    """float16 weights: the file about half the float32 one (measured 0.52: the graph and the casts weigh
    little); the metadata kept; input and output float32; masks agree with float32's on ≥ 99 % of the pixels
    of frames it never saw (measured 99.9+ %)."""
    import onnx

    from freespace.inference.predictor import Predictor

    ratio = files["f16"].stat().st_size / files["f32"].stat().st_size
    assert 0.45 < ratio < 0.56, ratio
    proto = onnx.load(str(files["f16"]))
    meta = {p.key: p.value for p in proto.metadata_props}
    assert meta["model"] == "fastscnn" and json.loads(meta["image_size"]) == list(TRAIN_SIZE)
    assert "float16" in meta["precision"]
    assert any(t.data_type == onnx.TensorProto.FLOAT16 for t in proto.graph.initializer)
    assert not any(t.data_type == onnx.TensorProto.FLOAT for t in proto.graph.initializer if len(t.dims) == 4)
    assert [i.type.tensor_type.elem_type for i in (*proto.graph.input, *proto.graph.output)] == \
        [onnx.TensorProto.FLOAT] * 2
    f32, f16 = Predictor(onnx=files["f32"]), Predictor(onnx=files["f16"])
    assert f16.resize_to == TRAIN_SIZE and f16.name == "fastscnn"
    same = total = road = 0
    for i in range(8):
        image, truth = road_frame(FRAME, 700 + i)
        a, b = f32.predict([image])[0], f16.predict([image])[0]
        assert a.dtype == b.dtype == np.float32
        same, total, road = same + int(((a >= 0.5) == (b >= 0.5)).sum()), total + a.size, road + int((a >= 0.5).sum())
        assert float(np.abs(a - b).max()) < 0.05
    assert same / total >= 0.99
    assert 0.1 < road / total < 0.9  # the masks hold road and non-road: agreement is not that of empty masks


def test_fp16_export_prints_its_check(files: dict[str, Path], tmp_path: Path, capsys) -> None:
    out = tmp_path / "m.onnx"
    capsys.readouterr()
    assert main(["export", "--checkpoint", str(files["ckpt"]), "--format", "onnx", "--fp16", "--out", str(out)]) == 0
    printed = capsys.readouterr().out.strip()
    assert printed.startswith("onnx float16 → ") and "max probability difference" in printed and "agree on" in printed
    assert printed.count("\n") == 0
    assert out.read_bytes() == files["f16"].read_bytes()  # the same check inputs, the same file: repeatable


def test_predict_onnx_runs_the_fp16_model(files: dict[str, Path], tmp_path: Path, capsys) -> None:
    frames, out = tmp_path / "frames", tmp_path / "masks"
    for i in range(3):
        write_image(frames / f"f{i}.png", road_frame(FRAME, 900 + i)[0])
    assert main(["predict", "--onnx", str(files["f16"]), "--input", str(frames), "--out", str(out),
                 "--no-progress"]) == 0
    assert "3 frames in" in capsys.readouterr().out
    for i in range(3):
        assert read_image(out / f"f{i}.png").shape == FRAME
        assert read_image(out / "overlays" / f"f{i}.png").shape == (*FRAME, 3)
    assert json.loads((out / "summary.json").read_text())["model"] == "fastscnn"


def test_fp16_mistakes_are_one_line_and_write_nothing(files: dict[str, Path], tmp_path: Path, capsys) -> None:
    out = tmp_path / "m.onnx"
    cal = tmp_path / "cal"
    write_image(cal / "a.png", road_frame(FRAME, 1)[0])
    base = ["export", "--checkpoint", str(files["ckpt"]), "--fp16", "--out", str(out)]
    for extra, message in ((["--format", "onnx", "--int8", "--calibration", str(cal)], "--fp16 and --int8 exclude"),
                           (["--format", "onnx", "--int8"], "--fp16 and --int8 exclude"),
                           (["--format", "torchscript"], "--fp16 is for --format onnx")):
        assert main([*base, *extra]) == 2, extra
        err = capsys.readouterr().err.strip()
        assert message in err and err.count("\n") == 0, err
        assert not out.exists()


def test_fp16_beyond_its_tolerance_is_refused(files: dict[str, Path], tmp_path: Path, monkeypatch, capsys) -> None:
    """A float16 model that differs from its checkpoint by more than the tolerance is refused in one line,
    and no file is written: here the tolerance is set below the difference this model has."""
    import freespace.inference.export as export

    monkeypatch.setattr(export, "FP16_MAX_PROB_DIFF", 1e-9)
    out = tmp_path / "m.onnx"
    assert main(["export", "--checkpoint", str(files["ckpt"]), "--format", "onnx", "--fp16", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "in float16 the road probabilities differ" in err and "without --fp16" in err and err.count("\n") == 0
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_fp16_overflow_is_refused(tmp_path: Path, capsys) -> None:
    """Logits beyond float16's range (65 504) become infinite, their probabilities NaN: refused, not written."""
    import torch

    from freespace.models import create_model

    net = create_model("fastscnn", width=0.25)
    with torch.no_grad():  # the classifier's last layer scaled so that the logits overflow float16
        last = [m for m in net.modules() if isinstance(m, torch.nn.Conv2d)][-1]
        last.weight.mul_(1e6)
        if last.bias is not None:
            last.bias.fill_(1e6)
    ckpt, out = tmp_path / "big.ckpt", tmp_path / "big.onnx"
    hyper = {"model": "fastscnn", "model_options": {"num_classes": 2, "width": 0.25}, "image_size": list(TRAIN_SIZE)}
    torch.save({"hyper_parameters": hyper, "state_dict": {f"net.{k}": v for k, v in net.state_dict().items()}}, ckpt)
    assert main(["export", "--checkpoint", str(ckpt), "--format", "onnx", "--fp16", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "in float16 the road probabilities differ from the checkpoint's by up to nan" in err, err
    assert err.count("\n") == 0 and not out.exists()


# --- the demo's published models -------------------------------------------------------------------------


def _publish(folder: Path, name: str, onnx: Path, frames: int = 2) -> Path:
    """``folder/name/``: model.onnx, README.md and ``frames`` example PNGs with their LICENSE."""
    model = folder / name
    (model / "examples").mkdir(parents=True)
    (model / "model.onnx").write_bytes(onnx.read_bytes())
    (model / "README.md").write_text(f"# {name}\n")
    (model / "examples" / "LICENSE").write_text("generated frames, no licence needed\n")
    for i in range(frames):
        write_image(model / "examples" / f"frame{i}.png", road_frame(FRAME, 300 + i)[0])
    return model


def test_demo_runs_every_published_model_as_predict_does(files: dict[str, Path], tmp_path: Path,
                                                         monkeypatch) -> None:
    from freespace.demo import published_lines, run_published_models

    models = tmp_path / "models"
    _publish(models, "tiny-f16", files["f16"])
    _publish(models, "tiny-f32", files["f32"])
    (models / "notes").mkdir()  # a folder without model.onnx is no published model
    monkeypatch.setenv("FREESPACE_MODELS", str(models))
    out = tmp_path / "out"
    out.mkdir()
    results = run_published_models(out)
    assert [r["name"] for r in results] == ["tiny-f16", "tiny-f32"]
    for r in results:
        target = out / "real" / r["name"]
        assert r["out"] == str(target) and r["frames"] == 2 and r["frames_per_second"] > 0
        assert sorted(p.name for p in (target / "overlays").iterdir()) == ["frame0.png", "frame1.png"]
        # the same files as `freespace predict --onnx` writes for these examples
        ref = tmp_path / f"ref-{r['name']}"
        assert main(["predict", "--onnx", str(models / r["name"] / "model.onnx"), "--input",
                     str(models / r["name"] / "examples"), "--out", str(ref), "--no-progress"]) == 0
        for name in ("frame0.png", "frame1.png", "overlays/frame0.png", "overlays/frame1.png"):
            assert np.array_equal(read_image(target / name), read_image(ref / name)), name
    lines = published_lines(results)
    assert len(lines) == 2 and all("overlays in" in line and "frames per second" in line for line in lines)
    assert str(out / "real" / "tiny-f16" / "overlays") in lines[0]
    # a second run replaces its predictions (the folders are predict's own)
    assert [r.get("error") for r in run_published_models(out)] == [None, None]


def test_no_published_model_is_one_line(tmp_path: Path, monkeypatch) -> None:
    from freespace.demo import models_folder, published_lines, run_published_models

    monkeypatch.setenv("FREESPACE_MODELS", str(tmp_path / "nowhere"))
    assert models_folder() == tmp_path / "nowhere"
    assert run_published_models(tmp_path / "out") == []
    lines = published_lines([])
    assert len(lines) == 1 and "no published model in" in lines[0] and str(tmp_path / "nowhere") in lines[0]
    assert not (tmp_path / "out").exists()
    monkeypatch.delenv("FREESPACE_MODELS")
    import freespace

    assert models_folder() == Path(freespace.__file__).resolve().parents[1] / "models"


def test_a_broken_published_model_fails_alone(files: dict[str, Path], tmp_path: Path, monkeypatch) -> None:
    from freespace.demo import published_lines, run_published_models

    models = tmp_path / "models"
    _publish(models, "a-broken", files["f16"]).joinpath("model.onnx").write_bytes(b"not a model")
    _publish(models, "b-no-examples", files["f16"], frames=0)
    _publish(models, "c-good", files["f16"])
    results = run_published_models(tmp_path / "out", models)
    assert [r["name"] for r in results] == ["a-broken", "b-no-examples", "c-good"]
    assert "cannot load" in results[0]["error"] and "holds no example frames" in results[1]["error"]
    assert results[2]["frames"] == 2
    lines = published_lines(results, models)
    assert [("failed" in line) for line in lines] == [True, True, False] and all("\n" not in x for x in lines)


def test_run_demo_ends_with_the_published_models(files: dict[str, Path], tmp_path: Path, monkeypatch) -> None:
    from freespace.data.synthetic import SynthConfig
    from freespace.demo import OUT_ENTRIES, run_demo

    assert "real/" in OUT_ENTRIES
    models = tmp_path / "models"
    _publish(models, "tiny", files["f16"])
    monkeypatch.setenv("FREESPACE_MODELS", str(models))
    out = tmp_path / "demo"
    result = run_demo(out, num_frames=1, seed=4, config=SynthConfig(width=160, height=128, frames_per_scenario=1),
                      train=False, figures=1)
    assert result["models_folder"] == str(models)
    assert [r["name"] for r in result["real"]] == ["tiny"] and result["real"][0]["frames"] == 2
    assert (out / "real" / "tiny" / "overlays" / "frame0.png").is_file()
    assert json.loads((out / "demo_summary.json").read_text())["real"][0]["name"] == "tiny"
    manifest = json.loads((out / ".freespace" / "manifest.json").read_text())
    assert "real/" in json.dumps(manifest)


def test_demo_command_prints_one_line_per_published_model(files: dict[str, Path], tmp_path: Path, monkeypatch,
                                                          capsys) -> None:
    """`freespace demo`'s last lines, with the demo cut to one rendered frame and no training: a line per
    model (overlays, frame rate), exit code 1 when a model failed; with none, one line saying so, exit 0."""
    import freespace.demo as demo
    from freespace.data.synthetic import SynthConfig

    real_run = demo.run_demo

    def short(out, **_):
        return real_run(out, num_frames=1, seed=4, config=SynthConfig(width=160, height=128, frames_per_scenario=1),
                        train=False, figures=1)

    monkeypatch.setattr(demo, "run_demo", short)
    models = tmp_path / "models"
    monkeypatch.setenv("FREESPACE_MODELS", str(models))
    assert main(["demo", "--out", str(tmp_path / "d0")]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("real frames: no published model in ") and str(models) in last
    _publish(models, "good", files["f16"])
    assert main(["demo", "--out", str(tmp_path / "d1")]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert f"overlays in {tmp_path / 'd1' / 'real' / 'good' / 'overlays'}" in last and "frames per second" in last
    _publish(models, "bad", files["f16"]).joinpath("model.onnx").write_bytes(b"junk")
    assert main(["demo", "--out", str(tmp_path / "d2")]) == 1
    lines = capsys.readouterr().out.strip().splitlines()
    assert "model bad: failed: cannot load" in lines[-2] and "model good: 2 example frames" in lines[-1]


def _repository_models() -> list[Path]:
    import freespace
    from freespace.demo import published_models

    return published_models(Path(freespace.__file__).resolve().parents[1] / "models")


@pytest.mark.parametrize("model", _repository_models(), ids=lambda p: p.parent.name)
def test_every_published_model_is_complete(model: Path) -> None:
    """Each model the repository publishes (issues 45 §4 and 48): the ONNX file at most 25 MB,
    loadable by the predictor with its training size in its metadata; a card naming the data's licence, the
    input size and showing a picture; a few real example frames (PNG, at most 2 MB together) with their
    licence."""
    from freespace.inference.predictor import Predictor

    folder = model.parent
    assert model.stat().st_size <= 25 * 2**20
    predictor = Predictor(onnx=model)
    assert predictor.resize_to is not None
    card = (folder / "README.md").read_text()
    h, w = predictor.resize_to
    assert "CC BY-NC-SA 3.0" in card and (f"{h}×{w}" in card or f"{h}x{w}" in card) and "![" in card
    examples = sorted((folder / "examples").glob("*.png"))
    assert examples and sum(p.stat().st_size for p in examples) <= 2 * 2**20
    assert (folder / "examples" / "LICENSE").read_text().strip()
    for path in examples:
        assert read_image(path).ndim == 3
