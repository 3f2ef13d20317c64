"""Codecs of the files the package reads and writes: images, disparity maps (png16/npy/pfm), depth maps
and road labels.

Conventions (the same in the whole package):

* images are ``H×W×3 uint8`` RGB (colour files) or ``H×W uint8`` (grey files) in memory;
* a disparity map is ``float32 H×W`` in pixels, NaN for "no value";
* a road label is a :class:`freespace.labels.RoadLabel` in memory;
* writers are atomic (:mod:`freespace.io.files`).

Only NumPy and OpenCV are imported here (and PyYAML by :func:`load_yaml`).
"""

from __future__ import annotations

import functools
import io as _io
import math
import warnings
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from freespace.errors import CorruptFileError, InvalidOptionError, ShapeMismatchError
from freespace.io.files import PathLike, atomic_write_bytes, read_bytes
from freespace.io.image_headers import (
    FORMATS,
    TIFF_SIGNATURES,
    frames_of,
    image_frame_count,
    image_header_size,
    image_orientation,
    png_damage,
    upright,
)
from freespace.labels import RoadLabel
from freespace.limits import MAX_IMAGE_FILE_BYTES, MAX_IMAGE_PIXELS

__all__ = ["load_yaml", "label_image_problem", "DISPARITY_SUFFIXES", "DEPTH_SUFFIXES", "IMAGE_SUFFIXES",
           "OUTPUT_IMAGE_SUFFIXES", "MAX_IMAGE_SIDE", "MIN_FRAME_SIDE", "read_image", "image_header_size",
           "image_orientation", "image_frame_count", "upright", "MultiFrameImageError", "check_image_pixels",
           "describe_image", "read_raw",
           "write_image", "encode_image", "read_disparity", "write_disparity", "png_disparity_overflow",
           "read_depth", "read_road_label",
           "road_label_from_image", "road_label_to_kitti"]

DISPARITY_SUFFIXES = (".png", ".npy", ".pfm")
DEPTH_SUFFIXES = (".png", ".npy", ".pfm")
#: the suffixes of the still-image files read here (frames, labels, right images): each one's content a format
#: whose header :func:`image_header_size` reads and OpenCV decodes; a folder's files of other suffixes are not
#: images to freespace (HDR and PFM files hold floats, not 8/16-bit images; ``.jp2`` and ``.avif`` are not read)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".ppm", ".pgm", ".pbm", ".pnm", ".pam", ".tif", ".tiff", ".webp",
                  ".ras", ".sr")
#: the suffixes of the image files written here (:func:`write_image`): what OpenCV encodes from any RGB or grey image
OUTPUT_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".ppm", ".tif", ".tiff", ".webp")

#: the largest image side (pixels) a network is trained or run at: bounds sizes read from options and files
MAX_IMAGE_SIDE = 8192
#: a frame's side at least (pixels): the smallest size a network trains at; a smaller image (a 1×1 icon) shows no road
MIN_FRAME_SIDE = 32

#: the file limit as the messages name it
_FILE_LIMIT = f"image file limit of {MAX_IMAGE_FILE_BYTES:,} bytes (MAX_IMAGE_FILE_BYTES)"
_PNG_DISPARITY_MAX = 65535  # the largest value of a KITTI disparity PNG: 255.996 px


def check_image_pixels(width: int, height: int, what: str) -> None:
    """Refuse (CorruptFileError, naming ``what`` and :data:`~freespace.limits.MAX_IMAGE_PIXELS`) an image of
    ``width × height`` pixels beyond the limit, before anything of that size is made."""
    if width * height > MAX_IMAGE_PIXELS:
        raise CorruptFileError(f"{what} is {width}×{height} pixels (W×H), {width * height:,} in all: more than the "
                               f"image limit of {MAX_IMAGE_PIXELS:,} pixels (MAX_IMAGE_PIXELS; 8K video's 7680×4320 "
                               f"fits); give a smaller image (or check the file: a crafted header?)")


class MultiFrameImageError(CorruptFileError):
    """An image file holds several images (an animated WebP, PNG or GIF, a multi-page TIFF), where one is read:
    refused rather than reduced to its first, with how many it holds (:func:`image_frame_count`). A command that
    skips unreadable frames (``adapt``) refuses it all the same: it is no damaged file but a sequence to split."""


def _tiff_probe(orientation: int) -> bytes:
    """A 3×2 (W×H) grey 8-bit uncompressed TIFF of the pixels 1…6, row by row, tagged with ``orientation``."""
    tags = [(256, 3), (257, 2), (258, 8), (259, 1), (262, 1), (273, 8 + 2 + 11 * 12 + 4), (274, orientation),
            (277, 1), (278, 2), (279, 6), (284, 1)]
    ifd = len(tags).to_bytes(2, "little") + b"".join(
        tag.to_bytes(2, "little") + (3).to_bytes(2, "little") + (1).to_bytes(4, "little") + value.to_bytes(4, "little")
        for tag, value in tags)
    return b"II*\x00" + (8).to_bytes(4, "little") + ifd + b"\x00" * 4 + bytes(range(1, 7))


@functools.cache
def _tiff_decoder_orients(orientation: int) -> bool:
    """Whether OpenCV's TIFF decoder applies the TIFF ``orientation`` tag itself (OpenCV 5 does, even with
    ``IMREAD_UNCHANGED``, where other formats come as stored): found once by decoding a tiny tagged TIFF."""
    stored = np.arange(1, 7, dtype=np.uint8).reshape(2, 3)
    img = cv2.imdecode(np.frombuffer(_tiff_probe(orientation), np.uint8), cv2.IMREAD_UNCHANGED)
    return img is not None and not np.array_equal(img, stored)


def _decode(path: PathLike, what: str, flags: int) -> np.ndarray:
    """Decode the image file ``path`` upright (its EXIF orientation applied, :func:`upright`), after checking its
    header (a sound PNG, a format read here, within :data:`~freespace.limits.MAX_IMAGE_PIXELS`) and that it holds
    one image (an animated or multi-page file is refused: :func:`image_frame_count`)."""
    data = read_bytes(path, what, MAX_IMAGE_FILE_BYTES, _FILE_LIMIT)
    damage = png_damage(data)
    if damage is not None:
        raise CorruptFileError(f"cannot decode {what} {path}: a damaged PNG file ({damage})")
    size = image_header_size(data)
    if size is None:
        raise CorruptFileError(f"cannot decode {what} {path}: not a readable image file (empty, truncated or another "
                               f"format; read here: {FORMATS})")
    check_image_pixels(*size, f"{what} {path}")
    frames, kind = frames_of(data)
    if frames > 1:
        raise MultiFrameImageError(f"cannot read {what} {path}: it holds {frames} images ({kind}), and freespace "
                                   f"reads one image a file rather than take the first alone; split it into one "
                                   f"image file per frame (e.g. `magick FILE frame_%04d.png`) and give those")
    if flags != cv2.IMREAD_UNCHANGED:  # the orientation is applied here, once, whatever the flags
        flags |= cv2.IMREAD_IGNORE_ORIENTATION
    img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if img is None:
        raise CorruptFileError(f"cannot decode {what} {path}: not a readable image file (empty, truncated or "
                               f"another format)")
    orientation = image_orientation(data)
    if orientation != 1 and not (data.startswith(TIFF_SIGNATURES) and _tiff_decoder_orients(orientation)):
        img = upright(img, orientation)
    return img


def read_raw(path: PathLike, *, what: str = "image") -> np.ndarray:
    """Decode an image file with its values as stored: 8 or 16 bits, 1–4 channels (colour channels in RGB order),
    upright as :func:`read_image` reads it (its EXIF orientation applied, so that a label stays on its image's
    pixels); a file of several images is refused (:class:`MultiFrameImageError`).

    For label ids and depth maps, whose values must not be converted.
    """
    img = _decode(path, what, cv2.IMREAD_UNCHANGED)
    if img.ndim == 3 and img.shape[2] >= 3:
        img = img[:, :, [2, 1, 0] + list(range(3, img.shape[2]))]
    return img


def read_image(path: PathLike, *, what: str = "image") -> np.ndarray:
    """Read an image file, upright: its EXIF orientation (a JPEG's, TIFF's, PNG's ``eXIf`` or WebP's; a dash-cam
    or phone frame stored turned, :func:`image_orientation`) applied, as image viewers show it, so that a frame
    tagged "turn 90°" comes out ``W×H`` where its pixels are stored ``H×W``. Every reader here does the same
    (:func:`read_raw`: labels and depth maps; disparity and depth PNGs), so that a label or a right image stays
    on its frame's pixels; :func:`image_header_size` gives the size so read.

    Returns:
        ``H×W×3 uint8`` RGB for colour files (alpha dropped), ``H×W uint8`` for grey files.
        16-bit files are scaled to 8 bits.

    Raises:
        InputFileError: the file is missing or unreadable. CorruptFileError: it is not an image; or
        :class:`MultiFrameImageError`: it holds several (an animated WebP, PNG or GIF, a multi-page TIFF: split
        it into one file per frame; freespace never takes the first alone).
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


def describe_image(shape: tuple[int, ...]) -> str:
    """An image's size (W×H) and kind as a message says it: ``"1242×375 RGB"`` for ``H×W×3`` (a colour image as
    :func:`read_image` returns it), ``"1242×375 grey"`` for ``H×W``; so that two images of one size and
    different channels are told apart (a grey left image with a colour right one)."""
    kind = "grey" if len(shape) == 2 or shape[2] == 1 else "RGB" if shape[2] == 3 else f"{shape[2]}-channel"
    return f"{shape[1]}×{shape[0]} {kind}"


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
    data = read_bytes(path, what, MAX_IMAGE_FILE_BYTES, _FILE_LIMIT)
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
    check_image_pixels(width, height, f"{what} {path}")
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
    data = read_bytes(path, what, MAX_IMAGE_FILE_BYTES, _FILE_LIMIT)
    try:  # the header first: what the array is and its size, before anything is made
        f = _io.BytesIO(data)
        version = np.lib.format.read_magic(f)
        header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, _, dtype = header(f)
    except (ValueError, OSError, EOFError) as exc:
        raise CorruptFileError(f"cannot decode {what} {path}: {str(exc).splitlines()[0]}") from None
    if len(shape) != 2 or not np.issubdtype(dtype, np.number) or np.issubdtype(dtype, np.complexfloating):
        raise CorruptFileError(f"{what} {path} holds a {dtype} array of shape {shape}; expected {expected}")
    check_image_pixels(shape[1], shape[0], f"{what} {path}")
    try:
        arr = np.load(_io.BytesIO(data), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise CorruptFileError(f"cannot decode {what} {path}: {str(exc).splitlines()[0]}") from None
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


def png_disparity_overflow(disparity: np.ndarray) -> int:
    """How many disparities of a ``float H×W`` map (px) exceed what a KITTI 16-bit PNG holds (255.996 px):
    :func:`write_disparity` writes them to a PNG as invalid."""
    disp = np.asarray(disparity, dtype=np.float32)
    return int(np.count_nonzero(np.round(np.where(np.isfinite(disp), disp, 0.0) * 256.0) > _PNG_DISPARITY_MAX))


def write_disparity(path: PathLike, disparity: np.ndarray) -> Path:
    """Write a ``float H×W`` disparity map (NaN = invalid) atomically, format by suffix.

    PNG is KITTI's 16-bit format (``value = round(256 d)``, invalid → 0); it holds disparities up to
    255.996 px, and larger ones (near objects with a wide baseline) are written as invalid with a warning, never
    clipped to a wrong value; ``.npy`` and ``.pfm`` keep float32 with NaN for invalid and have no such limit.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    disp = np.asarray(disparity, dtype=np.float32)
    if disp.ndim != 2:
        raise InvalidOptionError(f"disparity must be 2-D (H×W), got shape {disp.shape}")
    if suffix == ".png":
        scaled = np.round(np.where(np.isfinite(disp), disp, 0.0) * 256.0)
        beyond = scaled > _PNG_DISPARITY_MAX
        if beyond.any():
            warnings.warn(f"{int(beyond.sum())} disparities above {_PNG_DISPARITY_MAX / 256:.3f} px do not fit "
                          f"KITTI's 16-bit PNG and are written as invalid to {path.name}; write .npy or .pfm to "
                          f"keep them", stacklevel=2)
        valid = np.isfinite(disp) & (disp > 0) & ~beyond
        raw = np.zeros(disp.shape, np.uint16)
        raw[valid] = np.maximum(scaled[valid], 1).astype(np.uint16)
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

    Raises:
        CorruptFileError: the file is no label image (:func:`label_image_problem`: a confidence map, a
            prediction, a photograph), which either reading would take for road almost everywhere.
    """
    img = read_image(path, what="road label")
    problem = label_image_problem(img)
    if problem is not None:
        raise CorruptFileError(f"road label {path} is {problem}")
    return road_label_from_image(img)


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


#: the most distinct colours a colour road label may have (KITTI's: black, red, magenta; a few more for
#: another tool's palette), and grey levels a single-channel mask ("non-zero = road": 0 and a few road values;
#: a confidence map or a prediction has tens to hundreds)
MAX_LABEL_COLOURS = 8
MAX_MASK_LEVELS = 8


def label_image_problem(img: np.ndarray) -> str | None:
    """Why the image ``img`` (as :func:`read_image` returns it) is no road label that :func:`read_road_label`
    reads right, or None when it is one: a grey image of more than :data:`MAX_MASK_LEVELS` levels is a
    confidence map or a prediction (``freespace autolabel``'s ``confidence/``, ``freespace predict``'s maps),
    which "non-zero = road" would read as road nearly everywhere; a colour image of more than
    :data:`MAX_LABEL_COLOURS` colours is a photograph or an overlay. The text says what it looks like."""
    grey = img.ndim == 2 or (np.array_equal(img[:, :, 0], img[:, :, 1]) and np.array_equal(img[:, :, 1], img[:, :, 2]))
    if grey:
        levels = np.unique(img if img.ndim == 2 else img[:, :, 0])
        if levels.size > MAX_MASK_LEVELS:
            return (f"a grey image of {levels.size} levels, like a confidence map (autolabel's confidence/) or a "
                    f"prediction (`freespace predict`'s output), not a label (KITTI colours, or a mask: 0 and a road "
                    f"value)")
        return None
    packed = (img[:, :, 0].astype(np.uint32) << 16) | (img[:, :, 1].astype(np.uint32) << 8) | img[:, :, 2]
    colours = np.unique(packed).size
    if colours > MAX_LABEL_COLOURS:
        return (f"a colour image of {colours} colours, like a photograph or an overlay, not a label (KITTI colours: "
                f"road magenta, non-road red, don't care black)")
    return None


def road_label_to_kitti(label: RoadLabel) -> np.ndarray:
    """Encode a :class:`RoadLabel` as a KITTI colour ground truth image (``H×W×3 uint8`` RGB)."""
    out = np.zeros(label.road.shape + (3,), np.uint8)
    out[label.valid, 0] = 255
    out[label.valid & label.road, 2] = 255
    return out


# YAML


def _unique_keys_loader() -> type:
    """``yaml.SafeLoader`` (no code runs, no object but plain data is made) that refuses a mapping with a key
    twice, which PyYAML would otherwise read as its last value without a word."""
    import yaml

    class UniqueKeyLoader(yaml.SafeLoader):
        def construct_mapping(self, node: Any, deep: bool = False) -> dict[Any, Any]:
            if isinstance(node, yaml.MappingNode):
                seen: set[Any] = set()
                for key_node, _ in node.value:  # the keys written in this mapping (a merged `<<` one may be
                    if key_node.tag == "tag:yaml.org,2002:merge":  # overridden here, as YAML means)
                        continue
                    key = self.construct_object(key_node, deep=True)
                    try:
                        repeated = key in seen
                        seen.add(key)
                    except TypeError:  # an unhashable key: the base class refuses it
                        continue
                    if repeated:
                        raise _DuplicateKey(key, key_node.start_mark.line + 1)
            return super().construct_mapping(node, deep=deep)

    return UniqueKeyLoader


class _DuplicateKey(Exception):
    def __init__(self, key: Any, line: int) -> None:
        super().__init__(key, line)
        self.key, self.line = key, line


def load_yaml(path: PathLike) -> Any:
    """The data of the YAML file ``path``, read as ``yaml.safe_load`` reads it (no code runs), but a mapping
    that gives a key twice is refused: PyYAML keeps the last value silently, so the file's order would decide.

    Raises:
        CorruptFileError: not readable, not YAML, or a key given twice (the message names the key, its line
        and the file).
    """
    import yaml

    try:
        text = Path(path).read_text()
        return yaml.load(text, Loader=_loader())  # noqa: S506 (a SafeLoader)
    except _DuplicateKey as exc:
        raise CorruptFileError(f"{path}: {exc.key} is given twice (line {exc.line}, and before); keep one") from None
    except yaml.YAMLError as exc:
        raise CorruptFileError(f"cannot parse {path}: {str(exc).splitlines()[0]}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CorruptFileError(f"cannot read {path}: {str(exc).splitlines()[0]}") from None


@functools.cache
def _loader() -> type:
    return _unique_keys_loader()
