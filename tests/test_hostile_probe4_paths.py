"""Hostile probe 4 (issue 59): crashes and false success in the new paths.

* An option a layout does not take (``datasets info --dataset kitti-raw --disparity-dir X``) is one line, not a
  TypeError; ``datasets info`` prints flags, never the NUL-delimited parameter names.
* A split that would be empty (one drive split by scenario, drives too short for time blocks) is refused where
  splits are made: ``datasets split`` writes nothing and exits 2; ``datasets info`` lists it.
* The base install (no pydantic, no torch) generates and labels datasets, with and without a label tree; a
  command of an extra says in one line which extra to install.
* ``bench/realtime.py`` refuses ``--repeat 0``, a missing checkpoint and frames of mixed sizes before any work.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.data import get_dataset
from freespace.data.info import dataset_info, format_info
from freespace.errors import InvalidOptionError

from helpers import refused
from test_kitti_raw import make_drive

ROOT = Path(__file__).resolve().parents[1]

#: run the command line with these top-level modules missing, as in `pip install freespace` (no extras)
BASE_INSTALL = """import sys
class Missing:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in {"pydantic", "torch", "lightning", "scipy", "matplotlib", "albumentations"}:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, Missing())
from freespace.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _base(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BASE_INSTALL, *argv], capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("layout", ["kitti-raw", "synthia", "generic"])
def test_an_option_the_layout_does_not_take_is_one_line(layout: str, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    make_drive(tmp_path, frames=2)
    line = refused(capsys, ["datasets", "info", "--dataset", layout, "--root", str(tmp_path), "--disparity-dir",
                            str(tmp_path), "--no-progress"], match="--disparity-dir")
    assert "Traceback" not in line and "\0" not in line
    with pytest.raises(InvalidOptionError, match="strict"):
        get_dataset("kitti", tmp_path, strict=False)  # another layout's option, in the library


def test_one_drive_is_not_split_by_scenario(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    make_drive(tmp_path / "raw", frames=10)
    out = tmp_path / "lists"
    line = refused(capsys, ["datasets", "split", "--dataset", "kitti-raw", "--root", str(tmp_path / "raw"), "--out",
                            str(out)], match="leaves val and test empty")
    assert "--by time" in line and not out.exists()
    assert main(["datasets", "split", "--dataset", "kitti-raw", "--root", str(tmp_path / "raw"), "--out", str(out),
                 "--by", "time"]) == 0
    assert all((out / f"{k}.txt").read_text().strip() for k in ("train", "val", "test"))
    assert main(["datasets", "split", "--dataset", "kitti-raw", "--root", str(tmp_path / "raw"), "--out",
                 str(tmp_path / "all"), "--fractions", "1,0,0"]) == 0  # empty on purpose: asked for
    two = tmp_path / "short"
    make_drive(two, frames=2)  # 2 frames: no val or test block at 0.6/0.2/0.2
    refused(capsys, ["datasets", "split", "--dataset", "kitti-raw", "--root", str(two), "--out",
                     str(tmp_path / "short-lists"), "--by", "time"], match="leaves val and test empty")


def test_datasets_info_names_flags_and_prints_no_nul(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    make_drive(tmp_path, frames=4)
    assert main(["datasets", "info", "--dataset", "kitti-raw", "--root", str(tmp_path), "--no-progress"]) == 1
    out = capsys.readouterr().out
    assert "\0" not in out and "(--by time)" in out and "--fractions" in out
    info = dataset_info("kitti-raw", tmp_path, progress=False)  # the library: parameter names
    assert "\0" not in format_info(info) and "(by time)" in format_info(info)


def test_the_base_install_generates_and_labels_datasets(tmp_path: Path) -> None:
    data = tmp_path / "data"
    assert main(["synth", "--out", str(data), "--num", "3", "--width", "160", "--height", "96"]) == 0
    runs = [("generate", "--dataset", "synth", "--root", str(data), "--out", str(tmp_path / "gen")),
            ("autolabel", "--dataset", "synth", "--root", str(data), "--out", str(tmp_path / "al"),
             "--disparity-source", "file"),
            ("generate", "--dataset", "synth", "--root", str(data), "--out", str(tmp_path / "gen-al"), "--labels",
             str(tmp_path / "al"))]
    for argv in runs:
        res = _base(*argv)
        assert res.returncode == 0 and "Traceback" not in res.stderr, (argv, res.stderr[-2000:])
    assert len(list((tmp_path / "gen-al").glob("*.png"))) == 3


@pytest.mark.parametrize("argv,extra", [(["train", "--dataset", "synth", "--root", "R", "--out", "O"], "train"),
                                        (["predict", "--checkpoint", "C", "--input", "I", "--out", "O"], "train")])
def test_a_command_of_an_extra_says_which_to_install(argv: list[str], extra: str) -> None:
    res = _base(*argv)
    err = res.stderr.strip()
    assert res.returncode == 2 and len(err.splitlines()) == 1, err[-2000:]
    assert f"pip install 'freespace[{extra}]'" in err and f"freespace {argv[0]}" in err


# --- bench/realtime.py --------------------------------------------------------------------------------------

def _realtime(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "bench" / "realtime.py"), *argv], capture_output=True,
                          text=True, timeout=300)


def _frames(folder: Path, *sizes: tuple[int, int]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for i, (w, h) in enumerate(sizes):
        cv2.imwrite(str(folder / f"{i:06d}.png"), np.zeros((h, w, 3), np.uint8))
    return folder


@pytest.mark.parametrize("case", ["repeat 0", "repeat -3", "missing fast", "mixed sizes", "no frames"])
def test_realtime_refuses_before_any_work(case: str, tmp_path: Path) -> None:
    ckpt = tmp_path / "x.ckpt"
    ckpt.write_bytes(b"not used")
    frames = _frames(tmp_path / "frames", (64, 32), (64, 32))
    args = {"repeat 0": ["--repeat", "0"], "repeat -3": ["--repeat", "-3"],
            "missing fast": ["--fast", str(tmp_path / "missing.ckpt")],
            "mixed sizes": ["--frames", str(_frames(tmp_path / "mixed", (64, 32), (80, 32)))],
            "no frames": ["--frames", str(_frames(tmp_path / "empty"))]}[case]
    base = ["--fast", str(ckpt), "--best", str(ckpt), "--frames", str(frames), "--out", str(tmp_path / "out")]
    res = _realtime(*base, *args)
    err = res.stderr.strip()
    assert res.returncode == 2 and "Traceback" not in err, err[-2000:]
    assert err.splitlines()[-1].startswith("realtime.py: error:"), err
    assert not (tmp_path / "out").exists()
