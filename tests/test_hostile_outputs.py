"""Hostile outputs (issue 44, classes A and G): what an output path may be, and output folders inside real
workflows.

A. An output that is not a regular file (system damage). Every output option of every command (files:
   ``evaluate-kitti --out``, ``export --out``, ``generate --out/--model-json/--label-out``, ``autolabel
   --out/--confidence/--model-json``, ``predict --out V.mp4``; folders: ``predict``, ``evaluate``,
   ``kitti-submit``, ``train``, ``synth``, ``datasets split``, ``generate --dataset``, ``autolabel --dataset``,
   ``reproduce``, ``demo``, ``--cache-dir``) given a character device (``mknod c 1 3``, as ``/dev/null``), a
   named pipe, a socket, or a symbolic link to a device: refused in one line, the node still a node. The
   same at write time (a pipe planted after the up-front check: ``write_files_together``, a staged
   output, the video writer), at an entry name inside an owned folder, anywhere in a ``"dir/"`` entry, as
   the manifest or the lock (no reader ever blocks on a pipe). Outputs on ``/proc``, ``/sys`` and a
   ``devtmpfs`` ``/dev`` are refused before anything is written. A replaced file keeps its mode (0600 stays
   0600, a staged output and a video too) and its owner; a new file gets ``0666 & ~umask``; a read-only
   file is refused, not replaced. A link to a regular file is replaced by the new file (the file it leads
   to is untouched); a dangling link becomes the new file.

G. Output folders inside workflows. The README's flow ``evaluate --out RUN/eval`` then ``train --out RUN
   --resume`` (and a second evaluation) runs end to end, and a nested output folder is never touched by the
   outer command; one at or inside an entry of the outer command is refused (22). A run restarted without
   ``last.ckpt`` refuses a user file in ``checkpoints/`` (kept) and warns that a run which trained is
   trained anew (23). An output (folder or file, also through a link) inside a ``.freespace`` folder is
   refused, nothing created there (24). A manifest that is not JSON, not the manifest's shape, a pipe or a
   folder is named as unreadable, with the fix; nothing in the folder is touched (25).
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import socket
import stat
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.errors import CorruptFileError, FreespaceError, InvalidOptionError, OutputError
from freespace.io.codecs import write_image
from freespace.io.files import atomic_write_bytes, check_writable, replaceable, write_files_together, write_json
from freespace.io.outdir import META, claim_folder
from freespace.io.video import VideoWriter

from helpers import TRAINED_ARGS, refused, synthetic_pair

# ------------------------------------------------------------------------------------------------- helpers



def _node(path: Path, kind: str) -> Callable[[], bool]:
    """Make a non-regular file of ``kind`` at ``path``; return a check that it is still that node."""
    if kind == "chardev":
        try:
            os.mknod(path, 0o644 | stat.S_IFCHR, os.makedev(1, 3))  # what /dev/null is
        except PermissionError:
            pytest.skip("making a device node needs root")
        return lambda: stat.S_ISCHR(os.lstat(path).st_mode)
    if kind == "fifo":
        os.mkfifo(path)
        return lambda: stat.S_ISFIFO(os.lstat(path).st_mode)
    if kind == "socket":
        sock = socket.socket(socket.AF_UNIX)
        try:
            sock.bind(str(path))
        except OSError:
            pytest.skip("cannot bind a unix socket here (path too long)")
        sock.close()
        return lambda: stat.S_ISSOCK(os.lstat(path).st_mode)
    assert kind == "link-to-fifo"
    os.mkfifo(path.parent / f"target-of-{path.name}")
    path.symlink_to(f"target-of-{path.name}")
    return lambda: path.is_symlink() and stat.S_ISFIFO(os.stat(path).st_mode)


KINDS = ["chardev", "fifo", "socket", "link-to-fifo"]


@pytest.fixture
def pair(tmp_path: Path) -> dict[str, Path]:
    left, right, label, disparity = synthetic_pair((96, 160))
    files = {"L": tmp_path / "in" / "L.png", "R": tmp_path / "in" / "R.png", "M": tmp_path / "in" / "M.png"}
    files["L"].parent.mkdir()
    write_image(files["L"], left)
    write_image(files["R"], right)
    write_image(files["M"], (label.road & label.valid).astype(np.uint8) * 255)
    return files


def _images(trained: dict[str, Path]) -> Path:
    """The folder of the trained run's left images (an input of ``predict``)."""
    return trained["data"] / "data_road" / "training" / "image_2"


def _kitti_pair(folder: Path) -> tuple[Path, Path]:
    """A KITTI ground-truth folder and a prediction folder of one frame (both valid)."""
    gt, pred = folder / "gt", folder / "pred"
    gt.mkdir(parents=True)
    pred.mkdir()
    label = np.zeros((40, 60, 3), np.uint8)
    label[..., 0] = 255
    label[20:, :, 2] = 255  # road (magenta) below, non-road (red) above
    write_image(gt / "um_road_000000.png", label)
    conf = np.zeros((40, 60), np.uint8)
    conf[18:] = 230
    write_image(pred / "um_road_000000.png", conf)
    return gt, pred


# ---------------------------------------------------- A1. every output option: a device, pipe, socket, link

def _file_outputs(trained: dict[str, Path], pair: dict[str, Path], tmp: Path) -> dict[str, Callable[[Path], list[str]]]:
    """Commands with one output file each (the node given as ``x``); every other output is a fresh path."""
    f = pair
    gt, pred = _kitti_pair(tmp / "kitti")
    calib = tmp / "calib.txt"
    calib.write_text("P2: 100 0 80 0 0 100 48 0 0 0 1 0\nP3: 100 0 80 -50 0 100 48 0 0 0 1 0\n"
                     "Tr_cam_to_road: 1 0 0 0 0 1 0 -1.6 0 0 1 0\n")
    gen = ["generate", "--reference", str(f["L"]), "--target", str(f["R"]), "--road-mask", str(f["M"])]
    auto = ["autolabel", "--reference", str(f["L"]), "--target", str(f["R"])]
    virt = ["generate", "--virtual", "--reference", str(f["L"]), "--road-mask", str(f["M"]), "--calib", str(calib),
            "--shift", "0.2,0,0"]
    return {
        "evaluate-kitti --out": lambda x: ["evaluate-kitti", "--gt", str(gt), "--pred", str(pred), "--out", str(x)],
        "export --out": lambda x: ["export", "--checkpoint", str(trained["ckpt"]), "--format", "torchscript",
                                   "--out", str(x)],
        "generate --out": lambda x: [*gen, "--out", str(x)],
        "generate --model-json": lambda x: [*gen, "--out", str(tmp / "G.png"), "--model-json", str(x)],
        "generate --virtual --label-out": lambda x: [*virt, "--out", str(tmp / "V.png"), "--label-out", str(x)],
        "autolabel --out": lambda x: [*auto, "--out", str(x)],
        "autolabel --confidence": lambda x: [*auto, "--out", str(tmp / "A.png"), "--confidence", str(x)],
        "autolabel --model-json": lambda x: [*auto, "--out", str(tmp / "A.png"), "--model-json", str(x)],
        "predict --out V.mp4": lambda x: ["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(f["L"]),
                                          "--out", str(x), "--no-progress"],
    }


FILE_OUTPUTS = ["evaluate-kitti --out", "export --out", "generate --out", "generate --model-json",
                "generate --virtual --label-out", "autolabel --out", "autolabel --confidence", "autolabel --model-json",
                "predict --out V.mp4"]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("option", FILE_OUTPUTS)
def test_an_output_file_that_is_a_device_pipe_or_socket_is_refused(option: str, kind: str, trained: dict[str, Path],
                                                                  pair: dict[str, Path], tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    suffix = ".mp4" if option.endswith("mp4") else ".json" if "json" in option or "kitti" in option else \
        ".pt" if option.startswith("export") else ".png"
    node = tmp_path / f"x{suffix}"
    still = _node(node, kind)
    argv = _file_outputs(trained, pair, tmp_path)[option](node)
    err = refused(capsys, argv, match="not a regular file")
    assert ("character device" if kind == "chardev" else "socket" if kind == "socket" else "named pipe") in err
    assert still(), f"{option} replaced the {kind}"
    leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert not leftovers, leftovers


FOLDER_OUTPUTS = {
    "predict": lambda t, x: ["predict", "--checkpoint", str(t["ckpt"]), "--input", str(_images(t)), "--out", str(x)],
    "evaluate": lambda t, x: ["evaluate", "--checkpoint", str(t["ckpt"]), "--dataset", "synth", "--root",
                              str(t["data"]), "--out", str(x)],
    "kitti-submit": lambda t, x: ["kitti-submit", "--checkpoint", str(t["ckpt"]), "--root", str(t["data"]),
                                  "--out", str(x)],
    "train": lambda t, x: ["train", "--dataset", "synth", "--root", str(t["data"]), *TRAINED_ARGS, "--out", str(x)],
    "synth": lambda t, x: ["synth", "--out", str(x), "--num", "1", "--width", "64", "--height", "64"],
    "datasets split": lambda t, x: ["datasets", "split", "--dataset", "synth", "--root", str(t["data"]), "--out",
                                    str(x)],
    "generate --dataset": lambda t, x: ["generate", "--dataset", "synth", "--root", str(t["data"]), "--out", str(x)],
    "autolabel --dataset": lambda t, x: ["autolabel", "--dataset", "synth", "--root", str(t["data"]), "--out",
                                         str(x)],
    "generate --cache-dir": lambda t, x: ["generate", "--dataset", "synth", "--root", str(t["data"]),
                                          "--disparity-source", "sgbm", "--cache-dir", str(x), "--out",
                                          str(x.parent / "gen")],
    "reproduce": lambda t, x: ["reproduce", "--dataset", "synth", "--root", str(t["data"]), "--models", "segnet",
                               "--seeds", "1", "--epochs", "1", "--out", str(x)],
    "demo": lambda t, x: ["demo", "--out", str(x)],
}


@pytest.mark.parametrize("kind", ["chardev", "fifo", "link-to-fifo"])
@pytest.mark.parametrize("command", sorted(FOLDER_OUTPUTS))
def test_an_output_folder_that_is_a_device_or_pipe_is_refused(command: str, kind: str, trained: dict[str, Path],
                                                              tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    node = tmp_path / "x"
    still = _node(node, kind)
    refused(capsys, FOLDER_OUTPUTS[command](trained, node), match="not a folder")
    assert still()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["x"] + (["target-of-x"] if "link" in kind else []))


@pytest.mark.parametrize("kind", ["chardev", "fifo", "link-to-fifo"])
@pytest.mark.parametrize("where", ["entry", "inside-a-dir-entry", "manifest", "lock"])
def test_a_node_planted_in_an_owned_folder_is_refused(where: str, kind: str, tmp_path: Path) -> None:
    """At a file entry (``summary.json``), anywhere in a ``"dir/"`` entry, as the manifest or as the lock:
    refused in one line before any work, never opened (a pipe would block) and never replaced."""
    out = tmp_path / "out"
    with claim_folder(out, "predict", entries=["tree/"]) as folder, folder.staged(replace=False) as stage:
        (stage / "summary.json").write_text("{}")
        (stage / "tree").mkdir()
        (stage / "tree" / "a.png").write_bytes(b"x")
    target = {"entry": out / "summary.json", "inside-a-dir-entry": out / "tree" / "deep" / "x",
              "manifest": out / META / "manifest.json", "lock": out / META / "lock"}[where]
    target.unlink(missing_ok=True)
    target.parent.mkdir(parents=True, exist_ok=True)
    still = _node(target, kind)
    with pytest.raises(FreespaceError) as info:
        with claim_folder(out, "predict", entries=["tree/"]) as folder, folder.staged() as stage:
            (stage / "summary.json").write_text("{}")
    assert "\n" not in str(info.value) and str(target.name) in str(info.value)
    assert still()


def test_a_node_planted_after_the_check_is_refused_at_write_time(tmp_path: Path) -> None:
    """The writers check again when they write: a pipe that appears at an output file, at a staged
    output's entry, or at a video's path after the command started is never replaced, and the other files
    written together are left as they were."""
    keep, pipe = tmp_path / "keep.json", tmp_path / "pipe.json"
    keep.write_text("old")
    check_writable(pipe)  # the up-front check passes: nothing there yet
    os.mkfifo(pipe)
    with pytest.raises(OutputError, match="named pipe"):
        write_files_together({keep: b"new", pipe: b"new"})
    with pytest.raises(OutputError, match="named pipe"):
        atomic_write_bytes(pipe, b"new")
    assert keep.read_text() == "old" and stat.S_ISFIFO(os.lstat(pipe).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.json", "pipe.json"]

    out = tmp_path / "out"
    with pytest.raises(OutputError, match="named pipe"):
        with claim_folder(out, "predict") as folder, folder.staged() as stage:
            (stage / "a.png").write_bytes(b"x")
            os.mkfifo(out / "a.png")  # appears while the command works
    assert stat.S_ISFIFO(os.lstat(out / "a.png").st_mode)

    video = tmp_path / "v.mp4"
    writer = VideoWriter(video, fps=10)
    os.mkfifo(video)
    with pytest.raises(OutputError, match="named pipe"):
        with writer:
            writer.write(np.zeros((16, 16, 3), np.uint8))
    assert stat.S_ISFIFO(os.lstat(video).st_mode)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_fifo_manifest_does_not_hang_a_command(trained: dict[str, Path], tmp_path: Path) -> None:
    """In a fresh process, with a time limit: a pipe as the manifest is refused at once (never opened)."""
    out = tmp_path / "out"
    (out / META).mkdir(parents=True)
    os.mkfifo(out / META / "manifest.json")
    res = subprocess.run([sys.executable, "-m", "freespace.cli", "predict", "--checkpoint", str(trained["ckpt"]),
                          "--input", str(_images(trained)), "--out", str(out)], capture_output=True, text=True,
                         timeout=120)
    err = res.stderr.strip()
    assert res.returncode == 2 and len(err.splitlines()) == 1 and "unreadable manifest" in err, err


@pytest.mark.parametrize("path", ["/proc/freespace-probe.json", "/proc/sys/vm/drop_caches", "/sys/freespace-probe.json",
                                  "/sys/kernel/freespace-probe/x.json"])
def test_outputs_on_proc_and_sys_are_refused_up_front(path: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    gt, pred = _kitti_pair(tmp_path)
    refused(capsys, ["evaluate-kitti", "--gt", str(gt), "--pred", str(pred), "--out", path], match="file system")
    with pytest.raises(OutputError, match="file system"):
        atomic_write_bytes(path, b"x")  # at write time too
    with pytest.raises(FreespaceError, match="file system"):
        with claim_folder(Path(path).parent / "freespace-probe-folder", "predict"):
            pass


def test_outputs_on_a_devtmpfs_dev_are_refused_before_anything_is_written(tmp_path: Path) -> None:
    """As root a regular file could be made in ``/dev``: checked without writing (the check only stats)."""
    if not any(line.split(" - ")[1].split()[0] == "devtmpfs" and line.split()[4] == "/dev"
               for line in Path("/proc/self/mountinfo").read_text().splitlines() if " - " in line):
        pytest.skip("/dev is no devtmpfs here")
    for path, folder in (("/dev/freespace-probe.json", False), ("/dev/freespace-probe", True), ("/dev", True)):
        with pytest.raises(OutputError, match="devtmpfs"):
            check_writable(path, folder=folder)
        assert path == "/dev" or not os.path.lexists(path)


@pytest.mark.parametrize("path", ["/dev/stdout", "/dev/stderr", "/dev/freespace-probe.json"])
def test_a_name_in_dev_is_refused_whatever_it_leads_to(path: str) -> None:
    """``/dev/stdout`` leads to a regular file when the output is redirected to one: the name is still in
    ``/dev`` (the rename would replace the system's link). Checked only (these checks never write)."""
    with pytest.raises(FreespaceError, match="/dev"):
        check_writable(path)
    with pytest.raises(OutputError, match="/dev"):
        replaceable(path)
    assert not os.path.exists("/dev/freespace-probe.json")


def test_a_replaced_file_keeps_its_mode_and_owner(tmp_path: Path) -> None:
    """A2: 0600 stays 0600 (a file written alone, files written together, a staged output, a video); a new
    file gets 0666 & ~umask; as root, a file of another owner stays that owner's."""
    umask = os.umask(0o022)
    try:
        a, b = tmp_path / "a.json", tmp_path / "b.json"
        write_json(a, {"x": 1})
        assert stat.S_IMODE(a.stat().st_mode) == 0o644
        for mode in (0o600, 0o640, 0o755):
            a.chmod(mode)
            write_json(a, {"x": 2})
            assert stat.S_IMODE(a.stat().st_mode) == mode and json.loads(a.read_text()) == {"x": 2}
        b.write_text("{}")
        b.chmod(0o600)
        write_files_together({a: b"1", b: b"2"})
        assert stat.S_IMODE(b.stat().st_mode) == 0o600 and b.read_bytes() == b"2"

        out = tmp_path / "out"
        for i in range(2):
            with claim_folder(out, "predict") as folder, folder.staged() as stage:
                (stage / "s.json").write_text(str(i))
                (stage / "s.json").chmod(0o600)  # as mkstemp leaves a stage's file: the new one's mode is not kept
            if i == 0:
                assert stat.S_IMODE((out / "s.json").stat().st_mode) == 0o644
                (out / "s.json").chmod(0o640)
        assert stat.S_IMODE((out / "s.json").stat().st_mode) == 0o640 and (out / "s.json").read_text() == "1"

        video = tmp_path / "v.mp4"
        for i in range(2):
            with VideoWriter(video, fps=10) as writer:
                writer.write(np.full((16, 16, 3), i, np.uint8))
            if i == 0:
                assert stat.S_IMODE(video.stat().st_mode) == 0o644
                video.chmod(0o600)
        assert stat.S_IMODE(video.stat().st_mode) == 0o600

        if os.getuid() == 0:
            os.chown(a, 65534, 65534)
            write_json(a, {"x": 3})
            assert (a.stat().st_uid, a.stat().st_gid) == (65534, 65534)
    finally:
        os.umask(umask)


def test_a_read_only_output_file_is_refused_not_replaced(trained: dict[str, Path], tmp_path: Path,
                                                         capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "model.pt"
    out.write_text("mine")
    out.chmod(0o444)
    refused(capsys, ["export", "--checkpoint", str(trained["ckpt"]), "--format", "torchscript", "--out", str(out)],
            match="read-only")
    with pytest.raises(OutputError, match="read-only"):
        atomic_write_bytes(out, b"x")
    assert out.read_text() == "mine" and stat.S_IMODE(out.stat().st_mode) == 0o444


def test_an_output_file_through_a_link(tmp_path: Path) -> None:
    """A link to a regular file is replaced by the new file and the file it led to is untouched; a dangling
    link becomes the new file; a link to a folder is a folder."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "real.json").write_text("precious")
    link, dangling = tmp_path / "link.json", tmp_path / "dangling.json"
    link.symlink_to(elsewhere / "real.json")
    dangling.symlink_to(elsewhere / "missing.json")
    for path in (link, dangling):
        check_writable(path)
        write_json(path, {"new": True})
        assert not path.is_symlink() and json.loads(path.read_text()) == {"new": True}
    assert sorted(p.name for p in elsewhere.iterdir()) == ["real.json"]
    assert (elsewhere / "real.json").read_text() == "precious"
    (tmp_path / "dirlink").symlink_to(elsewhere, target_is_directory=True)
    with pytest.raises(InvalidOptionError, match="is a folder"):
        check_writable(tmp_path / "dirlink")


def test_a_link_that_cannot_be_followed_is_refused_in_one_line(trained: dict[str, Path], tmp_path: Path,
                                                               capsys: pytest.CaptureFixture) -> None:
    """A link loop (a file or a folder output: a traceback before), a link into a missing folder, and an
    output folder that is a dangling link: refused, naming the link; nothing is created."""
    loop, lost, dangling = tmp_path / "loop", tmp_path / "lost.pt", tmp_path / "dangling"
    loop.symlink_to("loop")
    lost.symlink_to(tmp_path / "missing" / "m.pt")
    dangling.symlink_to(tmp_path / "not-yet")
    export = ["export", "--checkpoint", str(trained["ckpt"]), "--format", "torchscript", "--out"]
    predict = ["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(_images(trained)), "--out"]
    refused(capsys, [*export, str(loop)], match="cannot be followed")
    refused(capsys, [*predict, str(loop)], match="cannot be followed")
    refused(capsys, [*export, str(lost)], match="does not exist")
    refused(capsys, [*predict, str(dangling)], match="does not exist")
    with pytest.raises(InvalidOptionError, match="cannot be followed"):
        with claim_folder(loop, "predict"):
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling", "loop", "lost.pt"]


# ---------------------------------------------------------------------- G22. nested output folders

def test_the_readme_flow_evaluate_into_the_run_then_resume(trained: dict[str, Path], tmp_path: Path) -> None:
    """``evaluate --out RUN/eval``, ``train --out RUN --resume`` (one more epoch), ``evaluate --out RUN/eval``
    again: all succeed, the evaluation's folder is left as it was by the training, and it stays
    evaluate's."""
    run = tmp_path / "run"
    shutil.copytree(trained["run"], run)
    evaluate = ["evaluate", "--checkpoint", str(run / "checkpoints" / "best.ckpt"), "--dataset", "synth", "--root",
                str(trained["data"]), "--out", str(run / "eval"), "--no-progress"]
    assert main(evaluate) == 0
    before = {p: p.read_bytes() for p in sorted((run / "eval").rglob("*")) if p.is_file()}
    epochs = TRAINED_ARGS[TRAINED_ARGS.index("--epochs") + 1]
    args = [a if a != epochs else str(int(epochs) + 1) for a in TRAINED_ARGS]
    assert main(["train", "--dataset", "synth", "--root", str(trained["data"]), *args, "--out", str(run),
                 "--resume"]) == 0
    assert {p: p.read_bytes() for p in sorted((run / "eval").rglob("*")) if p.is_file()} == before
    assert len((run / "metrics.csv").read_text().splitlines()) == int(epochs) + 2  # header + one row an epoch
    assert main(evaluate) == 0
    assert json.loads((run / "eval" / META / "manifest.json").read_text())["command"] == "evaluate"
    assert "eval/" not in json.loads((run / META / "manifest.json").read_text())["entries"]


def test_reproduce_tables_beside_an_evaluation_and_a_cell_without_checkpoints(trained: dict[str, Path], tmp_path: Path,
                                                                             capsys: pytest.CaptureFixture) -> None:
    """One cell (``--only``), ``evaluate --out OUT/eval`` on it, then ``reproduce --tables``: the tables are
    written and the evaluation is left as it was (22). The cell with its checkpoints deleted and a user file
    in ``checkpoints/``: the rerun refuses, naming the file, and deletes nothing (23)."""
    out = tmp_path / "rep"
    base = ["reproduce", "--dataset", "synth", "--root", str(trained["data"]), "--models", "segnet", "--seeds", "1",
            "--epochs", "1", "--image-size", "64x64", "--batch-size", "4", "--no-progress", "--out", str(out)]
    assert main([*base, "--only", "segnet,X,0"]) == 0
    cell = next((out / "runs").iterdir())
    assert main(["evaluate", "--checkpoint", str(cell / "checkpoints" / "best.ckpt"), "--dataset", "synth", "--root",
                 str(trained["data"]), "--out", str(out / "eval"), "--no-progress"]) == 0
    before = {p: p.read_bytes() for p in sorted((out / "eval").rglob("*")) if p.is_file()}
    for _ in range(2):
        assert main(["reproduce", "--tables", "--out", str(out)]) == 0
    assert (out / "results.csv").is_file()
    assert {p: p.read_bytes() for p in sorted((out / "eval").rglob("*")) if p.is_file()} == before

    for path in [cell / "metrics.json", *(cell / "checkpoints").glob("*.ckpt")]:
        path.unlink()
    (cell / "checkpoints" / "mine.txt").write_text("mine")
    capsys.readouterr()
    assert main([*base, "--only", "segnet,X,0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()  # reproduce's progress line, then the one-line error
    assert "checkpoints/mine.txt, which freespace train did not write" in err[-1] and "Traceback" not in "".join(err)
    assert (cell / "checkpoints" / "mine.txt").read_text() == "mine" and (cell / "config.yaml").is_file()


def test_a_nested_output_folder_is_never_touched_by_the_outer_command(tmp_path: Path) -> None:
    """The outer command replaces its own output (``reproduce --tables``'s folder here) beside another
    command's folder in it: the nested folder's files stay; a nested folder at or inside one of the outer
    command's entries is refused, named, before any work."""
    from freespace.experiments import OUT_ENTRIES

    out = tmp_path / "out"
    with claim_folder(out, "reproduce", entries=OUT_ENTRIES) as folder, folder.staged() as stage:
        (stage / "results.csv").write_text("old")
    with claim_folder(out / "eval", "evaluate") as folder, folder.staged() as stage:
        (stage / "metrics.json").write_text("{}")
    with claim_folder(out / "deeper" / "p", "predict") as folder, folder.staged() as stage:
        (stage / "a.png").write_bytes(b"x")
    for _ in range(2):
        with claim_folder(out, "reproduce", entries=OUT_ENTRIES) as folder, folder.staged() as stage:
            (stage / "results.csv").write_text("new")
    assert (out / "eval" / "metrics.json").read_text() == "{}" and (out / "deeper" / "p" / "a.png").is_file()
    assert (out / "results.csv").read_text() == "new"

    with claim_folder(out / "figures", "predict") as folder, folder.staged() as stage:  # at a "dir/" entry
        (stage / "b.png").write_bytes(b"x")
    with pytest.raises(InvalidOptionError, match="figures/, the output folder of freespace predict"):
        with claim_folder(out, "reproduce", entries=OUT_ENTRIES):
            pass
    assert (out / "figures" / "b.png").is_file()
    shutil.rmtree(out / "figures")

    with claim_folder(out / "sub", "evaluate") as folder, folder.staged() as stage:  # where the stage would write
        (stage / "metrics.json").write_text("{}")
    with pytest.raises(OutputError, match="inside sub/"):
        with claim_folder(out, "reproduce", entries=OUT_ENTRIES) as folder, folder.staged() as stage:
            (stage / "sub").mkdir()
            (stage / "sub" / "metrics.json").write_text("overwritten")
    assert (out / "sub" / "metrics.json").read_text() == "{}"


def test_an_evaluation_where_training_writes_is_refused(trained: dict[str, Path], tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "run"
    shutil.copytree(trained["run"], run)
    refused(capsys, ["evaluate", "--checkpoint", str(trained["ckpt"]), "--dataset", "synth", "--root",
                     str(trained["data"]), "--out", str(run / "checkpoints" / "eval")], match="lies inside")
    other = tmp_path / "other"  # an evaluation first, then a training run whose checkpoints/ it would be
    assert main(["evaluate", "--checkpoint", str(trained["ckpt"]), "--dataset", "synth", "--root",
                 str(trained["data"]), "--out", str(other / "checkpoints"), "--no-progress"]) == 0
    before = sorted(p.relative_to(other) for p in other.rglob("*"))
    refused(capsys, ["train", "--dataset", "synth", "--root", str(trained["data"]), *TRAINED_ARGS, "--out",
                     str(other)], match="checkpoints/, the output folder of freespace evaluate")
    assert sorted(p.relative_to(other) for p in other.rglob("*")) == before


# ------------------------------------------------------------ G23. a run whose checkpoints are gone

def test_a_restarted_run_keeps_a_user_file_and_says_it_trains_anew(trained: dict[str, Path], tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture,
                                                                  caplog: pytest.LogCaptureFixture) -> None:
    run = tmp_path / "run"
    shutil.copytree(trained["run"], run)
    for ckpt in (run / "checkpoints").glob("*.ckpt"):
        ckpt.unlink()
    (run / "metrics.json").unlink()
    (run / "checkpoints" / "mine.txt").write_text("mine")
    argv = ["train", "--dataset", "synth", "--root", str(trained["data"]), *TRAINED_ARGS, "--out", str(run)]
    refused(capsys, argv, match="checkpoints/mine.txt, which freespace train did not write")
    assert (run / "checkpoints" / "mine.txt").read_text() == "mine" and (run / "config.yaml").is_file()
    (run / "splits" / "notes.txt").write_text("mine")
    (run / "checkpoints" / "mine.txt").unlink()
    refused(capsys, argv, match="splits/notes.txt")
    (run / "splits" / "notes.txt").unlink()
    with caplog.at_level(logging.WARNING, logger="freespace.engine.train"):
        assert main(argv) == 0
    assert any("trained 1 epoch" in r.getMessage() and "last.ckpt is gone" in r.getMessage() for r in caplog.records)
    assert (run / "checkpoints" / "last.ckpt").is_file()


# --------------------------------------------------------------- G24. nothing inside a .freespace folder

def test_an_output_inside_a_freespace_folder_is_refused(trained: dict[str, Path], tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "run"
    shutil.copytree(trained["run"], run)
    meta = run / META
    before = sorted(p.name for p in meta.iterdir())
    (tmp_path / "link").symlink_to(meta, target_is_directory=True)
    predict = ["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(_images(trained)), "--no-progress"]
    for out in (meta / "p", meta, tmp_path / "link" / "p", meta / "stage-1-x"):
        refused(capsys, [*predict, "--out", str(out)], match=".freespace")
    refused(capsys, ["export", "--checkpoint", str(trained["ckpt"]), "--format", "onnx", "--out", str(meta / "m.onnx")],
            match=".freespace")
    refused(capsys, ["evaluate", "--checkpoint", str(trained["ckpt"]), "--dataset", "synth", "--root",
                     str(trained["data"]), "--out", str(tmp_path / "link" / "e")], match=".freespace")
    assert sorted(p.name for p in meta.iterdir()) == before


# ------------------------------------------------------------------------ G25. an unreadable manifest

@pytest.mark.parametrize("manifest", ["not-json", "a-list", "wrong-types", "a-folder", "a-fifo"])
def test_an_unreadable_manifest_is_named(manifest: str, trained: dict[str, Path], tmp_path: Path,
                                         capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "out"
    predict = ["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(_images(trained)), "--out", str(out),
               "--no-progress"]
    assert main(predict) == 0
    path = out / META / "manifest.json"
    path.unlink()
    if manifest == "a-folder":
        path.mkdir()
    elif manifest == "a-fifo":
        os.mkfifo(path)
    else:
        path.write_text({"not-json": "{bad", "a-list": "[]", "wrong-types": '{"command": 1, "entries": "x"}'}[manifest])
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    err = refused(capsys, predict, match="unreadable manifest")
    assert "did not write" not in err and "empty" in err and str(path) in err
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before
    with pytest.raises(CorruptFileError, match="unreadable manifest"):
        with claim_folder(out, "predict"):
            pass
