"""File formats: images, disparity (png16/npy/pfm), road labels, KITTI calibration, atomic writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, OutputError
from freespace.io.codecs import (
    read_disparity,
    read_image,
    read_road_label,
    road_label_to_kitti,
    write_disparity,
    write_image,
)
from freespace.io.files import atomic_write_text
from freespace.io.kitti import read_kitti_calib
from freespace.labels import RoadLabel

from helpers import shared_path


def _disparity() -> np.ndarray:
    rng = np.random.default_rng(0)
    d = rng.uniform(0.5, 200, (30, 40)).astype(np.float32)
    d[rng.random(d.shape) < 0.2] = np.nan
    return d


@pytest.mark.parametrize("suffix", [".png", ".npy", ".pfm"])
def test_disparity_round_trip(tmp_path: Path, suffix: str) -> None:
    d = _disparity()
    path = write_disparity(tmp_path / f"d{suffix}", d)
    back = read_disparity(path)
    assert back.dtype == np.float32 and back.shape == d.shape
    np.testing.assert_array_equal(np.isnan(back), np.isnan(d))
    tol = 1 / 512 if suffix == ".png" else 0
    np.testing.assert_allclose(back[~np.isnan(d)], d[~np.isnan(d)], atol=tol)


def test_pfm_rows_are_bottom_to_top(tmp_path: Path) -> None:
    d = np.arange(12, dtype=np.float32).reshape(3, 4) + 1
    path = tmp_path / "d.pfm"
    path.write_bytes(b"Pf\n4 3\n-1.0\n" + d[::-1].astype("<f4").tobytes())
    np.testing.assert_array_equal(read_disparity(path), d)
    path.write_bytes(b"Pf\n4 3\n1.0\n" + d[::-1].astype(">f4").tobytes())  # big-endian
    np.testing.assert_array_equal(read_disparity(path), d)


def test_kitti_disparity_png_encoding(tmp_path: Path) -> None:
    raw = np.array([[0, 256, 512 + 128]], np.uint16)
    write_image(tmp_path / "d.png", raw)
    d = read_disparity(tmp_path / "d.png")
    assert np.isnan(d[0, 0]) and d[0, 1] == 1.0 and d[0, 2] == 2.5


def test_disparity_png_never_clips(tmp_path: Path) -> None:
    """A disparity beyond KITTI's 16-bit range (255.996 px: a near object seen with a wide baseline) is written
    as invalid, with a warning that names the way out, never as a clipped, wrong value."""
    d = np.array([[255.99, 256.5, 300.0, 0.001, np.nan]], np.float32)
    with pytest.warns(UserWarning, match=r"2 disparities above 255\.996 px .* \.npy or \.pfm"):
        back = read_disparity(write_disparity(tmp_path / "d.png", d))
    assert back[0, 0] == pytest.approx(255.99, abs=1 / 512)
    assert np.isnan(back[0, 1:3]).all() and back[0, 3] == 1 / 256 and np.isnan(back[0, 4])
    np.testing.assert_array_equal(read_disparity(write_disparity(tmp_path / "d.npy", d))[0, :3], d[0, :3])


def test_real_kitti_disparity() -> None:
    d = read_disparity(shared_path("kitti_stereo_2015", "disp_occ_0", "000000_10.png"))
    assert d.shape == (375, 1242)
    assert 0.1 < np.isfinite(d).mean() < 0.4 and np.nanmax(d) < 256


def test_road_label_kitti_colours(tmp_path: Path) -> None:
    label = RoadLabel(road=np.array([[1, 0, 0]], bool), valid=np.array([[1, 1, 0]], bool))
    img = road_label_to_kitti(label)
    assert img[0].tolist() == [[255, 0, 255], [255, 0, 0], [0, 0, 0]]
    write_image(tmp_path / "gt.png", img)
    back = read_road_label(tmp_path / "gt.png")
    np.testing.assert_array_equal(back.road, label.road)
    np.testing.assert_array_equal(back.valid, label.valid)


def test_road_label_single_channel(tmp_path: Path) -> None:
    mask = np.array([[0, 1, 255]], np.uint8)
    write_image(tmp_path / "m.png", mask)
    back = read_road_label(tmp_path / "m.png")
    assert back.road.tolist() == [[False, True, True]] and back.valid.all()
    write_image(tmp_path / "m3.png", np.repeat(mask[..., None] * 255, 3, axis=2))  # grey saved as RGB
    assert read_road_label(tmp_path / "m3.png").road.tolist() == [[False, True, True]]


def test_image_round_trip_keeps_rgb_order(tmp_path: Path) -> None:
    img = np.zeros((4, 5, 3), np.uint8)
    img[..., 0] = 200  # red
    write_image(tmp_path / "x.png", img)
    np.testing.assert_array_equal(read_image(tmp_path / "x.png"), img)


def test_kitti_calib() -> None:
    calib = read_kitti_calib(shared_path("kitti_road_calib", "um_000000.txt"))
    assert calib["P2"].shape == (3, 4) and calib["R0_rect"].shape == (3, 3)
    assert calib["Tr_cam_to_road"].shape == (3, 4)
    assert calib["P2"][0, 0] == pytest.approx(721.5377)


def test_atomic_write_leaves_no_partial_file(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    atomic_write_text(target, "first")

    class Boom(Exception):
        pass

    class Exploding(str):
        def encode(self, *args: object, **kwargs: object) -> bytes:
            raise Boom

    with pytest.raises(Boom):
        atomic_write_text(target, Exploding("second"))
    assert target.read_text() == "first"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


# --- user mistakes -----------------------------------------------------------------------------------

def test_missing_and_corrupt_files(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="not found"):
        read_image(tmp_path / "nope.png")
    with pytest.raises(InputFileError, match="folder"):
        read_image(tmp_path)
    (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    with pytest.raises(CorruptFileError, match="cannot decode"):
        read_image(tmp_path / "bad.png")
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(CorruptFileError):
        read_disparity(tmp_path / "empty.png")
    (tmp_path / "bad.pfm").write_bytes(b"P6\n1 1\n255\n\0\0\0")
    with pytest.raises(CorruptFileError, match="PFM"):
        read_disparity(tmp_path / "bad.pfm")
    (tmp_path / "short.pfm").write_bytes(b"Pf\n10 10\n-1.0\n" + b"\0" * 12)
    with pytest.raises(CorruptFileError, match="truncated"):
        read_disparity(tmp_path / "short.pfm")
    (tmp_path / "bad.npy").write_bytes(b"not numpy")
    with pytest.raises(CorruptFileError):
        read_disparity(tmp_path / "bad.npy")
    np.save(tmp_path / "three.npy", np.zeros((2, 2, 2)))
    with pytest.raises(CorruptFileError, match="2-D"):
        read_disparity(tmp_path / "three.npy")
    write_image(tmp_path / "rgb.png", np.zeros((3, 3, 3), np.uint8))
    with pytest.raises(CorruptFileError, match="16-bit"):
        read_disparity(tmp_path / "rgb.png")
    (tmp_path / "d.tiff").write_bytes(b"x")
    with pytest.raises(InvalidOptionError, match="format"):
        read_disparity(tmp_path / "d.tiff")
    (tmp_path / "calib.txt").write_text("P0: 1 2 x\n")
    with pytest.raises(CorruptFileError, match="line 1"):
        read_kitti_calib(tmp_path / "calib.txt")


def test_unwritable_output(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="cannot write"):
        atomic_write_text(tmp_path / "file" / "sub" / "out.txt", "y")
