"""Paired statistics of the experiments: intervals by hand."""

from __future__ import annotations

import math

import pytest

from freespace.experiments.stats import paired_gain


def test_paired_gain_by_hand() -> None:
    # differences 1, 2, 3: mean 2, s = 1, t(0.975, 2) = 4.302652729911275
    g = paired_gain([11.0, 12.0, 13.0], [10.0, 10.0, 10.0])
    half = 4.302652729911275 / math.sqrt(3)
    assert (g.mean, g.n) == (2.0, 3)
    assert g.ci_low == pytest.approx(2 - half, abs=1e-9) and g.ci_high == pytest.approx(2 + half, abs=1e-9)
    assert not g.excludes_zero  # 2 − 2.48 < 0
    assert paired_gain([5.0, 5.1, 4.9, 5.0], [1.0, 1.0, 1.0, 1.0]).excludes_zero


def test_paired_gain_degenerate() -> None:
    one = paired_gain([3.0], [1.0])
    assert one.mean == 2.0 and one.n == 1 and math.isnan(one.ci_low) and not one.excludes_zero
    assert paired_gain([], []).n == 0
    with pytest.raises(ValueError, match="equal lengths"):
        paired_gain([1.0], [1.0, 2.0])
