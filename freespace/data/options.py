"""A dataset opened from the options a command gives (layout, root, split, disparity source), checked together."""

from __future__ import annotations

from typing import Any

from freespace.data.base import StereoRoadDataset
from freespace.data.registry import canonical_dataset, get_dataset
from freespace.errors import InvalidOptionError, param
from freespace.io.files import PathLike

__all__ = ["open_dataset"]

#: the layouts (by their own names: :func:`~freespace.data.registry.canonical_dataset`) that read a
#: ``disparity_dir`` (KITTI road trees), and those with Velodyne scans (``lidar_densify``)
DISPARITY_DIR_LAYOUTS = ("kitti",)
LIDAR_LAYOUTS = ("kitti", "kitti-raw")


def open_dataset(dataset: str, root: PathLike, split: str | None = None, *, disparity_source: str = "auto",
                 cache_dir: PathLike | None = None, max_disparity: int | None = None,
                 disparity_dir: PathLike | None = None, lidar_densify: float | None = None,
                 needs_right: str | None = None) -> StereoRoadDataset:
    """The layout ``dataset`` (its name or an alias) at ``root`` (:func:`~freespace.data.registry.get_dataset`),
    its disparity read as ``disparity_source`` says (``cache_dir``: the SGBM cache; ``max_disparity``: SGBM's range
    in pixels).

    ``disparity_dir`` (KITTI road trees only, with the sources ``auto`` or ``file``) names a folder of
    disparities; ``lidar_densify`` (pixels; the source ``lidar``, layouts with Velodyne scans) fills holes of
    the sparse LiDAR disparity. ``needs_right`` (what needs right images) refuses up front a layout that knows
    some of its drives have none (KITTI raw's ``require_right``).

    Raises:
        InvalidOptionError: an option that the layout or the disparity source would ignore, named; no layout
            answers to ``dataset``.
    """
    layout = canonical_dataset(dataset)
    options: dict[str, Any] = {"disparity_source": disparity_source, "cache_dir": cache_dir,
                               "max_disparity": max_disparity}
    if disparity_dir is not None:
        if layout not in DISPARITY_DIR_LAYOUTS:
            raise InvalidOptionError(f"{param('disparity_dir')} is for KITTI road trees; other layouts name their "
                                     f"disparity folder in freespace.yaml")
        if disparity_source not in ("auto", "file"):
            raise InvalidOptionError(f"{param('disparity_dir')} is read with {param('disparity_source')} auto or "
                                     f"file; with {disparity_source} it would be ignored: leave one of them out")
        options["disparity_dir"] = disparity_dir
    if lidar_densify is not None:
        if disparity_source != "lidar":
            raise InvalidOptionError(f"{param('lidar_densify')} is for {param('disparity_source')} lidar")
        if layout not in LIDAR_LAYOUTS:
            raise InvalidOptionError(f"{param('lidar_densify')} is for KITTI road and KITTI raw trees (the layouts "
                                     f"with Velodyne scans)")
        options["lidar_densify"] = lidar_densify
    opened = get_dataset(dataset, root, split, **options)
    if needs_right is not None and hasattr(opened, "require_right"):
        opened.require_right(needs_right)
    return opened
