"""Hostile input: every command refuses what would lose a user's data, and fails in one line.

Each case asserts what matters to the user: exit code 2, one line on stderr and no traceback, inputs
byte-identical afterwards, and no partial output left behind.
"""

from __future__ import annotations

import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.io import write_disparity, write_image

from helpers import synthetic_pair

SMALL = SynthConfig(width=160, height=128, frames_per_scenario=2)


def snapshot(*paths: Path) -> dict[str, bytes]:
    """The bytes of every file under ``paths`` (files or folders), by path."""
    files: dict[str, bytes] = {}
    for p in paths:
        for f in ([p] if p.is_file() else sorted(q for q in p.rglob("*") if q.is_file())):
            files[str(f)] = f.read_bytes()
    return files


def refused(capsys: pytest.CaptureFixture, argv: list[str], *, match: str | None = None) -> str:
    """Run the command in-process; assert exit 2 and exactly one line on stderr; return that line."""
    capsys.readouterr()
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, f"exit {code}, stderr: {err!r}"
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("freespace: error: "), err
    if match is not None:
        assert match.lower() in err.lower(), err
    return err


def run_cli(*args: str, timeout: float = 120, **kw) -> subprocess.CompletedProcess:
    """The command in a fresh process (what a user sees, tracebacks included)."""
    return subprocess.run([sys.executable, "-m", "freespace.cli", *args], capture_output=True, text=True,
                          timeout=timeout, **kw)


def refused_process(res: subprocess.CompletedProcess, match: str | None = None) -> None:
    err = res.stderr.strip()
    assert res.returncode == 2, (res.returncode, err[-2000:])
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err[-2000:]
    if match is not None:
        assert match.lower() in err.lower(), err


# --------------------------------------------------------------------------------------------- fixtures
@pytest.fixture
def pair(tmp_path: Path) -> dict[str, Path]:
    left, right, label, disparity = synthetic_pair((96, 160))
    mask = (label.road & label.valid).astype(np.uint8) * 255
    files = {"L": tmp_path / "L.png", "R": tmp_path / "R.png", "M": tmp_path / "M.png", "D": tmp_path / "D.png"}
    write_image(files["L"], left)
    write_image(files["R"], right)
    write_image(files["M"], mask)
    write_disparity(files["D"], disparity)
    return files


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A tiny dataset and a checkpoint trained on it for one epoch."""
    base = tmp_path_factory.mktemp("hostile")
    data = base / "data"
    write_dataset(data, 8, seed=3, config=SMALL, progress=False)
    assert main(["train", "--dataset", "synth", "--root", str(data), "--model", "segnet", "--epochs", "1",
                 "--batch-size", "4", "--image-size", "64x64", "--no-progress", "--out", str(base / "run")]) == 0
    return {"data": data, "run": base / "run", "ckpt": base / "run" / "checkpoints" / "best.ckpt", "base": base}


def _kitti_root(trained: dict[str, Path], tmp_path: Path) -> Path:
    root = tmp_path / "kitti"
    shutil.copytree(trained["data"], root)
    return root


# ------------------------------------------------------------------- 1. an output never overwrites an input
@pytest.mark.parametrize("out_opt", ["--out", "--model-json"])
@pytest.mark.parametrize("victim", ["L", "R", "M", "D"])
def test_generate_output_is_an_input(out_opt: str, victim: str, pair: dict[str, Path], tmp_path: Path,
                                     capsys: pytest.CaptureFixture) -> None:
    before = snapshot(tmp_path)
    args = ["generate", "--reference", str(pair["L"]), "--target", str(pair["R"]), "--road-mask", str(pair["M"]),
            "--disparity", str(pair["D"])]
    args += ["--out", str(pair[victim])] if out_opt == "--out" else ["--out", str(tmp_path / "G.png"),
                                                                      "--model-json", str(pair[victim])]
    refused(capsys, args, match="input")
    assert snapshot(tmp_path) == before


def test_generate_output_through_a_symlink(pair: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    link = tmp_path / "link.png"
    link.symlink_to(pair["L"])
    before = snapshot(pair["L"])
    refused(capsys, ["generate", "--reference", str(pair["L"]), "--target", str(pair["R"]), "--road-mask",
                     str(pair["M"]), "--disparity", str(pair["D"]), "--out", str(link)], match="input")
    assert snapshot(pair["L"]) == before


def test_generate_dataset_out_inside_the_dataset(trained: dict[str, Path], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture) -> None:
    root = _kitti_root(trained, tmp_path)
    image_2 = root / "data_road" / "training" / "image_2"
    before = snapshot(root)
    refused(capsys, ["generate", "--dataset", "synth", "--root", str(root), "--out", str(image_2)], match="inside")
    refused(capsys, ["generate", "--dataset", "synth", "--root", str(root), "--out", str(root / "gen")], match="inside")
    assert snapshot(root) == before


def test_train_run_folder_inside_the_dataset(trained: dict[str, Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture) -> None:
    root = _kitti_root(trained, tmp_path)
    before = snapshot(root)
    refused(capsys, ["train", "--dataset", "synth", "--root", str(root), "--out", str(root / "run")], match="inside")
    refused(capsys, ["train", "--dataset", "synth", "--root", str(root), "--out", str(tmp_path)], match="inside")
    assert snapshot(root) == before


def test_predict_out_is_the_input(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images = tmp_path / "images"
    shutil.copytree(trained["data"] / "data_road" / "training" / "image_2", images)
    before = snapshot(images)
    refused(capsys, ["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(images), "--out", str(images),
                     "--no-progress"], match="input")
    one = sorted(images.iterdir())[0]
    refused(capsys, ["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(one), "--out", str(images),
                     "--no-progress"], match="input")
    assert snapshot(images) == before


def test_export_out_is_the_checkpoint(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    ckpt = tmp_path / "model.ckpt"
    shutil.copy(trained["ckpt"], ckpt)
    before = snapshot(ckpt)
    refused(capsys, ["export", "--checkpoint", str(ckpt), "--format", "onnx", "--out", str(ckpt)], match="input")
    assert snapshot(ckpt) == before


def test_evaluate_kitti_out_inside_the_ground_truth(trained: dict[str, Path], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    gt = tmp_path / "gt"
    shutil.copytree(trained["data"] / "data_road" / "training" / "gt_image_2", gt)
    before = snapshot(gt)
    refused(capsys, ["evaluate-kitti", "--gt", str(gt), "--pred", str(gt), "--out", str(gt / "scores.json")],
            match="inside")
    assert snapshot(gt) == before


# --------------------------------------------------- 2. outputs made with other settings are never mixed
def test_synth_refuses_other_settings_in_the_same_folder(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "syn"
    assert main(["synth", "--out", str(out), "--num", "2", "--width", "96", "--height", "64"]) == 0
    before = snapshot(out)
    err = refused(capsys, ["synth", "--out", str(out), "--num", "2", "--width", "80", "--height", "64"])
    assert "width" in err and "--overwrite" in err
    assert snapshot(out) == before
    # the same settings extend the dataset; --overwrite replaces it, stale frames included
    assert main(["synth", "--out", str(out), "--num", "3", "--width", "96", "--height", "64"]) == 0
    assert len(list((out / "data_road" / "training" / "image_2").iterdir())) == 3
    assert main(["synth", "--out", str(out), "--num", "1", "--width", "80", "--height", "64", "--overwrite"]) == 0
    assert len(list((out / "data_road" / "training" / "image_2").iterdir())) == 1
    assert json.loads((out / "synth.json").read_text())["config"]["width"] == 80
    assert main(["datasets", "info", "--dataset", "synth", "--root", str(out), "--no-progress"]) == 0


def test_generate_dataset_refuses_other_fit_options(trained: dict[str, Path], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    gen = tmp_path / "gen"
    base = ["generate", "--dataset", "synth", "--root", str(trained["data"]), "--out", str(gen)]
    assert main(base) == 0
    before = snapshot(gen)
    err = refused(capsys, base + ["--inlier-threshold", "2.5"])
    assert "inlier_threshold" in err and "--overwrite" in err
    assert snapshot(gen) == before
    assert main(base) == 0  # the same options: resumes, nothing regenerated
    assert main(base + ["--inlier-threshold", "2.5", "--overwrite"]) == 0
    summary = json.loads((gen / "summary.json").read_text())
    assert summary["options"]["inlier_threshold"] == 2.5 and summary["skipped"] == 0


# --------------------------------------------------------------------------------------- 3. run folders
def test_failed_start_leaves_a_folder_a_plain_rerun_takes_over(trained: dict[str, Path], tmp_path: Path,
                                                               capsys: pytest.CaptureFixture) -> None:
    root = _kitti_root(trained, tmp_path)
    image = sorted((root / "data_road" / "training" / "image_2").iterdir())[0]
    good = image.read_bytes()
    image.write_bytes(b"not a png")
    run = tmp_path / "run"
    args = ["train", "--dataset", "synth", "--root", str(root), "--model", "segnet", "--epochs", "1",
            "--image-size", "64x64", "--no-progress", "--out", str(run)]
    refused(capsys, args, match=image.name)
    assert not (run / "checkpoints").exists()
    image.write_bytes(good)
    assert main(args) == 0  # a plain rerun takes the folder over
    assert (run / "metrics.json").is_file()


def test_resume_reads_only_its_own_folder(trained: dict[str, Path], tmp_path: Path) -> None:
    moved = tmp_path / "moved"
    shutil.copytree(trained["run"], moved)
    original_best = trained["ckpt"].read_bytes()
    # the original folder's best checkpoint is replaced by garbage: the moved run must not read it
    trained["ckpt"].write_bytes(b"garbage")
    try:
        assert main(["train", "--dataset", "synth", "--root", str(trained["data"]), "--model", "segnet",
                     "--epochs", "2", "--image-size", "64x64", "--no-progress", "--out", str(moved), "--resume"]) == 0
    finally:
        trained["ckpt"].write_bytes(original_best)
    metrics = json.loads((moved / "metrics.json").read_text())
    assert metrics["checkpoint"] == "checkpoints/best.ckpt"


class _Payload:
    def __reduce__(self):
        return (os.system, ("touch PWNED",))


def test_resume_refuses_a_malicious_checkpoint(trained: dict[str, Path], tmp_path: Path) -> None:
    run = tmp_path / "run"
    shutil.copytree(trained["run"], run)
    with open(run / "checkpoints" / "last.ckpt", "wb") as f:
        pickle.dump({"state_dict": _Payload()}, f)
    res = run_cli("train", "--dataset", "synth", "--root", str(trained["data"]), "--model", "segnet", "--epochs", "2",
                  "--image-size", "64x64", "--no-progress", "--out", str(run), "--resume", cwd=tmp_path)
    refused_process(res, match="last.ckpt")
    assert not (tmp_path / "PWNED").exists()


def test_torch_floor_loads_safely() -> None:
    import tomllib

    deps = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]
    torch_req = [d for d in deps["optional-dependencies"]["train"] if d.startswith("torch>")][0]
    major, minor = map(int, torch_req.split(">=")[1].split(".")[:2])
    assert (major, minor) >= (2, 6), "torch < 2.6 loads checkpoints with weights_only=False by default"


# ------------------------------------------------------------------ 5. tracebacks that reached the user
@pytest.mark.parametrize("argv", [
    ["synth", "--out", "{tmp}/s", "--num", "2", "--seed", "-1"],
    ["datasets", "split", "--dataset", "synth", "--root", "{data}", "--out", "{tmp}/lists", "--seed", "-1"],
    ["train", "--dataset", "synth", "--root", "{data}", "--seed", "-1", "--out", "{tmp}/run"],
    ["demo", "--out", "{tmp}/demo", "--seed", "-1"],
    ["train", "--dataset", "synth", "--root", "{data}", "--image-size", "100000x100000", "--out", "{tmp}/run"],
    ["synth", "--out", "{tmp}/s", "--num", "10000000000000"],
    ["reproduce", "--dataset", "synth", "--root", "{data}", "--seeds", "100000000000", "--out", "{tmp}/r"],
    ["demo", "--out", "{tmp}/demo", "--epochs", "0"],
    ["demo", "--out", "{tmp}/demo", "--epochs", "-1"],
    ["demo", "--out", "{tmp}/demo", "--num", "2"],
    ["generate", "--reference", "{tmp}/L.png", "--target", "{tmp}/R.png", "--road-mask", "{tmp}/M.png",
     "--out", "{tmp}/G.png", "--inlier-threshold", "inf"],
])
def test_bad_values_are_refused_before_any_work(argv: list[str], trained: dict[str, Path], pair: dict[str, Path],
                                                tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    argv = [a.format(tmp=tmp_path, data=trained["data"]) for a in argv]
    before = set(tmp_path.rglob("*"))
    t0 = time.perf_counter()
    err = refused(capsys, argv)
    assert time.perf_counter() - t0 < 10, "validated after starting work"
    assert set(tmp_path.rglob("*")) == before, "left output behind"
    assert "--splits" not in err


def test_huge_image_size_in_a_checkpoint(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    import torch

    ckpt = torch.load(trained["ckpt"], map_location="cpu", weights_only=True)
    ckpt["hyper_parameters"]["image_size"] = [100000, 100000]
    crafted = tmp_path / "huge.ckpt"
    torch.save(ckpt, crafted)
    _predict_refused(capsys, trained, tmp_path, ["--checkpoint", str(crafted)], "image size")


def _predict_refused(capsys: pytest.CaptureFixture, trained: dict[str, Path], tmp_path: Path, model: list[str],
                     match: str) -> None:
    """`predict` with this model on the training images is refused, and writes no output."""
    images = trained["data"] / "data_road" / "training" / "image_2"
    refused(capsys, ["predict", *model, "--input", str(images), "--out", str(tmp_path / "p"), "--no-progress"],
            match=match)
    assert not (tmp_path / "p").exists()


def test_foreign_onnx_model(tmp_path: Path, trained: dict[str, Path], capsys: pytest.CaptureFixture) -> None:
    import onnx
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("features", TensorProto.FLOAT, [1, 10])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 10])
    graph = helper.make_graph([helper.make_node("Relu", ["features"], ["y"])], "foreign", [x], [y])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    path = tmp_path / "foreign.onnx"
    onnx.save(model, path)
    _predict_refused(capsys, trained, tmp_path, ["--onnx", str(path)], "input")


CALIB_KEYS = ("P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam", "Tr_imu_to_velo", "Tr_cam_to_road")


def _edit_calib(path: Path, key: str, values: str) -> None:
    lines = [f"{key}: {values}" if line.startswith(key + ":") else line for line in path.read_text().splitlines()]
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("key,values,match", [
    ("P2", "1 2", "P2"),
    ("P2", " ".join(["nan"] * 12), "P2"),
    ("Tr_cam_to_road", " ".join(["0"] * 12), "Tr_cam_to_road"),
])
def test_evaluate_kitti_bev_malformed_calibration(key: str, values: str, match: str, trained: dict[str, Path],
                                                  tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    training = trained["data"] / "data_road" / "training"
    calib = tmp_path / "calib"
    shutil.copytree(training / "calib", calib)
    _edit_calib(sorted(calib.iterdir())[0], key, values)
    refused(capsys, ["evaluate-kitti", "--bev", "--calib", str(calib), "--gt", str(training / "gt_image_2"),
                     "--pred", str(training / "gt_image_2"), "--out", str(tmp_path / "s.json")], match=match)
    assert not (tmp_path / "s.json").exists()


def test_kitti_submit_singular_calibration(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "kitti"
    (root / "data_road").mkdir(parents=True)
    shutil.copytree(trained["data"] / "data_road" / "training", root / "data_road" / "testing")
    calib = sorted((root / "data_road" / "testing" / "calib").iterdir())
    _edit_calib(calib[-1], "Tr_cam_to_road", " ".join(["0"] * 12))
    out = tmp_path / "sub"
    refused(capsys, ["kitti-submit", "--checkpoint", str(trained["ckpt"]), "--root", str(root), "--out", str(out),
                     "--no-progress"], match="Tr_cam_to_road")
    assert not out.exists()


@pytest.mark.parametrize("yaml_text,match", [
    ("road_ids: [abc]\n", "road_ids"),
    ("label_channel: 99\n", "label_channel"),
    ("depth_scale: abc\n", "depth_scale"),
])
def test_generic_yaml_wrong_types(yaml_text: str, match: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "generic"
    for sub in ("left", "right", "labels"):
        (root / sub).mkdir(parents=True)
    left, right, label, _ = synthetic_pair((64, 96))
    write_image(root / "left" / "a.png", left)
    write_image(root / "right" / "a.png", right)
    write_image(root / "labels" / "a.png", (label.road * 1).astype(np.uint8))
    (root / "freespace.yaml").write_text("left: left\nright: right\nlabel: labels\n" + yaml_text)
    refused(capsys, ["datasets", "info", "--dataset", "generic", "--root", str(root), "--no-progress"], match=match)


# --------------------------------------------------------------------------------------- 7. no half results
def test_evaluate_with_a_corrupt_frame_leaves_nothing(trained: dict[str, Path], tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    root = _kitti_root(trained, tmp_path)
    sorted((root / "data_road" / "training" / "image_2").iterdir())[-1].write_bytes(b"corrupt")
    out = tmp_path / "eval"
    refused(capsys, ["evaluate", "--checkpoint", str(trained["ckpt"]), "--dataset", "synth", "--root", str(root),
                     "--subset", "all", "--no-progress", "--out", str(out)])
    assert not out.exists()


def test_failed_kitti_submit_keeps_the_previous_submission(trained: dict[str, Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "kitti"
    (root / "data_road").mkdir(parents=True)
    shutil.copytree(trained["data"] / "data_road" / "training", root / "data_road" / "testing")
    out = tmp_path / "sub"
    assert main(["kitti-submit", "--checkpoint", str(trained["ckpt"]), "--root", str(root), "--out", str(out),
                 "--no-progress"]) == 0
    before = snapshot(out)
    sorted((root / "data_road" / "testing" / "image_2").iterdir())[-1].write_bytes(b"corrupt")
    refused(capsys, ["kitti-submit", "--checkpoint", str(trained["ckpt"]), "--root", str(root), "--out", str(out),
                     "--no-progress"])
    assert snapshot(out) == before


# ------------------------------------------------------- 8. datasets info lists what generate/train would hit
@pytest.mark.parametrize("damage", ["8-bit disparity", "all-black label"])
def test_info_finds_what_generate_would_hit(damage: str, trained: dict[str, Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture) -> None:
    root = _kitti_root(trained, tmp_path)
    training = root / "data_road" / "training"
    if damage == "8-bit disparity":
        victim = sorted((training / "disparity").iterdir())[0]
        write_image(victim, np.full((128, 160), 30, np.uint8))
    else:
        victim = sorted((training / "gt_image_2").iterdir())[0]
        write_image(victim, np.zeros((128, 160, 3), np.uint8))
    capsys.readouterr()
    assert main(["datasets", "info", "--dataset", "synth", "--root", str(root), "--no-progress"]) == 1
    out = capsys.readouterr().out
    frame = victim.stem.replace("_road", "")
    assert frame in out and ("16-bit" in out if damage == "8-bit disparity" else "no road" in out), out


# --------------------------------------------------------------------------------------- 9. smaller fixes
def test_sgbm_on_a_narrow_image_says_why(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    left, right, label, _ = synthetic_pair((96, 100))
    for name, img in (("L", left), ("R", right), ("M", (label.road & label.valid).astype(np.uint8) * 255)):
        write_image(tmp_path / f"{name}.png", img)
    err = refused(capsys, ["generate", "--reference", str(tmp_path / "L.png"), "--target", str(tmp_path / "R.png"),
                           "--road-mask", str(tmp_path / "M.png"), "--out", str(tmp_path / "G.png")])
    assert "width" in err and "--max-disparity" in err and "disparity file" not in err


def test_killed_generate_leaves_no_workers(tmp_path: Path) -> None:
    data = tmp_path / "data"
    write_dataset(data, 40, seed=1, config=SMALL, progress=False)
    proc = subprocess.Popen([sys.executable, "-m", "freespace.cli", "generate", "--dataset", "synth", "--root",
                             str(data), "--out", str(tmp_path / "gen"), "--workers", "2", "--disparity-source",
                             "sgbm", "--cache-dir", str(tmp_path / "cache")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    children: list[int] = []
    while time.time() < deadline and len(children) < 2:
        time.sleep(0.2)
        children = _children(proc.pid)
    assert len(children) >= 2, "the workers never started"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 15
    while time.time() < deadline and any(_alive(c) for c in children):
        time.sleep(0.2)
    alive = [c for c in children if _alive(c)]
    for c in alive:
        os.kill(c, signal.SIGKILL)
    assert not alive, "worker processes outlived the killed command"


def _children(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    return [int(p) for p in out.split()]


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except FileNotFoundError:
        return False


# ------------------------------------------------------------------------ 10. output when not on a terminal
def test_training_off_a_terminal_prints_lines_not_bar_frames(trained: dict[str, Path], tmp_path: Path) -> None:
    res = run_cli("train", "--dataset", "synth", "--root", str(trained["data"]), "--model", "segnet", "--epochs", "2",
                  "--image-size", "64x64", "--out", str(tmp_path / "run"), timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    text = res.stdout + res.stderr
    assert "\r" not in text
    assert sum("epoch" in line.lower() for line in text.splitlines()) >= 2, text


# ======================================================================================================
# issue 20: tracebacks and signals
# Crafted checkpoints and ONNX models, unusable reproduce cells, outputs checked before the work, options
# that were ignored, Ctrl-C and SIGTERM on every kind of command, library noise.
# ======================================================================================================
def _crafted_checkpoint(trained: dict[str, Path], tmp_path: Path, edit, name: str = "crafted.ckpt",
                        source: str = "ckpt") -> Path:
    """A copy of the trained checkpoint (``source``: ``ckpt`` = best, ``last``) changed in place by
    ``edit(ckpt)``; a list that ``edit`` returns is saved instead (a checkpoint that is no mapping)."""
    import torch

    path = trained["ckpt"] if source == "ckpt" else trained["run"] / "checkpoints" / "last.ckpt"
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    result = edit(ckpt)
    out = tmp_path / name
    torch.save(result if isinstance(result, list) else ckpt, out)
    return out


def _first_weight(ckpt: dict) -> str:
    return next(iter(ckpt["state_dict"]))


def _zeros(*shape: int):
    import torch

    return torch.zeros(*shape)


CRAFTED_CHECKPOINTS = {
    "state_dict is a list": (lambda c: c.update(state_dict=list(c["state_dict"].values())), "state_dict"),
    "state_dict keys are numbers": (lambda c: c.update(state_dict={1: 2}), "state_dict"),
    "a weight missing": (lambda c: c["state_dict"].pop(_first_weight(c)), "1 missing"),
    "a weight of another shape": (lambda c: c["state_dict"].__setitem__(_first_weight(c), _zeros(3, 3)),
                                  "another shape"),
    "another preset's weights": (lambda c: c["hyper_parameters"]["model_options"].update(preset="paper"),
                                 "do not fit"),
    "NaN weights": (lambda c: c["state_dict"][_first_weight(c)].fill_(float("nan")), "non-finite"),
    "a list, not a mapping": (lambda c: [1, 2, 3], "not a freespace training checkpoint"),
    "hyper_parameters a list": (lambda c: c.update(hyper_parameters=[1]), "hyper_parameters"),
    "an unknown network": (lambda c: c["hyper_parameters"].update(model="fcn"), "unknown model 'fcn'"),
}


@pytest.mark.parametrize("case", list(CRAFTED_CHECKPOINTS))
def test_crafted_checkpoint_is_one_line(case: str, trained: dict[str, Path], tmp_path: Path,
                                        capsys: pytest.CaptureFixture) -> None:
    edit, match = CRAFTED_CHECKPOINTS[case]
    crafted = _crafted_checkpoint(trained, tmp_path, edit)
    _predict_refused(capsys, trained, tmp_path, ["--checkpoint", str(crafted)], match)


@pytest.mark.parametrize("command", ["export", "evaluate"])
def test_crafted_checkpoint_in_export_and_evaluate(command: str, trained: dict[str, Path], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture) -> None:
    crafted = _crafted_checkpoint(trained, tmp_path, CRAFTED_CHECKPOINTS["state_dict is a list"][0])
    out = tmp_path / ("m.onnx" if command == "export" else "eval")
    argv = (["export", "--format", "onnx"] if command == "export" else
            ["evaluate", "--dataset", "synth", "--root", str(trained["data"]), "--subset", "all", "--no-progress"])
    refused(capsys, argv + ["--checkpoint", str(crafted), "--out", str(out)], match="state_dict")
    assert not out.exists()


def test_checkpoint_asking_for_imagenet_weights_loads_offline(trained: dict[str, Path], tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture) -> None:
    """Rebuilding a network from a checkpoint never fetches pretrained weights: the checkpoint has them all."""
    import segmentation_models_pytorch as smp

    def no_network(*args, **kwargs):
        raise AssertionError("pretrained weights were asked for")

    monkeypatch.setattr(smp.encoders, "get_encoder", no_network)  # any encoder download would go through here
    crafted = _crafted_checkpoint(trained, tmp_path,
                                  lambda c: c["hyper_parameters"]["model_options"].update(encoder_weights="imagenet"))
    images = trained["data"] / "data_road" / "training" / "image_2"
    assert main(["predict", "--checkpoint", str(crafted), "--input", str(images), "--out", str(tmp_path / "p"),
                 "--no-progress"]) == 0, capsys.readouterr().err
    assert len(list((tmp_path / "p").glob("*.png"))) == len(list(images.iterdir()))


RESUME_CRAFTED = {
    "state_dict is a list": (lambda c: c.update(state_dict=list(c["state_dict"].values())), "state_dict"),
    "optimizer state a number": (lambda c: c.update(optimizer_states=[1]), "optimizer_states"),
    "loops a list": (lambda c: c.update(loops=[1]), "loops"),
    "callbacks a list": (lambda c: c.update(callbacks=[1]), "callbacks"),
    "a weight of another shape": (lambda c: c["state_dict"].__setitem__(_first_weight(c), _zeros(3, 3)),
                                  "another shape"),
    "a momentum buffer of another shape": (
        lambda c: c["optimizer_states"][0].update(state={0: {"momentum_buffer": _zeros(2)}}),
        "optimizer state"),
}


@pytest.mark.parametrize("case", list(RESUME_CRAFTED))
def test_resume_from_a_crafted_last_checkpoint(case: str, trained: dict[str, Path], tmp_path: Path,
                                               capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "run"
    shutil.copytree(trained["run"], run)
    edit, match = RESUME_CRAFTED[case]
    _crafted_checkpoint(trained, run / "checkpoints", edit, name="last.ckpt", source="last")
    before = snapshot(run)
    refused(capsys, ["train", "--dataset", "synth", "--root", str(trained["data"]), "--model", "segnet", "--epochs",
                     "2", "--image-size", "64x64", "--no-progress", "--out", str(run), "--resume"], match=match)
    assert snapshot(run) == before


def _onnx_model(path: Path, inputs, outputs, nodes, initializers=()) -> Path:
    import onnx
    from onnx import helper

    graph = helper.make_graph(nodes, path.stem, inputs, outputs, initializer=list(initializers))
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), path)
    return path


def _two_class_scores(path: Path, shape: list) -> Path:
    """An ONNX model N×3×H×W → N×2×H×W (the first two channels), input ``shape`` (numbers fix a side)."""
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("image", TensorProto.FLOAT, shape)
    y = helper.make_tensor_value_info("logits", TensorProto.FLOAT, [shape[0], 2, shape[2], shape[3]])
    consts = [helper.make_tensor(n, TensorProto.INT64, [1], [v]) for n, v in (("s", 0), ("e", 2), ("a", 1))]
    return _onnx_model(path, [x], [y], [helper.make_node("Slice", ["image", "s", "e", "a"], ["logits"])], consts)


@pytest.mark.parametrize("shape", [[1, 3, 48, 40], ["n", 3, 48, 40], [1, 3, "h", "w"]])
def test_onnx_with_a_fixed_input_size_or_batch(shape: list, trained: dict[str, Path], tmp_path: Path,
                                               capsys: pytest.CaptureFixture) -> None:
    """A fixed input size: frames are resized to it (and the maps back); a fixed batch: batches of it."""
    from freespace.io import read_image

    model = _two_class_scores(tmp_path / "fixed.onnx", shape)
    images = trained["data"] / "data_road" / "training" / "image_2"
    assert main(["predict", "--onnx", str(model), "--input", str(images), "--out", str(tmp_path / "p"),
                 "--batch-size", "3", "--no-progress"]) == 0, capsys.readouterr().err
    maps = sorted((tmp_path / "p").glob("*.png"))
    assert len(maps) == 8 and all(read_image(m).shape == (128, 160) for m in maps)


def test_onnx_refused_for_its_output_names_the_output(trained: dict[str, Path], tmp_path: Path,
                                                      capsys: pytest.CaptureFixture) -> None:
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("image", TensorProto.FLOAT, ["n", 3, "h", "w"])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, ["n", 1, "h", "w"])
    consts = [helper.make_tensor(n, TensorProto.INT64, [1], [v]) for n, v in (("s", 0), ("e", 1), ("a", 1))]
    model = _onnx_model(tmp_path / "one.onnx", [x], [y], [helper.make_node("Slice", ["image", "s", "e", "a"], ["y"])],
                        consts)
    err = refused(capsys, ["predict", "--onnx", str(model), "--input", str(trained["data"] / "data_road" / "training"
                                                                            / "image_2"), "--out", str(tmp_path / "p")])
    assert "its output is" in err and "its input is" not in err
    assert not (tmp_path / "p").exists()


def test_onnx_failing_at_run_time(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("image", TensorProto.FLOAT, ["n", 3, "h", "w"])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, ["n", "c", "h", "w"])
    shape = helper.make_tensor("shape", TensorProto.INT64, [4], [1, 2, 10, 10])
    model = _onnx_model(tmp_path / "reshape.onnx", [x], [y], [helper.make_node("Reshape", ["image", "shape"], ["y"])],
                        [shape])
    _predict_refused(capsys, trained, tmp_path, ["--onnx", str(model)], "the ONNX model failed")


def _fake_cell(runs: Path, seed: int, metrics: str | None) -> Path:
    """A run folder of reproduce's X arm for segnet (config.yaml) with ``metrics`` as its metrics.json."""
    run = runs / f"segnet-orig-s{seed}"
    run.mkdir(parents=True)
    (run / "config.yaml").write_text(f"dataset: synth\nroot: /data\nout: {run}\nmodel: segnet\naugment: none\n"
                                     f"seed: {seed}\n")
    if metrics is not None:
        (run / "metrics.json").write_text(metrics)
    return run


def test_tables_skip_unusable_cells_and_write_no_nan(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    good = {"accuracy": 0.9, "precision": 0.8, "recall": 0.7, "f_score": 0.75, "iou": 0.6, "max_f": 0.8, "ap": 0.85}
    runs = tmp_path / "out" / "runs"
    _fake_cell(runs, 0, json.dumps(good))
    _fake_cell(runs, 1, "{not json")
    _fake_cell(runs, 2, json.dumps({"accuracy": 0.9}))
    _fake_cell(runs, 3, json.dumps(good).replace("0.75", "NaN"))
    shifted = _fake_cell(runs, 4, json.dumps(good)) / "shifted"
    shifted.mkdir()
    (shifted / "metrics.json").write_text(json.dumps({**good, "iou": "high"}))
    capsys.readouterr()
    assert main(["reproduce", "--tables", "--out", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err
    warned = [line for line in err.splitlines() if "skipped" in line]
    assert len(warned) == 4, err
    for run, why in (("s1", "JSON"), ("s2", "no precision"), ("s3", "f_score is nan"), ("s4/shifted", "iou is 'high'")):
        assert any(f"segnet-orig-{run}" in line and why in line for line in warned), (run, err)

    def no_constants(text: str) -> None:
        raise AssertionError(f"{text} written into JSON")

    index = json.loads((tmp_path / "out" / "index.json").read_text(), parse_constant=no_constants)
    assert [e["status"] for e in index][:4] == ["done", "skipped: not readable as JSON (JSONDecodeError)",
                                                 "skipped: no precision, recall, f_score, iou, max_f, ap",
                                                 "skipped: f_score is nan, not a fraction in [0, 1]"]
    import csv

    rows = list(csv.DictReader((tmp_path / "out" / "results.csv").open()))
    assert [(r["test_set"], r["n"]) for r in rows] == [("test", "2")]  # seeds 0 and 4; no shifted row


@pytest.mark.parametrize("argv,match", [
    (["export", "--checkpoint", "{ckpt}", "--format", "onnx", "--out", "{tmp}/folder"], "is a folder"),
    (["export", "--checkpoint", "{ckpt}", "--format", "torchscript", "--out", "{tmp}/file/m.pt"], "is a file"),
    (["evaluate-kitti", "--gt", "{gt}", "--pred", "{gt}", "--out", "{tmp}/folder"], "is a folder"),
    (["predict", "--checkpoint", "{ckpt}", "--input", "{images}", "--out", "{tmp}/file/v.mp4"], "is a file"),
    (["predict", "--checkpoint", "{ckpt}", "--input", "{images}", "--out", "{tmp}/file"], "is a file"),
    (["evaluate", "--checkpoint", "{ckpt}", "--dataset", "synth", "--root", "{data}", "--out", "{tmp}/file/e"],
     "is a file"),
    (["kitti-submit", "--checkpoint", "{ckpt}", "--root", "{data}", "--out", "{tmp}/file/k"], "is a file"),
    (["generate", "--reference", "{tmp}/L.png", "--target", "{tmp}/R.png", "--road-mask", "{tmp}/M.png",
      "--out", "{tmp}/G.png", "--model-json", "{tmp}/folder"], "is a folder"),
    (["train", "--dataset", "synth", "--root", "{data}", "--out", "{tmp}/file/run"], "is a file"),
    (["reproduce", "--dataset", "synth", "--root", "{data}", "--out", "{tmp}/file/r"], "is a file"),
    (["datasets", "split", "--dataset", "synth", "--root", "{data}", "--out", "{tmp}/file"], "is a file"),
])
def test_outputs_are_checked_before_the_work(argv: list[str], match: str, trained: dict[str, Path],
                                             pair: dict[str, Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder" / "keep.txt").write_text("mine")
    (tmp_path / "file").write_text("mine")
    training = trained["data"] / "data_road" / "training"
    argv = [a.format(tmp=tmp_path, ckpt=trained["ckpt"], data=trained["data"], gt=training / "gt_image_2",
                     images=training / "image_2") for a in argv]
    before = set(tmp_path.rglob("*"))
    t0 = time.perf_counter()
    refused(capsys, argv, match=match)
    assert time.perf_counter() - t0 < 5, "refused after the work"
    assert set(tmp_path.rglob("*")) == before
    assert (tmp_path / "file").read_text() == "mine" and (tmp_path / "folder" / "keep.txt").read_text() == "mine"


def test_duplicate_without_right_images_is_named_and_leaves_nothing(trained: dict[str, Path], tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture) -> None:
    root = _kitti_root(trained, tmp_path)
    shutil.rmtree(root / "data_road_right")
    run = tmp_path / "run"
    err = refused(capsys, ["train", "--dataset", "synth", "--root", str(root), "--augment", "duplicate", "--model",
                           "segnet", "--image-size", "64x64", "--no-progress", "--out", str(run)], match="right images")
    assert "--augment duplicate" in err and "homography" not in err.split("(")[0]
    assert not run.exists()


def test_config_yaml_keeps_resolved_paths(trained: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture) -> None:
    """A run's config.yaml names its data and folder absolutely: `train --config` works from any folder and
    `--resume` takes the paths spelled another way; a resume says nothing about its checkpoint folder."""
    import yaml

    here, elsewhere = tmp_path / "here", tmp_path / "elsewhere"
    here.mkdir()
    elsewhere.mkdir()
    (here / "data").symlink_to(trained["data"])
    monkeypatch.chdir(here)
    common = ["--model", "segnet", "--image-size", "64x64", "--batch-size", "4", "--no-progress"]
    assert main(["train", "--dataset", "synth", "--root", "data", "--out", "run", "--epochs", "1", *common]) == 0
    config = yaml.safe_load((here / "run" / "config.yaml").read_text())
    assert config["root"] == str(trained["data"].resolve()) and config["out"] == str((here / "run").resolve())
    monkeypatch.chdir(elsewhere)
    assert main(["train", "--config", str(here / "run" / "config.yaml"), "--out", "copy", "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["train", "--dataset", "synth", "--root", str(here / "data"), "--out", str(here / "run"),
                 "--epochs", "2", "--resume", *common]) == 0
    assert "exists and is not empty" not in capsys.readouterr().err


def test_export_prints_no_library_warnings(trained: dict[str, Path], tmp_path: Path) -> None:
    for fmt in ("torchscript", "onnx"):
        res = run_cli("export", "--checkpoint", str(trained["ckpt"]), "--format", fmt, "--out", str(tmp_path / fmt))
        assert res.returncode == 0 and res.stderr == "", res.stderr[-2000:]


def test_truncated_png_is_one_line_without_libpng_noise(trained: dict[str, Path], tmp_path: Path) -> None:
    image = tmp_path / "cut.png"
    data = sorted((trained["data"] / "data_road" / "training" / "image_2").iterdir())[0].read_bytes()
    image.write_bytes(data[: len(data) // 2])
    res = run_cli("predict", "--checkpoint", str(trained["ckpt"]), "--input", str(image), "--out", str(tmp_path / "p"))
    refused_process(res, match="cut short")
    assert "libpng" not in res.stderr


@pytest.mark.parametrize("extra,match", [
    (["--test-root", "train={data}"], "'train' cannot name a test set"),
    (["--test-root", "val={other}"], "'val' cannot name a test set"),
    (["--test-root", "same={data}"], "--root's own frames"),
    (["--test-root", "{link}"], "--root's own frames"),
    (["--only", "segnet,X,0", "--variants", "X,FOO"], "unknown variants ['FOO']"),
    (["--only", "segnet,X,0", "--models", "nonexistent"], "unknown models ['nonexistent']"),
    (["--only", "segnet,X,0", "--models", "unet"], "not among --models"),
    (["--only", "segnet,HV-X,0", "--variants", "X,HA-X"], "not among --variants"),
])
def test_reproduce_refuses_test_sets_and_names_before_any_work(extra: list[str], match: str,
                                                               trained: dict[str, Path], tmp_path: Path,
                                                               capsys: pytest.CaptureFixture) -> None:
    other = _kitti_root(trained, tmp_path)
    (tmp_path / "link").symlink_to(trained["data"])
    extra = [a.format(data=trained["data"], other=other, link=tmp_path / "link") for a in extra]
    refused(capsys, ["reproduce", "--dataset", "synth", "--root", str(trained["data"]), "--epochs", "1",
                     "--out", str(tmp_path / "r"), *extra], match=match)
    assert not (tmp_path / "r").exists()


def test_ignored_options_are_refused(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    gt = trained["data"] / "data_road" / "training" / "gt_image_2"
    refused(capsys, ["evaluate-kitti", "--gt", str(gt), "--pred", str(gt), "--calib", str(tmp_path),
                     "--out", str(tmp_path / "s.json")], match="--calib is only used with --bev")
    refused(capsys, ["reproduce", "--tables", "--models", "unet", "--out", str(tmp_path)], match="takes no --models")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------- Ctrl-C and SIGTERM
def _signalled(args: list[str], sig: int, *, ready: str | None = None, children: int = 0,
               timeout: float = 120) -> tuple[int, str, float, list[int]]:
    """Start ``freespace ARGS``, wait until stderr shows ``ready`` (or ``children`` child processes run),
    send ``sig`` (SIGINT to the process group, as a terminal does; SIGTERM to the command only, as
    ``kill`` does) and return the exit code, stderr, the seconds from the signal to the exit, and the
    child processes seen."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "freespace.cli", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    lines: list[str] = []
    seen: list[int] = []
    try:
        deadline = time.time() + timeout
        if ready is not None:
            for line in proc.stderr:  # type: ignore[union-attr]
                lines.append(line)
                if ready in line or time.time() > deadline:
                    break
        while len(seen) < children and time.time() < deadline:
            time.sleep(0.1)
            seen = _children(proc.pid)
        assert proc.poll() is None, "finished before the signal: " + "".join(lines)[-2000:]
        t0 = time.perf_counter()
        os.killpg(proc.pid, sig) if sig == signal.SIGINT else proc.send_signal(sig)
        rest = proc.stderr.read()  # type: ignore[union-attr]
        code = proc.wait(timeout=60)
        return code, "".join(lines) + rest, time.perf_counter() - t0, seen
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _ended_by_signal(code: int, err: str, sig: int) -> None:
    expected = (130, "freespace: interrupted") if sig == signal.SIGINT else (143, "freespace: terminated (SIGTERM)")
    assert code == expected[0], (code, err[-2000:])
    assert err.rstrip().splitlines()[-1] == expected[1], err[-2000:]
    assert "Traceback" not in err and "Detected KeyboardInterrupt" not in err, err[-2000:]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_generate_workers_stop_at_once(sig: int, tmp_path: Path) -> None:
    data = tmp_path / "data"
    write_dataset(data, 40, seed=1, config=SMALL, progress=False)
    code, err, seconds, workers = _signalled(
        ["generate", "--dataset", "synth", "--root", str(data), "--out", str(tmp_path / "gen"), "--workers", "2",
         "--disparity-source", "sgbm", "--cache-dir", str(tmp_path / "cache")], sig, children=2)
    _ended_by_signal(code, err, sig)
    assert seconds < 5, f"took {seconds:.1f} s to stop"
    assert len(list((tmp_path / "gen").glob("*.png"))) < 40, "every frame was still generated"
    time.sleep(0.5)
    alive = [c for c in workers if _alive(c)]
    for c in alive:
        os.kill(c, signal.SIGKILL)
    assert not alive, "workers outlived the command"


@pytest.mark.parametrize("command,sig", [("train", signal.SIGINT), ("train", signal.SIGTERM),
                                         ("reproduce", signal.SIGINT)])
def test_training_commands_end_like_the_others(command: str, sig: int, trained: dict[str, Path],
                                               tmp_path: Path) -> None:
    args = ["--dataset", "synth", "--root", str(trained["data"]), "--epochs", "1000", "--patience", "1000",
            "--image-size", "64x64", "--batch-size", "4", "--no-progress", "--out", str(tmp_path / "out")]
    args = (["train", "--model", "segnet", *args] if command == "train" else
            ["reproduce", "--models", "segnet", "--variants", "X", "--seeds", "1", *args])
    code, err, seconds, _ = _signalled(args, sig, ready="epoch 1/")
    _ended_by_signal(code, err, sig)
    assert seconds < 20
