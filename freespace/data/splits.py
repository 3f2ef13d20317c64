"""Train/validation/test splits by scenario, with the paper's sizes, or by time blocks of each scenario;
written to and read from lists.

By scenario (:func:`make_splits`): the paper splits KITTI road's 289 labelled frames 173/58/58 and SYNTHIA's
and SYN-Stereo's 300 frames 180/60/60; other sizes get 60/20/20 %. Frames of one scenario (drive, sequence)
always land in the same split. The assignment is a deterministic function of the scenario list and the seed:
scenarios in a seeded random order each go to the split furthest below its target size. Sizes are met
exactly when every scenario is one frame (or all scenarios divide the targets), and as nearly as whole
scenarios allow otherwise.

By time blocks (:func:`make_block_splits`): each scenario's frames in time order are cut into three
contiguous blocks (train first, then val, then test), optionally with a gap of frames left out between
blocks. Neighbouring frames of a drive (10 Hz for KITTI raw) are near duplicates, so frames are never
assigned one by one (interleaved): a test frame's neighbours are then in no training block.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from freespace.data.base import StereoRoadDataset
from freespace.errors import DatasetError, InputFileError, InvalidOptionError, check_seed, param
from freespace.io.files import PathLike, atomic_write_text, missing_input

__all__ = ["SPLIT_NAMES", "SPLIT_BY", "split_sizes", "make_splits", "make_block_splits", "split_frames",
           "parse_fractions", "check_split_by", "write_splits", "read_splits", "split_dataset"]

SPLIT_NAMES = ("train", "val", "test")
SPLIT_BY = ("scenario", "time")
"""How frames are split: ``scenario`` (whole drives/sequences, :func:`make_splits`) or ``time`` (contiguous
time blocks of each scenario, :func:`make_block_splits`)."""
DEFAULT_FRACTIONS = (0.6, 0.2, 0.2)
_PAPER = {289: (173, 58, 58), 300: (180, 60, 60)}


def split_sizes(n: int) -> tuple[int, int, int]:
    """Train/val/test sizes for ``n`` frames: the paper's for 289 and 300, else 60/20/20 %."""
    if n in _PAPER:
        return _PAPER[n]
    val = test = int(round(0.2 * n))
    return n - val - test, val, test


def parse_fractions(fractions: Sequence[float] | str) -> tuple[float, float, float]:
    """Train/val/test fractions (``"0.8,0,0.2"`` or three numbers), each in [0, 1], adding up to 1, train > 0.

    Raises:
        InvalidOptionError: anything else.
    """
    try:
        values = tuple(float(x) for x in (fractions.split(",") if isinstance(fractions, str) else fractions))
    except (TypeError, ValueError):
        values = ()
    if len(values) != 3 or not all(0 <= v <= 1 for v in values) or abs(sum(values) - 1) > 1e-6 or not values[0] > 0:
        raise InvalidOptionError(f"{param('fractions')} must be three numbers TRAIN,VAL,TEST in [0, 1] adding up to 1 "
                                 f"with TRAIN > 0 (e.g. 0.8,0,0.2), got {fractions!r}")
    return values  # type: ignore[return-value]


def _sizes_of(n: int, fractions: tuple[float, float, float]) -> tuple[int, int, int]:
    val, test = int(round(fractions[1] * n)), int(round(fractions[2] * n))
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


def make_block_splits(frames: Sequence[tuple[str, str]], fractions: Sequence[float] = DEFAULT_FRACTIONS,
                      gap: int = 0) -> dict[str, list[str]]:
    """Split every scenario into contiguous time blocks: its first frames train, the next val, the last test.

    Args:
        frames: ``(frame name, scenario)`` pairs; within a scenario, names sort in time order (KITTI raw's
            ``<drive>/<ten-digit frame>``, or any zero-padded frame number).
        fractions: train/val/test shares of each scenario's frames (:func:`parse_fractions`); a scenario of
            ``n`` frames gets ``round(val · n)`` val and ``round(test · n)`` test frames, train the rest.
        gap: frames left out (in no split) at the end of the train block and of the val block when a later
            block follows, so that no two frames of different splits are closer than ``gap + 1`` frames.

    Returns:
        ``{"train": [...], "val": [...], "test": [...]}``, names sorted; frames of the gaps are in none.

    Raises:
        DatasetError: no frames, or a scenario too short for its blocks and gaps. InvalidOptionError: bad
            ``fractions`` or ``gap``.
    """
    shares = parse_fractions(fractions)
    if isinstance(gap, bool) or not isinstance(gap, int) or gap < 0:
        raise InvalidOptionError(f"{param('gap')} must be a whole number of frames ≥ 0, got {gap!r}")
    if not frames:
        raise DatasetError("no frames to split")
    groups: OrderedDict[str, list[str]] = OrderedDict()
    for name, scenario in sorted(frames, key=lambda f: (f[1], f[0])):
        groups.setdefault(scenario, []).append(name)
    out: dict[str, list[str]] = {k: [] for k in SPLIT_NAMES}
    for scenario, names in groups.items():
        n_train, n_val, n_test = _sizes_of(len(names), shares)
        cut_train = gap if (n_val or n_test) else 0
        cut_val = gap if (n_val and n_test) else 0
        if n_train - cut_train < 1 or (n_val and n_val - cut_val < 1):
            raise DatasetError(f"scenario {scenario} has {len(names)} frames: too few for time blocks "
                               f"{'/'.join(f'{x:g}' for x in shares)} with a gap of {gap} frames; lower "
                               f"{param('gap')} or leave the scenario out")
        out["train"] += names[:n_train - cut_train]
        out["val"] += names[n_train:n_train + n_val - cut_val]
        out["test"] += names[len(names) - n_test:]
    return {k: sorted(v) for k, v in out.items()}


def check_split_by(by: str, gap: int = 0) -> None:
    """Refuse an unknown ``by`` (:data:`SPLIT_BY`), a ``gap`` that is not a whole number ≥ 0, or one without
    ``by="time"`` (InvalidOptionError)."""
    if by not in SPLIT_BY:
        raise InvalidOptionError(f"unknown split {param('by')} {by!r}; choose one of {', '.join(SPLIT_BY)}")
    if isinstance(gap, bool) or not isinstance(gap, int) or gap < 0:
        raise InvalidOptionError(f"{param('gap')} must be a whole number of frames ≥ 0, got {gap!r}")
    if gap and by != "time":
        raise InvalidOptionError(f"{param('gap')} is for {param('by')} time (frames left out between time blocks)")


def split_frames(dataset: StereoRoadDataset, by: str = "scenario", *, seed: int = 0,
                 fractions: Sequence[float] | None = None, gap: int = 0) -> dict[str, list[str]]:
    """Train/val/test lists of a dataset's frames: the labelled ones, or every frame for a layout without
    labels of its own (KITTI raw, ``has_labels = False``: its labels come from ``freespace autolabel``).

    Args:
        dataset: a :class:`~freespace.data.base.StereoRoadDataset`.
        by: ``scenario`` (:func:`make_splits`; ``fractions`` None: the paper's sizes) or ``time``
            (:func:`make_block_splits`; ``fractions`` None: 0.6/0.2/0.2).
        seed: the shuffling seed of ``scenario``. gap: frames left out between the blocks of ``time``.

    Raises:
        InvalidOptionError: an unknown ``by``, ``gap`` without ``time``, or no frame to split.
        DatasetError: a split that ``fractions`` gives a share (every split, without ``fractions``) would be
            empty (one drive split by scenario; drives too short for time blocks), which training refuses.
    """
    check_split_by(by, gap)
    own_labels = getattr(type(dataset), "has_labels", True)
    frames = dataset.labelled().frames if own_labels else dataset.frames
    if not frames:
        raise InvalidOptionError(f"split {dataset.split!r} of {dataset.root} has no labelled frames to split")
    pairs = [(f.name, f.scenario) for f in frames]
    shares = parse_fractions(fractions) if fractions is not None else (1.0, 1.0, 1.0)
    if by == "time":
        splits = make_block_splits(pairs, fractions if fractions is not None else DEFAULT_FRACTIONS, gap)
    else:
        splits = make_splits(pairs, seed=seed, sizes=_sizes_of(len(pairs), shares) if fractions is not None else None)
    empty = [k for k, share in zip(SPLIT_NAMES, shares) if share > 0 and not splits[k]]
    if empty:
        sizes = "/".join(str(len(splits[k])) for k in SPLIT_NAMES)
        scenarios = len({s for _, s in pairs})
        blocks = f"split each drive into time blocks ({param('by')} time), " if by == "scenario" else ""
        raise DatasetError(f"the train/val/test split by {by} ({sizes}, seed {seed}) leaves {' and '.join(empty)} "
                           f"empty: {len(pairs)} {'labelled ' if own_labels else ''}frames in {scenarios} "
                           f"scenario{'s' if scenarios > 1 else ''}; add frames"
                           f"{' of more scenarios' if by == 'scenario' else ''}, {blocks}or give {param('fractions')} "
                           f"with 0 for a split you leave empty")
    return splits


def write_splits(folder: PathLike, splits: dict[str, list[str]]) -> list[Path]:
    """Write ``train.txt``, ``val.txt``, ``test.txt`` (one frame name a line) into ``folder``."""
    return [atomic_write_text(Path(folder) / f"{k}.txt", "".join(f"{n}\n" for n in splits[k])) for k in SPLIT_NAMES]


def read_splits(folder: PathLike, known: Sequence[str] | None = None) -> dict[str, list[str]]:
    """Read subset lists written by :func:`write_splits` (or by hand).

    Args:
        known: the dataset's frame names; names not in it are an error (lists from another dataset).

    Raises:
        InputFileError: a list is missing. DatasetError: unknown or repeated names.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputFileError(f"subset lists {folder} is a file; give the folder that holds train.txt, val.txt and "
                             f"test.txt")
    out = {}
    for k in SPLIT_NAMES:
        path = folder / f"{k}.txt"
        if not path.is_file():
            raise missing_input(path, "subset list", "file", hint="expected train.txt, val.txt, test.txt")
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
            raise DatasetError(f"{len(unknown)} frames in the subset lists of {folder} are not in the dataset "
                               f"(first: {unknown[0]}); the lists belong to another dataset")
    return out


def split_dataset(dataset: str, root: PathLike, out: PathLike, *, split: str | None = None, by: str = "scenario",
                  seed: int = 0, fractions: Sequence[float] | str | None = None,
                  gap: int = 0) -> dict[str, list[str]]:
    """``freespace datasets split``: the frames of ``dataset`` at ``root`` (its on-disk ``split``) split
    (:func:`split_frames`) and written as ``train.txt``, ``val.txt`` and ``test.txt`` into the folder ``out``
    (:mod:`freespace.io.outdir`: checked before any work, written all or nothing).

    Returns:
        ``{"train": names, "val": names, "test": names}``.
    """
    from freespace.data.registry import get_dataset
    from freespace.io.files import check_outputs, check_writable
    from freespace.io.outdir import claim_folder

    check_writable(out, folder=True)
    check_outputs({"out": out}, {"root": root})
    fractions = parse_fractions(fractions) if fractions is not None else None
    check_split_by(by, gap)
    frames = get_dataset(dataset, root, split, disparity_source="none")
    splits = split_frames(frames, by, seed=seed, fractions=fractions, gap=gap)
    with claim_folder(out, "datasets split") as folder, folder.staged() as staging:
        write_splits(staging, splits)
    return splits
