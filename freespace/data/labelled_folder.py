"""A labelled folder as a dataset: a user's own images and label images, paired by name, to train on.

``freespace train`` trains on the frames of such a folder (its options ``images``, ``labels``, and
``label_format`` or ``labels_like``); ``val_images``/``val_labels`` give validation frames apart, else the last share
of the frames by name order is held out (``val_share``). The labels are decoded by
:class:`freespace.evaluation.labelled.LabelFormat`, the one home of the label formats that ``evaluate`` reads too.

The frames are monocular: no right image, disparity, depth or calibration (the DS-Generator and the virtual views
need them, so ``augment`` is refused). Each frame is its own scenario (no drive to keep whole), its group
(``train`` or ``val``) its category.

Torch-free.
"""

from __future__ import annotations

import math
from pathlib import Path

from freespace.data.base import FrameRef, StereoRoadDataset
from freespace.evaluation.labelled import LabelFormat, LabelledFrame, read_label
from freespace.labels import RoadLabel

__all__ = ["LabelledFolderDataset", "held_out_by_name"]


class LabelledFolderDataset(StereoRoadDataset):
    """The frames of one or two labelled folders (``groups``: ``{"train": [...], "val": [...]}`` of
    :class:`~freespace.evaluation.labelled.LabelledFrame`, paired and checked by
    :func:`freespace.engine.labelled.labelled_frames`), their labels decoded by ``label_format``.

    A frame's name is its image's stem, unique over the groups.
    """

    name = "labelled folder"

    def __init__(self, groups: dict[str, list[LabelledFrame]], label_format: LabelFormat) -> None:
        self.groups = groups
        self.label_format = label_format
        super().__init__(groups["train"][0].image.parent, disparity_source="none")

    def _list(self) -> list[FrameRef]:
        frames = [FrameRef(name=f.name, category=group, scenario=f.name, left=f.image, label=f.label)
                  for group, members in self.groups.items() for f in members]
        return sorted(frames, key=lambda f: f.name)

    def read_label(self, frame: FrameRef) -> RoadLabel:
        """The frame's label, decoded by the folder's :class:`~freespace.evaluation.labelled.LabelFormat`."""
        return read_label(Path(frame.label), self.label_format)  # type: ignore[arg-type]


def held_out_by_name(names: list[str], share: float) -> tuple[list[str], list[str]]:
    """``names`` (sorted) split into training and validation frames: the last ``ceil(share · n)`` by name order are
    held out (at least one when ``share`` > 0, never all), so that consecutive frames of a video stay together and
    the validation frames come from the end of the drive. ``share`` 0 holds out none.

    Example:
        >>> held_out_by_name(["a", "b", "c", "d", "e"], 0.2)
        (['a', 'b', 'c', 'd'], ['e'])
    """
    names = sorted(names)
    n = min(len(names) - 1, math.ceil(share * len(names))) if share > 0 else 0
    return names[: len(names) - n], names[len(names) - n:]

