"""The road plane: one type, one sign convention, for the whole package.

Conventions
-----------
* The reference camera frame: x right, y down, z forward, in metres.
* :class:`RoadPlane` is ``{X : n·X = h}`` in a camera frame, with ``n`` the unit normal pointing from the
  camera *down to the road* (≈ (0, 1, 0) for a level camera) and ``h > 0`` the camera centre's height
  above the road, in metres. A calibration's plane (:attr:`freespace.geometry.StereoCalibration.road_plane`,
  from KITTI's ``Tr_cam_to_road`` or ``freespace.yaml``'s camera height and pitch), a fit of the road
  disparity (:meth:`RoadPlane.from_road_model`) and the plane-induced homographies
  (:func:`freespace.geometry.homography_from_pose`, :func:`freespace.geometry.virtual_homography`) all
  use this one.
* :func:`rotation_from_angles`: roll about z, pitch about x, yaw about y (degrees), ``R = R_yaw · R_pitch ·
  R_roll`` with the right-handed elementary rotations; positive pitch tilts the optical axis down.

NumPy only — never torch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from freespace.errors import InvalidOptionError
from freespace.geometry.road_model import RoadModel

__all__ = ["RoadPlane", "pose_ranges", "rotation_from_angles"]

#: a range of one pose parameter: ``(low, high)``, ``low ≤ high``
Interval = tuple[float, float]


def pose_ranges(values: object) -> tuple[Interval, Interval, Interval]:
    """Three ranges of pose parameters (camera moves in metres, or angles in degrees) as ``(low, high)``
    intervals: a number ``h ≥ 0`` is the symmetric range ``(−h, h)``, a pair ``(low, high)`` with ``low ≤ high``
    is itself (e.g. a camera raised by up to 3 m and lowered by up to 0.9 m: ``dy`` in ``(-3.0, 0.9)``, y down).

    Raises:
        ValueError: not three such ranges (a negative half-range, ``low > high``, or not finite).

    Example:
        >>> pose_ranges((0.5, (-3.0, 0.9), 2))
        ((-0.5, 0.5), (-3.0, 0.9), (-2.0, 2.0))
    """
    items = list(values) if isinstance(values, (list, tuple)) else []
    out: list[Interval] = []
    for v in items:
        if isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v < 1e6:
            out.append((-float(v), float(v)))
        elif (isinstance(v, (list, tuple)) and len(v) == 2
              and all(isinstance(x, (int, float)) and not isinstance(x, bool) and abs(x) < 1e6 for x in v)
              and v[0] <= v[1]):
            out.append((float(v[0]), float(v[1])))
        else:
            break
    if len(out) != 3 or len(items) != 3:
        raise ValueError("must be three ranges, each a half-range h ≥ 0 (±h) or LO:HI with LO ≤ HI")
    return out[0], out[1], out[2]


def rotation_from_angles(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """``R = Ry(yaw) · Rx(pitch) · Rz(roll)`` (3×3 float64), angles in degrees; see the module conventions.

    Example:
        >>> np.round(rotation_from_angles(0, 90, 0) @ [0, 0, 1], 6).tolist()  # looking straight down: forward is up
        [0.0, -1.0, 0.0]
    """
    r, p, y = (math.radians(float(a)) for a in (roll_deg, pitch_deg, yaw_deg))
    Rz = np.array([[math.cos(r), -math.sin(r), 0.0], [math.sin(r), math.cos(r), 0.0], [0.0, 0.0, 1.0]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(p), -math.sin(p)], [0.0, math.sin(p), math.cos(p)]])
    Ry = np.array([[math.cos(y), 0.0, math.sin(y)], [0.0, 1.0, 0.0], [-math.sin(y), 0.0, math.cos(y)]])
    return Ry @ Rx @ Rz


@dataclass(frozen=True)
class RoadPlane:
    """The road plane ``{X : n·X = h}`` in a camera frame (see the module conventions).

    Attributes:
        normal: unit normal ``n``, pointing from the camera down to the road (≈ (0, 1, 0) level).
        height: ``h > 0``, the camera centre's distance to the plane in metres.
    """

    normal: tuple[float, float, float]
    height: float

    def __post_init__(self) -> None:
        n = np.asarray(self.normal, dtype=np.float64)
        norm = float(np.linalg.norm(n)) if n.shape == (3,) else 0.0
        if not (norm > 0 and np.isfinite(n).all() and math.isfinite(self.height) and self.height > 0):
            raise InvalidOptionError(f"a road plane needs a non-zero finite normal and a height > 0 m under the "
                                     f"camera, got normal {self.normal} and height {self.height}")
        object.__setattr__(self, "normal", tuple(float(x) for x in n / norm))
        object.__setattr__(self, "height", float(self.height))

    @property
    def n(self) -> np.ndarray:
        """The unit normal as a 3-vector."""
        return np.asarray(self.normal, dtype=np.float64)

    @classmethod
    def from_road_model(cls, model: RoadModel, fx: float, baseline: float, cx: float, cy: float,
                        fy: float | None = None) -> RoadPlane:
        """The 3-D plane of a fitted disparity plane ``d = a·u + b·v + c`` (pixels) on a rectified rig.

        With ``u = fx·X/Z + cx``, ``v = fy·Y/Z + cy``, ``d = fx·B/Z``: ``a·fx·X + b·fy·Y + (a·cx + b·cy + c)·Z
        = fx·B`` — for ``fx = fy = f`` the plane ``a·X + b·Y + (a·cx + b·cy + c)·Z/f = B``.

        Args:
            model: the fitted road model. fx, fy: focal lengths (px; ``fy`` defaults to ``fx``).
            baseline: metres (> 0). cx, cy: principal point (px).

        Example:
            >>> model = RoadModel.from_affine(0.0, 1 / 3, -60.0)  # d = (v − 180) / 3
            >>> plane = RoadPlane.from_road_model(model, fx=700.0, baseline=0.5, cx=600.0, cy=180.0)
            >>> [round(x, 6) for x in plane.normal], round(plane.height, 6)  # a level camera 1.5 m up
            ([0.0, 1.0, 0.0], 1.5)
        """
        fy = fx if fy is None else fy
        if not (fx > 0 and fy > 0 and baseline > 0):
            raise InvalidOptionError(f"the rig needs fx, fy > 0 px and a baseline > 0 m, got fx {fx}, fy {fy}, "
                                     f"baseline {baseline}")
        a, b, c = model.affine
        w = np.array([a * fx, b * fy, a * cx + b * cy + c]) / (fx * baseline)  # w·X = 1
        norm = float(np.linalg.norm(w))
        if not norm > 0:
            raise InvalidOptionError("the road model is flat (d = 0 everywhere): it gives no road plane")
        return cls(tuple(float(x) for x in w / norm), 1.0 / norm)  # type: ignore[arg-type]

    @classmethod
    def from_camera(cls, height: float, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> RoadPlane:
        """The plane under a camera ``height`` metres above a flat road, pitched and rolled (degrees).

        Pitch convention, the one of the whole package (a virtual view's ``rotate``, ``freespace.yaml``'s
        ``camera``, ``SynthConfig.pitches_deg`` and its ``index.csv``): positive pitch tilts the optical axis
        *down*, towards
        the road, by ``pitch_deg`` below the horizon. The roll then turns the camera about its optical
        axis, signed like the paper's Φ (a fit of the road disparity gives ``Φ = roll_deg``). So
        ``n = Rz(roll)·Rx(pitch)·(0, 1, 0)`` with the elementary rotations of :func:`rotation_from_angles`.

        Example:
            >>> [round(x, 4) for x in RoadPlane.from_camera(1.5, pitch_deg=90).normal]  # looking straight down
            [0.0, 0.0, 1.0]
        """
        R = rotation_from_angles(roll_deg, 0.0, 0.0) @ rotation_from_angles(0.0, pitch_deg, 0.0)
        return cls(tuple(float(x) for x in R @ np.array([0.0, 1.0, 0.0])), float(height))  # type: ignore[arg-type]

    def clearance(self, shift: object) -> float:
        """The lowest height above this plane (metres) of a camera centre moved anywhere within ``shift``
        (the ranges of ``(dx, dy, dz)`` in metres, reference frame, as :func:`pose_ranges` takes them: ``h`` for
        ±h or ``(low, high)``): ``h − Σ max(nᵢ·lowᵢ, nᵢ·highᵢ)`` (``h − Σ |nᵢ|·hᵢ`` for half-ranges). Negative
        when such a move can take the camera through the road.

        Example:
            >>> RoadPlane((0, 1, 0), 1.65).clearance((0.5, 0.2, 0.0))  # a level camera: only dy counts
            1.45
            >>> round(RoadPlane((0, 1, 0), 1.65).clearance((0.5, (-3.0, 0.9), 0.0)), 6)  # lowered ≤ 0.9 m
            0.75
        """
        low, high = np.asarray(pose_ranges(shift), dtype=np.float64).T
        return self.height - float(np.maximum(self.n * low, self.n * high).sum())
