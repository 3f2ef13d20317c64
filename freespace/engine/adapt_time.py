"""Adapt's labels that reach the whole road (issue 70, item 1): carried along time, and completed by appearance.

**Along time**: when adapt's frames are a sequence — a video, or a folder of
consecutive frames — the teacher's confident labels of each round are carried from the next frames
(:mod:`freespace.datagen.temporal`: the road plane's homography between frames, from matched road pixels), so the
student learns the far road and the road beside the cars that the teacher is sure of only once the car is nearer.

The consecutive homographies are fitted once, on the frames at the model's size and the published model's road
(p ≥ 0.5 in the teacher's view); each round's labels are then carried along them. Held-out frames keep their place
in the chains but give no label (they stay out of training).

**By appearance** (``complete``): each training frame's label, after the carrying, has its don't care decided by a
graph cut on the frame's colours seeded with it (:func:`freespace.datagen.completion.complete_by_appearance`): road
grows up to the image's edges where it looks like the confident road.

NumPy and OpenCV only, never torch.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from freespace.errors import check_choice

__all__ = ["ACROSS_TIME", "MIN_SEQUENCE_SHARE", "check_across_time", "plan_sequence", "carried_labels",
           "round_labels"]

log = logging.getLogger(__name__)

#: the values of adapt's ``across_time``: ``auto`` carries labels when the frames are a sequence (at least
#: :data:`MIN_SEQUENCE_SHARE` of the consecutive pairs share a road homography), ``on`` whatever share, ``off`` never
ACROSS_TIME = ("auto", "on", "off")
#: ``auto``'s least share of consecutive pairs with a road homography: frames of one drive a few metres apart give
#: most pairs (CamVid at 15 frames a second: all; at one a second: a third); unrelated photos none
MIN_SEQUENCE_SHARE = 0.5


def check_across_time(value: Any) -> str:
    """``value`` if it is one of :data:`ACROSS_TIME`, else :class:`~freespace.errors.InvalidOptionError` naming
    ``across_time``."""
    return check_choice(value, ACROSS_TIME, "across_time")


def plan_sequence(images: np.ndarray, probs: np.ndarray, setting: str) -> tuple[list | None, dict[str, Any]]:
    """The consecutive road homographies of adapt's frames, or None when labels are not carried.

    Args:
        images: ``N×h×w×3 uint8`` RGB frames at the model's size, in the input's order.
        probs: ``N×h×w`` road probabilities of them (the teacher's view).
        setting: one of :data:`ACROSS_TIME`.

    Returns:
        The ``N − 1`` homographies (``None`` entries where a pair shares too little road) or None, and the record:
        ``setting``, ``pairs``, ``pairs_fitted``, ``used``.
    """
    from freespace.datagen.temporal import CarryOptions, sequence_homographies

    record: dict[str, Any] = {"setting": check_across_time(setting), "pairs": max(len(images) - 1, 0),
                              "pairs_fitted": 0, "used": False}
    if setting == "off" or len(images) < 2:
        return None, record
    steps = sequence_homographies(images, [p >= 0.5 for p in probs], CarryOptions())
    fitted = sum(H is not None for H in steps)
    record.update(pairs_fitted=fitted, used=setting == "on" or fitted >= MIN_SEQUENCE_SHARE * len(steps))
    log.info("adapt: %d of %d consecutive pairs share a road homography; labels %s along time", fitted, len(steps),
             "carried" if record["used"] else "not carried")
    return (steps if record["used"] else None), record


def carried_labels(images: np.ndarray, labels: np.ndarray, steps: list, held: np.ndarray) -> tuple[np.ndarray,
                                                                                                  dict[str, float]]:
    """Each frame's label with the road its next frames' labels saw (:func:`freespace.datagen.temporal.carry_along`
    with its default settings), the held-out frames giving none (their own labels are carried too, and not trained
    on; the shares count the training frames).

    Args:
        images: ``N×h×w×3 uint8`` RGB frames. labels: their ``N×h×w uint8`` pseudo-labels (1 road, 0 not road, 255
            don't care). steps: :func:`plan_sequence`'s homographies. held: indices of the held-out frames.

    Returns:
        ``N×h×w uint8`` labels and the carrying's shares (``gained``, ``overridden``, ``conflicts``).
    """
    from freespace.datagen.temporal import CarryOptions, carry_along

    voters = np.ones(len(images), bool)
    voters[held] = False
    out, record = carry_along(list(images), list(labels), None, CarryOptions(), steps, voters=list(voters))
    return np.stack(out), {k: record[k] for k in ("gained", "overridden", "conflicts")}


def round_labels(images: np.ndarray, probs: np.ndarray, labels: np.ndarray, steps: list | None, held: np.ndarray,
                 complete: bool,
                 release: tuple[float, float] = (0.0, 1.0)) -> tuple[np.ndarray | None, dict[str, float]]:
    """A round's labels of adapt's frames: the teacher's confident label, carried along ``steps`` (when not None)
    and completed by appearance on the training frames (with ``complete``); None when neither applies (adapt then
    takes the confident label as it is).

    Args:
        images: ``N×h×w×3 uint8`` RGB frames. probs: their ``N×h×w`` road probabilities (the teacher's view).
        labels: the teacher's confident labels of them (``N×h×w uint8``: 1 road, 0 not road, 255 don't care; adapt's
            ``pseudo_labels``). steps: :func:`plan_sequence`'s homographies or None.
        held: indices of the held-out frames (no label given, none completed).
        complete: complete the labels by appearance. release: the distance and far share of the confident not road
            the completion may also relabel (:func:`freespace.datagen.completion.released_seeds`; 0: none).

    Returns:
        ``N×h×w uint8`` labels (1 road, 0 not road, 255 don't care) or None, and the round's record: the carrying's
        shares (:func:`carried_labels`) and ``completed``, the share of the training frames' pixels the completion
        labelled.
    """
    if steps is None and not complete:
        return None, {}
    labels = labels.copy()
    record: dict[str, float] = {}
    if steps is not None:
        labels, record = carried_labels(images, labels, steps, held)
    if complete:
        from freespace.datagen.completion import complete_by_appearance

        train = np.setdiff1d(np.arange(len(images)), held)
        before = int((labels[train] == 255).sum())
        for i in train:
            labels[i] = complete_by_appearance(images[i], probs[i], seeds=labels[i], release=release[0],
                                               far=release[1])
        record["completed"] = round((before - int((labels[train] == 255).sum())) / max(labels[train].size, 1), 4)
    return labels, record
