"""KITTI's own file formats: calibration text files and Velodyne scans.

Only NumPy is imported here.
"""

from __future__ import annotations

import re

import numpy as np

from freespace.errors import CorruptFileError
from freespace.io.files import PathLike, read_bytes
from freespace.limits import MAX_BASELINE_M, MAX_FOCAL_PX, MAX_IMAGE_PIXELS, MAX_SCAN_POINTS, MIN_BASELINE_M

__all__ = ["read_kitti_calib", "read_kitti_raw_calib", "read_velodyne", "VELODYNE_POINT_BYTES"]

VELODYNE_POINT_BYTES = 16
"""Bytes per point of a KITTI Velodyne scan: float32 x, y, z, reflectance."""

# ---------------------------------------------------------------------------------------------------
# KITTI calibration

_CALIB_MAX_BYTES = 2**20


def _parse_calib(path: PathLike, text_keys: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """``KEY: v1 v2 ...`` lines of a KITTI calibration file as flat float64 arrays (``text_keys``, such as
    KITTI raw's ``calib_time``, are skipped: their values are not numbers)."""
    text = read_bytes(path, "calibration file", _CALIB_MAX_BYTES, "1 MiB a calibration file may have (KITTI's have "
                      "about 3 KB)").decode("utf-8", errors="replace")
    calib: dict[str, np.ndarray] = {}
    lines: dict[str, int] = {}
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        key, sep, values = line.partition(":")
        key = key.strip()
        if sep and key in lines:
            raise CorruptFileError(f"calibration file {path}: {key} is given twice (lines {lines[key]} and {lineno}); "
                                   f"keep the right one")
        lines[key] = lineno
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

    Raises:
        InputFileError: missing or unreadable. CorruptFileError: a line that is not ``KEY: numbers``, a key given
        twice, a matrix of the wrong size, no ``P2``, a rotation that is none (``R0_rect``, ``Tr_*``), or a rig no
        camera has: ``P2`` singular, a focal length ≤ 0 or beyond ``MAX_FOCAL_PX``, ``P3`` with other intrinsics,
        or a baseline outside ``MIN_BASELINE_M``…``MAX_BASELINE_M`` (``freespace.limits``).
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
        _check_rotation(path, key, calib[key][:, :3])
    _check_rig(path, calib, ("P2", "P3"))
    return calib


def _check_rotation(path: PathLike, key: str, rotation: np.ndarray) -> None:
    """Refuse a rotation (part) ``key`` that is singular or no rotation (``R·Rᵀ`` off the identity by more than
    1e-3: KITTI's are within 1e-6)."""
    det = np.linalg.det(rotation)
    if abs(det) < 1e-6:
        raise CorruptFileError(f"calibration file {path}: {key} is singular (its rotation part has "
                               f"determinant {det:.1e}); expected a rigid transform")
    error = float(np.abs(rotation @ rotation.T - np.eye(3)).max())
    if error > 1e-3 or det < 0:
        raise CorruptFileError(f"calibration file {path}: {key}'s rotation part is no rotation (determinant {det:.3g},"
                               f" R·Rᵀ off the identity by {error:.2g}); expected a rigid transform")


def _check_rig(path: PathLike, calib: dict[str, np.ndarray], keys: tuple[str, str], names: tuple[str, str] = ("", ""),
               size: tuple[int, int] | None = None) -> None:
    """Refuse a stereo rig no camera has: the left projection ``keys[0]`` (and the right ``keys[1]`` if the file has
    it) singular, a focal length that is not positive or beyond :data:`~freespace.limits.MAX_FOCAL_PX`, a principal
    point outside the image of ``size`` ``(W, H)`` (when known), intrinsics that differ between the two (not one
    rectified pair), or a baseline (metres, from the 4th columns) outside
    :data:`~freespace.limits.MIN_BASELINE_M`…:data:`~freespace.limits.MAX_BASELINE_M`. ``names``: the keys as the
    file spells them (``P_rect_02``), when they differ."""
    left, right = (name or key for name, key in zip(names, keys))
    P = calib[keys[0]]
    if abs(np.linalg.det(P[:, :3])) < 1e-9:
        raise CorruptFileError(f"calibration file {path}: {left} is singular; expected a camera projection matrix")
    fx, fy, cx, cy = P[0, 0], P[1, 1], P[0, 2], P[1, 2]
    if not (0 < fx <= MAX_FOCAL_PX and 0 < fy <= MAX_FOCAL_PX):
        raise CorruptFileError(f"calibration file {path}: {left} gives a focal length of {fx:g}×{fy:g} px (fx×fy); "
                               f"a camera's is positive and at most {MAX_FOCAL_PX:g} px: check the file's numbers")
    if size is not None and not (0 <= cx <= size[0] and 0 <= cy <= size[1]):
        raise CorruptFileError(f"calibration file {path}: {left} puts the principal point at ({cx:g}, {cy:g}) px, "
                               f"outside the {size[0]}×{size[1]} image; check the file's numbers")
    if keys[1] not in calib:
        return
    Q = calib[keys[1]]
    if not np.allclose(Q[:, :3], P[:, :3], rtol=1e-3, atol=1e-3):
        raise CorruptFileError(f"calibration file {path}: {right} has other intrinsics than {left} (first three "
                               f"columns differ), so the two are no rectified stereo pair; check the file")
    K = P[:, :3]
    baseline = float(np.linalg.solve(K, P[:, 3])[0] - np.linalg.solve(K, Q[:, 3])[0])
    if not MIN_BASELINE_M <= baseline <= MAX_BASELINE_M:
        where = "left of" if baseline < 0 else "from"
        raise CorruptFileError(f"calibration file {path}: {right} puts the right camera {abs(baseline):.4g} m {where} "
                               f"{left}'s; a stereo rig's baseline is {MIN_BASELINE_M:g}–{MAX_BASELINE_M:g} m to the "
                               f"right: check the file's 4th columns")


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
        ``KEY: numbers``, a key given twice, a missing or malformed key, a singular rotation or projection, or a
        rig no camera has (:func:`read_kitti_calib`'s checks, and a principal point outside ``S_rect_02``).
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
    for key, out, shape in (("P_rect_02", "P2", (3, 4)), ("R_rect_00", "R0_rect", (3, 3)),
                            ("S_rect_02", "S_rect_02", (1, 2)), ("P_rect_03", "P3", (3, 4))):
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
    if w * h > MAX_IMAGE_PIXELS:
        raise CorruptFileError(f"calibration file {cam_to_cam}: S_rect_02 gives images of {w:g}×{h:g} pixels, more "
                               f"than the image limit of {MAX_IMAGE_PIXELS:,} (MAX_IMAGE_PIXELS); check the file")
    _check_rotation(cam_to_cam, "R_rect_00", calib["R0_rect"])
    _check_rig(cam_to_cam, calib, ("P2", "P3"), ("P_rect_02", "P_rect_03"), (int(w), int(h)))
    return calib


def read_velodyne(path: PathLike) -> np.ndarray:
    """Read a KITTI Velodyne scan (``velodyne/<frame>.bin``: raw little-endian float32, 16 bytes per point).

    Returns:
        ``float32 N×4``: x, y, z (metres, Velodyne frame: x forward, y left, z up) and reflectance, N ≥ 1.

    Raises:
        InputFileError: missing or unreadable file. CorruptFileError: empty, a size that is not a
        multiple of 16 bytes (4 float32 per point), more than :data:`~freespace.limits.MAX_SCAN_POINTS` points
        (refused from its size, before it is read), or NaN/inf values.
    """
    data = read_bytes(path, "Velodyne scan", MAX_SCAN_POINTS * VELODYNE_POINT_BYTES,
                      f"scan limit of {MAX_SCAN_POINTS:,} points of {VELODYNE_POINT_BYTES} bytes (MAX_SCAN_POINTS; a "
                      f"KITTI scan holds about 120 000)")
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
