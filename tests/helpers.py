"""Shared test helpers (importable as ``helpers``: pyproject's pytest ``pythonpath`` holds ``tests``):
synthetic road planes and scenes, the shared real samples (tests skip when absent)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from freespace.geometry import StereoCalibration
from freespace.geometry.depth import depth_to_disparity, rig_from_kitti
from freespace.io.codecs import read_depth
from freespace.io.kitti import read_kitti_calib
from freespace.testing import road_frame, textured_image, tiny_road_checkpoint  # noqa: F401  (the tests import them from here)

#: the shared real samples: ../shared/data beside the checkout, or $FREESPACE_SHARED_DATA (a git worktree elsewhere)
SHARED = Path(os.environ.get("FREESPACE_SHARED_DATA") or Path(__file__).resolve().parents[2] / "shared" / "data")


#: the session's trained run (conftest.py's ``trained``): ``freespace synth`` frames of this size (W, H), two a drive
TRAINED_FRAMES, TRAINED_SIZE, TRAINED_SEED = 8, (160, 128), 3
#: its ``freespace train`` options besides --dataset, --root and --out
TRAINED_ARGS = ("--model", "segnet", "--epochs", "1", "--batch-size", "4", "--image-size", "64x64", "--no-progress")


def shared_path(*parts: str) -> Path:
    """A path under the shared samples (:data:`SHARED`), or skip the test when they are not there."""
    path = SHARED.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"shared sample data not available ({path})")
    return path


def plane_disparity(shape: tuple[int, int], roll_deg: float, kappa_hat: float, kappa: float) -> np.ndarray:
    """Exact disparity d = ϰ (v cos Φ − u sin Φ + κ) over an H×W grid (float32)."""
    h, w = shape
    phi = math.radians(roll_deg)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    return (kappa_hat * (v * math.cos(phi) - u * math.sin(phi) + kappa)).astype(np.float32)


def road_mask(shape: tuple[int, int], top: float = 0.55) -> np.ndarray:
    """A trapezoid road region in the lower part of an H×W image (bool)."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w]
    t = np.clip((v - top * h) / ((1 - top) * h), 0, 1)
    half = w * (0.05 + 0.45 * t)
    return (v >= top * h) & (np.abs(u - w / 2) <= half)




def noise_texture(shape: tuple[int, ...], seed: int) -> np.ndarray:
    """High-frequency random texture (uint8) that a stereo matcher can lock on to."""
    import cv2

    rng = np.random.default_rng(seed)
    img = rng.uniform(0, 255, shape).astype(np.float32)
    return np.clip(cv2.GaussianBlur(img, (0, 0), 1.0) * 2 - 128, 0, 255).astype(np.uint8)


def synthetic_pair(shape: tuple[int, int] = (160, 320), roll_deg: float = 1.0, seed: int = 0):
    """(left, right, road label, disparity) of a textured road plane seen by a stereo rig.

    The right image is the left one moved by the plane's disparity, so the road homography maps it back
    exactly; the road is a trapezoid in the lower half (don't-care above row 40).
    """
    from freespace.geometry import RoadModel, generate_view
    from freespace.labels import RoadLabel

    h, w = shape
    model = RoadModel.from_roll(math.radians(roll_deg), 0.3, -0.25 * h)
    left = noise_texture(shape + (3,), seed)
    right = generate_view(left, left, np.linalg.inv(model.homography))
    road = road_mask(shape, top=0.4)
    valid = np.ones(shape, bool)
    valid[:40] = False
    return left, right, RoadLabel(road=road, valid=valid), model.disparity(shape)


def disparity_from_depth_file(depth_path: Path, calib: dict[str, np.ndarray] | Path, *,
                              shape: tuple[int, int] | None = None) -> tuple[np.ndarray, StereoCalibration]:
    """``(float32 H×W disparity, rig)`` of a depth file and a parsed KITTI calibration (a virtual right camera
    when it has no P3), as the data sources compose them; ``calib`` may be the calibration file."""
    rig = rig_from_kitti(calib if isinstance(calib, dict) else read_kitti_calib(calib))
    return depth_to_disparity(read_depth(depth_path, shape=shape), rig.fx, rig.baseline), rig


def write_velodyne(path: Path, points: np.ndarray) -> Path:
    """Write ``N×4`` (x, y, z, reflectance) points as a KITTI ``.bin`` scan (little-endian float32)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(np.asarray(points).astype("<f4").tobytes())
    return path


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (exists and is no zombie)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def outlived(pids: list[int], seconds: float) -> list[int]:
    """The processes of ``pids`` still running after up to ``seconds`` of waiting for them to end; each is killed
    (SIGKILL), so that no test leaves one behind."""
    import signal
    import time

    deadline = time.time() + seconds
    while time.time() < deadline and any(alive(p) for p in pids):
        time.sleep(0.1)
    left = [p for p in pids if alive(p)]
    for p in left:
        os.kill(p, signal.SIGKILL)
    return left


def refused(capsys: pytest.CaptureFixture, argv: list[str], *, match: str | None = None) -> str:
    """Run the command in-process; assert exit 2 and exactly one line on stderr; return that line."""
    capsys.readouterr()
    from freespace.cli import main

    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, f"exit {code}, stderr: {err!r}"
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("freespace: error: "), err
    if match is not None:
        assert match.lower() in err.lower(), err
    return err


def tiny_model_folder(parent: Path, size: tuple[int, int] = (32, 96)) -> Path:
    """A model folder ``parent/tiny-road``: ``model.ckpt`` (a tiny Fast-SCNN of input ``size``, H×W) and a card."""
    folder = parent / "tiny-road"
    folder.mkdir()
    tiny_road_checkpoint(folder / "model.ckpt", size, width=0.25)
    (folder / "README.md").write_text("# tiny-road — a test model\n")
    return folder


def road_folders(parent: Path, size: tuple[int, int], count: int = 3) -> tuple[Path, Path]:
    """``parent/frames`` and ``parent/labels``: ``count`` rendered road frames ``f<i>.png`` of ``size`` (H, W)
    and their road masks as binary PNGs (255 = road), for ``predict`` and ``evaluate --label-format binary``."""
    from freespace.io.codecs import write_image

    frames, labels = parent / "frames", parent / "labels"
    frames.mkdir()
    labels.mkdir()
    for i in range(count):
        image, road = road_frame(size, i)
        write_image(frames / f"f{i}.png", image)
        write_image(labels / f"f{i}.png", (road * 255).astype(np.uint8))
    return frames, labels
