"""Hostile probe 5 (issue 72): image decoding, the Predictor, frame sources and file names.

* Frames are read upright: the EXIF orientation of a JPEG (APP1), TIFF, PNG (``eXIf``) or WebP (``EXIF``) is
  applied by every reader, the header's size agrees, and ``predict``, ``evaluate`` and ``adapt`` see the upright
  frame (masks and overlays at the upright size).
* ``Predictor.predict`` takes uint8, uint16 and float [0, 1] RGB images, one image, a batch array, a list or a
  generator; anything else is one line.
* A file of several images (animated WebP, PNG or GIF, multi-page TIFF) is refused with its count, never reduced
  to its first image.
* File names of bytes that are not UTF-8 are printed, recorded and written by ``predict``, ``evaluate`` and
  ``adapt``; OpenCV and ONNX Runtime open them.
* ``threads`` is checked before a model is touched: 0, a million, a float are refused.
* A file is an image or a video by its suffix: ``.pgm``, ``.pbm``, ``.pnm`` are images, an unknown suffix is
  refused in one line.

Every file is made here, byte by byte where a format's detail matters (no dependency beyond OpenCV).
"""

from __future__ import annotations

import json
import os
import struct
import time
import zlib
from functools import partial
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.errors import CorruptFileError, FreespaceError, InputFileError, InvalidOptionError
from freespace.io.codecs import (
    image_frame_count,
    image_header_size,
    image_orientation,
    read_disparity,
    read_image,
    read_raw,
    write_image,
)
from freespace.io.video import open_frames
from test_hostile_probe4_outputs import _onnx

from helpers import refused, road_frame, textured_image, tiny_road_checkpoint

SHAPE = (48, 64)  # H, W as stored: upright (64, 48) under orientations 5-8


# ------------------------------------------------------------------------------------------------- files


def _chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def _exif(orientation: int, order: str = ">") -> bytes:
    """A TIFF structure (an EXIF block) whose first IFD holds Orientation, in big (``>``) or little endian."""
    mark = b"MM\x00*" if order == ">" else b"II*\x00"
    return (mark + struct.pack(order + "IH", 8, 1) + struct.pack(order + "HHIHH", 274, 3, 1, orientation, 0)
            + struct.pack(order + "I", 0))


def _encode(suffix: str, rgb: np.ndarray, *params: int) -> bytes:
    ok, buf = cv2.imencode(suffix, rgb[:, :, ::-1] if rgb.ndim == 3 else rgb, list(params))
    assert ok
    return buf.tobytes()


def jpeg(rgb: np.ndarray, orientation: int, order: str = ">") -> bytes:
    """A JPEG with an Exif APP1 segment (right after SOI, as cameras write it) stating ``orientation``."""
    data = _encode(".jpg", rgb, cv2.IMWRITE_JPEG_QUALITY, 100)
    payload = b"Exif\x00\x00" + _exif(orientation, order)
    return data[:2] + b"\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload + data[2:]


def png(image: np.ndarray, orientation: int) -> bytes:
    """A PNG (8 or 16 bits) with an ``eXIf`` chunk after its header."""
    data = _encode(".png", image)
    return data[:33] + _chunk(b"eXIf", _exif(orientation, "<")) + data[33:]


def webp(rgb: np.ndarray, orientation: int) -> bytes:
    """A lossless WebP in the extended format (VP8X) with an ``EXIF`` chunk."""
    data = _encode(".webp", rgb, cv2.IMWRITE_WEBP_QUALITY, 101)
    assert data[12:16] == b"VP8L"
    h, w = rgb.shape[:2]
    exif = _exif(orientation)
    chunks = (b"VP8X" + struct.pack("<I", 10) + bytes([0x08, 0, 0, 0]) + (w - 1).to_bytes(3, "little")
              + (h - 1).to_bytes(3, "little") + data[12:] + b"EXIF" + struct.pack("<I", len(exif)) + exif)
    return b"RIFF" + struct.pack("<I", 4 + len(chunks)) + b"WEBP" + chunks


def tiff(pages: list[np.ndarray], orientation: int = 1) -> bytes:
    """An uncompressed little-endian TIFF of grey uint8 pages (one IFD each, chained), the first tagged with
    ``orientation``."""
    out = bytearray(b"II*\x00\x00\x00\x00\x00")
    link = 4
    for k, page in enumerate(pages):
        h, w = page.shape
        at = len(out)
        out += page.tobytes() + b"\x00" * (page.size % 2)
        tags = [(256, 3, w), (257, 3, h), (258, 3, 8), (259, 3, 1), (262, 3, 1), (273, 4, at),
                (274, 3, orientation if k == 0 else 1), (277, 3, 1), (278, 3, h), (279, 4, page.size), (284, 3, 1)]
        ifd = len(out)
        out[link:link + 4] = struct.pack("<I", ifd)
        out += struct.pack("<H", len(tags))
        for tag, kind, value in tags:
            entry = (value, 0) if kind == 3 else (value,)
            out += struct.pack("<HHIHH" if kind == 3 else "<HHII", tag, kind, 1, *entry)
        link = len(out)
        out += b"\x00\x00\x00\x00"
    return bytes(out)


def animated_webp(frames: list[np.ndarray]) -> bytes:
    """An animated WebP (VP8X with the animation flag, ANIM, one ANMF per frame of lossless VP8L data)."""
    h, w = frames[0].shape[:2]
    body = b"VP8X" + struct.pack("<I", 10) + bytes([0x02, 0, 0, 0]) + (w - 1).to_bytes(3, "little") \
        + (h - 1).to_bytes(3, "little") + b"ANIM" + struct.pack("<I", 6) + b"\x00" * 4 + b"\x00\x00"
    for frame in frames:
        vp8l = _encode(".webp", frame, cv2.IMWRITE_WEBP_QUALITY, 101)[12:]
        payload = b"\x00" * 6 + (w - 1).to_bytes(3, "little") + (h - 1).to_bytes(3, "little") \
            + (100).to_bytes(3, "little") + b"\x00" + vp8l
        body += b"ANMF" + struct.pack("<I", len(payload)) + payload + b"\x00" * (len(payload) % 2)
    return b"RIFF" + struct.pack("<I", 4 + len(body)) + b"WEBP" + body


def apng(frames: list[np.ndarray]) -> bytes:
    """An animated PNG: acTL, and a frame control before the IDAT (the first frame) and before each fdAT."""
    h, w = frames[0].shape[:2]
    datas = []
    for frame in frames:
        data, pos, idat = _encode(".png", frame), 8, b""
        while pos < len(data):
            length, kind = struct.unpack(">I4s", data[pos:pos + 8])
            idat += data[pos + 8:pos + 8 + length] if kind == b"IDAT" else b""
            pos += 12 + length
        datas.append(idat)
    first = _encode(".png", frames[0])
    out = first[:33] + _chunk(b"acTL", struct.pack(">II", len(frames), 0))
    seq = 0
    for k, idat in enumerate(datas):
        out += _chunk(b"fcTL", struct.pack(">IIIIIHHBB", seq, w, h, 0, 0, 1, 10, 0, 0))
        seq += 1
        if k == 0:
            out += _chunk(b"IDAT", idat)
        else:
            out += _chunk(b"fdAT", struct.pack(">I", seq) + idat)
            seq += 1
    return out + _chunk(b"IEND", b"")


def gif(frames: int) -> bytes:
    """A 1×1 GIF of ``frames`` images (a graphic control extension and an image each)."""
    head = b"GIF89a" + struct.pack("<HHBBB", 1, 1, 0x80, 0, 0) + b"\x00\x00\x00\xff\xff\xff"
    control = b"\x21\xf9\x04\x00\x0a\x00\x00\x00"  # a graphic control extension: 0.1 s
    image = control + b"\x2c" + struct.pack("<HHHHB", 0, 0, 1, 1, 0) + b"\x02\x02\x44\x01\x00"  # LZW: clear, 0, end
    return head + image * frames + b"\x3b"


def expected_upright(stored: np.ndarray, orientation: int) -> np.ndarray:
    """What a viewer shows of ``stored`` pixels tagged ``orientation`` (EXIF: 6 = turn 90° clockwise)."""
    return {1: lambda a: a, 2: np.fliplr, 3: lambda a: np.rot90(a, 2), 4: np.flipud, 5: lambda a: a.swapaxes(0, 1),
            6: lambda a: np.rot90(a, -1), 7: lambda a: np.rot90(a, 2).swapaxes(0, 1), 8: lambda a: np.rot90(a, 1)
            }[orientation](stored)


def quadrants(shape: tuple[int, int] = SHAPE) -> np.ndarray:
    """An RGB image of four flat quadrants of distinct colours (JPEG keeps them), whose orientation shows."""
    h, w = shape
    img = np.zeros((h, w, 3), np.uint8)
    for (r, c), colour in zip([(0, 0), (0, 1), (1, 0), (1, 1)], [(230, 30, 30), (30, 230, 30), (30, 30, 230),
                                                                  (230, 230, 30)]):
        img[r * h // 2:(r + 1) * h // 2, c * w // 2:(c + 1) * w // 2] = colour
    return img


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An ONNX road model of any input size: road where green beats red (scores 4·R and 4·G)."""
    return _onnx(tmp_path_factory.mktemp("probe5") / "good.onnx", 4.0)


def _bytes_name(folder: Path, name: bytes) -> Path:
    """``folder``/``name`` for a name of bytes that are not UTF-8, or skip where the file system refuses one."""
    path = Path(os.fsdecode(os.fsencode(folder) + b"/" + name))
    try:
        path.mkdir()
        path.rmdir()
    except OSError:
        pytest.skip("this file system takes only UTF-8 names")
    return path


def _strict_json(path: Path) -> object:
    """The JSON file ``path``, read as a strict reader does: UTF-8, and no lone surrogate in a string."""
    data = json.loads(path.read_bytes().decode("utf-8"))

    def strings(x: object) -> list[str]:
        if isinstance(x, str):
            return [x]
        if isinstance(x, dict):
            return [s for k, v in x.items() for s in strings(k) + strings(v)]
        if isinstance(x, list):
            return [s for v in x for s in strings(v)]
        return []
    assert not [s for s in strings(data) if any(0xD800 <= ord(c) <= 0xDFFF for c in s)], path
    return data


# ------------------------------------------------------------------------------------------------- 1. orientation


@pytest.mark.parametrize("orientation", range(1, 9))
def test_every_format_is_read_upright_by_every_reader(orientation: int, tmp_path: Path) -> None:
    """JPEG (both byte orders of its EXIF), PNG eXIf, WebP EXIF and TIFF: the pixels as a viewer shows them, the
    header's size the same; labels (read_raw) and 16-bit disparity PNGs alike."""
    rgb = quadrants()
    want = expected_upright(rgb, orientation)
    files = {"a.jpg": jpeg(rgb, orientation), "b.jpg": jpeg(rgb, orientation, "<"), "c.png": png(rgb, orientation),
             "d.webp": webp(rgb, orientation)}
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
        assert image_orientation(data) == orientation, name
        got = read_image(tmp_path / name)
        assert got.shape == want.shape, (name, got.shape)
        if name.endswith(".jpg"):  # lossy at the quadrants' edges: each quadrant's mean colour
            got, want_q = (cv2.resize(x, (2, 2), interpolation=cv2.INTER_AREA).astype(int) for x in (got, want))
            assert np.abs(got - want_q).max() <= 12, name
        else:
            np.testing.assert_array_equal(got, want, err_msg=name)
        assert image_header_size(data) == (want.shape[1], want.shape[0]), name
    grey = np.arange(SHAPE[0] * SHAPE[1], dtype=np.uint32).reshape(SHAPE).astype(np.uint8)
    (tmp_path / "t.tif").write_bytes(tiff([grey], orientation))
    np.testing.assert_array_equal(read_image(tmp_path / "t.tif"), expected_upright(grey, orientation))
    np.testing.assert_array_equal(read_raw(tmp_path / "t.tif", what="label"), expected_upright(grey, orientation))
    disparity = (np.arange(grey.size, dtype=np.uint16).reshape(SHAPE) + 1) * 16
    (tmp_path / "disp.png").write_bytes(png(disparity, orientation))
    np.testing.assert_allclose(read_disparity(tmp_path / "disp.png"), expected_upright(disparity / 256.0, orientation))


def test_predict_evaluate_and_adapt_see_the_dash_cam_frame_upright(model: Path, tmp_path: Path, capsys) -> None:
    """A frame stored 64×48 and tagged "turn 90°" (6) or "turn 270°" (8): predict's mask and overlay are 48×64
    (W×H), evaluate pairs it with its upright 48×64 label, adapt's frames are 48×64, and a frame source says so."""
    from freespace.engine.adapt_io import read_frames

    frames, labels = tmp_path / "frames", tmp_path / "labels"
    frames.mkdir()
    labels.mkdir()
    stored = textured_image(SHAPE, seed=3)
    for name, orientation in (("cam6", 6), ("cam8", 8)):
        (frames / f"{name}.jpg").write_bytes(jpeg(stored, orientation))
        label = np.zeros((SHAPE[1], SHAPE[0]), np.uint8)
        label[SHAPE[1] // 2:] = 255
        write_image(labels / f"{name}.png", label)
    assert open_frames(frames).size == (64, 48)
    out = tmp_path / "pred"
    assert main(["predict", "--onnx", str(model), "--input", str(frames), "--out", str(out), "--no-progress"]) == 0
    for name in ("cam6", "cam8"):
        assert read_image(out / f"{name}.png").shape == (64, 48)
        assert read_image(out / "overlays" / f"{name}.png").shape == (64, 48, 3)
    assert main(["evaluate", "--onnx", str(model), "--images", str(frames), "--labels", str(labels),
                 "--label-format", "binary", "--out", str(tmp_path / "eval"), "--no-progress"]) == 0
    assert _strict_json(tmp_path / "eval" / "metrics.json")["frames"] == 2  # type: ignore[index]
    assert read_frames(frames, (32, 32)).sizes == [(64, 48)]
    capsys.readouterr()


# ------------------------------------------------------------------------------------------------- 2. Predictor inputs


def test_the_predictor_takes_every_documented_input_and_refuses_the_rest(model: Path) -> None:
    from freespace.inference.predictor import Predictor

    predictor = Predictor(onnx=model)
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, SHAPE + (3,), dtype=np.uint8)
    other = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    ref = predictor.predict([image])[0]
    assert ref.shape == SHAPE and 0.2 < ref.mean() < 0.8 and ref.std() > 0.1  # the frame's road, not 0.5 or 0
    same = {
        "float64 [0, 1]": [image / 255.0],
        "float32 [0, 1]": [(image / 255.0).astype(np.float32)],
        "uint16": [image.astype(np.uint16) * 257],
        "one image": image,
        "a batch array": np.stack([image, image]),
        "a tuple": (image,),
        "a generator": (x for x in [image, image, image]),
    }
    grey = predictor.predict([image[:, :, 1]])[0]  # grey frames: repeated to RGB, as frame sources do
    np.testing.assert_allclose(grey, predictor.predict([np.repeat(image[:, :, 1:2], 3, axis=2)])[0], atol=1e-6)
    np.testing.assert_allclose(predictor.predict(image[:, :, 1])[0], grey, atol=1e-6)
    for what, given in same.items():
        probs = predictor.predict(given, batch_size=2)
        assert probs, what
        for p in probs:
            np.testing.assert_allclose(p, ref, atol=1e-3, err_msg=what)
    half = predictor.predict([(image / 255.0).astype(np.float16)])[0]
    np.testing.assert_allclose(half, ref, atol=0.02)
    mixed = predictor.predict(iter([image, other, image]), batch_size=2)
    assert [p.shape for p in mixed] == [SHAPE, (30, 40), SHAPE]
    bad = {
        "nothing": ([], "no image"),
        "an empty batch": (np.zeros((0,) + SHAPE + (3,), np.uint8), "no image"),
        "an empty generator": ((x for x in []), "no image"),
        "float 0…255": ([image.astype(np.float32)], "[0, 1]"),
        "NaN": ([np.full(SHAPE + (3,), np.nan)], "NaN"),
        "negative float": ([image / 255.0 - 0.5], "[0, 1]"),
        "RGBA": ([np.dstack([image, image[:, :, :1]])], "alpha"),
        "two channels": ([image[:, :, :2]], "H×W×3"),
        "empty image": ([np.zeros((0, 5, 3), np.uint8)], "empty"),
        "int64": ([image.astype(np.int64)], "uint8"),
        "bool": ([image > 9], "uint8"),
        "a path": ("frame.png", "read it first"),
        "a Path in a list": ([Path("frame.png")], "read it first"),
        "a number": (5, "iterable"),
        "a 5-D array": (np.zeros((1, 1, 4, 4, 3)), "H×W×3"),
    }
    for what, (given, needle) in bad.items():
        with pytest.raises(InvalidOptionError) as info:
            predictor.predict(given)
        text = str(info.value)
        assert needle in text and "\n" not in text, (what, text)
    with pytest.raises(InvalidOptionError, match="batch_size"):
        predictor.predict([image], batch_size=0)


# ------------------------------------------------------------------------------------------------- 3. multi-frame files


def test_a_file_of_several_images_is_refused_with_its_count_everywhere(model: Path, tmp_path: Path, capsys) -> None:
    """Animated WebP, PNG and GIF, multi-page TIFF: read_image, read_raw (labels), predict and adapt's frames
    refuse them, saying how many images they hold; the one-image files of the same formats are read."""
    from freespace.engine.adapt_io import read_frames
    from freespace.io.codecs import MultiFrameImageError

    frames = [np.full(SHAPE + (3,), 40 * k, np.uint8) for k in range(1, 4)]
    grey = [f[:, :, 0] for f in frames]
    many = {"anim.webp": (animated_webp(frames), "animated WebP"), "pages.tif": (tiff(grey), "multi-page TIFF"),
            "anim.png": (apng(frames), "animated PNG"), "anim_gif.png": (gif(3), "animated GIF")}
    pgm = _encode(".pgm", grey[0])
    many["frames.pgm"] = (pgm + pgm + pgm, "Netpbm file of several images")  # images one after another
    one = {"one.webp": animated_webp(frames[:1]), "one.tif": tiff(grey[:1]), "one.png": apng(frames[:1]),
           "one.pgm": pgm}
    for name, (data, kind) in many.items():
        assert image_frame_count(data) == 3, name
        (tmp_path / name).write_bytes(data)
        for reader in (read_image, read_raw):
            with pytest.raises(MultiFrameImageError, match=f"holds 3 images \\({'an' if kind[0] in 'aA' else 'a'} "
                                                           f"{kind}"):
                reader(tmp_path / name)
    for name, data in one.items():
        assert image_frame_count(data) == 1, name
        (tmp_path / name).write_bytes(data)
        assert read_image(tmp_path / name).shape[:2] == SHAPE, name
    assert image_frame_count(gif(1)) == 1
    folder = tmp_path / "cam"
    folder.mkdir()
    for i in range(3):
        write_image(folder / f"f{i}.png", textured_image(SHAPE, seed=i))
    (folder / "f3.webp").write_bytes(many["anim.webp"][0])
    err = refused(capsys, ["predict", "--onnx", str(model), "--input", str(folder / "f3.webp"), "--out",
                           str(tmp_path / "p")], match="holds 3 images")
    assert "f3.webp" in err and not (tmp_path / "p").exists()
    with pytest.raises(MultiFrameImageError, match="holds 3 images"):  # not skipped as an unreadable frame
        read_frames(folder, (32, 32))


# ------------------------------------------------------------------------------------------------- 4. file names


def test_names_of_any_bytes_are_printed_recorded_and_written(model: Path, tmp_path: Path, capsys) -> None:
    """predict (folder, shards, video out and in, an ONNX file of such a name), evaluate and adapt on frames
    named b'fr\\xe9me.png' in a folder b'd\\xe9': no UnicodeEncodeError (capsys' output is strict UTF-8), every
    output written under its own name, the printed line and the records showing the byte as \\xe9."""
    base = _bytes_name(tmp_path, b"d\xe9")
    frames, labels = base / "frames", base / "labels"
    frames.mkdir(parents=True)
    labels.mkdir()
    weird = os.fsdecode(b"fr\xe9me")
    for name in (weird, "ok"):
        write_image(frames / f"{name}.png", textured_image(SHAPE, seed=len(name)))
        label = np.zeros(SHAPE, np.uint8)
        label[SHAPE[0] // 2:] = 255
        write_image(labels / f"{name}.png", label)
    onnx = base / os.fsdecode(b"m\xe9.onnx")
    onnx.write_bytes(model.read_bytes())
    capsys.readouterr()

    out = base / "pred"
    assert main(["predict", "--onnx", str(onnx), "--input", str(frames), "--out", str(out), "--no-progress"]) == 0
    assert "d\\xe9" in capsys.readouterr().out
    assert (out / f"{weird}.png").is_file() and (out / "overlays" / f"{weird}.png").is_file()
    assert _strict_json(out / "predict.json")["input"].endswith("d\\xe9/frames")  # type: ignore[index]
    _strict_json(out / "summary.json")
    for k in (1, 2):  # a second shard's record matches the first's
        assert main(["predict", "--onnx", str(onnx), "--input", str(frames), "--out", str(base / "sharded"),
                     "--shard", f"{k}/2", "--no-progress"]) == 0
    assert _strict_json(base / "sharded" / "summary.json")["frames"] == 2  # type: ignore[index]
    video = base / os.fsdecode(b"v\xe9.mp4")
    assert main(["predict", "--onnx", str(model), "--input", str(frames), "--out", str(video), "--no-progress"]) == 0
    assert video.stat().st_size > 0
    assert main(["predict", "--onnx", str(model), "--input", str(video), "--out", str(base / "from_video"),
                 "--no-progress"]) == 0
    assert (base / "from_video" / (os.fsdecode(b"v\xe9") + "_000001.png")).is_file()

    ev = base / "eval"
    assert main(["evaluate", "--onnx", str(onnx), "--images", str(frames), "--labels", str(labels),
                 "--label-format", "binary", "--out", str(ev), "--no-progress"]) == 0
    assert "d\\xe9" in capsys.readouterr().out
    assert (ev / "overlays" / f"{weird}.png").is_file()
    rows = (ev / "per_frame.csv").read_bytes().decode("utf-8").splitlines()
    assert any(r.startswith("fr\\xe9me,") for r in rows), rows
    assert _strict_json(ev / "metrics.json")["images"].endswith("d\\xe9/frames")  # type: ignore[index]

    err = refused(capsys, ["predict", "--onnx", str(model), "--input", str(base / "none"), "--out",
                           str(base / "x")])
    assert "d\\xe9/none" in err


def test_adapt_on_frames_named_with_any_bytes(tmp_path: Path, capsys) -> None:
    """adapt end to end (one short round of a tiny model) from and into folders whose names are no UTF-8: the
    model folder is written, its card and records are UTF-8, the printed line shows the names."""
    base = _bytes_name(tmp_path, b"a\xe9")
    folder = base / "tiny"
    folder.mkdir(parents=True)
    tiny_road_checkpoint(folder / "model.ckpt", (32, 96), width=0.25)
    (folder / "README.md").write_text("# tiny\n")
    frames = base / "frames"
    frames.mkdir()
    for i in range(20):
        write_image(frames / os.fsdecode(b"f\xe9%02d.png" % i), road_frame((48, 120), 500 + i)[0])
    capsys.readouterr()
    out = base / "new"
    assert main(["adapt", "--model", str(folder), "--input", str(frames), "--out", str(out), "--epochs", "1",
                 "--threads", "1", "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "a\\xe9/tiny" in printed and "a\\xe9/new" in printed
    assert _strict_json(out / "summary.json")["frames"] == 20  # type: ignore[index]
    _strict_json(out / "config.json")
    (out / "README.md").read_bytes().decode("utf-8")


# ------------------------------------------------------------------------------------------------- 5. threads


def test_threads_are_checked_before_anything_else(model: Path, tmp_path: Path) -> None:
    """0 is refused (not "all cores"), a million is refused at once (not 41 GB allocated), floats and booleans
    too: by the Predictor of either kind (before the model file is looked at), by session_options and by
    predict() (before anything is written)."""
    from freespace.inference.evaluate import evaluate
    from freespace.inference.predict import predict
    from freespace.inference.predictor import Predictor, session_options

    missing = tmp_path / "model.onnx"
    for threads in (0, -1, 10**6, 1.5, True, "2"):
        t0 = time.perf_counter()
        for make in (partial(Predictor, onnx=missing, threads=threads),
                     partial(Predictor, checkpoint=tmp_path / "m.ckpt", threads=threads),
                     partial(session_options, threads)):
            with pytest.raises(InvalidOptionError, match="threads") as info:
                make()
            assert "ONNX" not in str(info.value) and "not found" not in str(info.value)
        with pytest.raises(InvalidOptionError, match="threads"):
            predict(tmp_path / "frames", tmp_path / "out", onnx=model, threads=threads)  # type: ignore[arg-type]
        with pytest.raises(InvalidOptionError, match="threads"):
            evaluate(tmp_path / "out", onnx=model, images=tmp_path / "i", labels=tmp_path / "l",
                     label_format="binary", threads=threads)  # type: ignore[arg-type]
        assert time.perf_counter() - t0 < 5 and not (tmp_path / "out").exists()
    assert session_options(1).intra_op_num_threads == 1


# ------------------------------------------------------------------------------------------------- 6. suffixes


@pytest.mark.parametrize("suffix", [".pgm", ".pbm", ".pnm", ".ppm", ".pam", ".ras", ".sr"])
def test_still_image_suffixes_are_images(suffix: str, model: Path, tmp_path: Path, capsys) -> None:
    """A PGM (PBM, PNM, …) is one frame named by its stem: predict writes plain.png, never plain_000000.png; a
    folder of them is a folder of frames; adapt takes it as images."""
    from freespace.engine.adapt_io import frame_paths

    image = textured_image(SHAPE, seed=1)
    data = _encode(suffix, (image[:, :, 0] > 128).astype(np.uint8) * 255 if suffix in (".pgm", ".pbm") else image)
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / f"plain{suffix}").write_bytes(data)
    source = open_frames(folder / f"plain{suffix}")
    assert source.kind == "image" and [f.name for f in source] == ["plain"]
    assert open_frames(folder).count == 1
    assert frame_paths(folder / f"plain{suffix}")[0] == "images"
    out = tmp_path / "out"
    assert main(["predict", "--onnx", str(model), "--input", str(folder / f"plain{suffix}"), "--out", str(out),
                 "--no-progress"]) == 0
    assert (out / "plain.png").is_file() and not (out / "plain_000000.png").exists()
    capsys.readouterr()


@pytest.mark.parametrize("name", ["disp.pfm", "sky.hdr", "photo.jp2", "scan.exr", "notes.txt", "frame", "x.avif"])
def test_a_file_neither_image_nor_video_is_refused_by_its_suffix(name: str, model: Path, tmp_path: Path,
                                                                capsys) -> None:
    """Whatever FFmpeg would make of it (it decodes a PFM or a JPEG 2000 as a one-frame video), a file whose
    suffix is neither an image's nor a video's is refused in one line that names both lists; nothing written."""
    path = tmp_path / name
    path.write_bytes(_encode(".pfm", np.zeros((8, 8, 3), np.float32)) if name.endswith(".pfm")
                     else _encode(".png", np.zeros((8, 8, 3), np.uint8)))
    with pytest.raises(InputFileError, match="neither"):
        open_frames(path)
    err = refused(capsys, ["predict", "--onnx", str(model), "--input", str(path), "--out", str(tmp_path / "out")],
                  match="no video FFmpeg decodes")
    assert ".pgm" in err and ".mp4" in err and not (tmp_path / "out").exists()


def test_corrupt_and_unreadable_stay_one_line(tmp_path: Path) -> None:
    """Cut-short and crafted headers of the formats added here still end in one CorruptFileError line."""
    cases = {"cut.jpg": jpeg(quadrants(), 6)[:30], "exif_loop.tif": b"II*\x00\x08\x00\x00\x00\x01\x00" + b"\x00" * 12
             + b"\x08\x00\x00\x00", "cut.ras": b"\x59\xa6\x6a\x95\x00\x00", "bad.webp": b"RIFF\x10\x00\x00\x00WEBPVP8X"}
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(CorruptFileError) as info:
            read_image(tmp_path / name)
        assert "\n" not in str(info.value), name
    assert isinstance(info.value, FreespaceError)
