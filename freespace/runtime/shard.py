"""Split work over machines: the shard ``K/N`` runs the K-th of N disjoint parts of a list of frames.

Convention: ``K`` is **1-based**, ``1 ≤ K ≤ N`` — the numbering of a SLURM job array started with
``sbatch --array=1-N`` (shard ``${SLURM_ARRAY_TASK_ID}/N``). Shard K takes every N-th frame of the sorted
frame names, starting with the K-th (round-robin): the shards are disjoint, together they hold every
frame exactly once, their sizes differ by at most one, and frames of every category and drive spread
over all of them. The split depends only on the set of names, not on their order or on the machine.

Only the standard library is imported here.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from freespace.errors import InvalidOptionError, param

__all__ = ["parse_shard", "select_shard", "SHARD_FORM"]

SHARD_FORM = ("K/N with whole numbers 1 ≤ K ≤ N (e.g. 1/4 … 4/4; K is 1-based, like SLURM_ARRAY_TASK_ID with "
              "--array=1-N)")

_SHARD = re.compile(r"\s*(\d+)\s*/\s*(\d+)\s*")


def parse_shard(text: str) -> tuple[int, int]:
    """Parse ``"K/N"`` into ``(k, n)``, 1-based: ``1 ≤ k ≤ n``.

    Example:
        >>> parse_shard("2/8")
        (2, 8)

    Raises:
        InvalidOptionError: anything else; the message gives the expected form.
    """
    m = _SHARD.fullmatch(str(text))
    if m is None:
        raise InvalidOptionError(f"{param('shard')} {text!r} is not of the form {SHARD_FORM}")
    k, n = int(m.group(1)), int(m.group(2))
    if n < 1 or not 1 <= k <= n:
        raise InvalidOptionError(f"{param('shard')} {text!r} is out of range: expected {SHARD_FORM}")
    return k, n


def select_shard(names: Iterable[str], k: int, n: int) -> list[str]:
    """The names of shard ``k`` of ``n`` (1-based): ``sorted(set(names))[k − 1 :: n]``.

    Args:
        names: frame names (duplicates count once).
        k, n: shard number and count, ``1 ≤ k ≤ n`` (see :func:`parse_shard`).

    Returns:
        The shard's names, sorted. Empty when ``n`` exceeds the number of names and ``k`` is past it.
    """
    if isinstance(k, bool) or isinstance(n, bool) or not (isinstance(k, int) and isinstance(n, int)) \
            or n < 1 or not 1 <= k <= n:
        raise InvalidOptionError(f"shard {k}/{n} is out of range: expected {SHARD_FORM}")
    return sorted(set(names))[k - 1::n]
