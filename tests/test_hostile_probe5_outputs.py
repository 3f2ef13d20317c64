"""Hostile probe 5 (issue 72): output atomicity, outputs over inputs, user regexes, propagation's sizes, the house.

1. A signal during the final move. SIGINT, SIGTERM or SIGHUP that arrives while a stage's files are moved into
   place (``predict``, ``evaluate``, ``adapt``'s model folder; several files written together) waits for the move:
   every file of the run is in place, and the command then ends as the signal says; one that arrives before the
   move leaves the folder as it was. Never some of the files.
2. An output over an input through a symbolic link. A folder or glob input (``predict``'s frames, ``evaluate``'s
   labels and images, ``adapt``'s frames, a dataset root at any depth) holding a link to a file of ``--out``, or
   into it, is refused in one line before anything is read, as the single file is.
3. A user's regular expression that backtracks. A generic layout's ``scenario_pattern`` with nested quantifiers
   (``(a+)+``, ``(\\w+\\s?)+``, ``(ab|a)*``, ``(a?){25}``, ``(.*a){12}``), a backreference or too many characters is
   refused in one line that states the rule; one that the rule lets through but backtracks over long names
   (``.*.*.*.*=``) is refused after a time limit, not minutes later.
4. Propagation's inputs. ``autolabel --propagate-from`` with a label or confidence map of another size than its
   frame is refused in one line naming both files and sizes (no traceback); a file where the tree's folder is
   wanted is called a file, not "not found".
5. The house. The product's tests read nothing of ``studies/`` (a checkout may have none); the modules that the
   next issues grow (labelling, propagation, a study's protocol) are each at most 400 lines, their public names
   importable from where they were.
"""

from __future__ import annotations

import ast
import json
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.errors import InvalidOptionError, Terminated
from freespace.io import outdir
from freespace.io.codecs import write_image
from freespace.io.files import check_outputs, write_files_together
from freespace.io.outdir import claim_folder
from freespace.runtime.signals import sigterm_raises

from helpers import refused, textured_image

ROOT = Path(__file__).resolve().parents[1]
SHAPE = (48, 64)

# ------------------------------------------------------------------------------------------------- helpers


class Hangup(Exception):
    """What the test's SIGHUP handler raises (Python's default for SIGHUP ends the process)."""


@pytest.fixture
def hangup_raises():
    """SIGHUP raises :class:`Hangup` for the test (restored after)."""
    def handler(signum: int, frame: object) -> None:
        raise Hangup()

    previous = signal.signal(signal.SIGHUP, handler)
    yield
    signal.signal(signal.SIGHUP, previous)


#: each signal, and what it raises in a command (SIGHUP: the test's handler)
SIGNALS = [(signal.SIGTERM, Terminated), (signal.SIGINT, KeyboardInterrupt), (signal.SIGHUP, Hangup)]


def _signal_after_first_move(monkeypatch: pytest.MonkeyPatch, signum: int) -> list[Path]:
    """Send ``signum`` to this process right after the stage's first file is moved into place; the targets moved."""
    real, moved = outdir._move, []

    def move(path: Path, target: Path, old: os.stat_result | None) -> None:
        real(path, target, old)
        moved.append(target)
        if len(moved) == 1:
            os.kill(os.getpid(), signum)

    monkeypatch.setattr(outdir, "_move", move)
    return moved


def _onnx(path: Path) -> Path:
    """An ONNX road model: the first two channels of the image as its class scores (any size)."""
    import onnx
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("image", TensorProto.FLOAT, ["n", 3, "h", "w"])
    y = helper.make_tensor_value_info("logits", TensorProto.FLOAT, ["n", 2, "h", "w"])
    consts = [helper.make_tensor("starts", TensorProto.INT64, [1], [0]),
              helper.make_tensor("ends", TensorProto.INT64, [1], [2]),
              helper.make_tensor("axes", TensorProto.INT64, [1], [1])]
    graph = helper.make_graph([helper.make_node("Slice", ["image", "starts", "ends", "axes"], ["logits"])], "road",
                              [x], [y], initializer=consts)
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), path)
    return path


def _frames(folder: Path, n: int) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        write_image(folder / f"f{i:02d}.png", textured_image(SHAPE, seed=i))
    return folder


def _labels(folder: Path, n: int) -> Path:
    """Class-id labels (road 1) for ``_frames``' frames."""
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        label = np.zeros(SHAPE, np.uint8)
        label[SHAPE[0] // 2:] = 1
        write_image(folder / f"f{i:02d}.png", label)
    return folder


def _state(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` but lock files, and its bytes."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.suffix != ".lock" and outdir.META not in p.relative_to(root).parts}


# ------------------------------------------------------------------ 1. a signal during the final move


#: what adapt's model folder holds (freespace.engine.adapt_io.write_model_folder), the card and summary among them
ADAPT_FILES = ("model.ckpt", "model.onnx", "adapted.png", "rounds.csv", "config.json", "README.md", "summary.json")


def _adapt_output(out: Path, text: str, names: tuple[str, ...] = ADAPT_FILES) -> None:
    """Place an adapted model folder as adapt does (claim_folder + OwnedFolder.staged), every file holding ``text``."""
    with sigterm_raises(), claim_folder(out, "adapt") as folder, folder.staged() as stage:
        for name in names:
            (stage / name).write_text(text)


@pytest.mark.parametrize("signum,raised", SIGNALS)
def test_a_signal_during_adapts_move_waits_for_every_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                          hangup_raises: None, signum: int, raised: type) -> None:
    out = tmp_path / "adapted"
    _adapt_output(out, "old", ADAPT_FILES + ("stale.csv",))
    moved = _signal_after_first_move(monkeypatch, signum)
    with pytest.raises(raised):
        _adapt_output(out, "new")
    assert len(moved) == len(ADAPT_FILES)  # the move went on to the last file, then the signal ended the run
    assert _state(out) == {name: b"new" for name in ADAPT_FILES}  # no new card beside an old model; stale gone
    assert not list((out / outdir.META).glob("stage-*"))


@pytest.mark.parametrize("signum,raised", SIGNALS)
def test_a_signal_before_the_move_leaves_the_folder_as_it_was(tmp_path: Path, hangup_raises: None, signum: int,
                                                              raised: type) -> None:
    out = tmp_path / "adapted"
    _adapt_output(out, "old")
    before = _state(out)
    with pytest.raises(raised):
        with sigterm_raises(), claim_folder(out, "adapt") as folder, folder.staged() as stage:
            for name in ADAPT_FILES[:3]:
                (stage / name).write_text("new")
            os.kill(os.getpid(), signum)
            time.sleep(1)  # (the handler runs before this ends)
    assert _state(out) == before


@pytest.mark.parametrize("signum,raised", SIGNALS)
def test_files_written_together_are_all_new_after_a_signal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                          hangup_raises: None, signum: int, raised: type) -> None:
    targets = [tmp_path / f"{name}.json" for name in ("a", "b", "c")]
    write_files_together({t: b"old" for t in targets})
    real, calls = os.replace, []

    def replace(src: str, dst: str) -> None:
        real(src, dst)
        calls.append(dst)
        if len(calls) == 1:
            os.kill(os.getpid(), signum)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(raised), sigterm_raises():
        write_files_together({t: b"new" for t in targets})
    monkeypatch.undo()
    assert [t.read_bytes() for t in targets] == [b"new"] * 3


@pytest.mark.parametrize("signum,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_predict_and_evaluate_place_all_their_files_or_none(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture, signum: int,
                                                            code: int) -> None:
    n = 12
    model, frames, labels = _onnx(tmp_path / "road.onnx"), _frames(tmp_path / "frames", n), _labels(tmp_path / "gt", n)
    runs = {"predict": ["predict", "--onnx", str(model), "--input", str(frames), "--no-progress"],
            "evaluate": ["evaluate", "--onnx", str(model), "--images", str(frames), "--labels", str(labels),
                         "--label-format", "class-id", "--road", "1", "--no-progress"]}
    for command, argv in runs.items():
        out = tmp_path / command
        moved = _signal_after_first_move(monkeypatch, signum)
        assert main([*argv, "--out", str(out)]) == code, capsys.readouterr().err
        assert len(moved) > n  # every file was moved: the frames' overlays and the rest
        assert sorted(p.stem for p in (out / "overlays").glob("*.png")) == [f"f{i:02d}" for i in range(n)]
        summary = out / ("metrics.json" if command == "evaluate" else "summary.json")
        assert summary.is_file() and json.loads(summary.read_text())["frames"] == n
        monkeypatch.undo()


# ------------------------------------------------------------------ 2. an output over an input through a link


def test_predict_refuses_an_input_folder_or_glob_with_a_link_into_out(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture) -> None:
    model, frames, out = _onnx(tmp_path / "road.onnx"), _frames(tmp_path / "frames", 2), tmp_path / "pred"
    base = ["predict", "--onnx", str(model), "--no-progress", "--out", str(out)]
    assert main([*base, "--input", str(frames)]) == 0
    inputs = _frames(tmp_path / "more", 2)
    (inputs / "z.png").symlink_to(out / "overlays" / "f00.png")  # read, then replaced by z's own overlay
    before = _state(out)
    for spec in (inputs, f"{inputs}/*.png"):
        refused(capsys, [*base, "--input", str(spec)], match="symbolic link")
    link_dir = _frames(tmp_path / "third", 1)
    (link_dir / "masks").symlink_to(out, target_is_directory=True)  # a link to the output folder itself
    refused(capsys, [*base, "--input", str(link_dir)], match="symbolic link")
    assert _state(out) == before


def test_evaluate_refuses_labels_or_images_with_a_link_into_out(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    model, out = _onnx(tmp_path / "road.onnx"), tmp_path / "eval"
    frames, labels = _frames(tmp_path / "frames", 2), _labels(tmp_path / "gt", 2)
    base = ["evaluate", "--onnx", str(model), "--label-format", "class-id", "--road", "1", "--no-progress", "--out",
            str(out)]
    assert main([*base, "--images", str(frames), "--labels", str(labels)]) == 0
    before = _state(out)
    linked_labels, linked_images = _labels(tmp_path / "gt2", 1), _frames(tmp_path / "frames2", 1)
    (linked_labels / "f01.png").symlink_to(out / "overlays" / "f00.png")
    (linked_images / "f01.png").symlink_to(out / "overlays" / "f01.png")
    refused(capsys, [*base, "--images", str(frames), "--labels", str(linked_labels)], match="symbolic link")
    refused(capsys, [*base, "--images", str(linked_images), "--labels", str(labels)], match="symbolic link")
    assert _state(out) == before


def test_adapt_refuses_frames_with_a_link_into_out(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    model = tmp_path / "model"
    model.mkdir()
    (model / "model.ckpt").write_bytes(b"")  # never loaded: the refusal comes first
    out = tmp_path / "adapted"
    out.mkdir()
    write_image(out / "kept.png", textured_image(SHAPE, seed=9))
    frames = _frames(tmp_path / "frames", 3)
    (frames / "f09.png").symlink_to(out / "kept.png")
    for spec in (frames, f"{frames}/*.png"):
        err = refused(capsys, ["adapt", "--model", str(model), "--input", str(spec), "--out", str(out)])
        assert str(out / "kept.png") in err and "--out" in err, err  # the file read through the link, named
    assert sorted(p.name for p in out.iterdir()) == ["kept.png"]


def test_a_link_into_an_output_is_refused_at_any_depth(tmp_path: Path) -> None:
    out, root = tmp_path / "out", tmp_path / "root"
    (out / "sub").mkdir(parents=True)
    (out / "sub" / "x.png").write_bytes(b"x")
    (root / "a" / "b").mkdir(parents=True)
    (root / "a" / "b" / "x.png").symlink_to(out / "sub" / "x.png")  # a file deep in the input, in the output
    with pytest.raises(InvalidOptionError, match=r"a/b/x.png, a symbolic link to .*out/sub/x.png in out"):
        check_outputs({"out": out}, {"root": root})
    (root / "a" / "b" / "x.png").unlink()
    (root / "a" / "c").symlink_to(out / "sub", target_is_directory=True)  # a folder inside the output
    with pytest.raises(InvalidOptionError, match="a/c, a symbolic link"):
        check_outputs({"out": out}, {"root": root})
    (root / "a" / "c").unlink()
    model = tmp_path / "model.onnx"
    model.write_bytes(b"m")
    (root / "m.onnx").symlink_to(model)  # a file output, read through a link
    with pytest.raises(InvalidOptionError, match="m.onnx, a symbolic link"):
        check_outputs({"out": model}, {"root": root})
    (root / "m.onnx").unlink()
    elsewhere = tmp_path / "elsewhere.png"
    elsewhere.write_bytes(b"e")
    (root / "e.png").symlink_to(elsewhere)  # a link that leads elsewhere is an input like any other
    check_outputs({"out": out}, {"root": root})
    check_outputs({"out": tmp_path / "new"}, {"root": root})


# ------------------------------------------------------------------ 3. a user's regular expression


def _generic(root: Path, pattern: str, names: list[str]) -> Path:
    (root / "left").mkdir(parents=True)
    for i, name in enumerate(names):
        write_image(root / "left" / f"{name}.png", textured_image((16, 16), seed=i))
    (root / "freespace.yaml").write_text(f"left: left\nscenario_pattern: {json.dumps(pattern)}\n")
    return root


LONG = "a" * 60 + "!"  # a frame name a backtracking pattern fails on after exponential time


@pytest.mark.parametrize("pattern,why", [
    (r"(?P<scenario>(a+)+)$", "quantifier inside a repeated group"),
    (r"(?P<scenario>(\w+\s?)+)$", "quantifier inside a repeated group"),
    (r"(?P<scenario>(ab|a)*)c", "alternation"),
    (r"(?P<scenario>(a?){25}a{25})", "quantifier inside a repeated group"),
    (r"(?P<scenario>(.*a){12})", "quantifier inside a repeated group"),
    (r"(?P<scenario>(?:(?:a*)*)*)$", "quantifier inside a repeated group"),
    (r"(?P<scenario>a)(?P=scenario)", "backreference"),
    ("(?P<scenario>" + "a" * 200 + ")", "characters"),
])
def test_a_backtracking_scenario_pattern_is_refused_at_once(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                            pattern: str, why: str) -> None:
    root = _generic(tmp_path / "set", pattern, [LONG, "b_1"])
    t0 = time.monotonic()
    err = refused(capsys, ["datasets", "info", "--dataset", "generic", "--root", str(root)], match=why)
    assert "scenario_pattern" in err and "no quantifier" in err and time.monotonic() - t0 < 10


def test_a_slow_scenario_pattern_is_stopped_in_time(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    from freespace.runtime import patterns

    monkeypatch.setattr(patterns, "MATCH_SECONDS", 1.0)
    root = _generic(tmp_path / "set", r"(?P<scenario>.*.*.*.*.*)=", ["a" * 200])
    t0 = time.monotonic()
    refused(capsys, ["datasets", "info", "--dataset", "generic", "--root", str(root)], match="took more than 1 s")
    assert time.monotonic() - t0 < 20


def test_a_plain_scenario_pattern_still_names_the_scenarios(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from freespace.data.folder import GenericStereo

    root = _generic(tmp_path / "set", r"^(?P<scenario>[^_]+)_\d+$", ["drive1_000", "drive1_001", "drive2_000"])
    assert [f.scenario for f in GenericStereo(root).frames] == ["drive1", "drive1", "drive2"]
    (root / "left" / "odd.png").write_bytes((root / "left" / "drive1_000.png").read_bytes())
    refused(capsys, ["datasets", "info", "--dataset", "generic", "--root", str(root)],
            match="does not match frame 'odd'")


# ------------------------------------------------------------------ 4. propagation's inputs


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    """A KITTI raw drive of 4 frames and its single-frame autolabel tree (``single``); the command's options."""
    from test_propagate import _synthetic_drive

    tmp = tmp_path_factory.mktemp("drive")
    root = _synthetic_drive(tmp, 4, 1.0)
    common = ["--dataset", "kitti-raw", "--root", str(root), "--disparity-source", "sgbm", "--cache-dir",
              str(tmp / "cache")]
    assert main(["autolabel", *common, "--out", str(tmp / "single")]) == 0
    return tmp, common


def _tree_copy(drive: tuple[Path, list[str]], name: str) -> Path:
    import shutil

    tree = drive[0] / name
    shutil.copytree(drive[0] / "single", tree, ignore=shutil.ignore_patterns(outdir.META))
    return tree


def test_propagation_refuses_a_label_or_confidence_of_another_size(drive: tuple[Path, list[str]],
                                                                    capsys: pytest.CaptureFixture) -> None:
    from freespace.io.codecs import read_image
    from test_propagate import DRIVE

    tmp, common = drive
    frame = Path(DRIVE) / "0000000001.png"
    cases = {"label": (frame, lambda a: a[:-8]), "confidence": (Path("confidence") / frame, lambda a: a[:, :-4]),
             "colour confidence": (Path("confidence") / frame, lambda a: np.dstack([a] * 3))}
    for i, (what, (rel, change)) in enumerate(cases.items()):
        tree = _tree_copy(drive, f"bad{i}")
        write_image(tree / rel, change(read_image(tree / rel)))
        err = refused(capsys, ["autolabel", *common, "--propagate-from", str(tree), "--out", str(tmp / f"p{i}")])
        assert str(tree / rel) in err, (what, err)
        other = "image_02" if what == "label" else str(tree / frame)  # the frame's image, or the label
        assert ("colour" in err) if what == "colour confidence" else (other in err and err.count("×") >= 2), err
        assert not (tmp / f"p{i}").exists()


def test_propagate_from_a_file_says_it_is_a_file(drive: tuple[Path, list[str]], capsys: pytest.CaptureFixture) -> None:
    tmp, common = drive
    file = tmp / "tree.txt"
    file.write_text("not a tree")
    err = refused(capsys, ["autolabel", *common, "--propagate-from", str(file), "--out", str(tmp / "p")])
    assert "is a file" in err and "not found" not in err, err
    from freespace.data.label_tree import check_label_tree
    from freespace.errors import InputFileError

    with pytest.raises(InputFileError, match=r"^labels .*tree.txt is a file; give the folder") as caught:
        check_label_tree(file, "kitti-raw", common[3], None)  # train's --labels: the same check
    assert "not found" not in str(caught.value)


# ------------------------------------------------------------------ 5. the house


def _study_reads(source: str) -> list[int]:
    """The lines of a test module that build a path into ``studies/`` (``ROOT / "studies"``, ``"studies/..."``)."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div):
            if any(isinstance(s, ast.Constant) and s.value == "studies" for s in (node.left, node.right)):
                lines.append(node.lineno)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith("studies/") \
                and "\n" not in node.value:
            lines.append(node.lineno)
    return lines


def test_the_product_tests_read_nothing_of_studies() -> None:
    assert _study_reads('ROOT = Path(".")\np = ROOT / "studies" / "x"\nq = Path("studies/x/protocol.yaml")\n') == [2, 3]
    found = [f"{p.name}:{line}" for p in sorted((ROOT / "tests").glob("*.py")) if p.name != Path(__file__).name
             for line in _study_reads(p.read_text(encoding="utf-8"))]
    assert not found, f"a test of a study lives with the study (studies/<study>/tests), or skips without it: {found}"


#: the modules the next issues grow, each split by job (issue 72), and the public names of their old homes
SPLIT = {"freespace.datagen.labeller": ["AutolabelOptions", "AutolabelResult", "autolabel"],
         "freespace.datagen.propagate": ["PropagateOptions", "Motion", "ego_motion", "compose", "source_frames",
                                         "propagate_frame", "propagate_dataset"],
         "freespace.experiments.protocol": ["DataSource", "DATA_KEYS", "Primary", "Protocol"]}


def test_labelling_propagation_and_protocols_stay_small() -> None:
    import importlib

    folders = [ROOT / "freespace" / "datagen", ROOT / "freespace" / "experiments" / "protocol.py",
               ROOT / "freespace" / "experiments" / "data_source.py"]
    files = [p for f in folders for p in (sorted(f.glob("*.py")) if f.is_dir() else [f])]
    long = {p.name: n for p in files if (n := len(p.read_text().splitlines())) > 400}
    assert not long, f"give each job its own module (at most 400 lines): {long}"
    for module, names in SPLIT.items():
        assert all(hasattr(importlib.import_module(module), name) for name in names), module
