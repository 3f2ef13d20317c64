"""The converged run's data check (studies/converged/datacheck.py): a CPU's rounding passes, a change of
the data does not."""

from __future__ import annotations

import hashlib
import importlib.util
from pathlib import Path

import cv2
import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "datacheck.py"
spec = importlib.util.spec_from_file_location("datacheck", SCRIPT)
datacheck = importlib.util.module_from_spec(spec)
spec.loader.exec_module(datacheck)


@pytest.fixture
def run(tmp_path: Path) -> tuple[Path, Path]:
    """A tiny WORK (one image, label, calibration and autolabel per set) and its references in REF."""
    rng = np.random.default_rng(0)
    work, ref = tmp_path / "work", tmp_path / "ref"
    for name in datacheck.SETS[:-1]:
        base = work / name / "data_road" / "training"
        for sub in ("image_2", "gt_image_2", "calib"):
            (base / sub).mkdir(parents=True)
        cv2.imwrite(str(base / "image_2" / "um_000000.png"), rng.integers(0, 256, (32, 48, 3), dtype=np.uint8))
        cv2.imwrite(str(base / "gt_image_2" / "um_road_000000.png"), np.zeros((32, 48, 3), np.uint8))
        (base / "calib" / "um_000000.txt").write_text("P2: 1 0 0 0\n")
    label = np.zeros((32, 48, 3), np.uint8)
    label[16:] = (255, 0, 255)
    label[:8] = (0, 0, 255)
    (work / "autolabels" / "confidence").mkdir(parents=True)
    cv2.imwrite(str(work / "autolabels" / "um_000000.png"), label)
    cv2.imwrite(str(work / "autolabels" / "confidence" / "um_000000.png"), np.full((32, 48), 200, np.uint8))
    ref.mkdir()
    (ref / "data.sha256").write_text("".join(f"{hashlib.sha256((work / f).read_bytes()).hexdigest()}  {f}\n"
                                             for f in datacheck.data_files(work)))
    assert datacheck.main(work, ref) == 0  # writes the fingerprints
    assert (ref / "data.fingerprints.json").exists()
    return work, ref


def _edit(path: Path, change) -> None:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    change(img)
    cv2.imwrite(str(path), img)


def test_cpu_rounding_passes(run: tuple[Path, Path]) -> None:
    work, ref = run
    image = work / "syn" / "data_road" / "training" / "image_2" / "um_000000.png"
    _edit(image, lambda a: a.__setitem__((0, 0, 0), a[0, 0, 0] ^ 1))  # one value one grey level off
    _edit(work / "autolabels" / "um_000000.png", lambda a: a.__setitem__((8, 0), 255))  # 1 pixel of 1536 flips
    _edit(work / "autolabels" / "confidence" / "um_000000.png", lambda a: a.__setitem__(slice(None), 0))  # not read
    assert datacheck.main(work, ref) == 0


@pytest.mark.parametrize("change", ["image", "autolabel", "calibration", "extra frame"])
def test_a_change_of_the_data_is_refused(run: tuple[Path, Path], change: str,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    work, ref = run
    base = work / "shifted" / "data_road" / "training"
    if change == "image":  # a renderer change: a region brighter
        _edit(base / "image_2" / "um_000000.png", lambda a: a.__setitem__(slice(0, 8), np.minimum(a[:8], 200) + 40))
    elif change == "autolabel":  # 3 % of the pixels change class
        _edit(work / "autolabels" / "um_000000.png", lambda a: a.__setitem__((slice(16, 17), slice(None)), 0))
    elif change == "calibration":
        (base / "calib" / "um_000000.txt").write_text("P2: 2 0 0 0\n")
    else:
        cv2.imwrite(str(base / "image_2" / "um_000001.png"), np.zeros((32, 48, 3), np.uint8))
    assert datacheck.main(work, ref) == 1
    assert "differ from the run's" in capsys.readouterr().out
