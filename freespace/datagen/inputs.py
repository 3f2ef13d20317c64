"""What a per-frame command (``generate``, ``autolabel``) takes from a dataset: the settings its outputs depend
on (for resuming, :mod:`freespace.datagen.runner`), and the checks of its SGBM search range made once, before
any work. Only NumPy and OpenCV are imported (never torch).
"""

from __future__ import annotations

import json
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

from freespace.data.base import FrameRef, StereoRoadDataset
from freespace.data.disparity import SGBM_SOURCES
from freespace.errors import FreespaceError, param
from freespace.geometry.stereo import SGBM_VERSION, check_search_range
from freespace.io.codecs import read_image

__all__ = ["dataset_settings", "may_use_sgbm", "check_sgbm_range"]


def dataset_settings(dataset: StereoRoadDataset) -> dict[str, Any]:
    """What a per-frame output depends on in the dataset: its layout, root, split and where its
    disparities come from (the source, its folder of disparity files, LiDAR densification, the SGBM version
    when a frame may be matched)."""
    disparity_dir = getattr(dataset, "disparity_dir", None)
    spec = getattr(dataset, "spec", None)
    settings = {"dataset": dataset.name, "root": str(Path(dataset.root).resolve()), "split": dataset.split,
                "disparity_source": dataset.disparity_source,
                "disparity_dir": str(Path(disparity_dir).resolve()) if disparity_dir is not None else None,
                "layout": json.loads(json.dumps(asdict(spec), default=str)) if is_dataclass(spec) else None}
    if dataset.disparity_source == "lidar":
        settings["lidar_densify"] = getattr(dataset, "lidar_densify", 0.0)
    if may_use_sgbm(dataset):
        settings["sgbm_version"] = SGBM_VERSION
    return settings


def _sgbm_matches(dataset: StereoRoadDataset, frame: FrameRef) -> bool:
    """Whether SGBM matches ``frame``: it has a right image, and the source is ``sgbm``, or one that falls
    back on SGBM (:data:`~freespace.data.disparity.SGBM_SOURCES`) and the frame has neither a disparity file
    nor a depth map."""
    source = dataset.disparity_source
    return source in SGBM_SOURCES and frame.right is not None and (
        source == "sgbm" or (frame.disparity is None and frame.depth is None))


def may_use_sgbm(dataset: StereoRoadDataset) -> bool:
    """Whether a frame's disparity may come from SGBM: always with source ``sgbm``; with ``auto`` or
    ``fused`` when a frame with a right image has neither a disparity file nor a depth map."""
    if dataset.disparity_source not in SGBM_SOURCES:
        return False
    return dataset.disparity_source == "sgbm" or any(_sgbm_matches(dataset, f) for f in dataset.frames)


def check_sgbm_range(dataset: StereoRoadDataset, max_disparity: int, *, labelled: bool = False) -> None:
    """Refuse, once and before any work, a ``max_disparity`` (pixels) that SGBM cannot use on the dataset's
    images: checked on the first frame that would be matched (with ``labelled``, the first labelled one);
    frames of other sizes still fail one by one, as does a frame whose image cannot be read."""
    frame = next((f for f in dataset.frames if _sgbm_matches(dataset, f) and (f.label is not None or not labelled)),
                 None)
    if frame is None:
        return
    try:
        width = read_image(frame.left, what="left image").shape[1]
    except FreespaceError:
        return  # the frame fails with its own reason
    check_search_range(max_disparity, width, f"give disparities ({param('disparity_dir')}, or depth maps with "
                                             f"{param('disparity_source')} depth)")
