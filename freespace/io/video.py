"""Frames in, video out: read a video file, a folder of images or a glob frame by frame; write MP4s.

Reading decodes one frame at a time (a generator): memory does not grow with the length of the video.
Writing goes to a temporary file beside the target, renamed into place when the writer is closed
without error, so an interrupted run never leaves a partial video.

Conventions: frames are ``H×W×3 uint8`` RGB in memory (grey images are repeated to three channels).
Only NumPy and OpenCV (whose wheels include FFmpeg) are imported here; never torch.

Example::

    from freespace.io.video import open_frames, VideoWriter

    source = open_frames("drive.mp4")                  # or "frames/" or "frames/*.png"
    with VideoWriter("out.mp4", fps=source.fps) as out:
        for frame in source:                           # VideoFrame(index, name, image)
            out.write(frame.image)
"""

from __future__ import annotations

import contextlib
import glob as _glob
import math
import os
import re
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, OutputError, ShapeMismatchError
from freespace.io.codecs import IMAGE_SUFFIXES, check_image_pixels, read_image
from freespace.io.files import PathLike, keep_mode, mark_written, missing_input, replaceable, unicode_name

__all__ = ["VideoFrame", "FrameSource", "VideoWriter", "open_frames", "is_video_path", "is_image_path",
           "IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "DEFAULT_FPS"]

#: the suffixes of the files decoded as videos (FFmpeg), an animated GIF among them; still images are
#: :data:`IMAGE_SUFFIXES` (PNG, JPEG, PGM, …), and a file of any other suffix is refused, never guessed at
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg", ".wmv", ".ts", ".m2ts", ".mts",
                  ".y4m", ".flv", ".3gp", ".ogv", ".mjpeg", ".mjpg", ".h264", ".h265", ".hevc", ".gif")
DEFAULT_FPS = 10.0
"""Frame rate given to folders and globs of images (KITTI's cameras run at 10 Hz)."""

_GLOB_CHARS = re.compile(r"[*?\[]")


@contextlib.contextmanager
def _quiet_opencv() -> Iterator[None]:
    """Silence OpenCV's and FFmpeg's own console messages while a capture or writer opens: a failure
    becomes one typed error line instead of backend warnings. ``OPENCV_FFMPEG_LOGLEVEL`` set by the
    user wins (it is only defaulted to quiet)."""
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
    cv_log = getattr(getattr(cv2, "utils", None), "logging", None)
    old = cv_log.getLogLevel() if cv_log is not None else None
    if cv_log is not None:
        cv_log.setLogLevel(cv_log.LOG_LEVEL_ERROR)
    try:
        yield
    finally:
        if cv_log is not None:
            cv_log.setLogLevel(old)


@contextlib.contextmanager
def _opencv_name(path: Path, *, folder: bool = False) -> Iterator[str]:
    """A name under which OpenCV opens ``path`` (``folder``: a file in the folder ``path``, the name's last part
    to be added): ``path`` itself, or, when it is no valid Unicode (a file name of bytes that are not UTF-8, which
    Python holds as surrogates and OpenCV's Python binding crashes on), a symbolic link of a plain name to it in a
    temporary folder, there while the ``with`` block lasts (open the capture or writer inside it: FFmpeg keeps the
    file open, not its name)."""
    name = os.fspath(path)
    if unicode_name(name):
        yield name
        return
    suffix = "" if folder else "".join(c for c in path.suffix if c.isascii() and (c.isalnum() or c == "."))
    with tempfile.TemporaryDirectory(prefix="freespace-") as tmp:
        link = os.path.join(tmp, ("folder" if folder else "input") + suffix)
        os.symlink(os.path.abspath(name), link)
        yield link


def _natural_key(path: Path) -> list[object]:
    """Sort key that orders ``frame_2`` before ``frame_10`` (digit runs compare as numbers)."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path.name)]


def is_video_path(path: PathLike) -> bool:
    """True when ``path`` names a file with a video suffix (:data:`VIDEO_SUFFIXES`)."""
    return Path(path).suffix.lower() in VIDEO_SUFFIXES


def is_image_path(path: PathLike) -> bool:
    """True when ``path`` names a file with a still-image suffix (:data:`IMAGE_SUFFIXES`)."""
    return Path(path).suffix.lower() in IMAGE_SUFFIXES


def _rgb(image: np.ndarray) -> np.ndarray:
    if image.ndim == 2:
        return np.repeat(image[:, :, None], 3, axis=2)
    return image


@dataclass(frozen=True)
class VideoFrame:
    """One decoded frame.

    Attributes:
        index: 0-based position in the source.
        name: a file-name stem for per-frame outputs: the image's stem (folder/glob), unique within the
            source letter case aside, or ``<video stem>_<index, 6 digits>`` (video).
        image: ``H×W×3 uint8`` RGB.
    """

    index: int
    name: str
    image: np.ndarray


@dataclass(frozen=True)
class FrameSource:
    """A sequence of frames, decoded lazily. Iterating it yields :class:`VideoFrame` one at a time
    (a fresh generator each time; only the current frame is held).

    Attributes:
        kind: ``"video"``, ``"folder"``, ``"glob"`` or ``"image"``.
        spec: what the user gave (path or pattern).
        paths: the input files (the video, or the images in order) — e.g. to refuse an output that
            would overwrite an input.
        fps: the video's frame rate, or the default for images.
        size: ``(H, W)`` of the first frame.
        count: number of frames for images; for a video the container's count (may be an estimate).
    """

    kind: str
    spec: str
    paths: tuple[Path, ...]
    fps: float
    size: tuple[int, int]
    count: int

    def __iter__(self) -> Iterator[VideoFrame]:
        return self._video_frames() if self.kind == "video" else self._image_frames()

    def __len__(self) -> int:
        return self.count

    def _image_frames(self) -> Iterator[VideoFrame]:
        for i, path in enumerate(self.paths):
            yield VideoFrame(i, path.stem, _rgb(read_image(path, what="frame")))

    def _video_frames(self) -> Iterator[VideoFrame]:
        path = self.paths[0]
        cap = _open_capture(path)
        try:
            i = 0
            while True:
                ok, bgr = cap.read()
                if not ok:
                    break
                yield VideoFrame(i, f"{path.stem}_{i:06d}", cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
                i += 1
        finally:
            cap.release()


def _open_capture(path: Path) -> cv2.VideoCapture:
    with _quiet_opencv(), _opencv_name(path) as name:
        cap = cv2.VideoCapture(name, cv2.CAP_FFMPEG)
    if not cap.isOpened():
        cap.release()
        raise CorruptFileError(f"cannot decode video {path}: not a video file OpenCV/FFmpeg can read (corrupt, "
                               f"truncated or an unsupported codec)")
    # frames upright, as images are read: a phone's video turned by its rotation metadata (OpenCV's default)
    cap.set(cv2.CAP_PROP_ORIENTATION_AUTO, 1)
    try:  # the size its stream states, before a frame is decoded
        check_image_pixels(int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)),
                           f"the frames of video {path}")
    except CorruptFileError:
        cap.release()
        raise
    return cap


def _probe_video(path: Path, default_fps: float) -> FrameSource:
    cap = _open_capture(path)
    try:
        ok, bgr = cap.read()
        if not ok or bgr is None:
            raise CorruptFileError(f"video {path} has no frames that can be decoded")
        fps = float(cap.get(cv2.CAP_PROP_FPS))
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        cap.release()
    if not (math.isfinite(fps) and 0 < fps < 1000):
        fps = default_fps
    return FrameSource("video", str(path), (path,), fps, bgr.shape[:2], max(count, 1))


def _image_source(kind: str, spec: str, paths: list[Path], fps: float) -> FrameSource:
    _refuse_name_clash(spec, paths)
    first = _rgb(read_image(paths[0], what="frame"))
    return FrameSource(kind, spec, tuple(paths), fps, first.shape[:2], len(paths))


def _refuse_name_clash(spec: str, paths: list[Path]) -> None:
    """Refuse images whose frame names (:attr:`VideoFrame.name`, the file stem) are one name, letter case
    aside (``a.png`` and ``a.jpg``, ``a.PNG`` and ``A.png``): their outputs (``<name>.png``) would be one file.

    Raises:
        InputFileError: naming the two files.
    """
    seen: dict[str, Path] = {}
    for path in paths:
        other = seen.setdefault(path.stem.casefold(), path)
        if other is not path:
            raise InputFileError(f"{spec}: {other} and {path} give one frame name {path.stem!r} (outputs are named "
                                 f"by the file name without its suffix, letter case aside); rename or move one of "
                                 f"them, or narrow the input")


def open_frames(source: PathLike, *, fps: float | None = None, default_fps: float = DEFAULT_FPS) -> FrameSource:
    """Open a video file, a folder of images, one image, or a glob of images as a :class:`FrameSource`.

    What ``source`` names, in this order: an existing folder (its images, :data:`IMAGE_SUFFIXES`, in
    natural order: ``2.png`` before ``10.png``); an existing image file (one frame); an existing video file
    (:data:`VIDEO_SUFFIXES`, decoded with FFmpeg); otherwise a glob pattern (``*``, ``?``, ``[``; its image files
    in natural order). A file is an image or a video by its suffix; one of neither is refused. The first frame is
    decoded here, so an unreadable source fails now.

    Images are read upright (their EXIF orientation applied, :func:`freespace.io.codecs.read_image`); an image
    file that holds several (an animated WebP or PNG, a multi-page TIFF) is refused when it is read, with how many
    it holds: split it into one file per frame (an animated GIF is a video here).

    Args:
        source: path or glob pattern.
        fps: frame rate to report instead of the source's own (> 0), or None.
        default_fps: frame rate of folders, globs and videos that do not state one (> 0).

    Returns:
        The :class:`FrameSource` (iterate it for the frames).

    Raises:
        InputFileError: the path does not exist, the folder has no images, the glob matches no image, a file
            has neither an image nor a video suffix, or two of its images give one frame name (``a.png`` and
            ``a.jpg``; letter case aside).
        CorruptFileError: the video cannot be decoded or has no frames; the first image is not an image, or holds
            several.
        InvalidOptionError: a frame rate ≤ 0.
    """
    for name, value in (("fps", fps), ("default fps", default_fps)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InvalidOptionError(f"the {name} must be a positive number of frames per second, got {value}")
    spec = os.fspath(source)
    path = Path(spec)
    if path.is_dir():
        paths = sorted((p for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES
                        and not p.name.startswith(".")), key=_natural_key)
        if not paths:
            raise InputFileError(f"folder {path} holds no images ({', '.join(IMAGE_SUFFIXES)}); name a video, a "
                                 f"folder of frames or a glob such as 'frames/*.png'")
        src = _image_source("folder", spec, paths, default_fps)
    elif path.is_file():
        if is_image_path(path):
            src = _image_source("image", spec, [path], default_fps)
        elif is_video_path(path):
            src = _probe_video(path, default_fps)
        else:  # decided by the suffix, never by what FFmpeg makes of it (it decodes a PGM as a one-frame video)
            raise InputFileError(f"input {path} is no image freespace reads ({', '.join(IMAGE_SUFFIXES)}) and no "
                                 f"video FFmpeg decodes ({', '.join(VIDEO_SUFFIXES)}): its suffix "
                                 f"{path.suffix or '(none)'} is neither; convert it to such images or to an MP4 "
                                 f"video (or give it the suffix of its format)")
    elif path.exists():  # a named pipe, socket or device: never opened (a pipe would block)
        raise missing_input(path, "input")
    elif _GLOB_CHARS.search(spec):
        paths = sorted((Path(p) for p in _glob.glob(spec)
                        if Path(p).is_file() and Path(p).suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)
        if not paths:
            raise InputFileError(f"no image file matches {spec!r} ({', '.join(IMAGE_SUFFIXES)}); check the pattern "
                                 f"(quote it so the shell does not expand it)")
        src = _image_source("glob", spec, paths, default_fps)
    else:
        raise InputFileError(f"input not found: {path} (name a video file, a folder of frames or a glob)")
    if fps is not None:
        src = FrameSource(src.kind, src.spec, src.paths, float(fps), src.size, src.count)
    return src


class VideoWriter:
    """Write ``H×W×3 uint8`` RGB frames to an MP4 file (MPEG-4 Part 2, fourcc ``mp4v``) atomically.

    The frames go to a hidden temporary file in the target's folder; :meth:`close` (or leaving the
    ``with`` block normally) renames it to ``path``. An exception inside the ``with`` block, or
    :meth:`abort`, deletes it: no partial video is ever left at ``path``.

    The frame size is fixed by the first frame. MPEG-4 needs even sizes: an odd width or height is
    padded by one replicated column or row (the video is then one pixel wider or taller); grey frames
    are repeated to three channels.

    Args:
        path: output file; its suffix must be ``.mp4``.
        fps: frames per second (> 0), e.g. :attr:`FrameSource.fps`.
    """

    def __init__(self, path: PathLike, fps: float) -> None:
        self.path = Path(path)
        if self.path.suffix.lower() != ".mp4":
            raise InvalidOptionError(f"video output {self.path} must end in .mp4")
        if not (math.isfinite(fps) and fps > 0):
            raise InvalidOptionError(f"the frame rate must be a positive number of frames per second, got {fps}")
        self.fps = float(fps)
        self.frames = 0
        self.size: tuple[int, int] | None = None  # (H, W) of the input frames
        self._writer: cv2.VideoWriter | None = None
        self._tmp: Path | None = None
        self._closed = False

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def _open(self, h: int, w: int) -> None:
        replaceable(self.path)  # no device, pipe or read-only file: before the first frame is encoded
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            stem = self.path.stem if self.path.stem.isprintable() and unicode_name(self.path.stem) else "video"
            fd, tmp = tempfile.mkstemp(dir=self.path.parent, prefix=f".{stem}.", suffix=".tmp.mp4")
            os.close(fd)
        except OSError as exc:
            raise OutputError(f"cannot write {self.path}: {exc.strerror}; choose a writable output folder") from None
        self._tmp = Path(tmp)
        with _quiet_opencv(), _opencv_name(self._tmp.parent, folder=True) as folder:
            writer = cv2.VideoWriter(os.path.join(folder, self._tmp.name), cv2.CAP_FFMPEG,
                                     cv2.VideoWriter_fourcc(*"mp4v"), self.fps, (w + w % 2, h + h % 2))
        if not writer.isOpened():
            self.abort()
            raise OutputError(f"cannot open an MP4 (mp4v) writer for {self.path}; this OpenCV build lacks FFmpeg "
                              f"video writing")
        self._writer = writer

    def write(self, image: np.ndarray) -> None:
        """Append one ``H×W×3`` RGB (or ``H×W`` grey) uint8 frame of the first frame's size."""
        if self._closed:
            raise InvalidOptionError(f"video {self.path} is already closed")
        img = _rgb(np.asarray(image))
        if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
            raise InvalidOptionError(f"video frames must be H×W×3 uint8 RGB, got {img.dtype} {img.shape}")
        h, w = img.shape[:2]
        if self.size is None:
            self.size = (h, w)
            self._open(h, w)
        elif self.size != (h, w):
            raise ShapeMismatchError(f"frame {self.frames} is {w}×{h} but the video {self.path} is "
                                     f"{self.size[1]}×{self.size[0]} (W×H); resize the frames to one size")
        bgr = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
        if h % 2 or w % 2:
            bgr = cv2.copyMakeBorder(bgr, 0, h % 2, 0, w % 2, cv2.BORDER_REPLICATE)
        self._writer.write(bgr)  # type: ignore[union-attr]
        self.frames += 1

    def close(self) -> Path:
        """Finish the file and move it to :attr:`path`. Returns the path written.

        Raises:
            InvalidOptionError: no frame was written (nothing is created). OutputError: the encoder
                produced no data or the rename failed.
        """
        if self._closed:
            return self.path
        if self._writer is None:
            self._closed = True
            raise InvalidOptionError(f"no frames to write to {self.path}")
        self._writer.release()
        self._writer = None
        tmp = self._tmp
        assert tmp is not None
        try:
            if tmp.stat().st_size == 0:
                raise OutputError(f"the MP4 encoder wrote nothing for {self.path}")
            keep_mode(tmp, replaceable(self.path))  # mkstemp makes 0600 files: a replaced file's mode, or 0666 & ~umask
            mark_written(tmp)
            os.replace(tmp, self.path)
        except OSError as exc:
            self.abort()
            raise OutputError(f"cannot write {self.path}: {exc.strerror}; choose a writable output path") from None
        except OutputError:
            self.abort()
            raise
        self._closed = True
        return self.path

    def abort(self) -> None:
        """Stop writing and delete the temporary file; :attr:`path` is left as it was."""
        if self._writer is not None:
            self._writer.release()
            self._writer = None
        if self._tmp is not None:
            self._tmp.unlink(missing_ok=True)
            self._tmp = None
        self._closed = True
