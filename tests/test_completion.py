"""Labels that reach the whole road (issue 70, item 1): a teacher's confident label completed by appearance, and
class-balanced thresholds per band (``freespace.datagen.completion``)."""

from __future__ import annotations

import numpy as np
import pytest

from freespace.datagen.completion import balanced_label, complete_by_appearance, confident_label, released_seeds
from freespace.errors import InvalidOptionError, ShapeMismatchError
from freespace.labels import IGNORE_INDEX


def _scene() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A grey road (rows 40–79) under a green verge and blue sky, with noise; a teacher sure of the near road
    (rows 60–79) and of the sky, unsure (p 0.6) of the far road (rows 40–59) and of the verge (p 0.4)."""
    rng = np.random.default_rng(0)
    image = np.empty((80, 120, 3), np.uint8)
    image[:20] = (70, 120, 200)
    image[20:40] = (60, 140, 60)
    image[40:] = (110, 110, 110)
    image = np.clip(image.astype(int) + rng.integers(-8, 9, image.shape), 0, 255).astype(np.uint8)
    prob = np.zeros((80, 120), np.float32)
    prob[20:40], prob[40:60], prob[60:] = 0.4, 0.6, 0.97
    road = np.zeros((80, 120), bool)
    road[40:] = True
    return image, prob, road


def test_appearance_completes_the_far_road_and_keeps_the_seeds() -> None:
    image, prob, road = _scene()
    confident = confident_label(prob)
    assert (confident[40:60] == IGNORE_INDEX).all() and (confident[60:] == 1).all() and (confident[:20] == 0).all()
    completed = complete_by_appearance(image, prob)
    assert (completed[60:] == 1).all() and (completed[:20] == 0).all()  # the seeds stay
    assert (completed[40:60] == 1).mean() > 0.95  # the far road, unsure, looks like the near road
    assert (completed[20:40] == 0).mean() > 0.95  # the verge does not
    one_class = complete_by_appearance(image, np.full((80, 120), 0.97, np.float32))
    assert (one_class == 1).all()  # no seed of not road: the confident label as it is


def test_released_seeds_let_the_cut_take_back_a_far_road_the_teacher_is_sure_of() -> None:
    image, prob, road = _scene()
    prob = prob.copy()
    prob[40:60] = 0.02  # the far road: the teacher is sure it is not road
    assert (complete_by_appearance(image, prob)[40:60] == 0).all()  # completion alone cannot reach it
    released = released_seeds(confident_label(prob), prob, 0.3)
    assert released[40:60].all() and not released[:40].any() and not released[60:].any()  # the seeds within 24 rows
    completed = complete_by_appearance(image, prob, release=0.3)
    assert (completed[40:60] == 1).mean() > 0.95  # grey like the near road: road
    assert (completed[20:40] == 0).mean() > 0.95 and (completed[:20] == 0).all()  # the green verge, the sky stay
    prob[70:, :30] = 0.02  # not road beside the car's own road (a pavement), near the bottom
    near = released_seeds(confident_label(prob), prob, 0.3)
    far = released_seeds(confident_label(prob), prob, 0.3, far=0.5)  # above row 60 + 0.5 × 20 only
    assert near[70:, :30].any() and not far[70:].any() and far[40:60].all()
    with pytest.raises(InvalidOptionError, match="release must be in"):
        released_seeds(confident_label(prob), prob, 1.5)


def test_balanced_thresholds_keep_each_band_labelled() -> None:
    _, prob, _ = _scene()
    prob = prob.copy()
    prob[40:60] = np.linspace(0.55, 0.8, 120, dtype=np.float32)  # a far road the teacher is never sure of
    assert (confident_label(prob)[40:60] == IGNORE_INDEX).all()
    balanced = balanced_label(prob, share=0.5, bands=4, min_confidence=0.6)
    far = balanced[40:60]
    assert (far == 1).mean() == pytest.approx(0.5, abs=0.05) and not (far == 0).any()
    assert (balanced[60:] == 1).all() and (balanced[:20] == 0).all()


def test_bad_inputs_are_one_line() -> None:
    image, prob, _ = _scene()
    with pytest.raises(ShapeMismatchError, match="give the probability of that image"):
        complete_by_appearance(image[:40], prob)
    with pytest.raises(InvalidOptionError, match="share must be in"):
        balanced_label(prob, share=0)
    with pytest.raises(InvalidOptionError, match="H×W map"):
        confident_label(prob[None])
