"""What an image file's first bytes say, read without decoding it: its format and damage (a PNG cut short or with a
bad CRC), its size as it is read (upright: its EXIF orientation applied), that orientation, and how many images it
holds (an animated WebP, PNG or GIF, a multi-page TIFF, several Netpbm images). The decoders of
:mod:`freespace.io.codecs` check a file with these before anything of its stated size is made.

Only NumPy and the standard library.
"""

from __future__ import annotations

import re
import zlib
from collections.abc import Callable, Iterator

import numpy as np

__all__ = ["png_damage", "image_header_size", "image_orientation", "upright", "image_frame_count", "frames_of",
           "FORMATS", "TIFF_SIGNATURES"]

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_damage(data: bytes) -> str | None:
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


def _u(data: bytes, at: int, n: int, order: str = "big") -> int:
    """The unsigned ``n``-byte integer at ``at`` (IndexError when the data ends before it)."""
    if at < 0 or at + n > len(data):
        raise IndexError(at)
    return int.from_bytes(data[at:at + n], order)  # type: ignore[arg-type]


def _jpeg_markers(data: bytes) -> Iterator[tuple[int, int]]:
    """``(marker, position)`` of each marker segment of a JPEG file up to its scan, skipping fill bytes and the
    markers without a segment (IndexError or ValueError for a file cut short or no JPEG)."""
    pos = 2
    while True:
        if data[pos] != 0xFF:
            raise ValueError("not a marker")
        marker = data[pos + 1]
        if marker == 0xFF:
            pos += 1
        elif marker == 0x01 or 0xD0 <= marker <= 0xD8:  # markers without a segment
            pos += 2
        elif marker in (0xD9, 0xDA):  # the end, or the scan: no header segment after it
            return
        else:
            yield marker, pos
            pos += 2 + _u(data, pos + 2, 2)


def _jpeg_size(data: bytes) -> tuple[int, int]:
    for marker, pos in _jpeg_markers(data):  # the frame header (SOFn) states the size
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            return _u(data, pos + 7, 2), _u(data, pos + 5, 2)
    raise ValueError("no frame header")


def _tiff_start(data: bytes) -> tuple[str, bool, int]:
    """A TIFF structure's byte order, whether it is a BigTIFF (8-byte offsets and counts) and its first IFD's
    offset."""
    order = "little" if data[:2] == b"II" else "big"
    big = _u(data, 2, 2, order) == 43
    return order, big, _u(data, 8 if big else 4, 8 if big else 4, order)


def _tiff_ifd(data: bytes, at: int, order: str, big: bool, most: int = 4096) -> tuple[dict[int, int], int]:
    """The single numbers of the TIFF IFD at offset ``at`` (tag → value: SHORT, LONG or LONG8 entries; of its first
    ``most`` entries, which TIFF sorts by tag) and the offset of the next IFD (0: none, or the file ends before
    it says)."""
    head, step, width = (8, 20, 8) if big else (2, 12, 4)
    entries = min(_u(data, at, head, order), 4096)
    found: dict[int, int] = {}
    for k in range(min(entries, most)):
        e = at + head + k * step
        tag, kind = _u(data, e, 2, order), _u(data, e + 2, 2, order)
        if kind in (3, 4, 16):
            found[tag] = _u(data, e + 4 + width, {3: 2, 4: 4, 16: 8}[kind], order)
    nxt = at + head + entries * step
    return found, (_u(data, nxt, width, order) if nxt + width <= len(data) else 0)


def _tiff_size(data: bytes) -> tuple[int, int]:
    order, big, first = _tiff_start(data)
    found = _tiff_ifd(data, first, order, big)[0]
    return found[256], found[257]  # ImageWidth, ImageLength


def _bmp_size(data: bytes) -> tuple[int, int]:
    if _u(data, 14, 4, "little") == 12:  # OS/2 header: 16-bit sizes
        return _u(data, 18, 2, "little"), _u(data, 20, 2, "little")
    w, h = _u(data, 18, 4, "little"), _u(data, 22, 4, "little")
    return w, min(h, 2**32 - h)  # a negative height (two's complement): rows stored top to bottom


def _webp_size(data: bytes) -> tuple[int, int]:
    chunk = data[12:16]
    if chunk == b"VP8 ":
        return _u(data, 26, 2, "little") & 0x3FFF, _u(data, 28, 2, "little") & 0x3FFF
    if chunk == b"VP8L":
        bits = _u(data, 21, 4, "little")
        return 1 + (bits & 0x3FFF), 1 + ((bits >> 14) & 0x3FFF)
    if chunk == b"VP8X":
        return 1 + _u(data, 24, 3, "little"), 1 + _u(data, 27, 3, "little")
    raise ValueError("unknown WebP chunk")


_PNM = re.compile(rb"P[1-6Ff](?:\s|#[^\n]*\n)+(\d+)(?:\s|#[^\n]*\n)+(\d+)")


def _pnm_size(data: bytes) -> tuple[int, int]:
    head = data[:4096]
    if head.startswith(b"P7"):  # PAM: WIDTH and HEIGHT lines
        w, h = (re.search(rb"\n\s*" + key + rb"\s+(\d+)", head) for key in (b"WIDTH", b"HEIGHT"))
        return int(w.group(1)), int(h.group(1))  # type: ignore[union-attr]
    m = _PNM.match(head)
    return int(m.group(1)), int(m.group(2))  # type: ignore[union-attr]


#: the image formats read here: how each begins, and how its header states its size (W, H)
_HEADERS: tuple[tuple[tuple[bytes, ...], Callable[[bytes], tuple[int, int]]], ...] = (
    ((_PNG_SIGNATURE,), lambda d: (_u(d, 16, 4), _u(d, 20, 4)) if d[12:16] == b"IHDR" else (0, 0)),
    ((b"\xff\xd8\xff",), _jpeg_size),
    ((b"BM",), _bmp_size),
    ((b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"), _tiff_size),
    ((b"P1", b"P2", b"P3", b"P4", b"P5", b"P6", b"P7", b"Pf", b"PF"), _pnm_size),
    ((b"GIF87a", b"GIF89a"), lambda d: (_u(d, 6, 2, "little"), _u(d, 8, 2, "little"))),
    ((b"RIFF",), lambda d: _webp_size(d) if d[8:12] == b"WEBP" else (0, 0)),
    ((b"\x59\xa6\x6a\x95",), lambda d: (_u(d, 4, 4), _u(d, 8, 4))),  # Sun raster
)
FORMATS = "PNG, JPEG, BMP, TIFF, PPM/PGM/PBM/PAM, Sun raster, GIF or WebP"


def _stored_size(data: bytes) -> tuple[int, int] | None:
    """The size ``(W, H)`` an image file's header states, as the pixels are stored; None: see
    :func:`image_header_size`."""
    for signatures, size in _HEADERS:
        if data.startswith(signatures):
            try:
                w, h = size(data)
            except (IndexError, KeyError, ValueError, AttributeError):
                return None
            return (w, h) if w >= 1 and h >= 1 else None
    return None


def image_header_size(data: bytes) -> tuple[int, int] | None:
    """The size ``(W, H)`` in pixels of an image file as it is read here (upright: width and height swapped when
    its EXIF orientation, :func:`image_orientation`, turns it by 90°), from its header (its first bytes, nothing
    decoded); None when ``data`` is no image of a format read here (PNG, JPEG, BMP, TIFF, PPM/PGM/PBM/PAM/PFM,
    Sun raster, GIF, WebP) or its header is cut short or states no size.

    Example:
        >>> image_header_size(b"P5 640 480 255 ")  # a PGM header
        (640, 480)
    """
    size = _stored_size(data)
    if size is not None and _ORIENTATIONS[image_orientation(data)][0]:
        return size[1], size[0]
    return size


#: what each EXIF orientation (1–8) does to the stored pixels to make them upright, in this order: transpose
#: (swap rows and columns), flip upside down, flip left to right (1: nothing; 6: turn 90° clockwise; 8: turn 90°
#: anticlockwise; 3: turn 180°; 2, 4, 5 and 7 mirror)
_ORIENTATIONS: dict[int, tuple[bool, bool, bool]] = {
    1: (False, False, False), 2: (False, False, True), 3: (False, True, True), 4: (False, True, False),
    5: (True, False, False), 6: (True, False, True), 7: (True, True, True), 8: (True, True, False)}
_EXIF = b"Exif\x00\x00"
TIFF_SIGNATURES = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
_ORIENTATION_TAG = 274


def _exif_orientation(tiff: bytes) -> int:
    """The orientation (tag 274 of its first IFD) of an EXIF block (a TIFF structure, with or without its
    ``Exif\\0\\0`` prefix); 1 when it states none or a value outside 1–8."""
    if tiff.startswith(_EXIF):
        tiff = tiff[len(_EXIF):]
    if not tiff.startswith(TIFF_SIGNATURES):
        return 1
    try:
        order, big, first = _tiff_start(tiff)
        value = _tiff_ifd(tiff, first, order, big)[0].get(_ORIENTATION_TAG, 1)
    except (IndexError, ValueError):
        return 1
    return value if value in _ORIENTATIONS else 1


def _png_chunks(data: bytes) -> Iterator[tuple[bytes, int, int]]:
    """``(type, position of the data, length)`` of a PNG file's chunks up to its first IDAT (included)."""
    pos = len(_PNG_SIGNATURE)
    while pos + 8 <= len(data):
        length, kind = _u(data, pos, 4), bytes(data[pos + 4:pos + 8])
        yield kind, pos + 8, length
        if kind in (b"IDAT", b"IEND"):
            return
        pos += 12 + length


def _riff_chunks(data: bytes) -> Iterator[tuple[bytes, int, int]]:
    """``(FourCC, position of the data, length)`` of a WebP (RIFF) file's chunks."""
    pos = 12
    while pos + 8 <= len(data):
        kind, length = bytes(data[pos:pos + 4]), _u(data, pos + 4, 4, "little")
        yield kind, pos + 8, length
        pos += 8 + length + (length & 1)


def image_orientation(data: bytes) -> int:
    """The EXIF orientation (1–8; 1: stored upright) an image file states, as cameras tag a frame they store
    turned (6: turn it 90° clockwise to view it): a JPEG's Exif APP1 segment, a TIFF's first IFD, a PNG's
    ``eXIf`` chunk or a WebP's ``EXIF`` chunk; 1 for other files, or one that states none (or a value outside
    1–8).

    Example:
        >>> image_orientation(b"P5 640 480 255 ")  # PGM holds no EXIF
        1
    """
    try:
        if data.startswith(b"\xff\xd8\xff"):
            for marker, pos in _jpeg_markers(data):
                if marker == 0xE1 and data[pos + 4:pos + 10] == _EXIF:
                    return _exif_orientation(data[pos + 4:pos + 2 + _u(data, pos + 2, 2)])
                if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
                    break  # the frame header: EXIF comes before it
        elif data.startswith(TIFF_SIGNATURES):
            return _exif_orientation(data)
        elif data.startswith(_PNG_SIGNATURE):
            for kind, pos, length in _png_chunks(data):
                if kind == b"eXIf":
                    return _exif_orientation(data[pos:pos + length])
        elif data.startswith(b"RIFF") and data[8:12] == b"WEBP":
            for kind, pos, length in _riff_chunks(data):
                if kind == b"EXIF":
                    return _exif_orientation(data[pos:pos + length])
    except (IndexError, ValueError):
        pass
    return 1


def upright(image: np.ndarray, orientation: int) -> np.ndarray:
    """``image`` (``H×W`` or ``H×W×C``, as stored in its file) turned and mirrored as its EXIF ``orientation``
    (1–8, :func:`image_orientation`) says, so that it stands upright (as image viewers show it); orientation 5–8
    swap its width and height.

    Example:
        >>> upright(np.array([[1, 2, 3]]), 6)  # 90° clockwise: the first pixel goes to the top
        array([[1],
               [2],
               [3]])
    """
    transpose, flip_v, flip_h = _ORIENTATIONS[orientation]
    if transpose:
        image = image.swapaxes(0, 1)
    if flip_v:
        image = image[::-1]
    if flip_h:
        image = image[:, ::-1]
    return np.ascontiguousarray(image)


def _gif_frames(data: bytes) -> int:
    """The images of a GIF file (its image descriptors, up to its trailer or the end of the file)."""
    steps = 0

    def skip_blocks(pos: int) -> int:
        nonlocal steps
        while data[pos]:
            pos += data[pos] + 1
            steps += 1
        return pos + 1

    frames, pos = 0, 13
    if data[10] & 0x80:  # a global colour table
        pos += 3 * (2 << (data[10] & 7))
    try:  # at most 2 million blocks (500 MB of full ones): a crafted file of tiny blocks costs little
        while pos < len(data) and data[pos] != 0x3B and steps < 2_000_000:
            steps += 1
            if data[pos] == 0x21:  # an extension: its label, then data sub-blocks
                pos = skip_blocks(pos + 2)
            elif data[pos] == 0x2C:  # an image: its descriptor, local colour table, LZW code size, sub-blocks
                frames += 1
                flags = data[pos + 9]
                pos += 10 + (3 * (2 << (flags & 7)) if flags & 0x80 else 0)
                pos = skip_blocks(pos + 1)
            else:
                break
    except IndexError:  # cut short: the images before the cut
        pass
    return frames


def _tiff_pages(data: bytes) -> int:
    """The full-resolution pages of a TIFF file: its IFDs, less reduced-resolution images (thumbnails) and
    transparency masks (NewSubfileType bits 0 and 2)."""
    order, big, at = _tiff_start(data)
    pages, seen = 0, set()
    while at and at not in seen and len(seen) < 10_000:  # a crafted chain costs little
        seen.add(at)
        try:
            tags, nxt = _tiff_ifd(data, at, order, big, most=16)  # NewSubfileType (254) is the lowest tag
        except (IndexError, ValueError):
            break
        pages += not tags.get(254, 0) & 0b101
        at = nxt
    return pages


#: the headers of a binary PBM (magic, width, height, one whitespace) and PGM or PPM (then the largest value)
_GAP = rb"(?:\s|#[^\n]*\n)+"
_PBM_HEADER = re.compile(rb"P4" + _GAP + rb"(\d+)" + _GAP + rb"(\d+)\s")
_PGM_HEADER = re.compile(rb"(P[56])" + _GAP + rb"(\d+)" + _GAP + rb"(\d+)" + _GAP + rb"(\d+)\s")
_PAM_HEADER = re.compile(rb"P7\n(.*?)ENDHDR\n", re.S)
_SPACE = re.compile(rb"[ \t\r\n]*")


def _pnm_images(data: bytes) -> int:
    """The images of a binary Netpbm file (PBM/PGM/PPM/PAM), which may hold several one after another: each
    header, then its raster of the size it states (1 for the text formats, P1–P3, whose rasters are not
    measured)."""
    images, pos = 0, 0
    while pos < len(data) and images < 100_000:
        if data.startswith(b"P7", pos):
            head = _PAM_HEADER.match(data, pos)
            if head is None:
                break
            fields = dict(re.findall(rb"(WIDTH|HEIGHT|DEPTH|MAXVAL)\s+(\d+)", head.group(1)))
            w, h, depth = (int(fields.get(k, b"0")) for k in (b"WIDTH", b"HEIGHT", b"DEPTH"))
            size, start = w * h * depth * (2 if int(fields.get(b"MAXVAL", b"255")) > 255 else 1), head.end()
        elif data.startswith(b"P4", pos):
            m = _PBM_HEADER.match(data, pos)
            if m is None:
                break
            size, start = (int(m.group(1)) + 7) // 8 * int(m.group(2)), m.end()  # rows padded to whole bytes
        else:
            m = _PGM_HEADER.match(data, pos)
            if m is None:
                break
            w, h, top = int(m.group(2)), int(m.group(3)), int(m.group(4))
            size, start = w * h * (3 if m.group(1) == b"P6" else 1) * (2 if top > 255 else 1), m.end()
        images += 1
        pos = _SPACE.match(data, start + size).end()  # type: ignore[union-attr]
    return max(images, 1)


def frames_of(data: bytes) -> tuple[int, str]:
    """How many images an image file holds, and what it is when more than one."""
    try:
        if data.startswith((b"P4", b"P5", b"P6", b"P7")):
            return _pnm_images(data), "a Netpbm file of several images"
        if data.startswith(TIFF_SIGNATURES):
            return _tiff_pages(data), "a multi-page TIFF"
        if data.startswith((b"GIF87a", b"GIF89a")):
            return _gif_frames(data), "an animated GIF"
        if data.startswith(_PNG_SIGNATURE):
            animation, before_idat = 0, False
            for kind, pos, _ in _png_chunks(data):
                if kind == b"acTL":
                    animation = _u(data, pos, 4)
                before_idat |= kind == b"fcTL"
            # the default image (IDAT) is a frame of the animation when a frame control comes before it
            return (animation + (0 if before_idat or not animation else 1)), "an animated PNG (APNG)"
        if data.startswith(b"RIFF") and data[8:12] == b"WEBP":
            return sum(kind == b"ANMF" for kind, _, _ in _riff_chunks(data)), "an animated WebP"
    except (IndexError, ValueError):
        pass
    return 1, ""


def image_frame_count(data: bytes) -> int:
    """How many images an image file holds: the frames of an animated WebP, PNG (APNG) or GIF, the pages of a
    multi-page TIFF (thumbnails and masks aside), the images of a binary Netpbm file (PGM, PPM, … one after
    another); 1 for any other image file (at least 1).

    Example:
        >>> image_frame_count(b"P5 640 480 255 ")
        1
    """
    return max(1, frames_of(data)[0])
