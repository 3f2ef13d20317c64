"""Road labels carried along time (freespace.datagen.temporal): the road plane's homography from matched road pixels,
chained along frames, and the votes that carry a later frame's road to an earlier one where the images agree."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from freespace.datagen.completion import complete_by_appearance
from freespace.datagen.temporal import CarryOptions, carried_votes, carry_along, chain_homographies, road_homography
from freespace.errors import InvalidOptionError, ShapeMismatchError
from freespace.labels import IGNORE_INDEX

H_W = (240, 320)
#: a forward step of the camera over a plane: the image expands away from a vanishing point near the top
FORWARD = np.array([[1.06, 0.0, -9.0], [0.0, 1.06, -4.0], [0.0, 2.0e-4, 1.0]])


def _texture(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    blocks = rng.integers(0, 256, (H_W[0] // 6, H_W[1] // 6, 3), dtype=np.uint8)
    return cv2.resize(blocks, H_W[::-1], interpolation=cv2.INTER_NEAREST)


def _next(image: np.ndarray, H: np.ndarray) -> np.ndarray:
    """The frame a camera that moved by ``H`` sees (its pixel x shows the earlier pixel H⁻¹x)."""
    return cv2.warpPerspective(image, H, H_W[::-1], flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def _bottom(rows: int) -> np.ndarray:
    mask = np.zeros(H_W, bool)
    mask[-rows:] = True
    return mask


def _mapped(H: np.ndarray, u: float, v: float) -> np.ndarray:
    x = H @ np.array([u, v, 1.0])
    return x[:2] / x[2]


def test_the_homography_of_matched_road_pixels_is_the_planes() -> None:
    a = _texture(0)
    b = _next(a, FORWARD)
    H = road_homography(a, b, _bottom(160), _bottom(160))
    assert H is not None
    for u, v in ((40, 200), (160, 150), (300, 230)):
        assert np.abs(_mapped(H, u, v) - _mapped(FORWARD, u, v)).max() < 1.0


def test_unrelated_frames_give_no_homography() -> None:
    assert road_homography(_texture(0), _texture(1), _bottom(160), _bottom(160)) is None


def test_frames_of_two_sizes_are_refused() -> None:
    with pytest.raises(ShapeMismatchError, match="one camera"):
        road_homography(_texture(0), _texture(0)[:-2], _bottom(160), _bottom(160)[:-2])


def test_chains_compose_and_break_after_a_missing_step() -> None:
    A, B = FORWARD, np.diag([1.0, 1.0, 1.0])
    B[0, 2] = 5.0
    chain = chain_homographies([A, B, None, A])
    assert np.allclose(chain[0], A / A[2, 2])
    composed = B @ A
    assert np.allclose(chain[1], composed / composed[2, 2])
    assert chain[2] is None and chain[3] is None


def test_a_later_frames_road_fills_the_earlier_frames_dont_care() -> None:
    a = _texture(2)
    b = _next(a, FORWARD)
    label_a = np.full(H_W, IGNORE_INDEX, np.uint8)
    label_a[-40:] = 1
    label_b = np.zeros(H_W, np.uint8)
    label_b[-150:] = 1  # the later frame is sure of more road
    road, other = carried_votes(a, [(b, label_b, FORWARD)])
    target = np.zeros(H_W, bool)  # a's pixels that land in b's road, away from the borders
    for v in range(100, 200, 10):
        for u in range(40, 280, 20):
            x = _mapped(FORWARD, u, v)
            target[v, u] = x[1] > H_W[0] - 150 + 2 and 2 < x[0] < H_W[1] - 2
    assert target.sum() > 20
    assert (road[target] == 1).all() and (other[target] == 0).all()
    labels, record = carry_along([a, b], [label_a, label_b], [_bottom(160)] * 2, CarryOptions(window=1))
    assert record["pairs_fitted"] == 1 and record["gained"] > 0.1
    assert (labels[0][target] == 1).all()
    assert (labels[0][-40:] == 1).all()  # what the frame was sure of stays
    assert (labels[1] == label_b).all()  # the last frame has no later source
    again, _ = carry_along([a, b], [label_a, label_b], None, CarryOptions(window=1), steps=[FORWARD])
    assert (again[0][target] == 1).all()  # known homographies give the same


def test_an_object_that_does_not_move_like_the_road_gets_no_vote() -> None:
    a = _texture(3)
    b = _next(a, FORWARD)
    b[150:200, 100:200] = (255, 255, 255)  # a car in the later frame, labelled road by a bad teacher
    label_b = np.ones(H_W, np.uint8)
    road, _ = carried_votes(a, [(b, label_b, FORWARD)])
    inv = np.linalg.inv(FORWARD)
    u, v = _mapped(inv, 150, 175).round().astype(int)  # where the car's middle lands in a
    assert road[v, u] == 0
    u, v = _mapped(inv, 150, 220).round().astype(int)  # the road below the car votes
    assert road[v, u] == 1


def test_a_not_road_label_is_overridden_only_when_asked() -> None:
    a = _texture(4)
    frames = [a, _next(a, FORWARD), _next(_next(a, FORWARD), FORWARD)]
    sure_not = np.zeros(H_W, np.uint8)  # the teacher: not road everywhere in the first frame
    road = np.ones(H_W, np.uint8)
    masks = [_bottom(200)] * 3
    kept, _ = carry_along(frames, [sure_not, road, road], masks, CarryOptions(window=2))
    flipped, record = carry_along(frames, [sure_not, road, road], masks, CarryOptions(window=2, override=2))
    assert (kept[0] != 1).all()  # contradicted: don't care at most, never road
    assert (kept[0] == IGNORE_INDEX).mean() > 0.3
    assert (flipped[0] == 1).mean() > 0.3 and record["overridden"] > 0.1


def test_bad_options_and_mismatched_inputs_are_refused() -> None:
    with pytest.raises(InvalidOptionError, match="window"):
        carry_along([_texture(0)], [np.zeros(H_W, np.uint8)], [_bottom(10)], CarryOptions(window=0))
    with pytest.raises(InvalidOptionError, match="max_grey_difference"):
        CarryOptions(max_grey_difference=0).check()
    with pytest.raises(ShapeMismatchError, match="one label a frame"):
        carry_along([_texture(0)] * 2, [np.zeros(H_W, np.uint8)], [_bottom(10)] * 2)
    with pytest.raises(ShapeMismatchError, match="one road map a frame"):
        carry_along([_texture(0)] * 2, [np.zeros(H_W, np.uint8)] * 2, [_bottom(10)])
    with pytest.raises(ShapeMismatchError, match="consecutive pair"):
        carry_along([_texture(0)] * 2, [np.zeros(H_W, np.uint8)] * 2, None, steps=[])
    with pytest.raises(ShapeMismatchError, match="voter flags"):
        carry_along([_texture(0)] * 2, [np.zeros(H_W, np.uint8)] * 2, None, steps=[FORWARD], voters=[True])
    with pytest.raises(ShapeMismatchError, match="votes on"):
        carried_votes(_texture(0), [(_texture(1), np.zeros((10, 10), np.uint8), np.eye(3))])


def test_carried_labels_seed_the_appearance_completion() -> None:
    image = np.zeros((*H_W, 3), np.uint8)
    image[120:] = (90, 90, 90)  # grey road below, blue sky above
    image[:120] = (40, 80, 200)
    prob = np.full(H_W, 0.5, np.float32)
    seeds = np.full(H_W, IGNORE_INDEX, np.uint8)
    seeds[200:], seeds[:40] = 1, 0
    out = complete_by_appearance(image, prob, seeds=seeds)
    assert (out[130:] == 1).all() and (out[:110] == 0).all()
    with pytest.raises(ShapeMismatchError, match="seeds"):
        complete_by_appearance(image, prob, seeds=seeds[:-1])


def test_adapt_plans_a_sequence_only_where_its_pairs_share_road() -> None:
    from freespace.engine.adapt_time import plan_sequence

    first = _texture(5)
    sequence = np.stack([first, _next(first, FORWARD), _next(_next(first, FORWARD), FORWARD)])
    probs = np.zeros(sequence.shape[:3], np.float32)
    probs[:, 80:] = 0.9
    steps, record = plan_sequence(sequence, probs, "auto")
    assert record == {"setting": "auto", "pairs": 2, "pairs_fitted": 2, "used": True} and len(steps) == 2
    photos = np.stack([_texture(6), _texture(7), _texture(8)])
    steps, record = plan_sequence(photos, probs, "auto")
    assert steps is None and record["pairs_fitted"] == 0 and not record["used"]
    assert plan_sequence(photos, probs, "on")[1]["used"]
    assert plan_sequence(sequence, probs, "off") == (None, {"setting": "off", "pairs": 2, "pairs_fitted": 0,
                                                            "used": False})
    with pytest.raises(InvalidOptionError, match="across_time"):
        plan_sequence(sequence, probs, "sometimes")


def test_held_out_frames_give_adapt_no_label() -> None:
    from freespace.engine.adapt_time import carried_labels

    a = _texture(9)
    images = np.stack([a, _next(a, FORWARD)])
    labels = np.full((2, *H_W), IGNORE_INDEX, np.uint8)
    labels[1, -150:] = 1
    carried, shares = carried_labels(images, labels, [FORWARD], np.array([], int))
    assert (carried[0] == 1).mean() > 0.2 and shares["gained"] > 0.1
    kept, shares = carried_labels(images, labels, [FORWARD], np.array([1]))
    assert (kept[0] == IGNORE_INDEX).all() and shares["gained"] == 0
    alone, shares = carried_labels(images, labels, [FORWARD], np.array([0]))  # held frame 0: shares of frame 1 only
    assert (alone[1] == labels[1]).all() and shares["gained"] == 0


def test_adapt_completes_the_training_frames_labels_by_appearance() -> None:
    from freespace.engine.adapt_time import round_labels

    image = np.zeros((*H_W, 3), np.uint8)
    image[120:], image[:120] = (90, 90, 90), (40, 80, 200)  # grey road below, blue sky above
    images = np.stack([image, image])
    probs = np.full((2, *H_W), 0.5, np.float32)
    probs[:, 200:], probs[:, :40] = 0.99, 0.01
    sure = np.where(probs > 0.9, 1, np.where(probs < 0.1, 0, IGNORE_INDEX)).astype(np.uint8)
    assert round_labels(images, probs, sure, None, np.array([1]), False) == (None, {})
    labels, record = round_labels(images, probs, sure, None, np.array([1]), True)
    assert (labels[0, 130:] == 1).all() and (labels[0, :110] == 0).all() and record["completed"] > 0.2
    assert (labels[1, 40:200] == IGNORE_INDEX).all()  # the held-out frame is left as the teacher labelled it
