"""Reading and writing images, disparity maps, road labels and KITTI calibration; atomic writes.

Conventions (the same in the whole package):

* images are ``H×W×3 uint8`` RGB (colour files) or ``H×W uint8`` (grey files) in memory;
* a disparity map is ``float32 H×W`` in pixels, NaN for "no value";
* a road label is a pair of ``bool H×W`` arrays: ``road`` and ``valid`` (``valid`` False = don't care);
* every writer writes to a temporary file beside the target and renames it, so a crash or a user
  mistake never leaves a partial output file.

Only NumPy and OpenCV are imported here.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from freespace.errors import CorruptFileError, InputFileError, InvalidOptionError, OutputError

PathLike = str | os.PathLike[str]

DISPARITY_SUFFIXES = (".png", ".npy", ".pfm")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".ppm", ".tif", ".tiff")  # what OpenCV reads and writes here

__all__ = [
    "DISPARITY_SUFFIXES",
    "IMAGE_SUFFIXES",
    "RoadLabel",
    "atomic_write_bytes",
    "atomic_write_text",
    "write_json",
    "read_image",
    "read_raw",
    "write_image",
    "encode_image",
    "read_disparity",
    "write_disparity",
    "read_road_label",
    "road_label_from_image",
    "road_label_to_kitti",
    "read_kitti_calib",
]


# ---------------------------------------------------------------------------------------------------
# atomic writes

_UMASK = os.umask(0)
os.umask(_UMASK)


def atomic_write_bytes(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then ``os.replace``).

    Parent folders are created. Returns the path written.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror}; choose a writable output folder") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600 files; outputs get the usual permissions
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise OutputError(f"cannot write {path}: {exc.strerror}; choose a writable output path") from None
        raise
    return path


def atomic_write_text(path: PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically. Returns the path written."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def write_json(path: PathLike, obj: Any) -> Path:
    """Write ``obj`` as indented JSON (NaN/inf are rejected: use None) atomically."""
    return atomic_write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")


# ---------------------------------------------------------------------------------------------------
# images


def _read_bytes(path: PathLike, what: str) -> bytes:
    path = Path(path)
    if not path.is_file():
        hint = "it is a folder, name a file" if path.is_dir() else "check the path"
        raise InputFileError(f"{what} not found: {path} ({hint})")
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InputFileError(f"cannot read {what} {path}: {exc.strerror}") from None


def _decode(path: PathLike, what: str, flags: int) -> np.ndarray:
    data = _read_bytes(path, what)
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


def _read_pfm(path: PathLike) -> np.ndarray:
    data = _read_bytes(path, "disparity")
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
        raise CorruptFileError(f"cannot decode disparity {path}: not a PFM file (bad header)") from None
    channels = 3 if header == b"PF" else 1
    dtype = "<f4" if scale < 0 else ">f4"
    count = width * height * channels
    if len(raw) < 4 * count:
        raise CorruptFileError(f"cannot decode disparity {path}: PFM data truncated "
                               f"({len(raw)} bytes for {width}×{height}×{channels} floats)")
    arr = np.frombuffer(raw, dtype=dtype, count=count).reshape(height, width, channels)
    if channels != 1:
        raise CorruptFileError(f"disparity {path} is a 3-channel PFM; expected a single-channel ('Pf') map")
    return np.flipud(arr[:, :, 0])  # PFM stores rows bottom to top


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
        _read_bytes(path, "disparity")
        try:
            arr = np.load(path, allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise CorruptFileError(f"cannot decode disparity {path}: {exc}") from None
        if arr.ndim != 2 or not np.issubdtype(arr.dtype, np.number):
            raise CorruptFileError(f"disparity {path} holds a {arr.dtype} array of shape {arr.shape}; "
                                   f"expected a 2-D float array")
        return _invalid_to_nan(arr)
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
        import io as _io

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
    """
    return road_label_from_image(read_image(path, what="road label"))


def road_label_from_image(img: np.ndarray) -> RoadLabel:
    """Decode a road label image already in memory (RGB or grey); see :func:`read_road_label`."""
    if img.ndim == 3 and not (np.array_equal(img[:, :, 0], img[:, :, 1])
                              and np.array_equal(img[:, :, 1], img[:, :, 2])):
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
        if key.startswith("P") and arr.size == 12 or key.startswith("Tr") and arr.size == 12:
            arr = arr.reshape(3, 4)
        elif key.startswith("R") and arr.size == 9:
            arr = arr.reshape(3, 3)
        calib[key] = arr
    if "P2" not in calib:
        raise CorruptFileError(f"calibration file {path} has no P2 line; expected a KITTI calibration file")
    return calib
