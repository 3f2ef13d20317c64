"""Train/validation/test splits by scenario, with the paper's sizes, written to and read from lists.

The paper splits KITTI road's 289 labelled frames 173/58/58 and SYNTHIA's and SYN-Stereo's 300
frames 180/60/60; other sizes get 60/20/20 %. Frames of one scenario (drive, sequence) always land in
the same split. The assignment is a deterministic function of the scenario list and the seed: scenarios in a
seeded random order each go to the split furthest below its target size. Sizes are met exactly when
every scenario is one frame (or all scenarios divide the targets), and as nearly as whole scenarios
allow otherwise.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from freespace.errors import DatasetError, InputFileError, InvalidOptionError, check_seed
from freespace.io.files import PathLike, atomic_write_text

__all__ = ["SPLIT_NAMES", "split_sizes", "make_splits", "write_splits", "read_splits"]

SPLIT_NAMES = ("train", "val", "test")
_PAPER = {289: (173, 58, 58), 300: (180, 60, 60)}


def split_sizes(n: int) -> tuple[int, int, int]:
    """Train/val/test sizes for ``n`` frames: the paper's for 289 and 300, else 60/20/20 %."""
    if n in _PAPER:
        return _PAPER[n]
    val = test = int(round(0.2 * n))
    return n - val - test, val, test


def make_splits(frames: Sequence[tuple[str, str]], seed: int = 0,
                sizes: tuple[int, int, int] | None = None) -> dict[str, list[str]]:
    """Split frames by scenario.

    Args:
        frames: ``(frame name, scenario)`` pairs.
        seed: the shuffling seed; the same frames and seed give the same splits.
        sizes: train/val/test frame counts (default :func:`split_sizes`).

    Returns:
        ``{"train": [...], "val": [...], "test": [...]}``, names sorted.
    """
    check_seed(seed)
    if not frames:
        raise DatasetError("no frames to split")
    sizes = sizes or split_sizes(len(frames))
    if sum(sizes) != len(frames) or min(sizes) < 0:
        raise InvalidOptionError(f"split sizes {sizes} must be ≥ 0 and add up to the {len(frames)} frames")
    groups: OrderedDict[str, list[str]] = OrderedDict()
    for name, scenario in sorted(frames):
        groups.setdefault(scenario, []).append(name)
    keys = sorted(groups)
    order = np.random.default_rng(seed).permutation(len(keys))
    out: dict[str, list[str]] = {k: [] for k in SPLIT_NAMES}
    targets = dict(zip(SPLIT_NAMES, sizes))
    for i in order:  # each scenario goes to the split that is furthest below its target
        members = groups[keys[i]]
        split = max(("test", "val", "train"), key=lambda k: targets[k] - len(out[k]))
        out[split] += members
    return {k: sorted(v) for k, v in out.items()}


def write_splits(folder: PathLike, splits: dict[str, list[str]]) -> list[Path]:
    """Write ``train.txt``, ``val.txt``, ``test.txt`` (one frame name a line) into ``folder``."""
    return [atomic_write_text(Path(folder) / f"{k}.txt", "".join(f"{n}\n" for n in splits[k])) for k in SPLIT_NAMES]


def read_splits(folder: PathLike, known: Sequence[str] | None = None) -> dict[str, list[str]]:
    """Read split lists written by :func:`write_splits` (or by hand).

    Args:
        known: the dataset's frame names; names not in it are an error (lists from another dataset).

    Raises:
        InputFileError: a list is missing. DatasetError: unknown or repeated names.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputFileError(f"split lists {folder} is a file; give the folder that holds train.txt, val.txt and "
                             f"test.txt")
    out = {}
    for k in SPLIT_NAMES:
        path = folder / f"{k}.txt"
        if not path.is_file():
            raise InputFileError(f"split list not found: {path} (expected train.txt, val.txt, test.txt)")
        out[k] = [line.strip() for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]
    for k in SPLIT_NAMES:
        twice = sorted({n for n in out[k] if out[k].count(n) > 1})
        if twice:
            raise DatasetError(f"{', '.join(twice[:5])} listed twice in {folder / f'{k}.txt'}; list each frame once")
    seen = [n for k in SPLIT_NAMES for n in out[k]]
    if len(seen) != len(set(seen)):
        dup = sorted({n for n in seen if seen.count(n) > 1})
        raise DatasetError(f"frames listed in more than one split in {folder}: {', '.join(dup[:5])}")
    if known is not None:
        unknown = sorted(set(seen) - set(known))
        if unknown:
            raise DatasetError(f"{len(unknown)} frames in the split lists of {folder} are not in the dataset "
                               f"(first: {unknown[0]}); the lists belong to another dataset")
    return out
