"""The KITTI road benchmark's bird's-eye view (BEV), exactly as the official devkit's transform does.

The BEV grid has 800 rows × 400 columns of 0.05 m cells covering x −10…10 m (columns, left to right) and
z 6…46 m (rows, row 0 farthest). Cell centres ``x = −9.975 + 0.05·col``, ``z = 45.975 − 0.05·row``, cast to
float32. With ``Tr = P2 · R0_rect · inv(Tr_cam_to_road)`` (4×4 forms; columns 0, 2, 3 kept because the road
plane is Y = 0), ``(u, v, w) = Tr · (x, z, 1)``, ``u /= w``, ``v /= w``; a cell is inside when
``1 ≤ u ≤ W`` and ``1 ≤ v ≤ H`` (1-based, as in the devkit) and copies the image pixel
``[floor(v) − 1, floor(u) − 1]``; outside cells are 0 (black: don't care in ground truth). NumPy only.
"""

from __future__ import annotations

import numpy as np

from freespace.errors import InvalidOptionError

__all__ = ["BEV_SHAPE", "bev_grid", "bev_matrix", "bev_lookup", "to_bev"]

BEV_SHAPE = (800, 400)
CELL = 0.05


def bev_grid() -> tuple[np.ndarray, np.ndarray]:
    """Cell-centre coordinates ``(x, z)`` in metres on the road plane, each ``float32 800×400``."""
    rows, cols = BEV_SHAPE
    x = (-9.975 + CELL * np.arange(cols)).astype(np.float32)
    z = (45.975 - CELL * np.arange(rows)).astype(np.float32)
    return np.broadcast_to(x[None, :], BEV_SHAPE), np.broadcast_to(z[:, None], BEV_SHAPE)


def bev_matrix(calib: dict[str, np.ndarray]) -> np.ndarray:
    """``Tr[:, [0, 2, 3]]`` (3×3) with ``Tr = P2 · R0_rect · inv(Tr_cam_to_road)`` from a parsed KITTI calibration."""
    try:
        P2, R0, road = calib["P2"], calib.get("R0_rect", calib.get("R_rect")), calib["Tr_cam_to_road"]
    except KeyError as exc:
        raise InvalidOptionError(f"the calibration has no {exc.args[0]}; the BEV transform needs P2, R0_rect and "
                                 f"Tr_cam_to_road") from None
    R = np.eye(4)
    R[:3, :3] = R0
    T = np.eye(4)
    T[:3, :] = road
    return (P2 @ R @ np.linalg.inv(T))[:, [0, 2, 3]]


def bev_lookup(calib: dict[str, np.ndarray], image_shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every BEV cell: ``(inside, row, col)`` — whether it sees the image and which pixel (0-based)."""
    x, z = bev_grid()
    Tr = bev_matrix(calib)
    pts = np.stack([x, z, np.ones_like(x)]).reshape(3, -1)
    uvw = Tr @ pts
    u = (uvw[0] / uvw[2]).reshape(BEV_SHAPE)
    v = (uvw[1] / uvw[2]).reshape(BEV_SHAPE)
    h, w = image_shape
    with np.errstate(invalid="ignore"):
        inside = (u >= 1) & (u <= w) & (v >= 1) & (v <= h)
    row = np.where(inside, np.floor(v) - 1, 0).astype(np.intp)
    col = np.where(inside, np.floor(u) - 1, 0).astype(np.intp)
    return inside, row, col


def to_bev(image: np.ndarray, calib: dict[str, np.ndarray]) -> np.ndarray:
    """The BEV of a perspective image (``H×W`` or ``H×W×C``, any dtype): ``800×400[×C]``, 0 outside."""
    inside, row, col = bev_lookup(calib, image.shape[:2])
    out = image[row, col]
    out[~inside] = 0
    return out
