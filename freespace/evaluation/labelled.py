"""Human-labelled image folders in the formats real sets come in: pairing, decoding, checking, per-frame scores,
intervals.

A *labelled folder* is a folder of images and a folder of label images, paired by name. Four label formats:

=============  =====================================================================================  ==============
format         what a label pixel means                                                               e.g.
=============  =====================================================================================  ==============
``kitti``      KITTI road ground truth: road where blue > 0, evaluated where red > 0 (the devkit's);   KITTI road
               ``<cat>_road_<id>.png`` pairs with the image ``<cat>_<id>``, ``*_lane_*`` is skipped
``binary``     a grey mask: non-zero is road; ``ignore`` values are don't care                         your own masks
``class-id``   a grey image of class ids: ``road`` ids are road, ``ignore`` ids don't care,           CamVid (road 3,
               every other id not road                                                                 void 11)
``palette``    an RGB image of class colours: a pixel within ``tolerance`` levels (every channel) of  Cityscapes
               a ``road`` colour is road, of an ``ignore`` colour don't care, others not road          (128, 64, 128)
=============  =====================================================================================  ==============

Label files are read with their own values (:func:`read_label_image`), never scaled: 8- or 16-bit grey labels hold
ids 0…255 or 0…65535 (a 16-bit mask with road 1 is road where it is 1); an alpha channel is dropped. A 16-bit
colour label of the ``palette`` format is reduced to the 8-bit colours the options name when it is an 8-bit palette
widened to 16 bits (every channel a multiple of 257, as ``v × 257`` widens), and refused otherwise; ``kitti``
reads any bit depth (its test is > 0).

Before a set is scored, :func:`scan_labels` reads its labels once and :meth:`LabelScan.check` refuses, in one line,
a set in which no label has a pixel to evaluate (every pixel don't care) and a road value that no label holds
(naming it and the values the labels do hold): either would score nothing while printing a score. A frame whose
label has no evaluated pixel is listed (:attr:`LabelScan.unevaluated`) and left out of the pooled scores.

Scores are counted at each label's own size (the prediction is resized to it) and pooled over frames by summing
the counts (never an average of per-frame scores, :mod:`freespace.evaluation.metrics`); the interval of a pooled
score is a frame-level bootstrap (:func:`bootstrap_intervals`): frames, not pixels, are the independent units, so
it needs two scored frames at least.

Never imports torch.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from freespace.errors import CorruptFileError, DatasetError, InputFileError, InvalidOptionError, param
from freespace.evaluation.metrics import Counts
from freespace.io.codecs import IMAGE_SUFFIXES, read_image, read_raw, road_label_from_image
from freespace.io.files import PathLike
from freespace.labels import RoadLabel

__all__ = ["LABEL_FORMATS", "LabelFormat", "LabelledFrame", "parse_label_format", "pair_labelled_frames",
           "read_label_image", "read_label", "LabelScan", "scan_labels", "check_labels", "frame_scores",
           "frame_evaluated", "bootstrap_intervals", "interval_note", "PooledScores", "POOLED_METRICS",
           "MIN_INTERVAL_FRAMES"]

LABEL_FORMATS = ("kitti", "binary", "class-id", "palette")
#: the pooled metrics that get a bootstrap interval
POOLED_METRICS = ("precision", "recall", "f_score", "iou")
#: the fewest scored frames a frame-level bootstrap interval is made of (one frame's resamples are all that frame:
#: an interval of zero width that says nothing of the uncertainty)
MIN_INTERVAL_FRAMES = 2
#: the largest grey label value (16-bit labels); colours are 8-bit levels
MAX_LABEL_VALUE = 65535


def _value_text(value: Any) -> str:
    """A label value as the options write it: ``3``, or ``128,64,128`` for a colour."""
    return ",".join(str(int(v)) for v in value) if isinstance(value, tuple) else str(int(value))


@dataclass(frozen=True)
class LabelFormat:
    """How a label image is decoded (see the module docstring).

    Attributes:
        kind: one of :data:`LABEL_FORMATS`.
        road: ``class-id``: the road class ids; ``palette``: the road colours as ``(R, G, B)``; else empty.
        ignore: the don't-care ids / grey values / colours.
        tolerance: ``palette``: the largest difference, in 8-bit levels on any channel, from a listed colour
            (scaled labels blend colours at class edges).
        preset: the public label set whose format this is (:mod:`freespace.evaluation.label_presets`), or None.
        max_value: ``class-id``: the largest id the format knows (a preset's set), or None: any.
    """

    kind: str
    road: tuple = ()
    ignore: tuple = ()
    tolerance: int = 0
    preset: str | None = None
    max_value: int | None = None

    def describe(self) -> dict[str, Any]:
        """A JSON-ready record of the format (written beside every score it produced)."""
        return {"kind": self.kind, "road": [list(v) if isinstance(v, tuple) else v for v in self.road],
                "ignore": [list(v) if isinstance(v, tuple) else v for v in self.ignore], "tolerance": self.tolerance,
                **({"preset": self.preset} if self.preset else {})}

    def decode(self, img: np.ndarray, path: PathLike = "label") -> RoadLabel:
        """The :class:`RoadLabel` of a label image ``img`` read from ``path``: ``H×W`` grey or ``H×W×3`` RGB,
        ``uint8`` or ``uint16``, with its own values (:func:`read_label_image`).

        Raises:
            CorruptFileError: the image has not the channels its format needs (a colour image of class ids, a grey
                one for a palette), a pixel type other than 8 or 16 bits, or 16-bit colours that are no 8-bit
                palette.
        """
        return self._decode(self.prepare(img, path))

    def prepare(self, img: np.ndarray, path: PathLike = "label") -> np.ndarray:
        """``img`` checked for this format and in the form :meth:`decode` reads: ``H×W`` grey values (``binary``,
        ``class-id``; a colour image of three equal channels is grey), ``H×W×3`` RGB (``kitti``), ``H×W×3`` 8-bit
        RGB (``palette``: a 16-bit palette reduced, see the module docstring). Raises as :meth:`decode`."""
        if img.dtype not in (np.uint8, np.uint16):
            raise CorruptFileError(f"label {path} has pixel type {img.dtype}; label images are 8- or 16-bit")
        if self.kind == "kitti":
            if img.ndim != 3:
                raise CorruptFileError(f"label {path} is a grey image, but {param('label_format')} kitti needs "
                                       f"KITTI's colour ground truth (road magenta, non-road red); a grey mask is "
                                       f"{param('label_format')} binary")
            return img
        if self.kind == "palette":
            if img.ndim != 3:
                raise CorruptFileError(f"label {path} is a grey image, but {param('label_format')} palette needs "
                                       f"colours; class ids are {param('label_format')} class-id")
            return _eight_bit_colours(img, path)
        return _grey(img, path, self.kind)

    def _decode(self, img: np.ndarray) -> RoadLabel:
        if self.kind == "kitti":
            return road_label_from_image(img)
        if self.kind == "palette":
            return RoadLabel(road=self._near(img, self.road), valid=~self._near(img, self.ignore))
        road = img > 0 if self.kind == "binary" else np.isin(img, self.road)
        valid = ~np.isin(img, self.ignore)
        return RoadLabel(road=road & valid, valid=valid)

    def _near(self, img: np.ndarray, colours: Iterable) -> np.ndarray:
        out = np.zeros(img.shape[:2], bool)
        for colour in colours:
            out |= (np.abs(img.astype(np.int32) - np.asarray(colour, np.int32)).max(axis=2) <= self.tolerance)
        return out

    def road_values(self, values: np.ndarray, valid: np.ndarray) -> dict[Any, np.ndarray]:
        """Which of ``values`` (a ``1×K`` or ``1×K×3`` image of prepared label values, :meth:`prepare`) are each
        road value: ``{road id or colour: bool K}`` (``class-id``, ``palette``), ``{"road": bool K}`` for the
        formats that mark road themselves (``binary``, ``kitti``); only evaluated values (``valid``) count."""
        if self.kind == "class-id":
            return {v: (values[0] == v) & valid for v in self.road}
        if self.kind == "palette":
            return {c: self._near(values, [c])[0] & valid for c in self.road}
        return {"road": self._decode(values).road[0] & valid}


def _eight_bit_colours(img: np.ndarray, path: PathLike) -> np.ndarray:
    if img.dtype == np.uint8:
        return img
    off = img % 257 != 0
    if off.any():
        at = np.argwhere(off.any(axis=2))[0]
        raise CorruptFileError(f"label {path} is a 16-bit colour image whose colours are no 8-bit palette widened "
                               f"to 16 bits (each channel a multiple of 257), e.g. {_value_text(tuple(img[tuple(at)]))}"
                               f" at row {at[0]}, column {at[1]}; {param('label_format')} palette reads 8-bit class "
                               f"colours: save the labels as 8-bit RGB")
    return (img // 257).astype(np.uint8)


def _grey(img: np.ndarray, path: PathLike, kind: str) -> np.ndarray:
    if img.ndim == 2:
        return img
    if np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 1], img[..., 2]):
        return img[..., 0]
    raise CorruptFileError(f"label {path} is a colour image, but {param('label_format')} {kind} reads grey values; "
                           f"colour labels are {param('label_format')} palette (class colours) or kitti (KITTI road "
                           f"ground truth)")


def _ints(text: str | None, what: str, top: int = MAX_LABEL_VALUE) -> tuple[int, ...]:
    if not text:
        return ()
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise InvalidOptionError(f"{param(what)} takes comma-separated integers (e.g. 3 or 3,4), "
                                 f"got {text!r}") from None
    if any(not 0 <= v <= top for v in values):
        kind = ("label values in [0, 65535] (8-bit labels hold 0…255, 16-bit ones 0…65535)" if top == MAX_LABEL_VALUE
                else "8-bit colour levels in [0, 255]")
        raise InvalidOptionError(f"{param(what)} values are {kind}, got {text!r}")
    return values


def _colours(text: str | None, what: str) -> tuple[tuple[int, int, int], ...]:
    if not text:
        return ()
    colours = []
    for part in text.split(";"):
        values = _ints(part, what, 255)
        if len(values) != 3:
            raise InvalidOptionError(f"{param(what)} takes R,G,B colours separated by ';' (e.g. 128,64,128), "
                                     f"got {text!r}")
        colours.append(values)
    return tuple(colours)  # type: ignore[return-value]


def _check_road_apart_from_ignore(fmt: LabelFormat) -> None:
    """Refuse road and don't-care values that claim the same pixels: such a road is never scored."""
    if fmt.kind == "binary" and 0 in fmt.ignore:
        raise InvalidOptionError(f"{param('ignore')} 0 would make every non-road pixel of a binary mask don't care "
                                 f"(0 is its one non-road value), leaving nothing but road to score; give only the "
                                 f"don't-care values")
    if fmt.kind == "class-id":
        both = sorted(set(fmt.road) & set(fmt.ignore))
        if both:
            raise InvalidOptionError(f"{', '.join(map(str, both))} {'is' if len(both) == 1 else 'are'} given to both "
                                     f"{param('road')} and {param('ignore')}: a value is road or don't care, not "
                                     f"both; remove it from one")
    if fmt.kind == "palette":
        for road in fmt.road:
            for ignore in fmt.ignore:
                if max(abs(a - b) for a, b in zip(road, ignore)) <= fmt.tolerance:
                    same = road == ignore
                    raise InvalidOptionError(
                        f"{param('road')} {_value_text(road)} and {param('ignore')} {_value_text(ignore)} "
                        + ("are the same colour: a colour is road or don't care, not both; remove it from one"
                           if same else f"lie within {param('tolerance')} {fmt.tolerance} of each other, so road "
                           f"pixels would be read as don't care; give a smaller {param('tolerance')}"))


def parse_label_format(kind: str, road: str | None = None, ignore: str | None = None,
                       tolerance: int | None = None) -> LabelFormat:
    """The :class:`LabelFormat` the command line names.

    Args:
        kind: one of :data:`LABEL_FORMATS`.
        road: ``class-id``: road ids (``"3"``, ``"3,4"``; 0…65535, 16-bit labels hold ids above 255);
            ``palette``: road colours (``"128,64,128"``, 8-bit levels, several separated by ``;``); not accepted by
            ``kitti`` and ``binary``.
        ignore: don't-care ids, grey values or colours in the same notation (not accepted by ``kitti``).
        tolerance: ``palette`` only: 8-bit levels (default 8).

    Raises:
        InvalidOptionError: an unknown format, a value the format does not take, one it needs missing, or a value
            that is both road and don't care (the same id or colour in ``road`` and ``ignore``, colours within
            ``tolerance`` of each other, or ``binary``'s only non-road value 0 in ``ignore``).
    """
    if kind not in LABEL_FORMATS:
        raise InvalidOptionError(f"{param('label_format')} must be one of {', '.join(LABEL_FORMATS)}, got {kind!r}")
    if kind in ("kitti", "binary") and road:
        raise InvalidOptionError(f"{param('road')} is for {param('label_format')} class-id or palette; {kind} labels "
                                 f"mark road themselves")
    if kind == "kitti" and ignore:
        raise InvalidOptionError(f"{param('ignore')} is not for {param('label_format')} kitti: KITTI marks don't care "
                                 f"black")
    if kind in ("class-id", "palette") and not road:
        example = "3 (CamVid)" if kind == "class-id" else "128,64,128 (Cityscapes)"
        raise InvalidOptionError(f"{param('label_format')} {kind} needs {param('road')}, the road's "
                                 f"{'class ids' if kind == 'class-id' else 'colours'}, e.g. {param('road')} {example}")
    if tolerance is not None and kind != "palette":
        raise InvalidOptionError(f"{param('tolerance')} is for {param('label_format')} palette")
    if tolerance is not None and not 0 <= tolerance <= 64:
        raise InvalidOptionError(f"{param('tolerance')} is in 8-bit levels, 0 to 64, got {tolerance}")
    if kind == "palette":
        fmt = LabelFormat(kind, _colours(road, "road"), _colours(ignore, "ignore"),
                          8 if tolerance is None else tolerance)
    else:
        fmt = LabelFormat(kind, _ints(road, "road"), _ints(ignore, "ignore"))
    _check_road_apart_from_ignore(fmt)
    return fmt


def read_label_image(path: PathLike) -> np.ndarray:
    """A label file's values as stored, never scaled: ``H×W`` (grey) or ``H×W×3`` (RGB), ``uint8`` or ``uint16``;
    an alpha channel is dropped.

    Raises:
        InputFileError: the file is missing or unreadable. CorruptFileError: it is no image, or not of 8 or 16 bits.
    """
    img = read_raw(path, what="label")
    if img.ndim == 3:
        img = img[:, :, 0] if img.shape[2] <= 2 else img[:, :, :3]  # grey (+ alpha) or RGB (+ alpha)
    if img.dtype not in (np.uint8, np.uint16):
        raise CorruptFileError(f"label {path} has pixel type {img.dtype}; label images are 8- or 16-bit")
    return np.ascontiguousarray(img)


def read_label(path: PathLike, label_format: LabelFormat) -> RoadLabel:
    """The :class:`RoadLabel` of the label file ``path``, read with its own values (:func:`read_label_image`) and
    decoded by ``label_format`` (:meth:`LabelFormat.decode`, which says what it raises)."""
    return label_format.decode(read_label_image(path), path)


@dataclass(frozen=True)
class LabelledFrame:
    """One image and its label file; ``name`` is the image's stem."""

    name: str
    image: Path
    label: Path

    def read(self, label_format: LabelFormat) -> tuple[np.ndarray, RoadLabel]:
        """The image (``H×W×3`` RGB ``uint8``) and its label, decoded by ``label_format`` (:func:`read_label`)."""
        return read_image(self.image), read_label(self.label, label_format)


def _image_name(label: Path, kind: str) -> str | None:
    """The stem of the image a label file belongs to, or None for a file that is no label of the format."""
    stem = label.stem
    if kind == "kitti":
        if "_road_" not in stem:
            return None  # KITTI's lane ground truth, or another file
        return stem.replace("_road_", "_", 1)
    return stem


def _folder(path: PathLike, flag: str) -> Path:
    folder = Path(path)
    if not folder.exists():
        raise InputFileError(f"{param(flag)} folder not found: {folder}")
    if not folder.is_dir():
        raise InputFileError(f"{param(flag)} must be a folder of images, got the file {folder}")
    return folder


def _some(names: list[str], most: int = 3) -> str:
    """``names`` for a message: the first ``most``, and how many more."""
    return ", ".join(names[:most]) + (f" and {len(names) - most} more" if len(names) > most else "")


def pair_labelled_frames(images: PathLike, labels: PathLike, label_format: LabelFormat, *, strict: bool = False,
                         images_flag: str = "images", labels_flag: str = "labels") -> list[LabelledFrame]:
    """Pair every label file of ``labels`` with the image of the same name in ``images``, sorted by name.

    Images without a label are left out (a set may label a few of its frames, as CamVid's dusk labels do), unless
    ``strict`` (training: a frame without its label is a mistake); a label without its image is an error, as are
    two images of one name (``a.png`` and ``a.jpg``: which did the label mean?). ``images_flag``/``labels_flag``:
    the parameters that named the folders, for messages.

    Raises:
        InputFileError: a folder is missing, labels have no image, or (``strict``) images have no label: the
            message counts them and names the first. DatasetError: no label file, or a name clash.
    """
    image_dir, label_dir = _folder(images, images_flag), _folder(labels, labels_flag)
    if image_dir.resolve() == label_dir.resolve():
        raise InvalidOptionError(f"{param(images_flag)} and {param(labels_flag)} are the same folder ({image_dir}); "
                                 f"give the folder of label images apart from the images")
    by_stem: dict[str, Path] = {}
    for path in sorted(image_dir.iterdir()):
        if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file():
            if path.stem in by_stem:
                raise DatasetError(f"two images are named {path.stem!r} in {image_dir} ({by_stem[path.stem].name}, "
                                   f"{path.name}); keep one")
            by_stem[path.stem] = path
    frames, orphans = [], []
    for label in sorted(label_dir.iterdir()):
        if label.suffix.lower() not in IMAGE_SUFFIXES or not label.is_file():
            continue
        name = _image_name(label, label_format.kind)
        if name is None:
            continue
        if name not in by_stem:
            orphans.append(label.name)
            continue
        frames.append(LabelledFrame(name, by_stem[name], label))
    if orphans:
        raise InputFileError(f"{len(orphans)} label{'s' if len(orphans) > 1 else ''} in {label_dir} "
                             f"{'have' if len(orphans) > 1 else 'has'} no image of the same name in {image_dir} "
                             f"({_some(orphans)}); give the images' folder with {param(images_flag)}, or move "
                             f"those labels away")
    if len({f.name for f in frames}) != len(frames):
        raise DatasetError(f"two labels in {label_dir} belong to one image; keep one label per frame")
    if not frames:
        hint = " (KITTI ground truth is named <cat>_road_<id>.png)" if label_format.kind == "kitti" else ""
        raise DatasetError(f"no label images in {label_dir}{hint}")
    if strict:
        paired = {f.name for f in frames}
        bare = [by_stem[n].name for n in by_stem if n not in paired]
        if bare:
            raise InputFileError(f"{len(bare)} of the {len(by_stem)} images in {image_dir} "
                                 f"{'have' if len(bare) > 1 else 'has'} no label of the same name in {label_dir} "
                                 f"({_some(bare)}); label them, or move them out of {param(images_flag)}")
    return frames


# ---------------------------------------------------------------------------------------------------------------
# what a set of labels holds


def _distinct(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct values of a prepared label image as a ``1×K`` (grey) or ``1×K×3`` (colour) image of its dtype,
    and each one's pixel count."""
    if img.ndim == 2:
        values, counts = np.unique(img, return_counts=True)
        return values[None], counts
    packed = (img[..., 0].astype(np.uint64) << 32) | (img[..., 1].astype(np.uint64) << 16) | img[..., 2]
    values, counts = np.unique(packed, return_counts=True)
    colours = np.stack([(values >> 32) & 0xFFFF, (values >> 16) & 0xFFFF, values & 0xFFFF], axis=-1)
    return colours.astype(img.dtype)[None], counts


@dataclass(frozen=True)
class LabelScan:
    """What the labels of a set hold, read by one :class:`LabelFormat` (:func:`scan_labels`).

    Attributes:
        label_format: the format the labels were read with.
        folders: the folders of the label files.
        frames: the number of labels read.
        values: each label value (a grey id, or an ``(R, G, B)`` colour; a 16-bit palette reduced to 8 bits) →
            its pixels over all labels.
        road: each road value of the format (``class-id``: ids, ``palette``: colours; ``"road"`` for ``binary``
            and ``kitti``, which mark road themselves) → its evaluated pixels over all labels.
        unevaluated: the frames whose label has no evaluated pixel (don't care everywhere), by name.
        bits: the labels' bit depths (8, 16).
    """

    label_format: LabelFormat
    folders: tuple[str, ...]
    frames: int
    values: dict[Any, int]
    road: dict[Any, int]
    unevaluated: tuple[str, ...]
    bits: tuple[int, ...]

    @property
    def missing_road(self) -> tuple:
        """The road values that no label holds at an evaluated pixel."""
        return tuple(v for v, n in self.road.items() if n == 0)

    def held(self, most: int = 5) -> str:
        """The values the labels hold, the ``most`` common first, each with its share of all pixels:
        ``"3 (41.2 %), 1 (33.0 %), … (9 values in all)"``."""
        total = sum(self.values.values()) or 1
        common = sorted(self.values.items(), key=lambda kv: (-kv[1], kv[0]))
        text = ", ".join(f"{_value_text(v)} ({100 * n / total:.1f} %)" for v, n in common[:most])
        return text + (f", … ({len(common)} values in all)" if len(common) > most else "")

    def check(self, *, each_road_value: bool | None = None) -> LabelScan:
        """This scan, after refusing a set that would score nothing while printing a score, or labels that are not
        of the public set its format names.

        ``each_road_value``: every road value must occur (what the user listed: a value that is in no label is a
        mistake); False: one at least (a public set's format, whose road classes need not all be in these frames);
        None (default): False for a preset's format, else True.

        Raises:
            DatasetError: no label has an evaluated pixel (every pixel don't care: ``ignore`` covers all the values
                the labels hold, or KITTI ground truth all black), or a road value is in no label (a ``road`` id or
                colour that the labels do not hold, or ``binary``/``kitti`` labels that mark no road); the message
                names the value and the values the labels hold.
        """
        fmt, where = self.label_format, ", ".join(self.folders)
        if each_road_value is None:
            each_road_value = fmt.preset is None
        beyond = sorted(v for v in self.values if not isinstance(v, tuple) and fmt.max_value is not None
                        and v > fmt.max_value)
        if beyond:
            raise DatasetError(f"the labels in {where} hold {', '.join(map(str, beyond[:5]))}"
                               f"{' …' if len(beyond) > 5 else ''}, ids that {fmt.preset} has not (its ids go to "
                               f"{fmt.max_value}): they are not {fmt.preset} labels; give their format with "
                               f"{param('label_format')} and {param('road')} (they hold {self.held()})")
        if len(self.unevaluated) == self.frames:
            if fmt.kind == "kitti":
                why = "is black everywhere (KITTI's don't care)"
                fix = "give KITTI road ground truth (road magenta, non-road red)"
            else:
                sep = ";" if fmt.kind == "palette" else ","
                why = (f"is don't care everywhere ({param('ignore')} {sep.join(_value_text(v) for v in fmt.ignore)} "
                       f"covers every value they hold: {self.held()})")
                fix = f"give in {param('ignore')} only the values that are don't care"
            raise DatasetError(f"every label in {where} {why}, so no pixel would be evaluated; {fix}")
        missing = self.missing_road
        if not missing or (not each_road_value and len(missing) < len(self.road)):
            return self
        if fmt.kind in ("binary", "kitti"):
            if fmt.kind == "kitti":
                what = "road is magenta, red and blue > 0"
            else:
                what = "road is a non-zero value" + (f" other than {param('ignore')} {','.join(map(str, fmt.ignore))}"
                                                     if fmt.ignore else "")
            raise DatasetError(f"no label in {where} marks road ({param('label_format')} {fmt.kind}: {what}); they "
                               f"hold {self.held()}; give labels that mark road, or their format with "
                               f"{param('label_format')}")
        names = "; ".join(_value_text(v) for v in missing) if fmt.kind == "palette" else \
            ",".join(_value_text(v) for v in missing)
        eight = (" (the labels are 8-bit: ids 0…255)" if fmt.kind == "class-id" and self.bits == (8,)
                 and any(v > 255 for v in missing) else "")
        near = f" (within {param('tolerance')} {fmt.tolerance})" if fmt.kind == "palette" else ""
        raise DatasetError(f"{param('road')} {names} {'is' if len(missing) == 1 else 'are'} in no label in "
                           f"{where}{near}{eight}: the labels hold {self.held()}; give the road's "
                           f"{'colours' if fmt.kind == 'palette' else 'class ids'} with {param('road')}")


def scan_labels(frames: Sequence[LabelledFrame], label_format: LabelFormat) -> LabelScan:
    """Read every label of ``frames`` once and count what they hold (:class:`LabelScan`); refuses nothing but a
    label that cannot be read or decoded (:func:`read_label`'s errors). :meth:`LabelScan.check` (or
    :func:`check_labels`) refuses a set that would score nothing."""
    if not frames:
        raise DatasetError("no label to scan: give a set of labelled frames")
    values: Counter = Counter()
    road: dict[Any, int] = {}
    unevaluated, bits = [], set()
    for frame in frames:
        img = read_label_image(frame.label)
        bits.add(8 * img.dtype.itemsize)
        distinct, counts = _distinct(label_format.prepare(img, frame.label))
        valid = label_format._decode(distinct).valid[0]
        if not counts[valid].sum():
            unevaluated.append(frame.name)
        for value, count in zip(distinct[0].tolist(), counts.tolist()):
            values[tuple(value) if isinstance(value, list) else value] += count
        for value, hit in label_format.road_values(distinct, valid).items():
            road[value] = road.get(value, 0) + int(counts[hit].sum())
    return LabelScan(label_format, tuple(sorted({str(f.label.parent) for f in frames})), len(frames), dict(values),
                     road, tuple(unevaluated), tuple(sorted(bits)))


def check_labels(frames: Sequence[LabelledFrame], label_format: LabelFormat, *,
                 each_road_value: bool | None = None) -> LabelScan:
    """:func:`scan_labels` then :meth:`LabelScan.check` (``each_road_value`` as there): the scan of a set fit to
    score (or to train on).

    Raises:
        DatasetError: as :meth:`LabelScan.check`. CorruptFileError, InputFileError: a label that cannot be read.
    """
    return scan_labels(frames, label_format).check(each_road_value=each_road_value)


# ---------------------------------------------------------------------------------------------------------------
# scores


def frame_evaluated(row: dict[str, Any]) -> bool:
    """Whether a per-frame row (:func:`frame_scores`) has an evaluated pixel."""
    return row["tp"] + row["fp"] + row["fn"] + row["tn"] > 0


def frame_scores(name: str, counts: Counts) -> dict[str, Any]:
    """One frame's row: its name, its confusion counts (pixels) and its precision, recall, F and IoU (fractions).

    A frame without an evaluated pixel (its label don't care everywhere) has no scores (None): nothing was
    measured on it. A frame with evaluated pixels but no road in its label nor in the prediction scores 1.0 on
    each (:meth:`~freespace.evaluation.metrics.Counts.metrics`: nothing to get wrong, every pixel a true negative);
    its counts add nothing to the pooled precision, recall, F and IoU.
    """
    scores = counts.metrics() if counts.tp + counts.fp + counts.fn + counts.tn else dict.fromkeys(POOLED_METRICS)
    return {"frame": name, "tp": counts.tp, "fp": counts.fp, "fn": counts.fn, "tn": counts.tn,
            **{k: scores[k] for k in POOLED_METRICS}}


def bootstrap_intervals(counts: np.ndarray, *, resamples: int = 2000, level: float = 0.95,
                        seed: int = 0) -> dict[str, list[float]] | None:
    """Frame-level percentile bootstrap intervals of the pooled precision, recall, F and IoU.

    Args:
        counts: ``N×3`` per-frame ``tp, fp, fn`` (pixels) of the N scored frames.
        resamples: bootstrap resamples (frames drawn with replacement, their counts summed, the metric computed).
        level: the interval's coverage. seed: the resampling's seed (the same counts give the same interval).

    Returns:
        ``{metric: [low, high]}`` for :data:`POOLED_METRICS` (fractions); None with fewer than
        :data:`MIN_INTERVAL_FRAMES` frames (one frame's resamples are all that frame: no interval). A resample in
        which a metric is undefined (no predicted road for precision, no road for recall, neither for F and IoU)
        is left out of that metric's interval; if all are, the interval is the convention's point 1.0
        (:meth:`~freespace.evaluation.metrics.Counts.metrics`).
    """
    counts = np.asarray(counts, np.float64).reshape(-1, 3)
    n = counts.shape[0]
    if n < MIN_INTERVAL_FRAMES:
        return None
    rng = np.random.default_rng(seed)
    sums = counts[rng.integers(0, n, size=(resamples, n))].sum(axis=1)  # resamples × 3
    tp, fp, fn = sums[:, 0], sums[:, 1], sums[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        metrics = (tp / (tp + fp), tp / (tp + fn), 2 * tp / (2 * tp + fp + fn), tp / (tp + fp + fn))
    q = [(1 - level) / 2 * 100, (1 + level) / 2 * 100]
    out = {}
    for k, values in zip(POOLED_METRICS, metrics):
        values = values[np.isfinite(values)]
        out[k] = [float(v) for v in np.percentile(values, q)] if values.size else [1.0, 1.0]
    return out


def interval_note(frames: int, *, resamples: int = 2000, level: float = 0.95, seed: int = 0) -> str:
    """What the ``intervals`` of ``frames`` scored frames are (:func:`bootstrap_intervals` with these settings),
    written beside them."""
    if frames < MIN_INTERVAL_FRAMES:
        return (f"none: a frame-level bootstrap interval needs {MIN_INTERVAL_FRAMES} scored frames at least, this set "
                f"has {frames}")
    return f"frame-level percentile bootstrap, {100 * level:g} %, {resamples} resamples, seed {seed}"


@dataclass
class PooledScores:
    """Per-frame counts of a labelled set (:func:`frame_scores` rows), pooled on demand."""

    rows: list[dict[str, Any]] = field(default_factory=list)

    def add(self, name: str, counts: Counts) -> None:
        """Add one frame's counts (a frame without an evaluated pixel too: it is listed, not scored)."""
        self.rows.append(frame_scores(name, counts))

    def summary(self, **bootstrap: Any) -> dict[str, Any]:
        """Pooled ``precision``, ``recall``, ``f_score``, ``iou`` (the scored frames' summed counts), their
        bootstrap ``intervals`` (None below :data:`MIN_INTERVAL_FRAMES` scored frames, ``interval`` says why), the
        number of scored ``frames``, and the frames left out for having no evaluated pixel (``unevaluated``:
        names, ``unevaluated_frames``: how many).

        Raises:
            DatasetError: no frame at all, no frame with an evaluated pixel, or no road in any scored label (recall,
                F and IoU would measure nothing).
        """
        if not self.rows:
            raise DatasetError("no frame was scored")
        scored = [r for r in self.rows if frame_evaluated(r)]
        unevaluated = [r["frame"] for r in self.rows if not frame_evaluated(r)]
        if not scored:
            raise DatasetError(f"none of the {len(self.rows)} frames has an evaluated pixel (every label don't care "
                               f"everywhere), so nothing can be scored; give labels that mark road and non-road")
        total = Counts(*(sum(r[k] for r in scored) for k in ("tp", "fp", "fn", "tn")))
        if total.tp + total.fn == 0:
            raise DatasetError(f"no label of the {len(scored)} scored frames marks road at an evaluated pixel, so "
                               f"recall, F and IoU would measure nothing; give labels that mark road")
        pooled = total.metrics()
        counts = np.array([[r["tp"], r["fp"], r["fn"]] for r in scored])
        return {**{k: pooled[k] for k in POOLED_METRICS}, "frames": len(scored),
                "unevaluated_frames": len(unevaluated), "unevaluated": unevaluated,
                "intervals": bootstrap_intervals(counts, **bootstrap),
                "interval": interval_note(len(scored), **bootstrap)}
