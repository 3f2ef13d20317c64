"""Paired statistics over seeds: the mean gain of one variant over another and its confidence interval.

The interval is Student's t-interval of the mean of the paired differences (one difference per seed:
the two variants share the seed's split, initialisation and data order), ``mean ± t(0.975, n−1)·s/√n``,
with the t quantile from SciPy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["PairedGain", "paired_gain"]


@dataclass(frozen=True)
class PairedGain:
    """Mean of paired differences with its two-sided t-interval (``nan`` bounds when ``n`` < 2)."""

    mean: float
    ci_low: float
    ci_high: float
    n: int

    @property
    def half_width(self) -> float:
        """Half the interval's width (same unit as the differences)."""
        return 0.5 * (self.ci_high - self.ci_low)

    @property
    def excludes_zero(self) -> bool:
        """Whether the interval lies wholly above or wholly below 0 (False when it is undefined)."""
        return self.n >= 2 and (self.ci_low > 0 or self.ci_high < 0)


def paired_gain(a: Sequence[float], b: Sequence[float], level: float = 0.95) -> PairedGain:
    """The gain of ``a`` over ``b`` (``a[i] − b[i]``, one pair per seed) with its ``level`` t-interval.

    Args:
        a, b: the metric of the two variants, in the same seed order and the same unit (e.g. points).
        level: two-sided confidence level.
    """
    if len(a) != len(b):
        raise ValueError(f"paired values need equal lengths, got {len(a)} and {len(b)}")
    diffs = [x - y for x, y in zip(a, b)]
    n = len(diffs)
    if n == 0:
        return PairedGain(math.nan, math.nan, math.nan, 0)
    mean = math.fsum(diffs) / n
    if n < 2:
        return PairedGain(mean, math.nan, math.nan, n)
    from scipy.stats import t

    sd = math.sqrt(math.fsum((d - mean) ** 2 for d in diffs) / (n - 1))
    half = float(t.ppf(0.5 + level / 2.0, n - 1)) * sd / math.sqrt(n)
    return PairedGain(mean, mean - half, mean + half, n)
