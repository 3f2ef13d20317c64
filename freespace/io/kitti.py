"""KITTI's own file formats: calibration text files and Velodyne scans.

Only NumPy is imported here.
"""

from __future__ import annotations

import re

import numpy as np

from freespace.errors import CorruptFileError
from freespace.io.files import PathLike, read_bytes

__all__ = ["read_kitti_calib", "read_kitti_raw_calib", "read_velodyne", "VELODYNE_POINT_BYTES"]

VELODYNE_POINT_BYTES = 16
"""Bytes per point of a KITTI Velodyne scan: float32 x, y, z, reflectance."""

# ---------------------------------------------------------------------------------------------------
# KITTI calibration


def _parse_calib(path: PathLike, text_keys: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """``KEY: v1 v2 ...`` lines of a KITTI calibration file as flat float64 arrays (``text_keys``, such as
    KITTI raw's ``calib_time``, are skipped: their values are not numbers)."""
    text = read_bytes(path, "calibration file").decode("utf-8", errors="replace")
    calib: dict[str, np.ndarray] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        key, sep, values = line.partition(":")
        key = key.strip()
        if sep and key in text_keys:
            continue
        try:
            if not sep:
                raise ValueError
            arr = np.array([float(x) for x in values.split()], dtype=np.float64)
        except ValueError:
            raise CorruptFileError(f"calibration file {path} line {lineno} is not 'KEY: numbers'") from None
        if not np.isfinite(arr).all():
            raise CorruptFileError(f"calibration file {path}: {key} has a value that is not finite (NaN or inf)")
        calib[key] = arr
    return calib


def _shaped(path: PathLike, key: str, arr: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    if arr.size != shape[0] * shape[1]:
        raise CorruptFileError(f"calibration file {path}: {key} has {arr.size} numbers, a {shape[0]}×{shape[1]} "
                               f"matrix needs {shape[0] * shape[1]}")
    return arr.reshape(shape)


def read_kitti_calib(path: PathLike) -> dict[str, np.ndarray]:
    """Parse a KITTI calibration text file (``KEY: v1 v2 ...`` lines): a frame's file of KITTI road, stereo or
    object, or KITTI raw's ``calib_cam_to_cam.txt`` of a recording day (read as :func:`read_kitti_raw_calib`
    reads it, without the Velodyne's file).

    Returns:
        A dict of float64 arrays: ``P0``–``P3`` are 3×4, ``R0_rect`` (or ``R_rect``) 3×3, ``Tr_*`` 3×4;
        other keys keep their flat values.
    """
    calib = _parse_calib(path, text_keys=("calib_time",))
    if "P2" not in calib and "P_rect_02" in calib:
        return _cam_to_cam(path, calib)
    for key, arr in calib.items():
        if re.fullmatch(r"P\d|Tr_\w+", key):
            calib[key] = _shaped(path, key, arr, (3, 4))
        elif re.fullmatch(r"R0?_rect", key):
            calib[key] = _shaped(path, key, arr, (3, 3))
    if "P2" not in calib:
        raise CorruptFileError(f"calibration file {path} has no P2 line; expected a KITTI calibration file (a "
                               f"frame's, with P2, or KITTI raw's calib_cam_to_cam.txt, with P_rect_02)")
    for key in [k for k in calib if k.startswith("Tr_")] + [k for k in ("R0_rect", "R_rect") if k in calib]:
        rotation = calib[key][:, :3]
        if abs(np.linalg.det(rotation)) < 1e-6:
            raise CorruptFileError(f"calibration file {path}: {key} is singular (its rotation part has "
                                   f"determinant {np.linalg.det(rotation):.1e}); expected a rigid transform")
    if abs(np.linalg.det(calib["P2"][:, :3])) < 1e-9:
        raise CorruptFileError(f"calibration file {path}: P2 is singular; expected a camera projection matrix")
    return calib


def _check_rotation(path: PathLike, key: str, rotation: np.ndarray) -> None:
    if abs(np.linalg.det(rotation)) < 1e-6:
        raise CorruptFileError(f"calibration file {path}: {key} is singular (its rotation part has "
                               f"determinant {np.linalg.det(rotation):.1e}); expected a rigid transform")


def read_kitti_raw_calib(cam_to_cam: PathLike, velo_to_cam: PathLike | None = None) -> dict[str, np.ndarray]:
    """Parse KITTI raw's calibration files of one recording day into the keys of :func:`read_kitti_calib`,
    so that :func:`freespace.geometry.depth.rig_from_kitti` and
    :func:`freespace.geometry.lidar.velodyne_to_disparity` read them as they read a KITTI road file.

    Args:
        cam_to_cam: ``<date>/calib_cam_to_cam.txt`` (``S_rect_0i``, ``R_rect_00``, ``P_rect_0i``, ...).
        velo_to_cam: ``<date>/calib_velo_to_cam.txt`` (``R``, ``T``: Velodyne → unrectified camera 0), or None.

    Returns:
        ``P2`` = ``P_rect_02`` and ``P3`` = ``P_rect_03`` (3×4; ``P3`` only when the file has it),
        ``R0_rect`` = ``R_rect_00`` (3×3), ``S_rect_02`` = ``(W, H)`` of the rectified left colour image in
        pixels, and with ``velo_to_cam`` ``Tr_velo_to_cam`` = ``[R | T]`` (3×4, metres). A Velodyne point
        then maps to the left image as KITTI's raw devkit maps it: ``P_rect_02 · R_rect_00 · [R | T] · X``.

    Raises:
        InputFileError: a file is missing or unreadable. CorruptFileError: a line that is not
        ``KEY: numbers``, a missing or malformed key, a singular rotation or projection.
    """
    calib = _cam_to_cam(cam_to_cam, _parse_calib(cam_to_cam, text_keys=("calib_time",)))
    if velo_to_cam is not None:
        velo = _parse_calib(velo_to_cam, text_keys=("calib_time",))
        missing = [k for k in ("R", "T") if k not in velo]
        if missing:
            raise CorruptFileError(f"calibration file {velo_to_cam} has no {' and no '.join(missing)} line; expected "
                                   f"KITTI raw's calib_velo_to_cam.txt (R: 9 numbers, T: 3)")
        rotation = _shaped(velo_to_cam, "R", velo["R"], (3, 3))
        translation = _shaped(velo_to_cam, "T", velo["T"], (3, 1))
        _check_rotation(velo_to_cam, "R", rotation)
        calib["Tr_velo_to_cam"] = np.hstack([rotation, translation])
    return calib


def _cam_to_cam(cam_to_cam: PathLike, cam: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The keys of :func:`read_kitti_calib` from the parsed lines ``cam`` of KITTI raw's calib_cam_to_cam.txt."""
    calib: dict[str, np.ndarray] = {}
    for key, out, shape in (("P_rect_02", "P2", (3, 4)), ("R_rect_00", "R0_rect", (3, 3)), ("S_rect_02", "S_rect_02", (1, 2)),
                            ("P_rect_03", "P3", (3, 4))):
        if key not in cam:
            if out == "P3":
                continue
            raise CorruptFileError(f"calibration file {cam_to_cam} has no {key} line; expected KITTI raw's "
                                   f"calib_cam_to_cam.txt of the recording day")
        calib[out] = _shaped(cam_to_cam, key, cam[key], shape)
    calib["S_rect_02"] = calib["S_rect_02"].reshape(2)
    w, h = calib["S_rect_02"]
    if not (w >= 1 and h >= 1 and w == int(w) and h == int(h)):
        raise CorruptFileError(f"calibration file {cam_to_cam}: S_rect_02 must be the image's width and height in "
                               f"pixels, got {w:g} {h:g}")
    _check_rotation(cam_to_cam, "R_rect_00", calib["R0_rect"])
    for key in ("P2", "P3"):
        if key in calib and abs(np.linalg.det(calib[key][:, :3])) < 1e-9:
            raise CorruptFileError(f"calibration file {cam_to_cam}: P_rect_0{key[1]} is singular; expected a camera "
                                   f"projection matrix")
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
    if not data or len(data) % VELODYNE_POINT_BYTES:
        raise CorruptFileError(f"Velodyne scan {path} has {len(data)} bytes; expected a non-empty multiple of 16 "
                               f"(float32 x, y, z, reflectance per point): a truncated copy? copy the scan again "
                               f"or delete it")
    points = np.frombuffer(data, dtype="<f4").reshape(-1, 4).astype(np.float32)
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise CorruptFileError(f"Velodyne scan {path} has {int(bad.sum())} points with NaN or inf values; "
                               f"expected a KITTI .bin scan (float32 x, y, z, reflectance)")
    return points
