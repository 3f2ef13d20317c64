"""--shard K/N: parsing (1-based K) and a deterministic, disjoint, covering split of frame names."""

from __future__ import annotations

import random

import pytest

from freespace.errors import InvalidOptionError
from freespace.runtime.shard import parse_shard, select_shard


@pytest.mark.parametrize("text, expected", [("1/1", (1, 1)), ("2/4", (2, 4)), ("4/4", (4, 4)),
                                            (" 3 / 10 ", (3, 10)), ("12/100", (12, 100))])
def test_parse_shard(text: str, expected: tuple[int, int]) -> None:
    assert parse_shard(text) == expected


@pytest.mark.parametrize("text", ["0/4", "5/4", "1/0", "0/0", "-1/4", "4", "1/2/3", "a/b", "1.5/4", "", "1of4"])
def test_parse_shard_rejects_with_the_form(text: str) -> None:
    with pytest.raises(InvalidOptionError, match=r"K/N with whole numbers 1 ≤ K ≤ N"):
        parse_shard(text)


@pytest.mark.parametrize("num_frames", [0, 1, 5, 17, 289])
@pytest.mark.parametrize("n", [1, 2, 3, 7, 16, 300])
def test_shards_are_disjoint_and_cover_every_frame(num_frames: int, n: int) -> None:
    names = [f"{cat}_{i:06d}" for i in range(num_frames) for cat in ("um",)]
    random.Random(num_frames * 1000 + n).shuffle(names)
    shards = [select_shard(names, k, n) for k in range(1, n + 1)]
    flat = [name for shard in shards for name in shard]
    assert len(flat) == len(set(flat)) == num_frames               # disjoint
    assert set(flat) == set(names)                                 # covering
    sizes = [len(s) for s in shards]
    assert max(sizes) - min(sizes) <= 1                            # balanced (N > frames: some empty)
    assert all(s == sorted(s) for s in shards)


def test_shards_do_not_depend_on_the_order_and_mix_categories() -> None:
    names = [f"{cat}_{i:06d}" for cat in ("um", "umm", "uu") for i in range(20)]
    shuffled = names[::-1]
    for k in (1, 2, 3, 4):
        assert select_shard(names, k, 4) == select_shard(shuffled, k, 4) == sorted(names)[k - 1::4]
        assert {n.split("_")[0] for n in select_shard(names, k, 4)} == {"um", "umm", "uu"}
    assert select_shard(["b", "a", "a", "c"], 1, 2) == ["a", "c"]   # duplicates count once


@pytest.mark.parametrize("k, n", [(0, 3), (4, 3), (1, 0), (True, 2)])
def test_select_shard_rejects_bad_numbers(k: int, n: int) -> None:
    with pytest.raises(InvalidOptionError, match="1 ≤ K ≤ N"):
        select_shard(["a"], k, n)
