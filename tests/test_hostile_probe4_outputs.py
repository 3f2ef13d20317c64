"""Hostile probe 4 (issue 59), classes 1, 3, 4 and 5: what `predict` and `export` write, tried as an attacker would.

1. Two inputs, one output. Frames are named by the image's file name without its suffix: two images of a
   folder or a glob whose names differ only in the suffix (``a.png``, ``a.jpg``, ``a.bmp``, ``a.tiff``) or in
   letter case (``a.PNG`` and ``a.png``, ``A.png`` and ``a.png``) are refused in one line naming both, for
   every way frames are read (a folder, a glob, a video ``--out``, a shard), before anything is written.
3. A model that returns nothing. An ONNX model or a checkpoint whose class scores hold NaN or infinity (all
   of them, or a few pixels) is refused in one line naming the model file; no mask, no video is written.
4. Outputs that replace a user's file. A file output (``export --out``, ``predict --out V.mp4``,
   ``evaluate-kitti --out``, ``generate``'s files) that exists and was not written by
   the same command is refused and left as it was, also when it is planted after the up-front check; the
   command's own output is replaced on a rerun. The name fits the output: ``export`` writes ``.onnx`` or
   ``.pt``, a video ``--out`` is ``.mp4`` (never ``x.mp4/``), an output folder never ends in a file's suffix
   (``--out x.png``); nothing is created where it refuses.
5. Shards that mix. The shards of one ``predict`` run share their folder; a shard made with another model,
   another input (same names elsewhere), another N or other overlays, or one that joins the output of a whole
   run (or of an older one with no record), is refused and the folder left as it was. The shard that
   completes the N writes ``summary.json`` (``--shard 1/1`` too); a whole run replaces every shard's files.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.errors import CorruptFileError, OutputError
from freespace.io.codecs import write_image
from freespace.io.files import MARK, check_writable, write_files_together

from helpers import refused, synthetic_pair, textured_image

SHAPE = (48, 64)

# ------------------------------------------------------------------------------------------------- helpers


def _onnx(path: Path, scale: float, log: bool = False) -> Path:
    """An ONNX road model: the first two channels of the image, times ``scale`` (NaN or inf: a broken model),
    with ``log`` their logarithm (−inf at a black pixel only)."""
    import onnx
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("image", TensorProto.FLOAT, ["n", 3, "h", "w"])
    y = helper.make_tensor_value_info("logits", TensorProto.FLOAT, ["n", 2, "h", "w"])
    consts = [helper.make_tensor("starts", TensorProto.INT64, [1], [0]),
              helper.make_tensor("ends", TensorProto.INT64, [1], [2]),
              helper.make_tensor("axes", TensorProto.INT64, [1], [1]),
              helper.make_tensor("scale", TensorProto.FLOAT, [], [scale])]
    nodes = [helper.make_node("Slice", ["image", "starts", "ends", "axes"], ["two"]),
             helper.make_node("Mul", ["two", "scale"], ["scaled" if log else "logits"])]
    if log:
        nodes.append(helper.make_node("Log", ["scaled"], ["logits"]))
    graph = helper.make_graph(nodes, path.stem, [x], [y], initializer=consts)
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), path)
    return path


def _frames(folder: Path, names: list[str]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for i, name in enumerate(names):
        write_image(folder / name, textured_image(SHAPE, seed=i))
    return folder


def _state(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (its manifest included, its empty lock files left out) and its bytes."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.suffix != ".lock"}


def _predict(model: Path, inputs: Path | str, out: Path, *extra: str) -> list[str]:
    return ["predict", "--onnx", str(model), "--input", str(inputs), "--out", str(out), "--no-progress", *extra]


@pytest.fixture(scope="module")
def models(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """ONNX models (``good``, ``other``: finite scores; ``nan``, ``inf``, ``ninf``: broken; ``log``: −inf at black
    pixels), a checkpoint (``ckpt``) and one whose scores overflow (``overflow``)."""
    import torch

    from freespace.models import create_model

    base = tmp_path_factory.mktemp("probe4")
    models = {name: _onnx(base / f"{name}.onnx", scale) for name, scale in
              (("good", 4.0), ("other", -4.0), ("nan", float("nan")), ("inf", float("inf")), ("ninf", float("-inf")))}
    models["log"] = _onnx(base / "log.onnx", 1.0, log=True)
    torch.manual_seed(0)
    net = create_model("segnet", num_classes=2, width=0.125)
    hyper = {"model": "segnet", "model_options": {"num_classes": 2, "width": 0.125}, "image_size": [32, 48]}
    torch.save({"hyper_parameters": hyper, "state_dict": {f"net.{k}": v for k, v in net.state_dict().items()}},
               base / "model.ckpt")
    models["ckpt"] = base / "model.ckpt"
    with torch.no_grad():  # finite weights whose activations overflow float32: infinity, then NaN
        for weight in net.parameters():
            if weight.dim() == 4:
                weight.mul_(1e12)
    torch.save({"hyper_parameters": hyper, "state_dict": {f"net.{k}": v for k, v in net.state_dict().items()}},
               base / "overflow.ckpt")
    models["overflow"] = base / "overflow.ckpt"
    return models


# ------------------------------------------------------------------------------ 1. two inputs, one output

CLASHES = {"suffix": ["a.png", "a.jpg"], "four suffixes": ["one.png", "one.jpg", "one.bmp", "one.tiff"],
           "suffix case": ["a.png", "a.PNG"], "name case": ["A.png", "a.png"],
           "among others": ["b.png", "c.png", "frame_2.png", "Frame_2.jpeg"]}


@pytest.mark.parametrize("case", sorted(CLASHES))
@pytest.mark.parametrize("how", ["folder", "glob", "video", "shard"])
def test_two_images_with_one_frame_name_are_refused(case: str, how: str, models: dict[str, Path], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    names = CLASHES[case]
    folder = _frames(tmp_path / "in", names)
    if len(list(folder.iterdir())) < len(names):
        pytest.skip("this file system folds letter case")
    inputs = str(folder / "*") if how == "glob" else folder
    out = tmp_path / ("v.mp4" if how == "video" else "p")
    extra = ["--shard", "2/2"] if how == "shard" else []
    err = refused(capsys, _predict(models["good"], inputs, out, *extra), match="one frame name")
    assert sum(f"{folder}/{n}" in err for n in names) == 2, err  # the two that clash
    assert not out.exists()


def test_names_that_differ_only_in_their_suffixes_case_elsewhere_pass(models: dict[str, Path], tmp_path: Path) -> None:
    folder = _frames(tmp_path / "in", ["a.PNG", "b.png", "c.JPG"])
    assert main(_predict(models["good"], folder, tmp_path / "p")) == 0
    assert sorted(p.name for p in (tmp_path / "p").glob("*.png")) == ["a.png", "b.png", "c.png"]
    assert json.loads((tmp_path / "p" / "summary.json").read_text())["frames"] == 3


def test_the_library_refuses_the_clash_too(tmp_path: Path) -> None:
    from freespace.errors import InputFileError
    from freespace.io.video import open_frames

    _frames(tmp_path / "in", ["x.png", "x.bmp"])
    with pytest.raises(InputFileError, match="one frame name"):
        open_frames(tmp_path / "in")


# ------------------------------------------------------------------------ 3. a model that returns nothing

@pytest.mark.parametrize("model", ["nan", "inf", "ninf", "overflow"])
@pytest.mark.parametrize("out", ["p", "v.mp4"])
def test_a_model_with_nan_or_infinite_scores_is_refused(model: str, out: str, models: dict[str, Path],
                                                        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    folder = _frames(tmp_path / "in", ["a.png", "b.png", "c.png"])
    flag = "--checkpoint" if model == "overflow" else "--onnx"
    argv = ["predict", flag, str(models[model]), "--input", str(folder), "--out", str(tmp_path / out), "--no-progress"]
    err = refused(capsys, argv, match="NaN or infinite")
    assert str(models[model]) in err
    assert not (tmp_path / out).exists()


def test_a_few_nan_pixels_are_refused(models: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Scores finite but at one pixel: a model taking the logarithm, on a frame with one black pixel."""
    image = np.maximum(textured_image(SHAPE, seed=0), 1)
    write_image(tmp_path / "fine.png", image)
    assert main(_predict(models["log"], tmp_path / "fine.png", tmp_path / "ok")) == 0
    image[5, 7] = 0
    write_image(tmp_path / "one.png", image)
    err = refused(capsys, _predict(models["log"], tmp_path / "one.png", tmp_path / "p"), match="NaN or infinite")
    assert "log.onnx" in err and not (tmp_path / "p").exists()


@pytest.mark.parametrize("fmt", ["onnx", "torchscript"])
def test_a_checkpoint_with_nan_or_infinite_scores_is_not_exported(fmt: str, models: dict[str, Path], tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / ("m.onnx" if fmt == "onnx" else "m.pt")
    err = refused(capsys, ["export", "--checkpoint", str(models["overflow"]), "--format", fmt, "--out", str(out)],
                  match="NaN or infinite")
    assert "overflow.ckpt" in err and not out.exists()


def test_a_broken_model_leaves_an_earlier_output_as_it_was(models: dict[str, Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture) -> None:
    folder = _frames(tmp_path / "in", ["a.png", "b.png"])
    assert main(_predict(models["good"], folder, tmp_path / "p")) == 0
    before = _state(tmp_path / "p")
    refused(capsys, _predict(models["nan"], folder, tmp_path / "p"), match="nan.onnx")
    assert _state(tmp_path / "p") == before


def test_the_predictor_refuses_it_in_the_library(models: dict[str, Path]) -> None:
    from freespace.inference.predictor import Predictor

    image = textured_image(SHAPE, seed=0)
    for name in ("nan", "overflow"):
        kind = "checkpoint" if name == "overflow" else "onnx"
        with pytest.raises(CorruptFileError, match="NaN or infinite"):
            Predictor(**{kind: models[name]}).predict([image])
    good = Predictor(onnx=models["good"]).predict([image])[0]
    assert np.isfinite(good).all() and good.shape == SHAPE


# ------------------------------------------------------------------- 4. outputs that replace a user's file

def _file_commands(models: dict[str, Path], tmp: Path) -> dict[str, tuple[str, object]]:
    """Commands with one output file each: option → (suffix of its file, argv for an output ``x``)."""
    left, right, label, _ = synthetic_pair((96, 160))
    inp = tmp / "inputs"
    inp.mkdir()
    for name, image in (("L", left), ("R", right), ("M", (label.road & label.valid).astype(np.uint8) * 255)):
        write_image(inp / f"{name}.png", image)
    gt, pred = tmp / "gt", tmp / "pred"
    label_rgb = np.zeros((40, 60, 3), np.uint8)
    label_rgb[..., 0], label_rgb[20:, :, 2] = 255, 255
    write_image(gt / "um_road_000000.png", label_rgb)
    write_image(pred / "um_road_000000.png", np.where(np.arange(40)[:, None] >= 18, 230, 0).repeat(60, 1)
                .astype(np.uint8))
    gen = ["generate", "--reference", str(inp / "L.png"), "--target", str(inp / "R.png"), "--road-mask",
           str(inp / "M.png")]
    ckpt = str(models["ckpt"])
    return {
        "export onnx": (".onnx", lambda x: ["export", "--checkpoint", ckpt, "--format", "onnx", "--out", str(x)]),
        "export torchscript": (".pt", lambda x: ["export", "--checkpoint", ckpt, "--format", "torchscript", "--out",
                                                 str(x)]),
        "predict video": (".mp4", lambda x: _predict(models["good"], inp / "L.png", x)),
        "evaluate-kitti": (".json", lambda x: ["evaluate-kitti", "--gt", str(gt), "--pred", str(pred), "--out",
                                               str(x)]),
        "generate --out": (".png", lambda x: [*gen, "--out", str(x)]),
        "generate --model-json": (".json", lambda x: [*gen, "--out", str(tmp / "G.png"), "--model-json", str(x)]),
    }


FILE_COMMANDS = ["export onnx", "export torchscript", "predict video", "evaluate-kitti", "generate --out",
                 "generate --model-json"]


@pytest.mark.parametrize("option", FILE_COMMANDS)
def test_a_file_the_command_did_not_write_is_never_replaced(option: str, models: dict[str, Path], tmp_path: Path,
                                                            capsys: pytest.CaptureFixture) -> None:
    suffix, argv = _file_commands(models, tmp_path)[option]
    mine = tmp_path / f"notes{suffix}"
    mine.write_bytes(b"my holiday, not a freespace output\n")
    err = refused(capsys, argv(mine), match="did not write")
    assert "move it away or choose another path" in err
    assert mine.read_bytes() == b"my holiday, not a freespace output\n"
    # its own output is replaced by a rerun; a copy without the mark is a user's file again
    own = tmp_path / f"own{suffix}"
    assert main(argv(own)) == 0
    assert os.getxattr(own, MARK) == option.split()[0].encode()
    assert main(argv(own)) == 0
    shutil.copyfile(own, mine)
    refused(capsys, argv(mine), match="did not write")


@pytest.mark.parametrize("option", ["--out", "--confidence", "--model-json"])
def test_a_users_file_is_refused_before_any_work(option: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """``autolabel`` checks its inputs against its outputs first: the mark is checked there too (on this
    pair the work itself would fail, with another message)."""
    left, right, _, _ = synthetic_pair((96, 160))
    write_image(tmp_path / "L.png", left)
    write_image(tmp_path / "R.png", right)
    mine = tmp_path / ("mine.json" if option == "--model-json" else "mine.png")
    mine.write_bytes(b"mine")
    argv = ["autolabel", "--reference", str(tmp_path / "L.png"), "--target", str(tmp_path / "R.png")]
    argv += [option, str(mine)] if option == "--out" else ["--out", str(tmp_path / "A.png"), option, str(mine)]
    refused(capsys, argv, match="did not write")
    assert mine.read_bytes() == b"mine" and not (tmp_path / "A.png").exists()


def test_a_file_another_command_wrote_is_not_replaced(models: dict[str, Path], tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    commands = _file_commands(models, tmp_path)
    target = tmp_path / "result.json"
    assert main(commands["generate --model-json"][1](target)) == 0
    before = target.read_bytes()
    refused(capsys, commands["evaluate-kitti"][1](target), match="output of freespace generate")
    assert target.read_bytes() == before
    # and the Python API's files are not the command line's
    write_files_together({tmp_path / "api.json": b"{}"})
    refused(capsys, commands["evaluate-kitti"][1](tmp_path / "api.json"), match="Python API")


def test_a_file_planted_after_the_check_is_not_replaced(tmp_path: Path) -> None:
    from freespace.io.video import VideoWriter

    for name in ("late.json", "late.mp4"):
        target = tmp_path / name
        check_writable(target)  # the command's up-front check: nothing there yet
        target.write_bytes(b"planted\n")
        with pytest.raises(OutputError, match="did not write"):
            if name.endswith(".json"):
                write_files_together({target: b"{}"})
            else:
                with VideoWriter(target, fps=10) as video:
                    video.write(np.zeros((16, 16, 3), np.uint8))
        assert target.read_bytes() == b"planted\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["late.json", "late.mp4"]  # no temporary file left


def test_a_link_is_replaced_as_a_link(models: dict[str, Path], tmp_path: Path) -> None:
    """The file it leads to is never written (nor checked): the link itself becomes the output."""
    target = tmp_path / "mine.onnx"
    target.write_bytes(b"mine")
    link = tmp_path / "m.onnx"
    link.symlink_to(target)
    assert main(["export", "--checkpoint", str(models["ckpt"]), "--format", "onnx", "--out", str(link)]) == 0
    assert not link.is_symlink() and target.read_bytes() == b"mine"


WRONG_NAMES = {
    "onnx to .mp4": (["export", "--format", "onnx"], "m.mp4", "must end in .onnx"),
    "onnx to .pt": (["export", "--format", "onnx"], "m.pt", "must end in .onnx"),
    "torchscript to .onnx": (["export", "--format", "torchscript"], "m.onnx", "must end in .pt or .pth"),
    "onnx to no suffix": (["export", "--format", "onnx"], "model", "must end in .onnx"),
    "onnx to m.onnx/": (["export", "--format", "onnx"], "m.onnx/", "ends in /"),
    "video x.mp4/": (["predict"], "x.mp4/", "ends in /"),
    "folder x.png": (["predict"], "x.png", "ends in .png"),
    "folder x.json": (["predict"], "x.json", "ends in .json"),
    "folder x.onnx with --shard": (["predict", "--shard", "1/2"], "x.onnx", "ends in .onnx"),
}


@pytest.mark.parametrize("case", sorted(WRONG_NAMES))
def test_the_name_fits_the_output(case: str, models: dict[str, Path], tmp_path: Path,
                                  capsys: pytest.CaptureFixture) -> None:
    command, name, match = WRONG_NAMES[case]
    folder = _frames(tmp_path / "in", ["a.png"])
    out = f"{tmp_path}/{name}"
    model = ["--checkpoint", str(models["ckpt"])] if command[0] == "export" else \
        ["--onnx", str(models["good"]), "--input", str(folder)]
    refused(capsys, [*command, *model, "--out", out], match=match)  # the --out as typed: a trailing / kept
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_evaluate_kitti_writes_json_only(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "gt").mkdir()
    (tmp_path / "pred").mkdir()
    refused(capsys, ["evaluate-kitti", "--gt", str(tmp_path / "gt"), "--pred", str(tmp_path / "pred"), "--out",
                     str(tmp_path / "holiday.mp4")], match="must end in .json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gt", "pred"]


@pytest.mark.parametrize("command", ["evaluate", "train", "kitti-submit"])
def test_other_output_folders_never_end_in_a_file_suffix(command: str, models: dict[str, Path], tmp_path: Path,
                                                         capsys: pytest.CaptureFixture) -> None:
    out = str(tmp_path / "results.csv")
    argv = {"evaluate": ["evaluate", "--checkpoint", str(models["ckpt"]), "--dataset", "synth", "--root",
                         str(tmp_path), "--out", out],
            "train": ["train", "--dataset", "synth", "--root", str(tmp_path), "--out", out],
            "kitti-submit": ["kitti-submit", "--checkpoint", str(models["ckpt"]), "--root", str(tmp_path), "--out",
                             out]}[command]
    refused(capsys, argv, match="ends in .csv")
    assert not Path(out).exists()


# --------------------------------------------------------------------------------------- 5. shards that mix

@pytest.fixture
def frames(tmp_path: Path) -> Path:
    return _frames(tmp_path / "in", [f"f{i}.png" for i in range(5)])


def _refused_into(capsys: pytest.CaptureFixture, argv: list[str], out: Path, match: str) -> None:
    before = _state(out)
    err = refused(capsys, argv, match="made otherwise")
    assert match in err, err
    assert _state(out) == before


def test_a_shard_of_another_model_is_refused(models: dict[str, Path], frames: Path, tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "p"
    assert main(_predict(models["good"], frames, out, "--shard", "1/2")) == 0
    _refused_into(capsys, _predict(models["other"], frames, out, "--shard", "2/2"), out, "model_sha256")
    _refused_into(capsys, ["predict", "--checkpoint", str(models["ckpt"]), "--input", str(frames), "--out", str(out),
                           "--no-progress", "--shard", "2/2"], out, "model")


def test_a_shard_of_other_inputs_or_another_count_is_refused(models: dict[str, Path], frames: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "p"
    assert main(_predict(models["good"], frames, out, "--shard", "1/2")) == 0
    twin = tmp_path / "right"  # the same names in another folder (KITTI's image_2 and image_3)
    shutil.copytree(frames, twin)
    _refused_into(capsys, _predict(models["good"], twin, out, "--shard", "2/2"), out, "input")
    _refused_into(capsys, _predict(models["good"], str(frames / "f[0-3].png"), out, "--shard", "2/2"), out, "frames")
    _refused_into(capsys, _predict(models["good"], frames, out, "--shard", "2/3"), out, "shards 2 → 3")
    _refused_into(capsys, _predict(models["good"], frames, out, "--shard", "2/2", "--no-overlays"), out, "overlays")
    assert main(_predict(models["good"], frames, out, "--shard", "2/2")) == 0  # the same run's other shard joins


def test_a_shard_never_joins_a_whole_run(models: dict[str, Path], frames: Path, tmp_path: Path,
                                         capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "p"
    assert main(_predict(models["good"], frames, out)) == 0
    _refused_into(capsys, _predict(models["good"], frames, out, "--shard", "1/2"), out, "shards None → 2")
    # an output with no record (an older version's): what made it is unknown
    (out / "predict.json").unlink()
    _refused_into(capsys, _predict(models["good"], frames, out, "--shard", "1/2"), out, "no readable predict.json")


def test_the_shards_of_one_run_make_one_summary(models: dict[str, Path], frames: Path, tmp_path: Path) -> None:
    out = tmp_path / "p"
    assert main(_predict(models["good"], frames, out, "--shard", "2/2")) == 0
    assert not (out / "summary.json").exists()
    assert main(_predict(models["good"], frames, out, "--shard", "1/2")) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 5 and summary["shards"] == 2
    assert sorted(p.name for p in out.glob("*.png")) == [f"f{i}.png" for i in range(5)]
    # a whole run replaces them all: no shard's summary stays
    assert main(_predict(models["other"], frames, out)) == 0
    assert sorted(p.name for p in out.glob("summary*.json")) == ["summary.json"]
    assert json.loads((out / "predict.json").read_text())["shards"] is None


def test_one_shard_of_one_is_the_whole_summary(models: dict[str, Path], frames: Path, tmp_path: Path) -> None:
    out = tmp_path / "p"
    assert main(_predict(models["good"], frames, out, "--shard", "1/1")) == 0
    assert json.loads((out / "summary.json").read_text())["frames"] == 5
    assert json.loads((out / "summary.shard-1-of-1.json").read_text())["frames"] == 5
