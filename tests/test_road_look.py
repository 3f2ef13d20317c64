"""The road-look veto: a drive's own labels teach a linear classifier on ImageNet features that takes gravel off
the geometric road."""

from __future__ import annotations

import numpy as np
import pytest

from freespace.datagen.options import LookOptions
from freespace.datagen.road_look import (
    CELL,
    cell_examples,
    fit_road_look,
    look_encoder,
    look_features,
    look_veto_frames,
    looks_like_road,
    road_probability,
    veto_label,
)
from freespace.errors import DatasetError, InvalidOptionError
from freespace.labels import RoadLabel

H, W = 128, 256


def _frame(seed: int) -> tuple[np.ndarray, RoadLabel, np.ndarray]:
    """A frame whose lower half the geometry calls road: smooth grey asphalt, and on the right a strip of gravel
    (coarse brown noise) it cannot tell apart; above it, green grass it calls not road, with a gravel bed whose
    kerb it saw (not road). Returns the image, the label and the gravel on the road (``bool H×W``)."""
    rng = np.random.default_rng(seed)
    image = np.empty((H, W, 3), np.float32)
    image[:] = (110, 110, 112)
    image += rng.normal(0, 3, (H, W, 1))
    grass = np.array([60, 130, 50]) + rng.normal(0, 12, (H, W, 3))
    gravel = np.array([120, 100, 80]) + np.kron(rng.normal(0, 40, (H // 2, W // 2, 1)), np.ones((2, 2, 3)))
    rows = np.arange(H)[:, None]
    cols = np.arange(W)[None, :]
    upper, strip = rows < H // 2, (cols >= 176) & (rows >= H // 2)
    bed = upper & (cols >= 160)
    image[upper & ~bed] = grass[upper & ~bed]
    image[bed | strip] = gravel[bed | strip]
    road = np.broadcast_to(~upper, (H, W)).copy()
    return np.clip(image, 0, 255).astype(np.uint8), RoadLabel(road, np.ones((H, W), bool)), strip


def test_cell_examples_take_road_only_in_the_band() -> None:
    _, label, _ = _frame(0)
    road, not_road = cell_examples(label, LookOptions(band=(0.25, 0.5)))
    assert road.shape == (H // CELL, W // CELL)
    cols = np.nonzero(road.any(0))[0]
    assert cols.min() == 8 and cols.max() == 15 and road[H // CELL - 1, 10] and not road[0].any()
    assert not_road[: H // CELL // 2].all() and not not_road[H // CELL // 2:].any()


def test_the_look_vetoes_gravel_on_the_road_and_keeps_the_asphalt() -> None:
    encoder = look_encoder()
    frames = [_frame(seed) for seed in range(3)]
    features = [look_features(image, encoder) for image, _, _ in frames]
    assert features[0].shape == (H // CELL, W // CELL, 152) and features[0].dtype == np.float32
    examples = [cell_examples(label, LookOptions(band=(0.25, 0.5))) for _, label, _ in frames]
    road = np.concatenate([f[r] for f, (r, _) in zip(features, examples)])
    not_road = np.concatenate([f[n] for f, (_, n) in zip(features, examples)])
    weights, bias = fit_road_look(road, not_road)
    image, label, strip = _frame(7)  # a frame it did not learn from
    probability = road_probability(look_features(image, encoder), weights, bias, label.shape)
    assert probability.shape == (H, W)
    new, vetoed = veto_label(label, probability, 0.5)
    asphalt = label.road & ~strip
    assert vetoed[strip].mean() > 0.8 and vetoed[asphalt].mean() < 0.05
    assert not (new.road & ~label.road).any() and not new.valid[vetoed].any()


def test_a_sequence_in_memory_is_vetoed_by_its_own_look() -> None:
    frames = [_frame(seed) for seed in range(4)]
    vetoed, row = look_veto_frames([f[0] for f in frames], [f[1] for f in frames], LookOptions(band=(0.25, 0.5)))
    assert row["road_examples"] > 0 and row["not_road_recall"] > 0.9
    for (_, label, strip), new in zip(frames, vetoed):
        assert new.road[strip].mean() < 0.2 and new.road[label.road & ~strip].mean() > 0.95


def test_adapts_look_is_learnt_from_the_training_frames_and_judges_every_frame() -> None:
    frames = [_frame(seed) for seed in range(5)]
    images = np.stack([image for image, _, _ in frames])
    labels = np.stack([np.where(label.road, 1, 0).astype(np.uint8) for _, label, _ in frames])
    labels[0, :8] = 255  # don't care teaches nothing
    looks, row = looks_like_road(images, labels, np.arange(4), LookOptions(band=(0.25, 0.5)))
    assert looks.shape == labels.shape and looks.dtype == bool and row["road_examples"] > 0
    _, label, strip = frames[4]  # a frame it did not learn from
    assert looks[4][strip].mean() < 0.2 and looks[4][label.road & ~strip].mean() > 0.95


def test_frame_sizes_that_fill_no_whole_cell_take_the_nearest_cell() -> None:
    p = road_probability(np.zeros((2, 3, 4), np.float32), np.zeros(4), 0.0, (21, 30))
    assert p.shape == (21, 30) and np.allclose(p, 0.5)


def test_too_few_examples_and_bad_options_are_refused() -> None:
    with pytest.raises(DatasetError, match="not-road cells"):
        fit_road_look(np.zeros((50, 4), np.float32), np.zeros((3, 4), np.float32))
    for bad in (LookOptions(band=(0.6, 0.4)), LookOptions(veto=1.0), LookOptions(cell_share=0.2)):
        with pytest.raises(InvalidOptionError):
            bad.check()


def test_the_fit_does_not_depend_on_torchs_global_random_state() -> None:
    """fit_road_look starts from zero weights: the same cells give the same classifier whatever ran before it."""
    import torch

    rng = np.random.default_rng(0)
    road = rng.normal(0.5, 1, (60, 8)).astype(np.float32)
    not_road = rng.normal(-0.5, 1, (80, 8)).astype(np.float32)
    fits = []
    for seed in (1, 2):
        torch.manual_seed(seed)
        fits.append(fit_road_look(road, not_road))
    np.testing.assert_array_equal(fits[0][0], fits[1][0])
    assert fits[0][1] == fits[1][1] and fits[0][0][0] > 0
