"""The frames a training run on a labelled folder reads (``freespace train`` with ``images`` and ``labels``), paired,
split and checked once, before anything is written.

Every label is read and decoded when the run is checked (:meth:`TrainConfig.check
<freespace.engine.config.TrainConfig.check>`), so that a user's mistake ends the command in one line with nothing
written: images without labels or labels without images (named and counted), a label of another size than its
image, labels in colour where ids are expected (or the other way round), a road id or colour that no label holds,
no road pixel anywhere, fewer training frames than a batch.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from freespace.errors import DatasetError, InvalidOptionError, param

__all__ = ["LabelledSet", "labelled_frames", "check_source", "label_format_of", "FOLDER_OPTIONS"]

#: the options of a labelled folder (``images``), refused with a dataset
FOLDER_OPTIONS = ("label_format", "labels_like", "road", "ignore", "tolerance", "val_images", "val_labels")


@dataclass(frozen=True)
class LabelledSet:
    """A labelled folder's frames as a run uses them: ``groups`` ``{"train": [...], "val": [...]}`` of
    :class:`~freespace.evaluation.labelled.LabelledFrame`, the ``label_format`` that decodes them, whether the
    validation frames were ``held_out`` of the training folder (the last by name) and the labels' ``stats``
    (:func:`~freespace.evaluation.labelled.scan_labels` of every label)."""

    groups: dict[str, list[Any]]
    label_format: Any
    held_out: bool
    stats: dict[str, Any]

    def dataset(self) -> Any:
        """The frames as a :class:`~freespace.data.labelled_folder.LabelledFolderDataset`."""
        from freespace.data.labelled_folder import LabelledFolderDataset

        same = self.groups["val"] is self.groups["train"]  # val_share 0: the training frames validate
        return LabelledFolderDataset({k: v for k, v in self.groups.items() if not (same and k == "val")},
                                     self.label_format)

    def files(self) -> dict[str, list[Path]]:
        """The files read, by the option that named their folder (``images``, ``labels``, and ``val_images``,
        ``val_labels`` when given)."""
        held = self.held_out and self.groups["val"] is not self.groups["train"]
        own = self.groups["train"] + (self.groups["val"] if held else [])
        found = {"images": [f.image for f in own], "labels": [f.label for f in own]}
        if not self.held_out:
            found.update(val_images=[f.image for f in self.groups["val"]],
                         val_labels=[f.label for f in self.groups["val"]])
        return found

    def record(self, config: Any) -> dict[str, Any]:
        """What ``metrics.json`` says of the frames: the folders, the label format, how validation was chosen,
        the counts and the labels' road share."""
        val = (f"the last {len(self.groups['val'])} of the {len(self.groups['train']) + len(self.groups['val'])} "
               f"frames of {config.images} by name (val_share {config.val_share:g})" if self.held_out and
               self.groups["val"] is not self.groups["train"] else
               "none held out (val_share 0): validation and test are the training frames" if self.held_out else
               f"{config.val_images}")
        return {"images": config.images, "labels": config.labels, "label_format": self.label_format.describe(),
                "labels_like": config.labels_like, "validation": val,
                "frames": {k: len(v) for k, v in self.groups.items()}, "labels_stats": self.stats}


def labelled_frames(config: Any) -> LabelledSet:
    """The frames of ``config``'s labelled folder (``images``/``labels``, and ``val_images``/``val_labels`` or the
    held-out ``val_share``; ``max_frames``: the first N by name), every label decoded and checked; computed once
    per configuration.

    Raises:
        InputFileError: a folder missing, images without labels or labels without images. DatasetError: a label of
            another size than its image, a road value in no label (no road pixel in any training label), no
            evaluated pixel, the same frame names in the training and validation folders. CorruptFileError: a label
            of the wrong kind for its format. InvalidOptionError: fewer training frames than ``batch_size``.
    """
    cached = getattr(config, "_labelled", None)
    if cached is not None:
        return cached
    from freespace.data.labelled_folder import held_out_by_name
    from freespace.evaluation.labelled import pair_labelled_frames, scan_labels

    fmt = label_format_of(config)
    frames = pair_labelled_frames(config.images, config.labels, fmt, strict=True)
    if config.max_frames is not None:
        frames = frames[: config.max_frames]
    if config.val_images is not None:
        val = pair_labelled_frames(config.val_images, config.val_labels, fmt, strict=True, images_flag="val_images",
                                   labels_flag="val_labels")
        train, held_out = frames, False
        both = sorted({f.name for f in train} & {f.name for f in val})
        if both:
            raise DatasetError(f"{len(both)} frame name{'s are' if len(both) > 1 else ' is'} in both the training and "
                               f"the validation images ({', '.join(both[:3])}): the same frames would be trained and "
                               f"validated on; give validation frames apart ({param('val_images')})")
    else:
        by_name = {f.name: f for f in frames}
        names_train, names_val = held_out_by_name(list(by_name), config.val_share)
        train, val, held_out = [by_name[n] for n in names_train], [by_name[n] for n in names_val], True
    if len(train) < config.batch_size:
        raise InvalidOptionError(f"{len(train)} training frames are fewer than {param('batch_size')} "
                                 f"{config.batch_size}; lower it to at most {len(train)}, or label more frames")
    _check_sizes(train + val)
    scan = scan_labels(train, fmt).check()  # no evaluated pixel, or a road value in no label: refused
    if val:
        scan_labels(val, fmt).check(each_road_value=False)  # a validation set may hold few road classes
    stats = {"frames": scan.frames, "unevaluated": list(scan.unevaluated), "values": scan.held(),
             "road_pixels": {str(k): v for k, v in scan.road.items()}, "bits": list(scan.bits)}
    found = LabelledSet({"train": train, "val": val or train}, fmt, held_out, stats)
    object.__setattr__(config, "_labelled", found)
    return found


def _check_sizes(frames: list[Any]) -> None:
    """Refuse a label whose size differs from its image's (read from the files' headers), naming the first and
    counting them."""
    wrong = [(f, a, b) for f in frames for a, b in [(_size(f.image, "image"), _size(f.label, "label"))] if a != b]
    if wrong:
        f, a, b = wrong[0]
        many = len(wrong) > 1
        raise DatasetError(f"{len(wrong)} label{'s are' if many else ' is'} not the size of "
                           f"{'their' if many else 'its'} image (first: {f.label} is {b[0]}×{b[1]}, {f.image} "
                           f"{a[0]}×{a[1]}, W×H); a label marks the pixels of its own image: give labels at the "
                           f"images' size")


def _size(path: Path, what: str) -> tuple[int, int]:
    """The upright size (W, H) an image file's header states (nothing decoded)."""
    from freespace.errors import CorruptFileError
    from freespace.io.codecs import image_header_size
    from freespace.io.files import read_bytes
    from freespace.limits import MAX_IMAGE_FILE_BYTES

    size = image_header_size(read_bytes(path, what, MAX_IMAGE_FILE_BYTES))
    if size is None:
        raise CorruptFileError(f"cannot decode {what} {path}: not a readable image file")
    return size


def check_source(config: Any) -> None:
    """Refuse a :class:`~freespace.engine.config.TrainConfig` whose frames come from nowhere or from two places.

    What the frames come from: a dataset (``dataset`` and ``root``) or a labelled folder (``images`` and
    ``labels`` with ``label_format`` or ``labels_like``), never both, and the options of the one chosen only."""
    if config.images is not None:
        given = [k for k in ("dataset", "root", "splits_dir") if getattr(config, k) is not None]
        if given:
            raise InvalidOptionError(f"{param('images')} trains on a labelled folder; {param(given[0])} is for a "
                                     f"dataset: give one or the other")
        if config.labels is None:
            raise InvalidOptionError(f"{param('images')} needs {param('labels')}, the folder of their label "
                                     f"images (paired by name)")
        if config.augment:
            raise InvalidOptionError(f"{param('augment')} {','.join(config.augment)} needs right images or a road "
                                     f"plane, which a labelled folder has not; train without it (the "
                                     f"conventional augmentation, {param('flip')}, {param('photometric')}, "
                                     f"{param('zoom')} and {param('crop_top')} work)")
        if config.human_share:
            raise InvalidOptionError(f"{param('human_share')} is for a dataset with a label tree; a labelled "
                                     f"folder's labels are all the user's")
        if (config.val_images is None) != (config.val_labels is None):
            raise InvalidOptionError(f"give {param('val_images')} and {param('val_labels')} together (validation "
                                     f"images and their labels)")
        label_format_of(config)  # a format, road, ignore and tolerance that go together
        return
    given = [k for k in FOLDER_OPTIONS if getattr(config, k) is not None]
    if given:
        raise InvalidOptionError(f"{param(given[0])} is for a labelled folder ({param('images')} and "
                                 f"{param('labels')}); a dataset's labels are its layout's")
    if config.dataset is None or config.root is None:
        missing = "dataset" if config.dataset is None else "root"
        raise InvalidOptionError(f"give {param('dataset')} and {param('root')} (a dataset's folder), or "
                                 f"{param('images')} and {param('labels')} (a labelled folder); "
                                 f"{param(missing)} is missing")

def label_format_of(config: Any) -> Any:
    """The :class:`~freespace.evaluation.labelled.LabelFormat` of a labelled folder's labels
    (:func:`~freespace.evaluation.label_presets.resolve_label_format` of the config's ``label_format``,
    ``labels_like``, ``road``, ``ignore`` and ``tolerance``), or None with a dataset."""
    if config.images is None:
        return None
    from freespace.evaluation.label_presets import resolve_label_format

    return resolve_label_format(config.label_format, config.labels_like, config.road, config.ignore,
                                config.tolerance)
