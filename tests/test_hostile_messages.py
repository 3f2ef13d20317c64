"""Hostile cases of issue 59, class 8: a message names the real cause, not something else it breaks.

* An unknown option is named as such, whatever its value (an existing path is not the shell's wildcard).
* A named pipe, a socket or a device where a file is wanted is "a named pipe" (never opened), not "not found".
* A frame of the split lists without a label is blamed on what lacks it (a shard's part of a label tree,
  ``--max-frames``), not on the lists; an empty split by scenario says how many scenarios there are.
* ``train --resume`` with a changed option names the option, before the checks the change would fail.
* ``reproduce`` checks every cell's training data before the first cell trains, and names the cell.
* ``--calib`` reads KITTI raw's ``calib_cam_to_cam.txt``; ``predict --threads`` is not ignored with
  ``--checkpoint``; a ``.webp`` is an image, and a file that is neither image nor video says so.
"""

from __future__ import annotations

import os
import shutil
import socket
import threading
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.data import get_dataset
from freespace.data.splits import make_splits
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.io.codecs import write_disparity, write_image
from freespace.io.kitti import read_kitti_calib
from freespace.io.video import open_frames

from helpers import refused, synthetic_pair
from test_kitti_raw import CAM_TO_CAM, DATE, make_drive

ONNX = Path(__file__).resolve().parents[1] / "models" / "real-road-fast" / "model.onnx"


@pytest.fixture
def pair(tmp_path: Path) -> dict[str, Path]:
    left, right, label, disparity = synthetic_pair((96, 160))
    files = {"L": tmp_path / "L.png", "R": tmp_path / "R.png", "M": tmp_path / "M.png", "D": tmp_path / "D.png"}
    write_image(files["L"], left)
    write_image(files["R"], right)
    write_image(files["M"], (label.road & label.valid).astype(np.uint8) * 255)
    write_disparity(files["D"], disparity)
    return files


# ----------------------------------------------------------------------------------- unknown options
@pytest.mark.parametrize("command", [
    ["predict", "--onnx", str(ONNX), "--input", "{L}", "--out", "{tmp}/p"],
    ["generate", "--reference", "{L}", "--target", "{R}", "--road-mask", "{M}", "--out", "{tmp}/g.png"],
    ["autolabel", "--reference", "{L}", "--disparity", "{D}", "--baseline", "0.5", "--out", "{tmp}/a.png"],
    ["train", "--dataset", "synth", "--root", "{tmp}", "--out", "{tmp}/run"],
])
@pytest.mark.parametrize("unknown", [["--bogus", "{M}"], ["--bogus={M}"], ["--mask", "{tmp}"]])
def test_an_unknown_option_is_named_whatever_its_value(command: list[str], unknown: list[str], pair: dict[str, Path],
                                                       tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    argv = [a.format(tmp=tmp_path, **pair) for a in [*command, *unknown]]
    err = refused(capsys, argv, match=f"unknown option {unknown[0].split('=')[0]}")
    assert "wildcard" not in err and f"freespace {command[0]} --help" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D.png", "L.png", "M.png", "R.png"]


def test_the_shell_s_expanded_wildcard_is_still_named(pair: dict[str, Path], tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    refused(capsys, ["predict", "--onnx", str(ONNX), "--input", str(pair["L"]), str(pair["R"]), str(pair["M"]),
                     "--out", str(tmp_path / "p")], match="unquoted wildcard")


# ------------------------------------------------------------------------ special files as inputs
@pytest.fixture(params=["fifo", "socket", "device"])
def special(request: pytest.FixtureRequest, tmp_path: Path):
    """A named pipe (a thread opens its other end after 20 s, so that a command that opened it fails instead of
    hanging), a listening Unix socket, or /dev/null through a link; each named ``*.png`` (a disparity's suffix);
    and the words its message must hold."""
    path = tmp_path / f"{request.param}.png"
    if request.param == "device":
        path.symlink_to(os.devnull)
        yield path, "character device"
        return
    if request.param == "fifo":
        os.mkfifo(path)
        timer = threading.Timer(20, lambda: os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
                                if path.exists() else None)
        timer.daemon = True
        timer.start()
        yield path, "named pipe"
        timer.cancel()
        return
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(path))
    yield path, "socket"
    sock.close()


@pytest.mark.parametrize("command", [
    ["predict", "--onnx", "{S}", "--input", "{L}", "--out", "{tmp}/p"],
    ["predict", "--onnx", str(ONNX), "--input", "{S}", "--out", "{tmp}/p"],
    ["predict", "--checkpoint", "{S}", "--input", "{L}", "--out", "{tmp}/p"],
    ["generate", "--reference", "{S}", "--target", "{R}", "--road-mask", "{M}", "--out", "{tmp}/g.png"],
    ["generate", "--reference", "{L}", "--target", "{R}", "--road-mask", "{S}", "--out", "{tmp}/g.png"],
    ["autolabel", "--reference", "{L}", "--target", "{R}", "--calib", "{S}", "--out", "{tmp}/a.png"],
    ["autolabel", "--reference", "{L}", "--disparity", "{S}", "--baseline", "0.5", "--out", "{tmp}/a.png"],
    ["train", "--config", "{S}", "--out", "{tmp}/run"],
    ["train", "--dataset", "synth", "--root", "{tmp}/syn", "--model", "unet", "--encoder-weights", "{S}", "--out",
     "{tmp}/run"],
])
def test_a_special_file_where_a_file_is_wanted_is_named(command: list[str], special, pair: dict[str, Path],
                                                        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path, kind = special
    if command[0] == "train" and "--root" in command:
        write_dataset(tmp_path / "syn", 4, seed=0, config=SynthConfig(width=64, height=48, frames_per_scenario=2),
                      progress=False)
    argv = [a.format(tmp=tmp_path, S=path, **pair) for a in command]
    err = refused(capsys, argv, match=f"{path} is a {kind}")
    assert "not found" not in err
    assert not any(tmp_path.glob("[pga].png")) and not (tmp_path / "p").exists() and not (tmp_path / "run").exists()


# ----------------------------------------------------------------------- labels, splits and scenarios
@pytest.fixture(scope="module")
def raw(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A KITTI raw drive of 6 frames with scans; its whole LiDAR label tree, and the first shard's of two."""
    base = tmp_path_factory.mktemp("raw")
    root = base / "raw"
    make_drive(root, frames=6, right=False, velodyne=True)
    trees = {}
    for name, shard in (("whole", []), ("part", ["--shard", "1/2"])):
        trees[name] = base / name
        assert main(["-q", "autolabel", "--dataset", "kitti-raw", "--root", str(root), "--disparity-source", "lidar",
                     *shard, "--out", str(trees[name])]) == 0
    lists = base / "lists"
    assert main(["-q", "datasets", "split", "--dataset", "kitti-raw", "--root", str(root), "--by", "time",
                 "--fractions", "0.5,0.25,0.25", "--out", str(lists)]) == 0
    return {"root": root, "lists": lists, **trees}


def test_a_shard_s_part_of_a_label_tree_is_blamed_not_the_split_lists(raw: dict[str, Path], tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture) -> None:
    err = refused(capsys, ["-q", "train", "--dataset", "kitti-raw", "--root", str(raw["root"]), "--labels",
                           str(raw["part"]),
                           "--splits", str(raw["lists"]), "--epochs", "1", "--out", str(tmp_path / "run")],
                  match=f"--labels {raw['part']} has no {DATE}_drive_0001_sync/")
    assert "summary.shard-1-of-2.json" in err and "each shard K/N" in err and "another dataset" not in err
    assert not (tmp_path / "run").exists()


def test_frames_cut_by_max_frames_are_blamed_not_the_split_lists(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "syn"
    write_dataset(root, 12, seed=0, config=SynthConfig(width=64, height=48, frames_per_scenario=2), progress=False)
    names = [f.name for f in get_dataset("synth", root).frames]
    lists = tmp_path / "lists"
    lists.mkdir()
    for split, chosen in (("train", names[:4]), ("val", names[4:6]), ("test", names[10:])):
        (lists / f"{split}.txt").write_text("".join(f"{n}\n" for n in chosen))
    err = refused(capsys, ["train", "--dataset", "synth", "--root", str(root), "--splits", str(lists), "--max-frames",
                           "6", "--out", str(tmp_path / "run")], match="--max-frames 6 leaves it out")
    assert "another dataset" not in err


def test_an_empty_split_by_scenario_counts_the_scenarios(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "syn"
    write_dataset(root, 30, seed=0, config=SynthConfig(width=64, height=48, frames_per_scenario=10), progress=False)
    splits = make_splits([(f.name, f.scenario) for f in get_dataset("synth", root).frames])
    assert not all(splits.values())  # three drives of ten frames: one split gets none (the README's old quickstart)
    refused(capsys, ["train", "--dataset", "synth", "--root", str(root), "--epochs", "1", "--out",
                     str(tmp_path / "run")], match="the 30 labelled frames are 3 scenarios")


# ------------------------------------------------------------------------- resume, reproduce
@pytest.mark.parametrize("change, named", [(["--model", "unet", "--encoder-weights", "imagenet"], "model 'segnet'"),
                                           (["--root", "nowhere"], "root "),
                                           (["--labels", "nowhere"], "labels None")])
def test_an_option_changed_on_resume_is_named_first(change: list[str], named: str, trained: dict[str, Path],
                                                    tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "run"
    shutil.copytree(trained["run"], run)
    refused(capsys, ["train", "--resume", "--out", str(run), *change], match="--resume with other options")
    refused(capsys, ["train", "--resume", "--out", str(run), *change], match=named)


def test_reproduce_checks_every_cell_s_data_before_any_trains(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "syn"
    write_dataset(root, 12, seed=0, config=SynthConfig(width=64, height=48, frames_per_scenario=2), progress=False)
    tree = tmp_path / "lab"
    assert main(["-q", "autolabel", "--dataset", "synth", "--root", str(root), "--out", str(tree)]) == 0
    frames = get_dataset("synth", root).frames
    for name in make_splits([(f.name, f.scenario) for f in frames])["train"]:  # X-auto's training frames: unlabelled
        (tree / f"{name}.png").unlink()
    out = tmp_path / "rep"
    refused(capsys, ["reproduce", "--dataset", "synth", "--root", str(root), "--autolabels", str(tree), "--variants",
                     "X-auto", "--models", "segnet", "--seeds", "1", "--epochs", "1", "--image-size", "32x32",
                     "--no-progress", "--out", str(out)],
            match=f"run segnet-auto-s0 (variant X-auto): --autolabels {tree} has no label of any")
    assert not out.exists(), "a cell trained before the one that cannot"


def test_reproduce_names_x_without_labels_before_training(raw: dict[str, Path], tmp_path: Path,
                                                          capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "rep"
    refused(capsys, ["reproduce", "--dataset", "kitti-raw", "--root", str(raw["root"]), "--autolabels",
                     str(raw["whole"]), "--variants", "X-auto", "--models", "segnet", "--seeds", "1", "--epochs", "1",
                     "--image-size", "32x96", "--no-progress", "--out", str(out)],
            match="run segnet-orig-s0 (variant X): kitti-raw at")
    assert not out.exists()


# ---------------------------------------------------------------- files that are what they are
def test_calib_reads_kitti_raw_s_cam_to_cam(pair: dict[str, Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture) -> None:
    cam = tmp_path / "calib_cam_to_cam.txt"
    cam.write_text(CAM_TO_CAM)
    calib = read_kitti_calib(cam)
    assert calib["P2"].shape == (3, 4) and calib["P2"][0, 3] == pytest.approx(44.85728)
    assert calib["P3"][0, 3] == pytest.approx(-339.5242)
    capsys.readouterr()
    assert main(["autolabel", "--reference", str(pair["L"]), "--disparity", str(pair["D"]), "--calib", str(cam),
                 "--out", str(tmp_path / "a.png")]) == 0
    assert (tmp_path / "a.png").is_file()
    velo = tmp_path / "calib_velo_to_cam.txt"
    velo.write_text("calib_time: 15-Mar-2012 11:37:16\nR: 1 0 0 0 1 0 0 0 1\nT: 0 0 0\n")
    refused(capsys, ["autolabel", "--reference", str(pair["L"]), "--target", str(pair["R"]), "--calib", str(velo),
                     "--out", str(tmp_path / "b.png")], match="calib_cam_to_cam.txt, with P_rect_02")


def test_predict_threads_hold_with_a_checkpoint(trained: dict[str, Path], pair: dict[str, Path],
                                                tmp_path: Path) -> None:
    import torch

    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        assert main(["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(pair["L"]), "--threads", "1",
                     "--no-progress", "--out", str(tmp_path / "p")]) == 0
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(threads)


def test_webp_frames_are_images_and_an_unknown_file_says_what_it_is_not(pair: dict[str, Path],
                                                                        tmp_path: Path) -> None:
    frames = tmp_path / "frames"
    frames.mkdir()
    image = np.zeros((48, 64, 3), np.uint8)
    for i in range(2):
        write_image(frames / f"{i}.webp", image + i)
    assert open_frames(frames).kind == "folder" and open_frames(frames).count == 2
    one = open_frames(frames / "1.webp")
    assert one.kind == "image" and one.size == (48, 64)
    (tmp_path / "notes.txt").write_text("not a frame")
    with pytest.raises(Exception, match="is no image freespace reads .* and no video FFmpeg decodes"):
        open_frames(tmp_path / "notes.txt")


def test_the_generic_layout_s_missing_yaml_says_what_to_write(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    err = refused(capsys, ["datasets", "info", "--dataset", "generic", "--root", str(tmp_path)],
                  match="freespace.yaml not found")
    assert "`left: " in err and "docs/datasets.md" in err and "datasets --help" not in err


def test_every_option_has_help_and_the_help_speaks_to_users() -> None:
    """`freespace --help` opens with what the tool does; every option of every command says what it is for."""
    import argparse

    from freespace.cli import build_parser

    parser = build_parser()
    assert parser.description.startswith("freespace: drivable road")
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    bare = [(name, a.option_strings[0]) for name, p in sub.choices.items() for a in p._actions
            if a.option_strings and not a.help and a.dest != "help"]
    assert bare == []
    parsers = [parser]  # argparse expands `%` in help: a bare one breaks `--help` of its command
    while parsers:
        command = parsers.pop()
        assert command.format_help().startswith("usage: "), command.prog
        parsers += [child for a in command._actions if isinstance(a, argparse._SubParsersAction)
                    for child in a.choices.values()]
