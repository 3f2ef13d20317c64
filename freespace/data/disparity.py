"""Where a frame's left disparity comes from (torch-free): a file, depth and the camera, a LiDAR scan and
the calibration, or SGBM, which is cached on disk.

The disparity *mode* of a dataset (:data:`DISPARITY_SOURCES`) says which sources may be used; the *source*
of a loaded sample (``file``, ``depth``, ``lidar``, ``sgbm`` or ``none``) says which one was.

``auto`` takes the file, else depth + camera, else SGBM; it never takes a LiDAR scan: a scan gives a
sparse map (about one pixel in twenty, none above the scanner's field of view) whose use should be a
choice, and a tree that gains a ``velodyne/`` folder must not silently change what ``auto`` generated.
Ask for it with ``lidar``.

``fused`` joins a LiDAR scan and SGBM (:func:`fuse_disparities`): where both measure a pixel they must agree
(within :data:`FUSE_TOLERANCE_PX` or :data:`FUSE_TOLERANCE_REL` of the disparity) and the scan's value is
kept; where they disagree the pixel has no disparity (so an autolabel leaves it don't care); where only one
measures, its value is kept. A frame with only one of the two gets that one.
"""

from __future__ import annotations

import hashlib
import io as _io
import json
import logging
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from freespace.errors import DatasetError, InvalidOptionError, param
from freespace.geometry import StereoCalibration, compute_disparity
from freespace.geometry.depth import depth_to_disparity
from freespace.geometry.stereo import SGBM_VERSION
from freespace.io.codecs import read_disparity
from freespace.io.files import PathLike, atomic_write_bytes, check_writable

log = logging.getLogger(__name__)

__all__ = ["DISPARITY_SOURCES", "SGBM_SOURCES", "FUSE_TOLERANCE_PX", "FUSE_TOLERANCE_REL", "check_disparity_source",
           "DisparityCache", "fuse_disparities", "resolve_disparity"]

DISPARITY_SOURCES = ("auto", "file", "depth", "lidar", "sgbm", "fused", "none")
"""``auto``: file, else depth + camera, else cached SGBM; ``file``: file, else depth + camera; ``depth``:
depth + camera only; ``lidar``: the frame's Velodyne scan projected with its calibration only; ``sgbm``:
always SGBM; ``fused``: the Velodyne scan and SGBM joined (:func:`fuse_disparities`); ``none``: no
disparity."""
SGBM_SOURCES = ("auto", "sgbm", "fused")
"""The disparity sources under which a frame's disparity may come from SGBM."""


class FrameFiles(Protocol):
    """The files of one frame this module reads (a :class:`freespace.data.base.FrameRef`)."""

    name: str
    left: Path
    right: Path | None
    disparity: Path | None
    depth: Path | None
    velodyne: Path | None


def check_disparity_source(mode: str) -> str:
    """``mode`` if it is one of :data:`DISPARITY_SOURCES`, else InvalidOptionError."""
    if mode not in DISPARITY_SOURCES:
        raise InvalidOptionError(f"unknown disparity source {mode!r}; choose one of {', '.join(DISPARITY_SOURCES)}")
    return mode


class DisparityCache:
    """SGBM disparities on disk, keyed by the frame's image files (path, size, mtime), the matcher
    settings and its version (:data:`~freespace.geometry.stereo.SGBM_VERSION`), so a second run costs one ``.npy``
    read. Default folder: ``$XDG_CACHE_HOME/freespace/sgbm`` (``~/.cache/freespace/sgbm``)."""

    def __init__(self, folder: PathLike | None = None, **settings: Any) -> None:
        base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "freespace" / "sgbm"
        self.folder = Path(folder) if folder is not None else base
        if folder is not None:  # an output folder the user named: no device, nothing on /proc, … (one line)
            check_writable(self.folder, "cache_dir", folder=True)
        if self.folder.exists() and not self.folder.is_dir():
            raise InvalidOptionError(f"{param('cache_dir')} {self.folder} is a file; give a folder for the SGBM "
                                     f"disparities")
        self.settings = dict(sorted(settings.items()))

    def path(self, frame: FrameFiles) -> Path:
        """Cache file of ``frame`` under the current settings."""
        parts = [self.settings, SGBM_VERSION]
        for p in (frame.left, frame.right):
            st = Path(p).stat()  # type: ignore[arg-type]
            parts.append([str(Path(p).resolve()), st.st_size, st.st_mtime_ns])  # type: ignore[arg-type]
        key = hashlib.sha1(json.dumps(parts, default=str).encode()).hexdigest()[:16]
        return self.folder / f"{frame.name}-{key}.npy"

    def get(self, frame: FrameFiles, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """The cached disparity, computing and storing it on a miss."""
        path = self.path(frame)
        if path.is_file():
            try:
                return np.load(path, allow_pickle=False)
            except (OSError, ValueError):
                log.warning("unreadable cache file %s: recomputing", path)
        disp = compute_disparity(left, right, **self.settings)
        buf = _io.BytesIO()
        np.save(buf, disp)
        atomic_write_bytes(path, buf.getvalue())
        return disp


#: two disparities of one pixel agree when they differ by at most this many pixels …
FUSE_TOLERANCE_PX = 1.0
#: … or by at most this share of the LiDAR disparity, whichever is larger (SGBM's error on a real road is
#: about 0.3 px; a LiDAR point seen past an object's edge, the scanner sitting 0.8 m above the camera, differs
#: by many pixels)
FUSE_TOLERANCE_REL = 0.05


def fuse_disparities(lidar: np.ndarray, sgbm: np.ndarray) -> np.ndarray:
    """Join a LiDAR disparity and an SGBM disparity of one left image (``float32 H×W`` pixels, NaN invalid).

    Where both are valid and agree (``|lidar − sgbm| ≤ max(FUSE_TOLERANCE_PX, FUSE_TOLERANCE_REL · lidar)``)
    the LiDAR value is kept; where both are valid and disagree the pixel becomes NaN (neither is trusted);
    where one is valid, its value is kept. Returns a new ``float32 H×W`` map.

    >>> import numpy as np
    >>> lidar = np.array([[10.0, 10.0, np.nan, np.nan]], np.float32)
    >>> sgbm = np.array([[10.4, 14.0, 7.0, np.nan]], np.float32)
    >>> fuse_disparities(lidar, sgbm)
    array([[10., nan,  7., nan]], dtype=float32)
    """
    if lidar.shape != sgbm.shape:
        raise ValueError(f"the LiDAR disparity is {lidar.shape} and the SGBM one {sgbm.shape}; give maps of one image")
    both = np.isfinite(lidar) & np.isfinite(sgbm)
    agree = np.zeros_like(both)
    agree[both] = np.abs(lidar[both] - sgbm[both]) <= np.maximum(FUSE_TOLERANCE_PX, FUSE_TOLERANCE_REL * lidar[both])
    out = np.where(np.isfinite(lidar), lidar, sgbm).astype(np.float32)
    out[both & ~agree] = np.nan
    return out


def resolve_disparity(frame: FrameFiles, left: np.ndarray, right: np.ndarray | None,
                      calib: StereoCalibration | None, *, mode: str, cache: DisparityCache,
                      read_depth: Callable[[], np.ndarray],
                      read_lidar: Callable[[], np.ndarray] | None = None) -> tuple[np.ndarray | None, str]:
    """The frame's left disparity (``float32 H×W`` pixels, NaN invalid) and its source.

    ``mode`` ``auto``: the disparity file, else depth (``read_depth()``, metres) and ``calib`` (with a
    baseline > 0; a monocular camera, baseline 0, gives no disparity from depth), else
    cached SGBM of ``left`` and ``right``; ``file``: file or depth only; ``depth``: depth only; ``lidar``:
    ``read_lidar()`` only (the scan's disparity, already in pixels); ``sgbm``: always SGBM; ``fused``: the
    scan and SGBM joined by :func:`fuse_disparities` (either alone where the frame has only one); ``none``:
    nothing. Returns ``(None, "none")`` when no allowed source is there, except for ``depth`` and
    ``lidar``, which were asked for by name.

    Raises:
        DatasetError: mode ``depth`` and the frame has no depth file or no camera (or a monocular one,
            baseline 0); mode ``lidar`` and
            it has no scan or no calibration; mode ``fused`` and it has neither a scan nor a right image.
    """
    if mode == "depth":
        if frame.depth is None or calib is None or not calib.baseline > 0:
            what = ("depth map" if frame.depth is None else "camera calibration (f and B for d = f·B/Z)"
                    if calib is None else "baseline (a monocular camera: give `baseline` for d = f·B/Z)")
            raise DatasetError(f"{frame.name} has no {what}; {param('disparity_source')} depth needs one for every "
                               f"frame")
        return depth_to_disparity(read_depth(), calib.fx, calib.baseline), "depth"
    if mode == "lidar":
        if frame.velodyne is None or read_lidar is None:
            raise DatasetError(f"{frame.name} has no Velodyne scan (velodyne/<frame>.bin); "
                               f"{param('disparity_source')} lidar "
                               f"needs one for every frame")
        return read_lidar(), "lidar"
    if mode == "fused":
        lidar = read_lidar() if frame.velodyne is not None and read_lidar is not None else None
        sgbm = cache.get(frame, left, right) if right is not None else None
        if lidar is None and sgbm is None:
            raise DatasetError(f"{frame.name} has neither a Velodyne scan nor a right image; "
                               f"{param('disparity_source')} fused needs one of them")
        if lidar is None or sgbm is None:
            return (sgbm, "sgbm") if lidar is None else (lidar, "lidar")
        return fuse_disparities(lidar, sgbm), "fused"
    if mode in ("auto", "file"):
        if frame.disparity is not None:
            return read_disparity(frame.disparity), "file"
        if frame.depth is not None and calib is not None and calib.baseline > 0:  # 0: monocular, no disparity
            return depth_to_disparity(read_depth(), calib.fx, calib.baseline), "depth"
    if mode in ("auto", "sgbm") and right is not None:
        return cache.get(frame, left, right), "sgbm"
    return None, "none"
