"""Hostile probe 4 (issue 59): inputs that explode, and calibrations and pairs that lie.

* Every image reader (frames, right images, labels, disparity and depth maps in PNG, JPEG, BMP, PGM, TIFF, .npy,
  .pfm) refuses a header that states more than ``MAX_IMAGE_PIXELS`` before anything is decoded, and a file beyond
  ``MAX_IMAGE_FILE_BYTES`` before it is read; a Velodyne scan of more than ``MAX_SCAN_POINTS`` points is refused
  from its size. Each message names its limit.
* Calibrations are checked where they are read: a key given twice, a focal length ≤ 0, a baseline no rig has, a
  principal point outside the image, a right camera with other intrinsics, a rotation that is none; a drive's
  problem is one line, not one per frame. A grey left image with a colour right one is told as such.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.data import get_dataset
from freespace.data.info import dataset_info
from freespace.errors import CorruptFileError, FreespaceError, InvalidOptionError, ShapeMismatchError
from freespace.io.codecs import read_depth, read_disparity, read_image, read_raw, read_road_label
from freespace.io.kitti import read_kitti_calib, read_kitti_raw_calib, read_velodyne
from freespace.io.video import open_frames
from freespace.limits import MAX_IMAGE_FILE_BYTES, MAX_IMAGE_PIXELS, MAX_SCAN_POINTS

from helpers import refused
from test_kitti_raw import CAM_TO_CAM, DATE, make_drive

HUGE = 30000  # a side: 30000×30000 = 9·10⁸ pixels, 27× the limit


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def huge_png(bits: int = 8, colour: int = 2, size: tuple[int, int] = (HUGE, HUGE)) -> bytes:
    """An 80-byte PNG, sound to its CRCs, whose header says 30000×30000 (or ``size``, W×H)."""
    ihdr = struct.pack(">IIBBBBB", *size, bits, colour, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", zlib.compress(b"\0" * 64))
            + _png_chunk(b"IEND", b""))


def _patched(suffix: str, patch) -> bytes:  # noqa: ANN001
    ok, buf = cv2.imencode(suffix, np.full((8, 8, 3), 90, np.uint8))
    assert ok
    return patch(bytearray(buf.tobytes()))


def _jpeg(data: bytearray) -> bytes:
    at = data.index(b"\xff\xc0")  # the baseline frame header: length, precision, height, width
    data[at + 5:at + 9] = struct.pack(">HH", HUGE, HUGE)
    return bytes(data)


def _bmp(data: bytearray) -> bytes:
    data[18:26] = struct.pack("<ii", HUGE, -HUGE)  # a negative height: rows top to bottom
    return bytes(data)


def _tiff(data: bytearray) -> bytes:
    order = "<" if data[:2] == b"II" else ">"
    ifd = struct.unpack(order + "I", data[4:8])[0]
    for k in range(struct.unpack(order + "H", data[ifd:ifd + 2])[0]):
        at = ifd + 2 + 12 * k
        tag, kind = struct.unpack(order + "HH", data[at:at + 4])
        if tag in (256, 257):
            data[at + 8:at + 12] = struct.pack(order + ("HH" if kind == 3 else "I"),
                                               *((HUGE, 0) if kind == 3 else (HUGE,)))
    return bytes(data)


CRAFTED = {
    "png": lambda: huge_png(),
    "grey16.png": lambda: huge_png(16, 0),
    "jpg": lambda: _patched(".jpg", _jpeg),
    "bmp": lambda: _patched(".bmp", _bmp),
    "tif": lambda: _patched(".tif", _tiff),
    "pgm": lambda: f"P5\n# a comment\n{HUGE} {HUGE}\n255\n".encode() + b"\0" * 64,
    "ppm": lambda: f"P6 {HUGE} {HUGE} 255\n".encode() + b"\0" * 64,
}


@pytest.fixture
def no_decoding(monkeypatch: pytest.MonkeyPatch) -> None:
    """Decoding anything fails the test: the refusal must come from the header."""
    def decode(*args: object, **kwargs: object) -> None:
        raise AssertionError("an image was decoded")

    monkeypatch.setattr(cv2, "imdecode", decode)


@pytest.mark.parametrize("name", sorted(CRAFTED))
@pytest.mark.parametrize("reader", [read_image, read_raw, read_road_label])
def test_a_crafted_image_header_is_refused_before_decoding(name: str, reader, tmp_path: Path,  # noqa: ANN001
                                                           no_decoding: None) -> None:
    path = tmp_path / f"crafted.{name}"
    path.write_bytes(CRAFTED[name]())
    with pytest.raises(CorruptFileError) as info:
        reader(path)
    message = str(info.value)
    assert f"{HUGE}×{HUGE}" in message and "MAX_IMAGE_PIXELS" in message and str(path) in message
    assert "\n" not in message


def test_the_limit_is_the_pixels_not_the_sides(tmp_path: Path) -> None:
    """An image within the limit decodes whatever its shape; one pixel row more than the limit is refused."""
    wide = tmp_path / "wide.png"
    cv2.imwrite(str(wide), np.zeros((2, 4000), np.uint8))
    assert read_image(wide).shape == (2, 4000)
    at_limit = tmp_path / "limit.png"
    at_limit.write_bytes(huge_png(size=(MAX_IMAGE_PIXELS // 2, 3)))
    with pytest.raises(CorruptFileError, match="MAX_IMAGE_PIXELS"):
        read_image(at_limit)


@pytest.mark.parametrize("suffix", [".png", ".npy", ".pfm"])
def test_disparity_and_depth_headers_are_refused_before_decoding(suffix: str, tmp_path: Path,
                                                                 no_decoding: None) -> None:
    path = tmp_path / f"map{suffix}"
    if suffix == ".png":
        path.write_bytes(huge_png(16, 0))
    elif suffix == ".npy":
        header = "{'descr': '<f4', 'fortran_order': False, 'shape': (%d, %d), }" % (HUGE, HUGE)
        header += " " * (63 - (10 + len(header)) % 64) + "\n"
        path.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + b"\0" * 64)
    else:
        path.write_bytes(f"Pf\n{HUGE} {HUGE}\n-1.0\n".encode() + b"\0" * 64)
    for reader in (read_disparity, read_depth):
        with pytest.raises(CorruptFileError, match="MAX_IMAGE_PIXELS"):
            reader(path)


def _sparse(path: Path, size: int, head: bytes = b"") -> Path:
    with path.open("wb") as f:
        f.write(head)
        f.truncate(size)
    return path


def test_a_file_beyond_the_byte_limit_is_refused_unread(tmp_path: Path) -> None:
    path = _sparse(tmp_path / "big.png", MAX_IMAGE_FILE_BYTES + 1, huge_png()[:33])
    with pytest.raises(CorruptFileError, match="MAX_IMAGE_FILE_BYTES"):
        read_image(path)
    with pytest.raises(CorruptFileError, match="MAX_IMAGE_FILE_BYTES"):
        read_disparity(path.rename(tmp_path / "big.npy"))


def test_a_scan_beyond_the_point_limit_is_refused_from_its_size(tmp_path: Path) -> None:
    scan = _sparse(tmp_path / "0000000000.bin", (MAX_SCAN_POINTS + 1) * 16)
    with pytest.raises(CorruptFileError) as info:
        read_velodyne(scan)
    assert "MAX_SCAN_POINTS" in str(info.value) and f"{MAX_SCAN_POINTS:,}" in str(info.value)


def test_a_video_whose_stream_states_too_many_pixels_is_refused(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """The size a stream states is checked before a frame is decoded (the limit lowered to 255 pixels here: FFmpeg
    opens no stream of 30000×30000)."""
    video = tmp_path / "clip.y4m"
    video.write_bytes(b"YUV4MPEG2 W16 H16 F10:1 Ip A1:1 C420jpeg\n" + (b"FRAME\n" + b"\x80" * 384) * 2)
    assert open_frames(video).size == (16, 16)
    monkeypatch.setattr("freespace.io.codecs.MAX_IMAGE_PIXELS", 255)
    with pytest.raises(CorruptFileError, match="16×16 pixels .*MAX_IMAGE_PIXELS"):
        open_frames(video)


def test_cli_refuses_a_crafted_frame_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    big, small = tmp_path / "left.png", tmp_path / "right.png"
    big.write_bytes(huge_png())
    cv2.imwrite(str(small), np.zeros((8, 8, 3), np.uint8))
    refused(capsys, ["generate", "--reference", str(big), "--target", str(small), "--road-mask", str(small),
                     "--out", str(tmp_path / "out.png")], match="MAX_IMAGE_PIXELS")
    assert not (tmp_path / "out.png").exists()


def test_datasets_info_reports_a_crafted_frame_and_a_huge_scan(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    drive = make_drive(tmp_path, frames=2, velodyne=True)
    (drive / "image_03" / "data" / "0000000001.png").write_bytes(huge_png())
    _sparse(drive / "velodyne_points" / "data" / "0000000000.bin", (MAX_SCAN_POINTS + 1) * 16)
    info = dataset_info("kitti-raw", tmp_path, progress=False)
    text = "\n".join(info["problems"])
    assert "MAX_IMAGE_PIXELS" in text and "MAX_SCAN_POINTS" in text, text
    assert main(["datasets", "info", "--dataset", "kitti-raw", "--root", str(tmp_path), "--no-progress"]) == 1
    assert "\0" not in capsys.readouterr().out


# --- calibrations -------------------------------------------------------------------------------------

def _edited(text: str, key: str, values: str | None = None, *, twice: bool = False) -> str:
    lines = []
    for line in text.splitlines():
        if line.startswith(key + ":"):
            new = f"{key}: {values}" if values is not None else line
            lines += [line, new] if twice else [new]
        else:
            lines.append(line)
    return "\n".join(lines) + "\n"


LEFT_X = 0.0598  # metres: where P_rect_02 puts the left colour camera (its centre's x, rectified camera 0 at 0)


def _p(fx: float = 721.5377, cx: float = 609.5593, cy: float = 172.854, baseline: float | None = None) -> str:
    """A ``P_rect_0i`` line's numbers: ``K [I | t]`` with the camera ``baseline`` metres right of the left one."""
    tx = 0.0 if baseline is None else fx * (LEFT_X - baseline)
    return f"{fx} 0 {cx} {tx} 0 {fx} {cy} 0 0 0 1 0"


LYING_CAM_TO_CAM = {
    "4700 km baseline": (_edited(CAM_TO_CAM, "P_rect_03", _p(baseline=4.7e6)), ["P_rect_03", "m"]),
    "baseline to the left": (_edited(CAM_TO_CAM, "P_rect_03", _p(baseline=-0.54)), ["P_rect_03", "left of"]),
    "a 1 mm baseline": (_edited(CAM_TO_CAM, "P_rect_03", _p(baseline=0.001)), ["P_rect_03", "0.001"]),
    "P_rect_02 twice": (_edited(CAM_TO_CAM, "P_rect_02", twice=True), ["P_rect_02", "twice"]),
    "S_rect_02 twice": (_edited(CAM_TO_CAM, "S_rect_02", twice=True), ["S_rect_02", "twice"]),
    "negative focal length": (_edited(CAM_TO_CAM, "P_rect_02", _p(fx=-721.5377)), ["P_rect_02", "focal length"]),
    "principal point off the image": (_edited(CAM_TO_CAM, "P_rect_02", _p(cx=5000)), ["P_rect_02", "principal point"]),
    "right intrinsics differ": (_edited(CAM_TO_CAM, "P_rect_03", _p(fx=500, baseline=0.54)),
                                ["P_rect_03", "intrinsics"]),
    "rotation that is none": (_edited(CAM_TO_CAM, "R_rect_00", "2 0 0 0 2 0 0 0 2"), ["R_rect_00", "no rotation"]),
    "huge S_rect_02": (_edited(CAM_TO_CAM, "S_rect_02", f"{HUGE} {HUGE}"), ["S_rect_02", "MAX_IMAGE_PIXELS"]),
}


@pytest.mark.parametrize("case", sorted(LYING_CAM_TO_CAM))
def test_a_lying_kitti_raw_calibration_is_refused_where_read(case: str, tmp_path: Path) -> None:
    text, words = LYING_CAM_TO_CAM[case]
    path = tmp_path / "calib_cam_to_cam.txt"
    path.write_text(text)
    with pytest.raises(CorruptFileError) as info:
        read_kitti_raw_calib(path)
    assert all(w in str(info.value) for w in words) and str(path) in str(info.value), str(info.value)


@pytest.mark.parametrize("case", ["4700 km baseline", "P_rect_02 twice", "negative focal length"])
def test_a_lying_calibration_is_one_line_per_drive(case: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Two drives of one day, 36 frames: one problem each, and a strict open refuses in one line."""
    for number in (1, 2):
        make_drive(tmp_path, number, frames=18)
    (tmp_path / DATE / "calib_cam_to_cam.txt").write_text(LYING_CAM_TO_CAM[case][0])
    with pytest.raises(FreespaceError):
        dataset_info("kitti-raw", tmp_path, progress=False)  # no drive left to open
    assert main(["datasets", "info", "--dataset", "kitti-raw", "--root", str(tmp_path), "--no-progress"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and LYING_CAM_TO_CAM[case][1][0] in lines[0], lines
    make_drive(tmp_path / "good", 3, frames=2)  # one sound day beside: the bad one is listed once per drive
    (tmp_path / "2011_09_28").mkdir()
    (tmp_path / "good" / DATE).rename(tmp_path / "2011_09_28" / "x")
    good = tmp_path / "2011_09_28" / "2011_09_28_drive_0003_sync"
    (tmp_path / "2011_09_28" / "x" / f"{DATE}_drive_0003_sync").rename(good)
    for name in ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt"):
        (tmp_path / "2011_09_28" / "x" / name).rename(tmp_path / "2011_09_28" / name)
    info = dataset_info("kitti-raw", tmp_path, progress=False)
    bad = [p for p in info["problems"] if LYING_CAM_TO_CAM[case][1][0] in p]
    assert len(bad) == 2 and info["splits"]["all"]["frames"] == 2, info["problems"]


def test_a_lying_kitti_road_calibration_is_refused(tmp_path: Path) -> None:
    P2 = "721.5377 0 609.5593 0 0 721.5377 172.854 0 0 0 1 0"
    for p3, word in (("721.5377 0 609.5593 -3.4e9 0 721.5377 172.854 0 0 0 1 0", "m from"),
                     ("-721.5377 0 609.5593 -389 0 721.5377 172.854 0 0 0 1 0", "intrinsics")):
        path = tmp_path / "um_000000.txt"
        path.write_text(f"P2: {P2}\nP3: {p3}\n")
        with pytest.raises(CorruptFileError, match=word):
            read_kitti_calib(path)
    path.write_text(f"P2: {P2}\nP2: {P2}\n")
    with pytest.raises(CorruptFileError, match="twice"):
        read_kitti_calib(path)


@pytest.mark.parametrize("camera,word", [("{fx: -320, cx: 320, cy: 240, baseline: 0.5}", "fx"),
                                         ("{fx: 320, cx: 320, cy: 240, baseline: 4700000}", "baseline"),
                                         ("{fx: 320, cx: -10, cy: 240, baseline: 0.5}", "cx"),
                                         ("{fx: 320, cx: 320, cy: 240, baseline: 0}", "baseline")])
def test_a_lying_folder_camera_is_refused(camera: str, word: str, tmp_path: Path) -> None:
    (tmp_path / "left").mkdir()
    cv2.imwrite(str(tmp_path / "left" / "a.png"), np.zeros((8, 8, 3), np.uint8))
    (tmp_path / "freespace.yaml").write_text(f"camera: {camera}\n")
    with pytest.raises(InvalidOptionError, match=word):
        get_dataset("generic", tmp_path)


# --- pairs ----------------------------------------------------------------------------------------------

def _grey_left(drive: Path) -> None:
    for path in sorted((drive / "image_02" / "data").glob("*.png")):
        cv2.imwrite(str(path), np.zeros((375, 1242), np.uint8))


def test_a_grey_left_image_with_a_colour_right_one_says_so(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    drive = make_drive(tmp_path, frames=12)
    _grey_left(drive)
    info = dataset_info("kitti-raw", tmp_path, progress=False)
    mixed = [p for p in info["problems"] if "grey" in p]
    assert len(mixed) == 1 and "1242×375 RGB" in mixed[0] and "1242×375 grey" in mixed[0], info["problems"]
    assert "12 frames" in mixed[0]
    line = refused(capsys, ["generate", "--dataset", "kitti-raw", "--root", str(tmp_path), "--out",
                            str(tmp_path / "gen"), "--disparity-source", "sgbm"], match="grey")
    assert "colour" in line and "12 pairs" in line
    ds = get_dataset("kitti-raw", tmp_path, strict=False, disparity_source="none")
    with pytest.raises(ShapeMismatchError, match="1242×375 RGB but the left is 1242×375 grey"):
        ds.load(0)


def test_a_grey_and_a_colour_image_as_one_pair_say_so(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    left, right = tmp_path / "l.png", tmp_path / "r.png"
    cv2.imwrite(str(left), np.zeros((64, 96), np.uint8))
    cv2.imwrite(str(right), np.zeros((64, 96, 3), np.uint8))
    mask = tmp_path / "m.png"
    cv2.imwrite(str(mask), np.repeat(np.arange(64, dtype=np.uint8)[:, None] > 40, 96, 1).astype(np.uint8) * 255)
    refused(capsys, ["generate", "--reference", str(left), "--target", str(right), "--road-mask", str(mask),
                     "--out", str(tmp_path / "o.png")], match="96×64 grey but target is 96×64 RGB")
