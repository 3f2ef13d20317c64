"""Video in and out: MP4 round trip, folders and globs of frames, frame-by-frame decoding, atomic
writes, one-line errors."""

from __future__ import annotations

import inspect
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, ShapeMismatchError
from freespace.io.codecs import write_image
from freespace.io.video import DEFAULT_FPS, VideoWriter, open_frames

from helpers import textured_image


def _frames(n: int, shape: tuple[int, int] = (96, 128)) -> list[np.ndarray]:
    base = textured_image(shape, seed=1)
    return [np.roll(base, 3 * i, axis=1) for i in range(n)]


def test_mp4_round_trip(tmp_path: Path) -> None:
    frames = _frames(25)
    out = tmp_path / "out" / "clip.mp4"
    with VideoWriter(out, fps=12.5) as writer:
        for f in frames:
            writer.write(f)
            assert not out.exists()                                 # only the temporary file so far
    assert out.is_file() and writer.frames == 25
    assert [p.name for p in out.parent.iterdir()] == ["clip.mp4"]  # no temporary file left
    source = open_frames(out)
    assert (source.kind, source.fps, source.size, source.count) == ("video", 12.5, (96, 128), 25)
    back = list(source)
    assert len(back) == 25
    assert [f.index for f in back] == list(range(25)) and back[3].name == "clip_000003"
    assert all(f.image.shape == (96, 128, 3) and f.image.dtype == np.uint8 for f in back)
    # MPEG-4 is lossy: every decoded frame is nearest its own original, in order (measured mean error
    # 5.8–6.4 grey levels to its own, ≥ 25 to any other)
    errors = np.array([[np.abs(f.image.astype(int) - orig.astype(int)).mean() for orig in frames] for f in back])
    assert (errors.argmin(axis=1) == np.arange(25)).all()
    assert errors.diagonal().max() < 10
    assert len(list(source)) == 25                                  # a source can be iterated again


def test_reader_is_a_generator_holding_one_frame(tmp_path: Path) -> None:
    shape = (120, 160)
    with VideoWriter(tmp_path / "long.mp4", fps=30) as writer:
        for f in _frames(80, shape):
            writer.write(f)
    source = open_frames(tmp_path / "long.mp4")
    frames = iter(source)
    assert inspect.isgenerator(frames)
    frame_bytes = shape[0] * shape[1] * 3
    tracemalloc.start()
    try:
        count = sum(1 for _ in frames)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert count == 80
    # the decoded BGR frame, its RGB copy and the previous frame: measured 3.0 frames (a list: 81)
    assert peak < 4 * frame_bytes


def test_folder_and_glob_of_frames(tmp_path: Path) -> None:
    frames = _frames(12, (64, 80))
    folder = tmp_path / "frames"
    for i, f in enumerate(frames):
        write_image(folder / f"f{i}.png", f)                        # f10 after f9: natural order
    (folder / "notes.txt").write_text("not a frame")
    write_image(folder / "grey" / "g0.png", frames[0][:, :, 0])
    for spec in (folder, str(folder / "f*.png")):
        source = open_frames(spec)
        assert source.kind == ("folder" if spec == folder else "glob")
        assert source.fps == DEFAULT_FPS and source.count == 12 and source.size == (64, 80)
        got = list(source)
        assert [f.name for f in got] == [f"f{i}" for i in range(12)]
        for f, orig in zip(got, frames):
            np.testing.assert_array_equal(f.image, orig)            # lossless PNGs
        video = tmp_path / f"{source.kind}.mp4"
        with VideoWriter(video, fps=open_frames(spec, default_fps=5).fps) as writer:
            for f in got:
                writer.write(f.image)
        again = open_frames(video)
        assert (again.fps, again.size, len(list(again))) == (5.0, (64, 80), 12)
    grey = list(open_frames(folder / "grey"))
    assert grey[0].image.shape == (64, 80, 3)                        # grey frames come as RGB
    assert open_frames(folder / "f3.png").count == 1
    assert open_frames(folder, fps=2.5).fps == 2.5


def test_odd_size_is_padded_to_even(tmp_path: Path) -> None:
    with VideoWriter(tmp_path / "odd.mp4", fps=10) as writer:
        for f in _frames(3, (51, 75)):
            writer.write(f)
    source = open_frames(tmp_path / "odd.mp4")
    assert source.size == (52, 76) and len(list(source)) == 3


def test_reader_errors(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="input not found"):
        open_frames(tmp_path / "missing.mp4")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputFileError, match="holds no images"):
        open_frames(tmp_path / "empty")
    with pytest.raises(InputFileError, match="no image file matches"):
        open_frames(str(tmp_path / "empty" / "*.png"))
    (tmp_path / "garbage.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"garbage" * 50)
    with pytest.raises(CorruptFileError, match="cannot decode video"):
        open_frames(tmp_path / "garbage.mp4")
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(CorruptFileError, match="cannot decode frame"):
        open_frames(tmp_path / "bad.png")
    with pytest.raises(InvalidOptionError, match="positive"):
        open_frames(tmp_path, fps=0)


def test_reader_errors_are_one_line(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "garbage.mp4").write_bytes(b"garbage" * 50)
    with pytest.raises(CorruptFileError) as info:
        open_frames(tmp_path / "garbage.mp4")
    assert "\n" not in str(info.value)
    assert capfd.readouterr().err == ""                             # no OpenCV/FFmpeg console noise


def test_writer_errors_leave_no_file(tmp_path: Path) -> None:
    out = tmp_path / "v.mp4"
    with pytest.raises(RuntimeError):
        with VideoWriter(out, fps=10) as writer:
            writer.write(_frames(1)[0])
            raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ShapeMismatchError, match="frame 1 is 80×64 but the video"):
        with VideoWriter(out, fps=10) as writer:
            writer.write(_frames(1)[0])
            writer.write(_frames(1, (64, 80))[0])
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(InvalidOptionError, match="no frames"):
        with VideoWriter(out, fps=10):
            pass
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(InvalidOptionError, match=r"\.mp4"):
        VideoWriter(tmp_path / "v.avi", fps=10)
    with pytest.raises(InvalidOptionError, match="frame rate"):
        VideoWriter(out, fps=-1)
    with pytest.raises(InvalidOptionError, match="uint8"):
        VideoWriter(out, fps=10).write(np.zeros((8, 8, 3), np.float32))
