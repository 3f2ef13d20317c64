"""KITTI's own file formats: calibration text files and Velodyne scans.

Only NumPy is imported here.
"""

from __future__ import annotations

import re

import numpy as np

from freespace.errors import CorruptFileError
from freespace.io.files import PathLike, read_bytes

__all__ = ["read_kitti_calib", "read_velodyne"]

# ---------------------------------------------------------------------------------------------------
# KITTI calibration


def read_kitti_calib(path: PathLike) -> dict[str, np.ndarray]:
    """Parse a KITTI calibration text file (``KEY: v1 v2 ...`` lines).

    Returns:
        A dict of float64 arrays: ``P0``–``P3`` are 3×4, ``R0_rect`` (or ``R_rect``) 3×3, ``Tr_*`` 3×4;
        other keys keep their flat values.
    """
    text = read_bytes(path, "calibration file").decode("utf-8", errors="replace")
    calib: dict[str, np.ndarray] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        key, sep, values = line.partition(":")
        try:
            if not sep:
                raise ValueError
            arr = np.array([float(x) for x in values.split()], dtype=np.float64)
        except ValueError:
            raise CorruptFileError(f"calibration file {path} line {lineno} is not 'KEY: numbers'") from None
        key = key.strip()
        if not np.isfinite(arr).all():
            raise CorruptFileError(f"calibration file {path}: {key} has a value that is not finite (NaN or inf)")
        if re.fullmatch(r"P\d|Tr_\w+", key):
            if arr.size != 12:
                raise CorruptFileError(f"calibration file {path}: {key} has {arr.size} numbers, a 3×4 matrix "
                                       f"needs 12")
            arr = arr.reshape(3, 4)
        elif re.fullmatch(r"R0?_rect", key):
            if arr.size != 9:
                raise CorruptFileError(f"calibration file {path}: {key} has {arr.size} numbers, a 3×3 matrix "
                                       f"needs 9")
            arr = arr.reshape(3, 3)
        calib[key] = arr
    if "P2" not in calib:
        raise CorruptFileError(f"calibration file {path} has no P2 line; expected a KITTI calibration file")
    for key in [k for k in calib if k.startswith("Tr_")] + [k for k in ("R0_rect", "R_rect") if k in calib]:
        rotation = calib[key][:, :3]
        if abs(np.linalg.det(rotation)) < 1e-6:
            raise CorruptFileError(f"calibration file {path}: {key} is singular (its rotation part has "
                                   f"determinant {np.linalg.det(rotation):.1e}); expected a rigid transform")
    if abs(np.linalg.det(calib["P2"][:, :3])) < 1e-9:
        raise CorruptFileError(f"calibration file {path}: P2 is singular; expected a camera projection matrix")
    return calib


def read_velodyne(path: PathLike) -> np.ndarray:
    """Read a KITTI Velodyne scan (``velodyne/<frame>.bin``: raw little-endian float32, 16 bytes per point).

    Returns:
        ``float32 N×4``: x, y, z (metres, Velodyne frame: x forward, y left, z up) and reflectance, N ≥ 1.

    Raises:
        InputFileError: missing or unreadable file. CorruptFileError: empty, a size that is not a
        multiple of 16 bytes (4 float32 per point), or NaN/inf values.
    """
    data = read_bytes(path, "Velodyne scan")
    if not data or len(data) % 16:
        raise CorruptFileError(f"Velodyne scan {path} has {len(data)} bytes; expected a non-empty multiple of 16 "
                               f"(float32 x, y, z, reflectance per point)")
    points = np.frombuffer(data, dtype="<f4").reshape(-1, 4).astype(np.float32)
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise CorruptFileError(f"Velodyne scan {path} has {int(bad.sum())} points with NaN or inf values; "
                               f"expected a KITTI .bin scan (float32 x, y, z, reflectance)")
    return points
