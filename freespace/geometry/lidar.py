"""Disparity from KITTI Velodyne scans: project the points into the left image (the scans are read by
:func:`freespace.io.kitti.read_velodyne`).

Conventions
-----------
A scan is ``float32 N×4`` (x, y, z in metres in the Velodyne frame — x forward, y left, z up — and the
reflectance), stored as raw little-endian float32, 16 bytes per point (KITTI's format). A point goes to
the image as ``p̃ = P2 · R0_rect · Tr_velo_to_cam · (x, y, z, 1)`` (``R0_rect`` and ``Tr_velo_to_cam``
padded to 4×4); ``u = p̃₀/p̃₂``, ``v = p̃₁/p̃₂`` in the package's pixel convention (0-based, u right,
v down, pixel centres at integers, as :class:`~freespace.geometry.StereoCalibration` reads P2), and
``Z = p̃₂`` is the depth along the P2 camera's optical axis. A point lands on the pixel
``(round(u), round(v))``.

The map is sparse: about 5 % of the pixels of a KITTI image have a point, and only below the horizon.
The road fit (:func:`freespace.geometry.fit_road_model`) needs only the road's points, so the sparse
map is what to fit; :func:`densify_nearest` fills small gaps for uses that want a dense map (display,
disparity inputs of a network), at the price of values copied from a neighbour.

Only NumPy and OpenCV are imported here; never torch.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from freespace.errors import CorruptFileError, InvalidOptionError
from freespace.geometry.depth import depth_to_disparity, rig_from_kitti

__all__ = [
    "velodyne_to_camera",
    "project_velodyne",
    "velodyne_to_disparity",
    "densify_nearest",
    "DEFAULT_MIN_DEPTH_M",
]

DEFAULT_MIN_DEPTH_M = 0.1
"""Points closer than this along the optical axis (metres) — and every point behind the camera — are dropped."""


def _matrix(calib: dict[str, np.ndarray], keys: tuple[str, ...], shape: tuple[int, int],
            default: np.ndarray | None = None) -> np.ndarray:
    for key in keys:
        if key in calib:
            m = np.asarray(calib[key], np.float64)
            if m.size != shape[0] * shape[1] or not np.isfinite(m).all():
                raise CorruptFileError(f"calibration {key} must be {shape[0]}×{shape[1]} finite numbers, got "
                                       f"{m.size} values")
            return m.reshape(shape)
    if default is not None:
        return default
    raise CorruptFileError(f"the calibration has no {keys[0]}; projecting a Velodyne scan needs a KITTI calibration "
                           f"with Tr_velo_to_cam, R0_rect and P2")


def velodyne_to_camera(points: np.ndarray, calib: dict[str, np.ndarray], camera: str = "P2") -> np.ndarray:
    """Homogeneous image coordinates of Velodyne points: ``p̃ = P · R0_rect · Tr_velo_to_cam · (x, y, z, 1)``.

    Args:
        points: ``N×3`` or ``N×4`` points in the Velodyne frame (metres; a 4th column is ignored).
        calib: a parsed KITTI calibration (:func:`freespace.io.kitti.read_kitti_calib`) with
            ``Tr_velo_to_cam`` (3×4), ``P2`` (3×4) and ``R0_rect`` (3×3; identity when absent).
        camera: the projection matrix to use.

    Returns:
        ``float64 N×3`` ``(p̃₀, p̃₁, p̃₂)``; ``u = p̃₀/p̃₂``, ``v = p̃₁/p̃₂``, depth ``Z = p̃₂`` (metres).

    Example:
        >>> calib = {"Tr_velo_to_cam": np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0]]),  # x fwd, y left, z up
        ...          "P2": np.array([[700.0, 0, 600, 0], [0, 700, 180, 0], [0, 0, 1, 0]])}
        >>> p = velodyne_to_camera(np.array([[10.0, 0.0, -1.5]]), calib)  # 10 m ahead, 1.5 m below the scanner
        >>> (p[:, :2] / p[:, 2:]).tolist(), float(p[0, 2])  # (u, v) and the depth Z
        ([[600.0, 285.0]], 10.0)
    """
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise InvalidOptionError(f"points must be N×3 or N×4, got shape {pts.shape}")
    tr = _matrix(calib, ("Tr_velo_to_cam", "Tr_velo_cam"), (3, 4))
    r0 = _matrix(calib, ("R0_rect", "R_rect"), (3, 3), np.eye(3))
    P = _matrix(calib, (camera,), (3, 4))
    M = P @ np.vstack([np.hstack([r0, np.zeros((3, 1))]), [0, 0, 0, 1]]) @ np.vstack([tr, [0, 0, 0, 1]])
    return pts[:, :3].astype(np.float64) @ M[:, :3].T + M[:, 3]


def project_velodyne(points: np.ndarray, calib: dict[str, np.ndarray], shape: tuple[int, int], *,
                     camera: str = "P2", min_depth: float = DEFAULT_MIN_DEPTH_M) -> np.ndarray:
    """Sparse depth map of a Velodyne scan: the nearest point per pixel.

    Args:
        points: ``N×3``/``N×4`` scan (:func:`read_velodyne`). calib: KITTI calibration dict (see
            :func:`velodyne_to_camera`). shape: ``(H, W)`` of the image.
        camera: projection matrix name. min_depth: points with ``Z ≤ min_depth`` metres (behind or
            just in front of the camera) are dropped.

    Returns:
        ``float32 H×W`` depth ``Z`` in metres along the optical axis, NaN where no point landed. Where
        several points land on one pixel, the nearest (smallest Z) wins.

    Example:
        >>> calib = {"Tr_velo_to_cam": np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0]]),
        ...          "P2": np.array([[700.0, 0, 600, 0], [0, 700, 180, 0], [0, 0, 1, 0]])}
        >>> scan = np.array([[10.0, 0, -1.5], [20.0, 0, -3.0], [-5.0, 0, 0]])  # two on one pixel, one behind
        >>> depth = project_velodyne(scan, calib, (375, 1242))
        >>> float(depth[285, 600]), int(np.isfinite(depth).sum())  # the nearest point wins its pixel
        (10.0, 1)
    """
    h, w = (int(x) for x in shape)
    if h < 1 or w < 1 or not (math.isfinite(min_depth) and min_depth >= 0):
        raise InvalidOptionError(f"shape must be (H, W) ≥ 1 and min_depth ≥ 0, got {shape}, {min_depth}")
    p = velodyne_to_camera(points, calib, camera)
    z = p[:, 2]
    front = z > min_depth
    p, z = p[front], z[front]
    u = np.rint(p[:, 0] / z)
    v = np.rint(p[:, 1] / z)
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    idx = (v[inside] * w + u[inside]).astype(np.int64)
    z = z[inside]
    order = np.lexsort((z, idx))            # by pixel, then nearest first
    idx, z = idx[order], z[order]
    first = np.ones(idx.size, bool)
    first[1:] = idx[1:] != idx[:-1]
    depth = np.full(h * w, np.nan, np.float32)
    depth[idx[first]] = z[first].astype(np.float32)
    return depth.reshape(h, w)


def velodyne_to_disparity(points: np.ndarray, calib: dict[str, np.ndarray], shape: tuple[int, int], *,
                          baseline: float | None = None, min_depth: float = DEFAULT_MIN_DEPTH_M,
                          densify_gap: int = 0) -> np.ndarray:
    """Sparse (optionally densified) disparity of a Velodyne scan in the left (P2) image.

    ``d = f·B / Z`` with ``f = P2[0, 0]`` and ``B`` from P2 and P3, or a virtual baseline when
    ``baseline`` is given or P3 is missing (:func:`freespace.geometry.depth.rig_from_kitti`).

    Args:
        points, calib, shape, min_depth: as :func:`project_velodyne`.
        baseline: virtual baseline in metres, or None for the calibration's.
        densify_gap: 0 (default) keeps the sparse map; ``k > 0`` fills every empty pixel within ``k``
            pixels of a point with that nearest point's disparity (:func:`densify_nearest`).

    Returns:
        ``float32 H×W`` disparity in pixels, NaN = no value.

    Example:
        >>> calib = {"Tr_velo_to_cam": np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0]]),
        ...          "P2": np.array([[700.0, 0, 600, 0], [0, 700, 180, 0], [0, 0, 1, 0]])}
        >>> d = velodyne_to_disparity(np.array([[10.0, 0, -1.5]]), calib, (375, 1242), baseline=0.5)
        >>> float(d[285, 600]), int(np.isfinite(d).sum())  # f·B/Z = 700 · 0.5 / 10
        (35.0, 1)
    """
    rig = rig_from_kitti(calib, baseline=baseline)
    disparity = depth_to_disparity(project_velodyne(points, calib, shape, min_depth=min_depth), rig.fx, rig.baseline)
    return densify_nearest(disparity, densify_gap) if densify_gap else disparity


def densify_nearest(disparity: np.ndarray, max_gap_px: float) -> np.ndarray:
    """Fill holes with the value of the nearest valid pixel, within ``max_gap_px``.

    Args:
        disparity: ``float32 H×W`` map, NaN = no value (e.g. a projected LiDAR scan).
        max_gap_px: largest Euclidean distance in pixels from a hole to a valid pixel that is filled
            (≥ 0; 0 returns a copy). Holes farther from every value stay NaN, so the sky and areas the
            scanner never reached are not invented.

    Returns:
        ``float32 H×W``: the valid values unchanged, holes within reach filled (nearest neighbour
        by OpenCV's 5×5-mask distance transform, within about 2 % of the Euclidean distance; never
        interpolated across values), the rest NaN.

    Example:
        >>> d = np.full((5, 5), np.nan, np.float32)
        >>> d[2, 2] = 7.0
        >>> filled = densify_nearest(d, 1.5)  # the 8 neighbours are within 1.5 px, the corners are not
        >>> int(np.isfinite(filled).sum()), float(filled[1, 1]), bool(np.isnan(filled[0, 0]))
        (9, 7.0, True)
    """
    if not (math.isfinite(max_gap_px) and max_gap_px >= 0):
        raise InvalidOptionError(f"the densification gap must be ≥ 0 pixels, got {max_gap_px}")
    disp = np.asarray(disparity, np.float32)
    if disp.ndim != 2:
        raise InvalidOptionError(f"disparity must be 2-D (H×W), got shape {disp.shape}")
    valid = np.isfinite(disp)
    out = disp.copy()
    if max_gap_px == 0 or not valid.any() or valid.all():
        return out
    # distance (and label) of every pixel to the nearest zero pixel of the mask = the nearest valid pixel
    dist, labels = cv2.distanceTransformWithLabels((~valid).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5,
                                                   labelType=cv2.DIST_LABEL_PIXEL)
    lookup = np.zeros(int(labels.max()) + 1, np.float32)
    lookup[labels[valid]] = disp[valid]
    fill = ~valid & (dist <= max_gap_px)
    out[fill] = lookup[labels[fill]]
    return out
