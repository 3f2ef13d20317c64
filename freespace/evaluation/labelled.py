"""Human-labelled image folders in the formats real sets come in: pairing, decoding, per-frame scores, intervals.

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

Scores are counted at each label's own size (the prediction is resized to it) and pooled over frames by summing
the counts (never an average of per-frame scores, :mod:`freespace.evaluation.metrics`); the interval of a pooled
score is a frame-level bootstrap (:func:`bootstrap_intervals`): frames, not pixels, are the independent units.

Never imports torch.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from freespace.errors import CorruptFileError, DatasetError, InputFileError, InvalidOptionError, param
from freespace.evaluation.metrics import Counts
from freespace.io.codecs import IMAGE_SUFFIXES, read_image, road_label_from_image
from freespace.io.files import PathLike
from freespace.labels import RoadLabel

__all__ = ["LABEL_FORMATS", "LabelFormat", "LabelledFrame", "parse_label_format", "pair_labelled_frames",
           "frame_scores", "bootstrap_intervals", "PooledScores", "POOLED_METRICS"]

LABEL_FORMATS = ("kitti", "binary", "class-id", "palette")
#: the pooled metrics that get a bootstrap interval
POOLED_METRICS = ("precision", "recall", "f_score", "iou")


@dataclass(frozen=True)
class LabelFormat:
    """How a label image is decoded (see the module docstring).

    Attributes:
        kind: one of :data:`LABEL_FORMATS`.
        road: ``class-id``: the road class ids; ``palette``: the road colours as ``(R, G, B)``; else empty.
        ignore: the don't-care ids / grey values / colours.
        tolerance: ``palette``: the largest difference, in 8-bit levels on any channel, from a listed colour
            (scaled labels blend colours at class edges).
    """

    kind: str
    road: tuple = ()
    ignore: tuple = ()
    tolerance: int = 0

    def describe(self) -> dict[str, Any]:
        """A JSON-ready record of the format (written beside every score it produced)."""
        return {"kind": self.kind, "road": [list(v) if isinstance(v, tuple) else v for v in self.road],
                "ignore": [list(v) if isinstance(v, tuple) else v for v in self.ignore], "tolerance": self.tolerance}

    def decode(self, img: np.ndarray, path: PathLike = "label") -> RoadLabel:
        """The :class:`RoadLabel` of a label image ``img`` (``H×W`` or ``H×W×3`` RGB ``uint8``) read from ``path``.

        Raises:
            CorruptFileError: the image has not the channels its format needs (a colour image of class ids, a grey
                one for a palette).
        """
        if self.kind == "kitti":
            if img.ndim != 3:
                raise CorruptFileError(f"label {path} is a grey image, but {param('label_format')} kitti needs "
                                       f"KITTI's colour ground truth (road magenta, non-road red); a grey mask is "
                                       f"{param('label_format')} binary")
            return road_label_from_image(img)
        if self.kind == "palette":
            if img.ndim != 3:
                raise CorruptFileError(f"label {path} is a grey image, but {param('label_format')} palette needs "
                                       f"colours; class ids are {param('label_format')} class-id")
            return RoadLabel(road=self._near(img, self.road), valid=~self._near(img, self.ignore))
        grey = _grey(img, path, self.kind)
        road = grey > 0 if self.kind == "binary" else np.isin(grey, self.road)
        valid = ~np.isin(grey, self.ignore)
        return RoadLabel(road=road & valid, valid=valid)

    def _near(self, img: np.ndarray, colours: tuple) -> np.ndarray:
        out = np.zeros(img.shape[:2], bool)
        for colour in colours:
            out |= (np.abs(img.astype(np.int16) - np.asarray(colour, np.int16)).max(axis=2) <= self.tolerance)
        return out


def _grey(img: np.ndarray, path: PathLike, kind: str) -> np.ndarray:
    if img.ndim == 2:
        return img
    if np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 1], img[..., 2]):
        return img[..., 0]
    raise CorruptFileError(f"label {path} is a colour image, but {param('label_format')} {kind} reads grey values; "
                           f"colour labels are {param('label_format')} palette (class colours) or kitti (KITTI road "
                           f"ground truth)")


def _ints(text: str | None, what: str) -> tuple[int, ...]:
    if not text:
        return ()
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise InvalidOptionError(f"{param(what)} takes comma-separated integers (e.g. 3 or 3,4), "
                                 f"got {text!r}") from None
    if any(not 0 <= v <= 255 for v in values):
        raise InvalidOptionError(f"{param(what)} values are 8-bit label values in [0, 255], got {text!r}")
    return values


def _colours(text: str | None, what: str) -> tuple[tuple[int, int, int], ...]:
    if not text:
        return ()
    colours = []
    for part in text.split(";"):
        values = _ints(part, what)
        if len(values) != 3:
            raise InvalidOptionError(f"{param(what)} takes R,G,B colours separated by ';' (e.g. 128,64,128), "
                                     f"got {text!r}")
        colours.append(values)
    return tuple(colours)  # type: ignore[return-value]


def parse_label_format(kind: str, road: str | None = None, ignore: str | None = None,
                       tolerance: int | None = None) -> LabelFormat:
    """The :class:`LabelFormat` the command line names.

    Args:
        kind: one of :data:`LABEL_FORMATS`.
        road: ``class-id``: road ids (``"3"``, ``"3,4"``); ``palette``: road colours (``"128,64,128"``, several
            separated by ``;``); not accepted by ``kitti`` and ``binary``.
        ignore: don't-care ids, grey values or colours in the same notation (not accepted by ``kitti``).
        tolerance: ``palette`` only: 8-bit levels (default 8).

    Raises:
        InvalidOptionError: an unknown format, a value the format does not take, or one it needs missing.
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
        return LabelFormat(kind, _colours(road, "road"), _colours(ignore, "ignore"),
                           8 if tolerance is None else tolerance)
    return LabelFormat(kind, _ints(road, "road"), _ints(ignore, "ignore"))


@dataclass(frozen=True)
class LabelledFrame:
    """One image and its label file; ``name`` is the image's stem."""

    name: str
    image: Path
    label: Path

    def read(self, label_format: LabelFormat) -> tuple[np.ndarray, RoadLabel]:
        """The image (``H×W×3`` RGB ``uint8``) and its label, decoded by ``label_format``."""
        return read_image(self.image), label_format.decode(read_image(self.label, what="label"), self.label)


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


def pair_labelled_frames(images: PathLike, labels: PathLike, label_format: LabelFormat) -> list[LabelledFrame]:
    """Pair every label file of ``labels`` with the image of the same name in ``images``, sorted by name.

    Images without a label are left out (a set may label a few of its frames, as CamVid's dusk labels do); a label
    without its image is an error, as are two images of one name (``a.png`` and ``a.jpg``: which did the label
    mean?).

    Raises:
        InputFileError: a folder is missing, or a label has no image. DatasetError: no label file, or a name clash.
    """
    image_dir, label_dir = _folder(images, "images"), _folder(labels, "labels")
    if image_dir.resolve() == label_dir.resolve():
        raise InvalidOptionError(f"{param('images')} and {param('labels')} are the same folder ({image_dir}); give "
                                 f"the folder of label images apart from the images")
    by_stem: dict[str, Path] = {}
    for path in sorted(image_dir.iterdir()):
        if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file():
            if path.stem in by_stem:
                raise DatasetError(f"two images are named {path.stem!r} in {image_dir} ({by_stem[path.stem].name}, "
                                   f"{path.name}); keep one")
            by_stem[path.stem] = path
    frames = []
    for label in sorted(label_dir.iterdir()):
        if label.suffix.lower() not in IMAGE_SUFFIXES or not label.is_file():
            continue
        name = _image_name(label, label_format.kind)
        if name is None:
            continue
        if name not in by_stem:
            raise InputFileError(f"label {label} has no image {name}.* in {image_dir}; give the images' folder with "
                                 f"{param('images')}")
        frames.append(LabelledFrame(name, by_stem[name], label))
    if len({f.name for f in frames}) != len(frames):
        raise DatasetError(f"two labels in {label_dir} belong to one image; keep one label per frame")
    if not frames:
        hint = " (KITTI ground truth is named <cat>_road_<id>.png)" if label_format.kind == "kitti" else ""
        raise DatasetError(f"no label images in {label_dir}{hint}")
    return frames


def frame_scores(name: str, counts: Counts) -> dict[str, Any]:
    """One frame's row: its name, its confusion counts (pixels) and its precision, recall, F and IoU (fractions)."""
    m = counts.metrics()
    return {"frame": name, "tp": counts.tp, "fp": counts.fp, "fn": counts.fn, "tn": counts.tn,
            **{k: m[k] for k in POOLED_METRICS}}


def bootstrap_intervals(counts: np.ndarray, *, resamples: int = 2000, level: float = 0.95,
                        seed: int = 0) -> dict[str, list[float]]:
    """Frame-level percentile bootstrap intervals of the pooled precision, recall, F and IoU.

    Args:
        counts: ``N×3`` per-frame ``tp, fp, fn`` (pixels) of N ≥ 1 frames.
        resamples: bootstrap resamples (frames drawn with replacement, their counts summed, the metric computed).
        level: the interval's coverage. seed: the resampling's seed (the same counts give the same interval).

    Returns:
        ``{metric: [low, high]}`` for :data:`POOLED_METRICS` (fractions); with one frame the interval is the point.
    """
    counts = np.asarray(counts, np.float64)
    n = counts.shape[0]
    rng = np.random.default_rng(seed)
    sums = counts[rng.integers(0, n, size=(resamples, n))].sum(axis=1)  # resamples × 3
    tp, fp, fn = sums[:, 0], sums[:, 1], sums[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        precision = np.where(tp + fp > 0, tp / (tp + fp), 1.0)
        recall = np.where(tp + fn > 0, tp / (tp + fn), 1.0)
        f = np.where(precision + recall > 0, 2 * precision * recall / (precision + recall), 0.0)
        iou = np.where(tp + fp + fn > 0, tp / (tp + fp + fn), 1.0)
    q = [(1 - level) / 2 * 100, (1 + level) / 2 * 100]
    return {k: [float(v) for v in np.percentile(values, q)]
            for k, values in zip(POOLED_METRICS, (precision, recall, f, iou))}


@dataclass
class PooledScores:
    """Per-frame counts of a labelled set, pooled on demand."""

    rows: list[dict[str, Any]] = field(default_factory=list)

    def add(self, name: str, counts: Counts) -> None:
        """Add one frame's counts."""
        self.rows.append(frame_scores(name, counts))

    def summary(self, **bootstrap: Any) -> dict[str, Any]:
        """Pooled ``precision``, ``recall``, ``f_score``, ``iou`` (summed counts), their bootstrap ``intervals``
        and the number of ``frames``."""
        if not self.rows:
            raise DatasetError("no frame was scored")
        total = Counts(*(sum(r[k] for r in self.rows) for k in ("tp", "fp", "fn", "tn")))
        pooled = total.metrics()
        counts = np.array([[r["tp"], r["fp"], r["fn"]] for r in self.rows])
        return {**{k: pooled[k] for k in POOLED_METRICS}, "frames": len(self.rows),
                "intervals": bootstrap_intervals(counts, **bootstrap)}
