"""Reading and writing images, disparity and depth maps, road labels and KITTI calibration; atomic writes.

Conventions (the same in the whole package):

* images are ``H×W×3 uint8`` RGB (colour files) or ``H×W uint8`` (grey files) in memory;
* a disparity map is ``float32 H×W`` in pixels, NaN for "no value";
* a road label is a pair of ``bool H×W`` arrays: ``road`` and ``valid`` (``valid`` False = don't care);
  as a class map (training, losses) it is 1 road, 0 non-road, :data:`IGNORE_INDEX` (255) don't care;
* every writer writes to a temporary file beside the target and renames it, so a crash or a user
  mistake never leaves a partial output file.

Only NumPy and OpenCV are imported here.
"""

from __future__ import annotations

import csv
import io as _io
import json
import math
import os
import re
import tempfile
import zlib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, OutputError, ShapeMismatchError

PathLike = str | os.PathLike[str]

DISPARITY_SUFFIXES = (".png", ".npy", ".pfm")
DEPTH_SUFFIXES = (".png", ".npy", ".pfm")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".ppm", ".tif", ".tiff")  # what OpenCV reads and writes here

#: the largest image side (pixels) a network is trained or run at: bounds sizes read from options and files
MAX_IMAGE_SIDE = 8192

#: the class id of don't-care pixels in label class maps (losses ignore it, metrics skip it)
IGNORE_INDEX = 255

__all__ = [
    "IGNORE_INDEX",
    "MAX_IMAGE_SIDE",
    "DISPARITY_SUFFIXES",
    "IMAGE_SUFFIXES",
    "RoadLabel",
    "atomic_write_bytes",
    "write_files_together",
    "atomic_write_text",
    "encode_json",
    "write_json",
    "write_csv",
    "read_image",
    "read_raw",
    "write_image",
    "encode_image",
    "read_disparity",
    "write_disparity",
    "read_depth",
    "read_road_label",
    "road_label_from_image",
    "road_label_to_kitti",
    "read_kitti_calib",
    "check_outputs",
    "missing_input",
    "check_writable",
    "check_writable_files",
]


# ---------------------------------------------------------------------------------------------------
# atomic writes

_UMASK = os.umask(0)
os.umask(_UMASK)


def atomic_write_bytes(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then ``os.replace``).

    Parent folders are created. Returns the path written.
    """
    return write_files_together({path: data})[0]


def write_files_together(files: Mapping[PathLike, bytes]) -> list[Path]:
    """Write several output files all or nothing: each goes to a temporary file beside its target, and
    only when every one is written are they renamed into place. When any write fails, the temporary
    files are removed and every earlier file at the targets is left as it was.

    Returns the paths written.
    """
    staged: list[tuple[str, Path]] = []
    try:
        for target, data in files.items():
            target = Path(target)
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
            except OSError as exc:
                raise OutputError(f"cannot write {target}: {exc.strerror}; choose a writable output path") from None
            staged.append((tmp, target))
            try:
                with os.fdopen(fd, "wb") as f:
                    f.write(data)
                os.chmod(tmp, 0o666 & ~_UMASK)
            except OSError as exc:
                raise OutputError(f"cannot write {target}: {exc.strerror}; choose a writable output path") from None
        for tmp, target in staged:
            os.replace(tmp, target)
    except BaseException:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        raise
    return [target for _, target in staged]


def atomic_write_text(path: PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically. Returns the path written."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def encode_json(obj: Any) -> bytes:
    """``obj`` as the bytes of an indented UTF-8 JSON file (NaN/inf are rejected: use None)."""
    return (json.dumps(obj, indent=2, allow_nan=False) + "\n").encode("utf-8")


def check_writable(path: PathLike, flag: str = "--out", *, folder: bool = False) -> Path:
    """Refuse, before any work, an output that cannot be written where it is named.

    Args:
        path: the output file (``folder=False``) or folder (``folder=True``); it need not exist.
        flag: the option that named it, for the message.

    Raises :class:`InvalidOptionError` when ``path`` is a folder where a file is wanted or a file where a
    folder is, and :class:`OutputError` when a folder on the way to it is a file, or the nearest existing
    folder is not writable (folders on the way are created by the writers). Nothing is created.
    """
    path = Path(os.path.expanduser(os.fspath(path)))
    if folder and path.exists() and not path.is_dir():
        raise InvalidOptionError(f"{flag} {path} is a file; give a folder")
    if not folder and path.is_dir():
        raise InvalidOptionError(f"{flag} {path} is a folder; give a file name")
    existing = path.absolute().parent
    while not existing.exists() and not existing.is_symlink() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"cannot write {flag} {path}: {existing} is a file, not a folder; choose another path")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write {flag} {path}: no permission to write in {existing}; choose a writable "
                          f"folder")
    return path


def check_writable_files(outputs: Mapping[str, PathLike | None]) -> None:
    """:func:`check_writable` for every output file given (option → path; None = not given), before any
    input is read."""
    for flag, path in outputs.items():
        if path is not None:
            check_writable(path, flag)


def write_json(path: PathLike, obj: Any) -> Path:
    """Write ``obj`` as indented JSON (NaN/inf are rejected: use None) atomically."""
    return atomic_write_bytes(path, encode_json(obj))


def check_outputs(outputs: dict[str, PathLike | None], inputs: dict[str, PathLike | None]) -> None:
    """Refuse outputs that would overwrite or land among a command's inputs, before any work.

    Args:
        outputs: option name → output path (file or folder; None = not given).
        inputs: option name → input path (file or folder; None = not given).

    Raises :class:`InvalidOptionError` when an output is an input, lies inside an input folder, or is a
    folder that holds an input, or when two outputs are the same path. Symbolic links are resolved
    first, so a link to an input counts as the input.
    """
    def real(p: PathLike) -> Path:
        return Path(os.path.realpath(os.path.expanduser(os.fspath(p))))

    outs = {k: real(v) for k, v in outputs.items() if v is not None}
    ins = {k: real(v) for k, v in inputs.items() if v is not None}
    for out_name, out in outs.items():
        for in_name, src in ins.items():
            if out == src:
                raise InvalidOptionError(f"{out_name} {out} is the input {in_name}; the command would overwrite "
                                         f"it: choose another output path")
            if out.is_relative_to(src):
                raise InvalidOptionError(f"{out_name} {out} lies inside the input {in_name} {src}; choose an "
                                         f"output outside the input folder")
            if src.is_relative_to(out):
                raise InvalidOptionError(f"the input {in_name} {src} lies inside {out_name} {out}; choose an "
                                         f"output folder that holds no input")
    seen: dict[Path, str] = {}
    for out_name, out in outs.items():
        if out in seen:
            raise InvalidOptionError(f"{out_name} and {seen[out]} are the same path {out}; give two paths")
        seen[out] = out_name


def write_csv(path: PathLike, fields: Sequence[str], rows: Iterable[Mapping[str, Any]],
              extra: Literal["raise", "ignore"] = "raise") -> Path:
    """Write ``rows`` (dicts) as a CSV file with the header ``fields``, atomically.

    Values are written with ``str`` (missing keys as empty cells), lines end with ``\n``. ``extra``: what a
    key outside ``fields`` does — ``"raise"`` (ValueError, a programming error) or ``"ignore"``.
    """
    buf = _io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(fields), extrasaction=extra, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return atomic_write_text(path, buf.getvalue())


# ---------------------------------------------------------------------------------------------------
# images


def missing_input(path: PathLike, what: str, kind: Literal["file", "folder"] = "file") -> InputFileError:
    """The one-line error for an input ``path`` that is not the ``kind`` asked for: that it is a folder
    where a file is wanted (or the other way round), else that it is not found. ``what`` names it
    ("checkpoint", "ground-truth folder", ...)."""
    path = Path(path)
    if kind == "file" and path.is_dir():
        return InputFileError(f"{what} {path} is a folder; name a file")
    if kind == "folder" and path.exists():
        return InputFileError(f"{what} {path} is a file; give a folder")
    return InputFileError(f"{what} not found: {path}")


def _read_bytes(path: PathLike, what: str) -> bytes:
    path = Path(path)
    if not path.is_file():
        hint = "it is a folder, name a file" if path.is_dir() else "check the path"
        raise InputFileError(f"{what} not found: {path} ({hint})")
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputFileError(f"cannot read {what} {path}: {exc.strerror}") from None


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_damage(data: bytes) -> str | None:
    """What is wrong with a damaged PNG file — cut short, or a critical chunk whose CRC does not match —
    found before decoding (libpng would print its own complaint to stderr); None for a sound PNG or
    another format."""
    if not data.startswith(_PNG_SIGNATURE):
        return None
    view, pos = memoryview(data), len(_PNG_SIGNATURE)
    while pos + 12 <= len(data):
        length = int.from_bytes(view[pos:pos + 4], "big")
        kind = bytes(view[pos + 4:pos + 8])
        name = kind.decode("ascii") if kind.isalpha() else repr(kind)  # crafted types stay on one line
        end = pos + 12 + length
        if end > len(data):
            return f"cut short in its {name} chunk"
        critical = kind[:1].isupper()  # ancillary chunks with a bad CRC are skipped by libpng
        if critical and zlib.crc32(view[pos + 4:end - 4]) != int.from_bytes(view[end - 4:end], "big"):
            return f"its {name} chunk is damaged (CRC mismatch)"
        if kind == b"IEND":
            return None
        pos = end
    return "cut short (no IEND chunk)"


def _decode(path: PathLike, what: str, flags: int) -> np.ndarray:
    data = _read_bytes(path, what)
    damage = _png_damage(data)
    if damage is not None:
        raise CorruptFileError(f"cannot decode {what} {path}: a damaged PNG file ({damage})")
    img = cv2.imdecode(np.frombuffer(data, np.uint8), flags) if data else None
    if img is None:
        raise CorruptFileError(f"cannot decode {what} {path}: not a readable image file (empty, truncated or "
                               f"another format)")
    return img


def read_raw(path: PathLike, *, what: str = "image") -> np.ndarray:
    """Decode an image file as stored: 8 or 16 bits, 1–4 channels (colour channels in RGB order).

    For label ids and depth maps, whose values must not be converted.
    """
    img = _decode(path, what, cv2.IMREAD_UNCHANGED)
    if img.ndim == 3 and img.shape[2] >= 3:
        img = img[:, :, [2, 1, 0] + list(range(3, img.shape[2]))]
    return img


def read_image(path: PathLike, *, what: str = "image") -> np.ndarray:
    """Read an image file.

    Returns:
        ``H×W×3 uint8`` RGB for colour files (alpha dropped), ``H×W uint8`` for grey files.
        16-bit files are scaled to 8 bits.

    Raises:
        InputFileError: the file is missing or unreadable. CorruptFileError: it is not an image.
    """
    img = _decode(path, what, cv2.IMREAD_UNCHANGED)
    if img.dtype == np.uint16:
        img = (img.astype(np.uint32) * 255 // 65535).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise CorruptFileError(f"{what} {path} has pixel type {img.dtype}; expected an 8- or 16-bit image")
    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[:, :, :3]
        if img.shape[2] == 1:
            img = img[:, :, 0]
        else:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(img)


def encode_image(image: np.ndarray, suffix: str = ".png") -> bytes:
    """Encode an ``H×W×3`` RGB or ``H×W`` grey uint8 (or uint16 grey, PNG only) image to file bytes."""
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(suffix, image)
    if not ok:
        raise InvalidOptionError(f"cannot encode an image as {suffix!r}; use .png or .jpg")
    return buf.tobytes()


def write_image(path: PathLike, image: np.ndarray) -> Path:
    """Write an RGB or grey uint8 image atomically; the format follows the suffix (PNG recommended)."""
    path = Path(path)
    return atomic_write_bytes(path, encode_image(image, path.suffix.lower() or ".png"))


# ---------------------------------------------------------------------------------------------------
# disparity


def _invalid_to_nan(disp: np.ndarray) -> np.ndarray:
    disp = disp.astype(np.float32, copy=True)
    disp[~np.isfinite(disp) | (disp <= 0)] = np.nan
    return disp


def _read_pfm(path: PathLike, what: str = "disparity") -> np.ndarray:
    data = _read_bytes(path, what)
    try:
        header, rest = data.split(b"\n", 1)
        dims, rest = rest.split(b"\n", 1)
        scale_line, raw = rest.split(b"\n", 1)
        header = header.strip()
        if header not in (b"Pf", b"PF"):
            raise ValueError("bad magic")
        width, height = (int(x) for x in dims.split())
        scale = float(scale_line)
    except ValueError:
        raise CorruptFileError(f"cannot decode {what} {path}: not a PFM file (bad header)") from None
    if width < 1 or height < 1:
        raise CorruptFileError(f"cannot decode {what} {path}: its PFM header gives a size of {width}×{height} "
                               f"(W×H); both must be ≥ 1")
    if not (math.isfinite(scale) and scale != 0):
        raise CorruptFileError(f"cannot decode {what} {path}: its PFM scale is {scale}; it must be a finite, "
                               f"non-zero number (negative = little-endian)")
    channels = 3 if header == b"PF" else 1
    dtype = "<f4" if scale < 0 else ">f4"
    count = width * height * channels
    if len(raw) < 4 * count:
        raise CorruptFileError(f"cannot decode {what} {path}: PFM data truncated "
                               f"({len(raw)} bytes for {width}×{height}×{channels} floats)")
    arr = np.frombuffer(raw, dtype=dtype, count=count).reshape(height, width, channels)
    if channels != 1:
        raise CorruptFileError(f"{what} {path} is a 3-channel PFM; expected a single-channel ('Pf') map")
    return np.flipud(arr[:, :, 0])  # PFM stores rows bottom to top


def _read_npy_2d(path: Path, what: str, expected: str) -> np.ndarray:
    """A real-valued 2-D array from a ``.npy`` file (no pickles), or a one-line error naming ``what``."""
    _read_bytes(path, what)
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise CorruptFileError(f"cannot decode {what} {path}: {str(exc).splitlines()[0]}") from None
    if arr.ndim != 2 or not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise CorruptFileError(f"{what} {path} holds a {arr.dtype} array of shape {arr.shape}; expected {expected}")
    return arr


def read_disparity(path: PathLike) -> np.ndarray:
    """Read a disparity map.

    Formats, chosen by suffix: KITTI 16-bit PNG (``d = value / 256``, 0 = invalid), ``.npy`` (float,
    2-D) and ``.pfm`` (single channel).

    Returns:
        ``float32 H×W`` disparity in pixels; NaN where there is no value (0, negative, NaN or inf in
        the file).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".png":
        raw = _decode(path, "disparity", cv2.IMREAD_UNCHANGED)
        if raw.dtype != np.uint16 or raw.ndim != 2:
            raise CorruptFileError(f"disparity {path} is a {raw.dtype} image with shape {raw.shape}; expected a "
                                   f"KITTI disparity PNG (16-bit, one channel, d = value/256)")
        return _invalid_to_nan(raw.astype(np.float32) / 256.0)
    if suffix == ".npy":
        return _invalid_to_nan(_read_npy_2d(path, "disparity", "a 2-D float array"))
    if suffix == ".pfm":
        return _invalid_to_nan(_read_pfm(path))
    raise InvalidOptionError(f"unknown disparity format {suffix!r} for {path}; use one of "
                             f"{', '.join(DISPARITY_SUFFIXES)}")


def write_disparity(path: PathLike, disparity: np.ndarray) -> Path:
    """Write a ``float H×W`` disparity map (NaN = invalid) atomically, format by suffix.

    PNG is KITTI's 16-bit format (values clipped to [0, 255.996], invalid → 0); ``.npy`` and ``.pfm``
    keep float32 with NaN for invalid.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    disp = np.asarray(disparity, dtype=np.float32)
    if disp.ndim != 2:
        raise InvalidOptionError(f"disparity must be 2-D (H×W), got shape {disp.shape}")
    if suffix == ".png":
        valid = np.isfinite(disp) & (disp > 0)
        raw = np.zeros(disp.shape, np.uint16)
        raw[valid] = np.clip(np.round(disp[valid] * 256.0), 1, 65535).astype(np.uint16)
        return atomic_write_bytes(path, encode_image(raw, ".png"))
    if suffix == ".npy":
        buf = _io.BytesIO()
        np.save(buf, disp)
        return atomic_write_bytes(path, buf.getvalue())
    if suffix == ".pfm":
        h, w = disp.shape
        header = f"Pf\n{w} {h}\n-1.0\n".encode("ascii")
        return atomic_write_bytes(path, header + np.flipud(disp).astype("<f4").tobytes())
    raise InvalidOptionError(f"unknown disparity format {suffix!r} for {path}; use one of "
                             f"{', '.join(DISPARITY_SUFFIXES)}")


# ---------------------------------------------------------------------------------------------------
# depth


def read_depth(path: PathLike, *, png_scale: float = 0.001,
               shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a depth map (distance along the camera's optical axis, Z).

    Formats, chosen by suffix:

    * ``.png``: SNE-RoadSeg's ``depth_u16`` — 16-bit, one channel, ``Z = value · png_scale`` (default
      millimetres: 0.001 m per unit); 0 and 65535 mean "no depth" (65535 is where an interpolation
      saturated).
    * ``.npy`` (2-D numeric array) and ``.pfm`` (single channel): float depth in metres.

    Args:
        path: the depth file.
        png_scale: metres per stored unit of a PNG (> 0); float files are always metres.
        shape: ``(H, W)`` the map must have (e.g. its image's), or None not to check.

    Returns:
        ``float32 H×W`` depth in metres; NaN where there is no value (0/65535 in a PNG; ≤ 0, NaN or
        inf in a float file).

    Raises:
        InputFileError: missing or unreadable file. CorruptFileError: not a depth map of a known kind
        (an 8-bit or colour PNG, a non-2-D array, a truncated file). ShapeMismatchError: not ``shape``.
        InvalidOptionError: an unknown suffix or a bad ``png_scale``.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if not (math.isfinite(png_scale) and png_scale > 0):
        raise InvalidOptionError(f"the depth PNG scale must be a positive number of metres per unit, got {png_scale}")
    if suffix == ".png":
        raw = _decode(path, "depth", cv2.IMREAD_UNCHANGED)
        if raw.dtype != np.uint16 or raw.ndim != 2:
            bits = "8-bit" if raw.dtype == np.uint8 else str(raw.dtype)
            chans = 1 if raw.ndim == 2 else raw.shape[2]
            raise CorruptFileError(f"depth {path} is a {bits} image with {chans} channel(s); expected a 16-bit "
                                   f"one-channel depth PNG (depth_u16: millimetres, 0 = none)")
        depth = raw.astype(np.float32) * np.float32(png_scale)
        depth[(raw == 0) | (raw == 65535)] = np.nan
    elif suffix == ".npy":
        depth = _invalid_to_nan(_read_npy_2d(path, "depth", "a 2-D float array in metres"))
    elif suffix == ".pfm":
        depth = _invalid_to_nan(_read_pfm(path, "depth"))
    else:
        raise InvalidOptionError(f"unknown depth format {suffix!r} for {path}; use one of {', '.join(DEPTH_SUFFIXES)}")
    if shape is not None and depth.shape != tuple(shape):
        raise ShapeMismatchError(f"depth {path} is {depth.shape[1]}×{depth.shape[0]} but its image is "
                                 f"{shape[1]}×{shape[0]} (W×H); use the depth map of this frame")
    return depth


# ---------------------------------------------------------------------------------------------------
# road labels


@dataclass(frozen=True)
class RoadLabel:
    """A road label: ``road`` and ``valid`` are ``bool H×W``; ``valid`` False marks don't-care pixels."""

    road: np.ndarray
    valid: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.road.shape  # type: ignore[return-value]


def read_road_label(path: PathLike) -> RoadLabel:
    """Read a road label.

    Two encodings are accepted:

    * KITTI road colour ground truth (``gt_image_2/*_road_*.png``): road = magenta (255, 0, 255),
      non-road = red (255, 0, 0), black = don't care. As in the official devkit, road = blue > 0 and
      evaluated (valid) = red > 0.
    * single-channel masks (or colour files whose three channels are equal): non-zero = road, every
      pixel valid.

    A colour file that is black everywhere is KITTI ground truth with every pixel don't care (no pixel
    is evaluated); a single-channel file of zeros is a mask without road.
    """
    return road_label_from_image(read_image(path, what="road label"))


def road_label_from_image(img: np.ndarray) -> RoadLabel:
    """Decode a road label image already in memory (RGB or grey); see :func:`read_road_label`.

    A colour (``H×W×3``) image that is black everywhere is KITTI ground truth with every pixel don't care
    (``valid`` all False), not a mask without road: KITTI marks non-road red, never black.
    """
    if img.ndim == 3 and (not (np.array_equal(img[:, :, 0], img[:, :, 1])
                               and np.array_equal(img[:, :, 1], img[:, :, 2])) or not img.any()):
        red, blue = img[:, :, 0], img[:, :, 2]
        road = blue > 0
        return RoadLabel(road=road & (red > 0), valid=red > 0)
    grey = img if img.ndim == 2 else img[:, :, 0]
    road = grey > 0
    return RoadLabel(road=road, valid=np.ones_like(road))


def road_label_to_kitti(label: RoadLabel) -> np.ndarray:
    """Encode a :class:`RoadLabel` as a KITTI colour ground truth image (``H×W×3 uint8`` RGB)."""
    out = np.zeros(label.road.shape + (3,), np.uint8)
    out[label.valid, 0] = 255
    out[label.valid & label.road, 2] = 255
    return out


# ---------------------------------------------------------------------------------------------------
# KITTI calibration


def read_kitti_calib(path: PathLike) -> dict[str, np.ndarray]:
    """Parse a KITTI calibration text file (``KEY: v1 v2 ...`` lines).

    Returns:
        A dict of float64 arrays: ``P0``–``P3`` are 3×4, ``R0_rect`` (or ``R_rect``) 3×3, ``Tr_*`` 3×4;
        other keys keep their flat values.
    """
    text = _read_bytes(path, "calibration file").decode("utf-8", errors="replace")
    calib: dict[str, np.ndarray] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        key, sep, values = line.partition(":")
        try:
            if not sep:
                raise ValueError
            arr = np.array([float(x) for x in values.split()], dtype=np.float64)
        except ValueError:
            raise CorruptFileError(f"calibration file {path} line {lineno} is not 'KEY: numbers'") from None
        key = key.strip()
        if not np.isfinite(arr).all():
            raise CorruptFileError(f"calibration file {path}: {key} has a value that is not finite (NaN or inf)")
        if re.fullmatch(r"P\d|Tr_\w+", key):
            if arr.size != 12:
                raise CorruptFileError(f"calibration file {path}: {key} has {arr.size} numbers, a 3×4 matrix "
                                       f"needs 12")
            arr = arr.reshape(3, 4)
        elif re.fullmatch(r"R0?_rect", key):
            if arr.size != 9:
                raise CorruptFileError(f"calibration file {path}: {key} has {arr.size} numbers, a 3×3 matrix "
                                       f"needs 9")
            arr = arr.reshape(3, 3)
        calib[key] = arr
    if "P2" not in calib:
        raise CorruptFileError(f"calibration file {path} has no P2 line; expected a KITTI calibration file")
    for key in [k for k in calib if k.startswith("Tr_")] + [k for k in ("R0_rect", "R_rect") if k in calib]:
        rotation = calib[key][:, :3]
        if abs(np.linalg.det(rotation)) < 1e-6:
            raise CorruptFileError(f"calibration file {path}: {key} is singular (its rotation part has "
                                   f"determinant {np.linalg.det(rotation):.1e}); expected a rigid transform")
    if abs(np.linalg.det(calib["P2"][:, :3])) < 1e-9:
        raise CorruptFileError(f"calibration file {path}: P2 is singular; expected a camera projection matrix")
    return calib
