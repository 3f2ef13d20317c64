"""`freespace datasets info`: what a dataset holds and every problem in it (the integrity scan)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from freespace.data.base import FrameRef, Problem, StereoRoadDataset, check_dataset_root
from freespace.data.registry import get_dataset, get_dataset_class
from freespace.data.splits import check_split_by, split_frames
from freespace.errors import DatasetError, FreespaceError, InputFileError, param, render
from freespace.io.codecs import describe_image, read_disparity, read_image, read_raw
from freespace.io.files import PathLike
from freespace.io.kitti import read_velodyne

__all__ = ["dataset_info", "format_info", "check_dataset", "scan_dataset", "image_size"]

_KINDS = ("right", "label", "disparity", "depth", "velodyne", "calib")


def image_size(path: PathLike) -> tuple[int, int]:
    """``(H, W)`` of an image file; decodes it fully so corrupt files are caught.

    Raises:
        InputFileError, CorruptFileError.
    """
    img = read_raw(path)
    return int(img.shape[0]), int(img.shape[1])


def check_dataset(dataset: StereoRoadDataset, progress: bool = False) -> list[Problem]:
    """Open every file of every frame; return every problem found (missing partners, sizes that
    disagree, unreadable files, files without a left image)."""
    return scan_dataset(dataset, progress)[0]


def _read(dataset: StereoRoadDataset, frame: FrameRef, kind: str, path: Path,
          problems: list[Problem]) -> tuple[int, ...] | None:
    """Read the file ``path`` of ``frame`` (``kind``: ``left``, ``right``, ``label``, ...) as generate and train
    read it, so that every problem they would hit shows here (appended to ``problems``, as its own content's);
    returns its shape (``(H, W)``; ``(H, W, 3)`` for a colour image), None for a scan (it has no image size: its
    projection needs the calibration). Raises :class:`FreespaceError` for a file that cannot be read."""
    if kind == "disparity":
        disparity = read_disparity(path)
        if not np.isfinite(disparity).any():
            problems.append(Problem(frame.name, f"disparity {path} has no valid value (all 0 or NaN)"))
        return disparity.shape
    if kind == "depth":
        depth = dataset.read_depth(frame)
        if not np.isfinite(depth).any():
            problems.append(Problem(frame.name, f"depth {path} has no valid value (all 0 or none)"))
        return depth.shape
    if kind == "velodyne":
        read_velodyne(path)
        return None
    if kind == "label":
        label = dataset.read_label(frame)
        if not label.valid.any():
            problems.append(Problem(frame.name, f"label {path} has no evaluated pixel (all black: don't care "
                                                f"everywhere), so no road to fit or score"))
        elif not (label.road & label.valid).any():
            problems.append(Problem(frame.name, f"label {path} marks no road pixel (the DS-Generator needs road to "
                                                f"fit)"))
        return label.road.shape
    return read_image(path, what=f"{kind} image").shape  # as loading reads it: grey or RGB


def _calibration_problem(dataset: StereoRoadDataset, frame: FrameRef, left: tuple[int, ...] | None) -> str | None:
    """What is wrong with the rig of ``frame`` (unreadable, implausible, a principal point outside its left image
    of shape ``left``), or None."""
    try:
        rig = dataset.calibration(frame)
    except (FreespaceError, KeyError, ValueError) as exc:
        return f"bad calibration {frame.calib}: {exc}"
    if rig is not None and left is not None and not (0 <= rig.cx <= left[1] and 0 <= rig.cy <= left[0]):
        return (f"bad calibration {frame.calib}: the principal point ({rig.cx:g}, {rig.cy:g}) px lies outside the "
                f"{left[1]}×{left[0]} left image; give the calibration of these images")
    return None


def scan_dataset(dataset: StereoRoadDataset,
                 progress: bool = False) -> tuple[list[Problem], dict[str, tuple[int, int]]]:
    """:func:`check_dataset`, plus the ``(H, W)`` of every readable left image by frame name.

    A problem that many frames share, a calibration (a KITTI raw day, a folder layout's camera) or right images
    of another size or kind (grey or RGB) than the left ones in a scenario (a drive), is reported once, with the
    frames it spoils, not once per frame."""
    from freespace.runtime.log import progress_bar

    problems = list(dataset.orphans())
    left_sizes: dict[str, tuple[int, int]] = {}
    expect = dataset.expected_partners()
    shared: dict[str, list[str]] = {}  # a problem of many frames (a calibration, a drive's pairs) → those frames
    for frame in progress_bar(dataset.frames, desc="check", unit="frame", enabled=progress):
        shapes: dict[str, tuple[int, ...]] = {}
        for kind in ("left", "right", "label", "disparity", "depth", "velodyne"):
            path = getattr(frame, kind)
            if path is None:
                if kind in expect:
                    problems.append(Problem(frame.name, f"missing {kind} file"))
                continue
            try:
                shape = _read(dataset, frame, kind, path, problems)
            except FreespaceError as exc:
                problems.append(Problem(frame.name, exc.render(param)))  # its parameters rendered at the end
                continue
            if shape is not None:
                shapes[kind] = shape
        if frame.calib is None and "calib" in expect:
            problems.append(Problem(frame.name, "missing calib file"))
        elif frame.calib is not None:
            problem = _calibration_problem(dataset, frame, shapes.get("left"))
            if problem is not None:
                shared.setdefault(problem, []).append(frame.name)
        problems += _size_problems(frame.name, shapes)
        if "right" in shapes and "left" in shapes and shapes["right"] != shapes["left"]:
            shared.setdefault(f"right images are {describe_image(shapes['right'])} but the left ones "
                              f"{describe_image(shapes['left'])} in {frame.scenario}; a stereo pair has two images of "
                              f"one size and kind", []).append(frame.name)
        if "left" in shapes:
            left_sizes[frame.name] = shapes["left"][:2]  # type: ignore[assignment]
    for problem, frames in shared.items():
        more = f" ({len(frames)} frames: {frames[0]} … {frames[-1]})" if len(frames) > 1 else ""
        problems.append(Problem(frames[0], problem + more))
    return problems, left_sizes


def _size_problems(name: str, shapes: dict[str, tuple[int, ...]]) -> list[Problem]:
    """A frame's files whose size differs from its left image's (but the right image's: its problem is its drive's,
    :func:`scan_dataset`)."""
    ref = shapes.get("left")
    if ref is None:
        return []
    problems = []
    for kind, shape in shapes.items():
        if kind != "right" and shape[:2] != ref[:2]:
            problems.append(Problem(name, f"{kind} is {shape[1]}×{shape[0]} but left is {ref[1]}×{ref[0]}"))
    return problems


def dataset_info(name: str, root: PathLike, *, progress: bool = True, seed: int = 0,
                 disparity_dir: PathLike | None = None, by: str = "scenario",
                 fractions: tuple[float, float, float] | None = None, gap: int = 0,
                 spell: Callable[[str], str] = str) -> dict[str, Any]:
    """Open every on-disk split of dataset ``name`` at ``root`` and check every frame.

    A layout's ``info_options`` (KITTI raw: ``strict=False``) open it so that every problem of its tree is
    listed, not only the first.

    Returns:
        ``{"dataset", "root", "splits": {split: {"frames", "categories", "resolutions", "have", "paper_split"}},
        "problems": [str, ...]}``; ``have`` counts the frames with each partner file; ``paper_split`` gives
        the train/val/test sizes of the labelled frames (every frame for a layout without labels of its own)
        split as :func:`freespace.data.splits.split_frames` splits them (``by``, ``seed``, ``fractions``,
        ``gap``), and ``split_by`` says how. A problem names a parameter as ``spell`` writes it (the command
        line: its flag; :func:`freespace.errors.render`).

    Raises:
        InputFileError: the root is missing. DatasetError: no split holds any frame.
    """
    layout = get_dataset_class(name)
    check_dataset_root(root, layout.name)
    check_split_by(by, gap)
    options: dict[str, Any] = {"disparity_source": "file", **getattr(layout, "info_options", {})}
    if disparity_dir is not None:
        options["disparity_dir"] = disparity_dir
    info: dict[str, Any] = {"dataset": name, "root": str(root), "splits": {}, "problems": []}
    errors = []
    for split in layout.splits:
        try:
            ds = get_dataset(name, root, split, **options)
        except (DatasetError, InputFileError) as exc:
            errors.append(exc)
            continue
        problems, sizes = scan_dataset(ds, progress=progress)
        entry: dict[str, Any] = {
            "frames": len(ds),
            "categories": dict(sorted(Counter(f.category for f in ds.frames).items())),
            "scenarios": len({f.scenario for f in ds.frames}),
            "resolutions": {f"{w}×{h}": n for (h, w), n in sorted(Counter(sizes.values()).items())},
            "have": {k: sum(getattr(f, k) is not None for f in ds.frames) for k in _KINDS},
        }
        own_labels = getattr(layout, "has_labels", True)
        labelled = [(f.name, f.scenario) for f in (ds.labelled() if own_labels else ds)]
        if labelled:
            try:
                splits = split_frames(ds, by, seed=seed, fractions=fractions, gap=gap)
                entry["paper_split"] = {k: len(v) for k, v in splits.items()}
                entry["split_by"] = by
            except DatasetError as exc:  # a split left empty: one drive by scenario, drives too short for blocks
                problems.append(Problem("split", exc.render(param)))
        info["splits"][split] = entry
        info["problems"] += [f"[{split}] {render(str(p), spell)}" for p in problems]
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
            how = "by time blocks" if e.get("split_by") == "time" else "by scenario"
            lines.append(f"    train/val/test {how}: {ps['train']}/{ps['val']}/{ps['test']}")
    problems = info["problems"]
    lines.append(f"{len(problems)} problem{'s' if len(problems) != 1 else ''}" + (":" if problems else ""))
    lines += [f"  {p}" for p in problems]
    return "\n".join(lines)
