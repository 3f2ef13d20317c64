"""`freespace datasets info`: what a dataset holds and every problem in it."""

from __future__ import annotations

from collections import Counter
from typing import Any

from freespace.data.base import get_dataset
from freespace.data.splits import make_splits
from freespace.errors import DatasetError, InputFileError
from freespace.io import PathLike

__all__ = ["dataset_info", "format_info"]

_KINDS = ("right", "label", "disparity", "depth", "calib")


def dataset_info(name: str, root: PathLike, *, progress: bool = True, seed: int = 0,
                 disparity_dir: PathLike | None = None) -> dict[str, Any]:
    """Open every on-disk split of dataset ``name`` at ``root`` and check every frame.

    Returns:
        ``{"dataset", "root", "splits": {split: {"frames", "categories", "resolutions", "have", "paper_split"}},
        "problems": [str, ...]}``; ``have`` counts the frames with each partner file; ``paper_split`` gives
        the train/val/test sizes of the labelled split (by scenario, ``seed``).

    Raises:
        InputFileError: the root is missing. DatasetError: no split holds any frame.
    """
    from freespace.data.base import _REGISTRY, _load_layouts

    _load_layouts()
    options: dict[str, Any] = {"disparity": "file"}
    if disparity_dir is not None:
        options["disparity_dir"] = disparity_dir
    layout = _REGISTRY.get(name)
    splits = layout.splits if layout is not None else ("all",)
    info: dict[str, Any] = {"dataset": name, "root": str(root), "splits": {}, "problems": []}
    errors = []
    for split in splits:
        try:
            ds = get_dataset(name, root, split, **options)
        except (DatasetError, InputFileError) as exc:
            if "dataset root not found" in str(exc):
                raise
            errors.append(exc)
            continue
        problems, sizes = ds.scan(progress=progress)
        entry: dict[str, Any] = {
            "frames": len(ds),
            "categories": dict(sorted(Counter(f.category for f in ds.frames).items())),
            "scenarios": len({f.scenario for f in ds.frames}),
            "resolutions": {f"{w}×{h}": n for (h, w), n in sorted(Counter(sizes.values()).items())},
            "have": {k: sum(getattr(f, k) is not None for f in ds.frames) for k in _KINDS},
        }
        labelled = [(f.name, f.scenario) for f in ds.frames if f.label is not None]
        if labelled:
            entry["paper_split"] = {k: len(v) for k, v in make_splits(labelled, seed=seed).items()}
        info["splits"][split] = entry
        info["problems"] += [f"[{split}] {p}" for p in problems]
    if not info["splits"]:
        raise errors[0] if errors else DatasetError(f"no frames under {root}")
    return info


def format_info(info: dict[str, Any]) -> str:
    """Human-readable report of :func:`dataset_info`."""
    lines = [f"{info['dataset']} at {info['root']}"]
    for split, e in info["splits"].items():
        cats = ", ".join(f"{k} {v}" for k, v in e["categories"].items())
        lines.append(f"  {split}: {e['frames']} frames ({cats}), {e['scenarios']} scenarios")
        lines.append(f"    resolution: {', '.join(f'{k} ({v})' for k, v in e['resolutions'].items()) or 'unknown'}")
        have = ", ".join(f"{k} {v}/{e['frames']}" for k, v in e["have"].items())
        lines.append(f"    files: {have}")
        if "paper_split" in e:
            ps = e["paper_split"]
            lines.append(f"    train/val/test by scenario: {ps['train']}/{ps['val']}/{ps['test']}")
    problems = info["problems"]
    lines.append(f"{len(problems)} problem{'s' if len(problems) != 1 else ''}" + (":" if problems else ""))
    lines += [f"  {p}" for p in problems]
    return "\n".join(lines)
