"""Hostile input, issue 44's classes B, E and H: numbers out of bounds, weights files that are no weights, and
the small things (empty paths, messages that blame the wrong input, a README command that was refused).

B. Bounds. Every numeric option of every command has a bound declared with its type (walked from the parsers,
   so a new option is tested the day it is added): 0/-1 where below, 99999999999999999999, nan, inf, 1e400
   and text are refused in one line naming the flag, before any work; worker counts at most 4 per CPU core
   (``train``'s also from a ``--config`` file, checked against this machine); ``--batch-size`` (train, YAML,
   predict) no longer ends in an ``islice`` traceback; ``autolabel --camera-height`` keeps the road fits'
   0.1–8 m; SIGTERM during training with loader workers ends in one line, exit 143, and no process left,
   also when it comes while a worker is forked (the handler used to run in an at-fork hook that swallowed it).
E. Weights files are checked at load: meta, sparse, integer, boolean, complex and quantised tensors, NaN,
   infinity and absurd magnitudes are refused in one line naming the file (and tensor) before any epoch;
   ``tu-NAME`` of no timm model, an empty value, a folder: one line with the flag; ``imagenet`` weights missing
   from the hub's cache fail at once (no network at run time), not after 30 s of retries.
H. The manual's (docs/networks.md) ``reproduce … --encoder-name`` command takes networks that all have an encoder; no
   option value is empty (``--out ''`` is not the current folder, on the command line or in YAML); a folder given for a
   file (``--calib DIR``) is called a folder, not an input holding ``--out``; autolabel's failed fit does not blame a
   label it never read; argparse's own mistakes (a missing required option, an unknown command or choice) end in one
   line pointing to the command's ``--help``, not in the usage block.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import build_parser
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.io.codecs import write_disparity, write_image
from freespace.limits import Bounded, max_workers

from helpers import outlived, refused, synthetic_pair

SMALL = SynthConfig(width=160, height=128, frames_per_scenario=2)
HOSTILE_NUMBERS = ["99999999999999999999", "-99999999999999999999", "nan", "inf", "-inf", "1e400", "x", "1,2"]



def _options() -> list[tuple[list[str], argparse.Action]]:
    """``(command words, action)`` of every option of every command that takes a value."""
    found = []

    def walk(parser: argparse.ArgumentParser, words: list[str]) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, words + [name])
            elif action.option_strings and action.nargs != 0 and action.dest not in ("help", "version"):
                found.append((words, action))

    walk(build_parser(), [])
    return found


NUMERIC = [(words, a) for words, a in _options() if isinstance(a.type, Bounded)]


def _id(item: tuple[list[str], argparse.Action]) -> str:
    return " ".join(item[0]) + " " + item[1].option_strings[-1]


# ------------------------------------------------------------------------------------------------ B. bounds
def test_every_numeric_option_has_a_bounded_type() -> None:
    plain = [_id(o) for o in _options() if o[1].type in (int, float)]
    assert not plain, f"numeric options without bounds: {plain}"
    assert len(NUMERIC) >= 45  # generate, autolabel, synth, datasets, train, predict, reproduce, demo
    for words, action in NUMERIC:
        assert action.type.low is not None and action.type.upper() is not None, _id((words, action))


@pytest.mark.parametrize("option", NUMERIC, ids=_id)
def test_every_numeric_option_refuses_hostile_values(option: tuple[list[str], argparse.Action],
                                                     capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    words, action = option
    flag, kind = action.option_strings[-1], action.type
    below = [str(kind.low - 1)] if not kind.low_open else [str(kind.low)]
    cwd = os.getcwd()
    os.chdir(tmp_path)  # nothing may be written, anywhere
    try:
        for value in HOSTILE_NUMBERS + below + [str(kind.upper() * 10 + 1), ""]:
            t0 = time.perf_counter()
            err = refused(capsys, [*words, flag, value], match=flag)
            assert time.perf_counter() - t0 < 5, "checked after starting work"
            assert ("empty" if value == "" else "must be") in err, err
    finally:
        os.chdir(cwd)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("command", ["generate", "autolabel", "synth"])
def test_worker_processes_are_bounded_by_the_cores(command: str, capsys: pytest.CaptureFixture) -> None:
    refused(capsys, [command, "--workers", str(max_workers() + 1)], match="per CPU core")
    refused(capsys, [command, "--workers", "100000"], match="--workers")


def test_train_workers_beyond_the_machine_are_refused_before_work(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    data = tmp_path / "data"
    write_dataset(data, 6, seed=1, config=SMALL, progress=False)
    err = refused(capsys, ["train", "--dataset", "synth", "--root", str(data), "--workers", str(max_workers() + 1),
                           "--out", str(tmp_path / "run")], match="--workers")
    assert "per CPU core" in err
    refused(capsys, ["train", "--dataset", "synth", "--root", str(data), "--devices", str(max_workers() + 1),
                     "--out", str(tmp_path / "run")], match="--devices")  # one process per device on a CPU
    assert not (tmp_path / "run").exists()
    config = tmp_path / "c.yaml"  # a run's config.yaml from a larger machine: the same check
    config.write_text(f"dataset: synth\nroot: {data}\nworkers: {max_workers() + 1}\n")
    refused(capsys, ["train", "--config", str(config), "--out", str(tmp_path / "run")], match="per CPU core")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("key, value, match", [
    ("batch_size", "99999999999999999999", "batch_size must be in [1, 1024]"),
    ("workers", "100000", "workers must be in [0, 1024]"),
    ("epochs", "1.0e+400", "epochs must be an integer"),
    ("weight_decay", "1.0e+20", "weight_decay must be in [0, 1]"),
    ("devices", "99999999999999999999", "devices must be in"),
    ("num_nodes", "99999999999999999999", "num_nodes must be in"),
    ("patience", "99999999999999999999", "patience must be in"),
    ("max_frames", "99999999999999999999", "max_frames must be in"),
    ("out", "''", "out must be a path, not empty"),
])
def test_config_file_values_have_the_flags_bounds(key: str, value: str, match: str, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    config = tmp_path / "c.yaml"
    config.write_text(f"dataset: synth\nroot: {tmp_path}\nout: {tmp_path / 'run'}\n{key}: {value}\n"
                      if key != "out" else f"dataset: synth\nroot: {tmp_path}\nout: {value}\n")
    refused(capsys, ["train", "--config", str(config)], match=match)
    assert not (tmp_path / "run").exists()


def test_the_flags_bounds_are_the_fields_bounds() -> None:
    """The command line's type of a training option is derived from its TrainConfig field: one declaration."""
    from freespace.engine.config import TrainConfig
    from freespace.engine.options import options

    kinds = {o.name: o.kind for o in options()}
    assert kinds["batch_size"](" 1024") == 1024
    for name, value in (("batch_size", 1025), ("epochs", 0), ("lr", 10.0), ("momentum", 1.0), ("workers", -1)):
        with pytest.raises(ValueError):
            kinds[name](str(value))
        with pytest.raises(ValueError):
            TrainConfig(dataset="synth", root="r", out="o", **{name: value})


def test_predict_batch_size_is_bounded(capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    refused(capsys, ["predict", "--checkpoint", str(tmp_path / "c.ckpt"), "--input", str(tmp_path), "--batch-size",
                     "99999999999999999999", "--out", str(tmp_path / "p")],
            match="--batch-size must be an integer in [1, 1024]")


@pytest.mark.parametrize("height", ["0.01", "0.0999", "8.01", "100"])
def test_autolabel_camera_height_keeps_the_road_fits_bound(height: str, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture) -> None:
    from freespace.datagen.autolabel import AutolabelOptions
    from freespace.errors import InvalidOptionError

    left, _, _, disparity = synthetic_pair((96, 160))
    write_image(tmp_path / "L.png", left)
    write_disparity(tmp_path / "D.png", disparity)
    err = refused(capsys, ["autolabel", "--reference", str(tmp_path / "L.png"), "--disparity", str(tmp_path / "D.png"),
                           "--camera-height", height, "--out", str(tmp_path / "A.png")], match="--camera-height")
    assert "[0.1, 8]" in err and "lower centre" not in err
    assert not (tmp_path / "A.png").exists()
    with pytest.raises(InvalidOptionError, match="camera_height must be 0.1–8 m"):
        AutolabelOptions(camera_height=float(height)).check()


def test_the_pose_of_a_virtual_view_is_bounded(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    for option, value in (("--shift", "0,0,99999999999999999999"), ("--rotate", "1e30,0,0"), ("--shift", "nan,0,0")):
        refused(capsys, ["generate", "--virtual", option, value], match=f"{option} must be three finite numbers")


def _descendants(pid: int) -> list[int]:
    found = []
    try:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return found
    for child in map(int, children):
        found += [child, *_descendants(child)]
    return found


def _comm(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return ""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_sigterm_stops_training_and_its_loader_workers(tmp_path: Path) -> None:
    data = tmp_path / "data"
    write_dataset(data, 8, seed=3, config=SMALL, progress=False)
    proc = subprocess.Popen([sys.executable, "-m", "freespace.cli", "train", "--dataset", "synth", "--root", str(data),
                             "--model", "segnet", "--epochs", "50", "--image-size", "64x64", "--workers", "2",
                             "--no-progress", "--out", str(tmp_path / "run")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline, seen = time.time() + 120, []
    while time.time() < deadline and proc.poll() is None:
        seen = _descendants(proc.pid)
        if any(_comm(c) == "pt_data_worker" for c in seen):
            break
        time.sleep(0.05)
    assert any(_comm(c) == "pt_data_worker" for c in seen), "no loader worker started"
    proc.send_signal(signal.SIGTERM)
    seen = sorted(set(seen) | set(_descendants(proc.pid)))
    _, err = proc.communicate(timeout=120)
    left = outlived(seen, 10)
    assert proc.returncode == 143, (proc.returncode, err[-2000:])
    assert err.strip().splitlines() == ["freespace: terminated (SIGTERM)"], err[-2000:]
    assert not left, f"processes outlived the command: {[(c, _comm(c)) for c in left]}"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork and signal masks")
def test_a_signal_during_a_loader_fork_is_not_lost(tmp_path: Path) -> None:
    """A SIGTERM that arrives while a loader worker is forked reaches the trainer as the exception, after the
    fork (here sent from an at-fork hook: without the blocked mask the handler ran there, and Python swallowed its
    exception); in the worker, SIGTERM ends it silently although the trainer's handler raises."""
    script = textwrap.dedent("""
        import os, signal, sys, time
        from freespace.engine.data import loader_context

        class Stop(BaseException):
            pass

        def handler(signum, frame):
            raise Stop()

        def work():
            time.sleep(30)

        signal.signal(signal.SIGTERM, handler)
        ctx = loader_context()
        worker = ctx.Process(target=work, daemon=True)
        os.register_at_fork(after_in_parent=lambda: os.kill(os.getpid(), signal.SIGTERM))
        try:
            worker.start()
            time.sleep(2)
            print("lost")
        except Stop:
            print("raised after the fork")
        os.kill(worker.pid, signal.SIGTERM)
        worker.join(10)
        print("worker", worker.exitcode)
    """)
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert res.stdout.split("\n")[:2] == ["raised after the fork", f"worker {-signal.SIGTERM}"], res.stdout + res.stderr
    assert "Traceback" not in res.stderr and "Exception ignored" not in res.stderr, res.stderr


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="forked loader workers")
def test_a_loader_worker_thread_is_quiet_when_the_trainer_hangs_up() -> None:
    """When the trainer stops half-way through taking a batch's shared memory, the worker's resource-sharer
    thread fails on the lost connection: that stays silent (the command's one line is the report); any other
    failure of a worker's thread is still printed."""
    script = textwrap.dedent("""
        import threading
        from freespace.engine.data import loader_context

        def fail(exc):
            def run():
                raise exc
            return run

        def work():
            for exc in (ConnectionResetError(104, "Connection reset by peer"), EOFError(), ValueError("kept")):
                thread = threading.Thread(target=fail(exc))
                thread.start()
                thread.join()

        worker = loader_context().Process(target=work)
        worker.start()
        worker.join(30)
        print("worker", worker.exitcode)
    """)
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert res.stdout.strip() == "worker 0", res.stdout + res.stderr
    assert res.stderr.count("Traceback") == 1 and "ValueError: kept" in res.stderr, res.stderr
    assert "ConnectionResetError" not in res.stderr and "EOFError" not in res.stderr, res.stderr


# ---------------------------------------------------------------------------------------------- E. weights
@pytest.fixture(scope="module")
def resnet18_state() -> dict:
    import segmentation_models_pytorch as smp

    return {k: v.clone() for k, v in smp.encoders.get_encoder("resnet18", weights=None).state_dict().items()}


def _crafted(state: dict, how: str):
    import torch

    first = "conv1.weight"
    floats = {k for k, v in state.items() if v.is_floating_point()}
    if how == "meta":
        return {k: torch.empty_like(v, device="meta") for k, v in state.items()}
    if how == "sparse":
        return {**state, first: state[first].to_sparse()}
    if how == "integer":
        return {k: (v * 100).to(torch.int32) if k in floats else v for k, v in state.items()}
    if how == "complex":
        return {k: v.to(torch.complex64) if k in floats else v for k, v in state.items()}
    if how == "bool":
        return {**state, first: state[first] > 0}
    if how == "nan":
        return {**state, first: torch.full_like(state[first], float("nan"))}
    if how == "inf":
        return {**state, "bn1.running_var": torch.full_like(state["bn1.running_var"], float("inf"))}
    if how == "x1e30":
        return {k: v * 1e30 if k in floats else v for k, v in state.items()}
    if how == "nested":
        return {"state_dict": state}
    raise ValueError(how)


@pytest.mark.parametrize("how, match", [
    ("meta", "is meta"), ("sparse", "is sparse"), ("integer", "is torch.int32"), ("complex", "is torch.complex64"),
    ("bool", "is torch.bool"), ("nan", "contains NaN"), ("inf", "contains infinite values"),
    ("x1e30", "magnitude"), ("nested", "nests one under 'state_dict'"),
])
def test_weights_that_are_no_weights_are_refused_at_load(how: str, match: str, resnet18_state: dict,
                                                         tmp_path: Path) -> None:
    import torch

    from freespace.errors import FreespaceError
    from freespace.models import create_model

    path = tmp_path / f"{how}.pth"
    torch.save(_crafted(resnet18_state, how), path)
    with pytest.raises(FreespaceError) as info:
        create_model("unet", encoder_name="resnet18", encoder_weights=str(path))
    message = str(info.value)
    assert match in message and str(path) in message and "\n" not in message, message


@pytest.mark.parametrize("dtype", ["float64", "float16", "bfloat16"])
def test_weights_of_other_float_types_are_taken(dtype: str, resnet18_state: dict, tmp_path: Path) -> None:
    import torch

    from freespace.models import create_model

    path = tmp_path / "w.pth"
    torch.save({k: v.to(getattr(torch, dtype)) if v.is_floating_point() else v for k, v in resnet18_state.items()},
               path)
    model = create_model("unet", encoder_name="resnet18", encoder_weights=str(path))
    got = model.net.encoder.state_dict()["conv1.weight"]
    assert torch.equal(got, resnet18_state["conv1.weight"].to(getattr(torch, dtype)).float())


def test_nan_weights_are_refused_before_any_epoch(resnet18_state: dict, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    import torch

    data = tmp_path / "data"
    write_dataset(data, 6, seed=1, config=SMALL, progress=False)
    path = tmp_path / "nan.pth"
    torch.save(_crafted(resnet18_state, "nan"), path)
    err = refused(capsys, ["train", "--dataset", "synth", "--root", str(data), "--model", "unet", "--encoder-name",
                           "resnet18", "--encoder-weights", str(path), "--out", str(tmp_path / "run")],
                  match="contains NaN")
    assert "--lr" not in err and not (tmp_path / "run").exists()


@pytest.mark.parametrize("value, match", [
    ("tu-nosuchmodel", "timm has no model 'nosuchmodel'"),
])
def test_unknown_timm_encoder(value: str, match: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    refused(capsys, ["train", "--dataset", "synth", "--root", str(tmp_path), "--model", "unet", "--encoder-name", value,
                     "--out", str(tmp_path / "run")], match=match)


def test_weights_messages_name_the_flag(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    base = ["train", "--dataset", "synth", "--root", str(tmp_path), "--model", "unet", "--encoder-name", "resnet18",
            "--out", str(tmp_path / "run")]
    folder = tmp_path / "weights"
    folder.mkdir()
    for value, match in (("", "--encoder-weights is empty"), (str(folder), "is a folder"),
                         (str(tmp_path / "none.pth"), "--encoder-weights takes imagenet")):
        err = refused(capsys, [*base, "--encoder-weights", value], match=match)
        assert "encoder_weights" not in err and "None" not in err and "file not found: ." not in err, err


def test_weights_missing_from_the_hub_cache_fail_at_once(tmp_path: Path) -> None:
    """No network at run time: `imagenet` weights of smp's and timm's encoders come from the hub's cache (here an
    empty one), and their absence is one line at once, not 30 s of download retries."""
    script = ("from freespace.models import create_model\n"
              "from freespace.errors import PretrainedWeightsError\n"
              "import sys, time\n"
              "for name in ('resnet18', 'tu-resnet18'):\n"
              "    t = time.time()\n"
              "    try:\n"
              "        create_model('unet', encoder_name=name, encoder_weights='imagenet')\n"
              "    except PretrainedWeightsError as e:\n"
              "        print(round(time.time() - t, 1), e)\n")
    env = {**os.environ, "HF_HOME": str(tmp_path / "hf"), "HF_HUB_OFFLINE": "0"}
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=env)
    lines = res.stdout.strip().splitlines()
    assert len(lines) == 2, res.stdout + res.stderr
    for line in lines:
        seconds, message = line.split(" ", 1)
        assert float(seconds) < 10 and "not in the Hugging Face cache" in message, line
    assert "Retrying" not in res.stderr and "Warning" not in res.stderr, res.stderr[-2000:]


# ------------------------------------------------------------------------------------------ H. small things
def test_the_manual_reproduce_command_with_an_encoder_is_accepted() -> None:
    from freespace.experiments import parse_models
    from freespace.models import model_options

    readme = (Path(__file__).resolve().parents[1] / "docs" / "networks.md").read_text()
    blocks = re.findall(r"freespace reproduce ((?:[^\n]*\\\n)*[^\n]*--encoder-name[^\n]*)", readme)
    assert blocks, "docs/networks.md shows reproduce with an encoder"
    for block in blocks:
        models = re.search(r"--models (\S+)", block)
        assert models, f"the README's reproduce with --encoder-name lists its --models: {block}"
        for name in parse_models(models.group(1)):
            assert "encoder_name" in model_options(name), f"{name} takes no encoder, yet the README gives it one"


def test_reproduce_all_models_with_an_encoder_says_which_networks_take_one(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture) -> None:
    data = tmp_path / "data"
    write_dataset(data, 6, seed=1, config=SMALL, progress=False)
    refused(capsys, ["reproduce", "--dataset", "synth", "--root", str(data), "--encoder-name", "efficientnet-lite0",
                     "--out", str(tmp_path / "r")], match="segnet takes none; the networks that do: ")
    assert not (tmp_path / "r").exists()


VALUED = [o for o in _options() if o[1].type is None or o[1].type is str]


@pytest.mark.parametrize("option", VALUED, ids=_id)
def test_no_option_value_is_empty(option: tuple[list[str], argparse.Action], capsys: pytest.CaptureFixture,
                                  tmp_path: Path) -> None:
    words, action = option
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        for value in ("", " "):
            refused(capsys, [*words, action.option_strings[-1], value], match=f"{action.option_strings[-1]} is empty")
    finally:
        os.chdir(cwd)
    assert not list(tmp_path.iterdir()), "wrote into the current folder"


def test_empty_config_path(capsys: pytest.CaptureFixture) -> None:
    refused(capsys, ["train", "--config", ""], match="--config is empty")


@pytest.fixture
def pair(tmp_path: Path) -> dict[str, Path]:
    left, right, label, disparity = synthetic_pair((96, 160))
    files = {k: tmp_path / f"{k}.png" for k in ("L", "R", "M", "D")}
    write_image(files["L"], left)
    write_image(files["R"], right)
    write_image(files["M"], (label.road & label.valid).astype(np.uint8) * 255)
    write_disparity(files["D"], disparity)
    return files


def test_a_folder_for_calib_is_called_a_folder(pair: dict[str, Path], tmp_path: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    folder = tmp_path / "calib"
    folder.mkdir()
    out = folder / "A.png"  # the output inside the folder: once blamed as "inside the input --calib"
    err = refused(capsys, ["autolabel", "--reference", str(pair["L"]), "--disparity", str(pair["D"]), "--calib",
                           str(folder), "--out", str(out)], match="--calib")
    assert "is a folder" in err and "--out" not in err
    err = refused(capsys, ["generate", "--virtual", "--reference", str(pair["L"]), "--road-mask", str(pair["M"]),
                           "--calib", str(folder), "--label-out", str(folder / "VL.png"),
                           "--out", str(folder / "V.png")],
                  match="--calib")
    assert "is a folder" in err and "--out" not in err
    assert not list(folder.iterdir())


def test_autolabel_failure_does_not_blame_a_label(pair: dict[str, Path], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    flat = tmp_path / "flat.png"
    write_disparity(flat, np.full((96, 160), 20.0, np.float32))
    err = refused(capsys, ["autolabel", "--reference", str(pair["L"]), "--disparity", str(flat), "--out",
                           str(tmp_path / "A.png")], match="fits no road plane")
    assert "road label" not in err and "road mask" not in err, err


@pytest.mark.parametrize("argv", [[], ["nosuch"], ["export", "--checkpoint", "x"], ["train", "--dataset", "synth"],
                                  ["datasets", "split", "--dataset", "kitti-raw"], ["predict", "--bogus"],
                                  ["datasets", "info", "--dataset", "nosuch", "--root", "."]])
def test_argparse_mistakes_are_one_line(capsys: pytest.CaptureFixture, argv: list[str]) -> None:
    """A missing required option, an unknown command or choice: one line with the command's help to read,
    not argparse's usage block."""
    err = refused(capsys, argv)
    assert "--help" in err and "usage:" not in err
