"""Road-plane virtual views: the reference image and its road label seen from any camera pose.

The DS-Generator warps the *right* image into the left view with the road homography; the same
geometry gives the view of the road from any pose, without a second camera. A point on the road plane
``n·X = h`` (reference camera frame) seen from a virtual camera with rotation ``R`` and centre ``C`` maps
through ``H = K·R·(I − C nᵀ/h)·K⁻¹`` (reference pixels → virtual pixels). Everything off the road plane
comes out distorted, as in the DS-Generator: that is the method.

Conventions
-----------
* Pixels are 0-based, ``u`` = column (right), ``v`` = row (down), pixel centres at integers.
* The reference camera frame: x right, y down, z forward, in metres.
* The road plane :class:`~freespace.geometry.plane.RoadPlane` is ``{X : n·X = h}`` in the reference frame,
  with ``n`` the unit normal pointing from the camera *down to the road* (≈ (0, 1, 0) for a level camera)
  and ``h > 0`` the camera centre's height above the road, in metres (:mod:`freespace.geometry.plane`).
* A virtual pose :class:`VirtualPose` is a translation ``(dx, dy, dz)`` of the camera centre, in metres in
  the reference frame (``C = (dx, dy, dz)``: positive dx moves the camera to the right, positive dy moves
  it down, positive dz forward), and a rotation given as roll (about z), pitch (about x) and yaw (about y)
  in degrees, applied as ``R = R_yaw · R_pitch · R_roll``.
* ``R`` maps reference coordinates to virtual coordinates: a point ``X`` of the reference frame is
  ``R·(X − C)`` in the virtual camera's frame. ``R_roll = Rz(roll)``, ``R_pitch = Rx(pitch)``,
  ``R_yaw = Ry(yaw)`` are the right-handed elementary rotation matrices (e.g. ``Rx(θ) = [[1, 0, 0],
  [0, cos θ, −sin θ], [0, sin θ, cos θ]]``). So, alone: positive pitch tilts the virtual optical axis
  down (towards +y), positive yaw turns it left (towards −x), positive roll turns the camera's x axis
  up (towards −y, counter-clockwise as seen from behind the camera; the picture turns clockwise).
* The right camera of a rectified rig with baseline B is the pose ``shift = (B, 0, 0)``, no rotation:
  then ``H`` is the DS-Generator's ``H_tr``.

NumPy + OpenCV only — never torch.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import overload

import cv2
import numpy as np

from freespace.errors import InvalidOptionError, ShapeMismatchError, param
from freespace.geometry.plane import RoadPlane, rotation_from_angles
from freespace.labels import RoadLabel

__all__ = ["VirtualPose", "virtual_homography", "virtual_view"]


def _triple(text: str | tuple[float, float, float] | list[float] | np.ndarray, what: str) -> tuple[float, float, float]:
    if isinstance(text, str):
        parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            values = []
    else:
        values = [float(x) for x in np.ravel(np.asarray(text, dtype=np.float64))]
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise InvalidOptionError(f"{what} must be three finite numbers A,B,C, got {text!r}")
    return values[0], values[1], values[2]


@dataclass(frozen=True)
class VirtualPose:
    """A virtual camera pose relative to the reference camera (see the module conventions).

    Attributes:
        shift: ``(dx, dy, dz)``, the virtual camera centre ``C`` in the reference frame, metres
            (x right, y down, z forward).
        roll, pitch, yaw: degrees, about z, x and y; ``R = R_yaw · R_pitch · R_roll`` maps reference
            coordinates to virtual ones (``X ↦ R·(X − C)``).
    """

    shift: tuple[float, float, float] = (0.0, 0.0, 0.0)
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0

    @classmethod
    def parse(cls, shift: str | None = None, rotate: str | None = None) -> VirtualPose:
        """From the command-line strings ``"DX,DY,DZ"`` (metres) and ``"ROLL,PITCH,YAW"`` (degrees).

        Example:
            >>> VirtualPose.parse("0.5,0,0", "0,2,-1")
            VirtualPose(shift=(0.5, 0.0, 0.0), roll=0.0, pitch=2.0, yaw=-1.0)
        """
        s = _triple(shift, f"{param('shift')} DX,DY,DZ (metres)") if shift is not None else (0.0, 0.0, 0.0)
        r = _triple(rotate, f"{param('rotate')} ROLL,PITCH,YAW (degrees)") if rotate is not None else (0.0, 0.0, 0.0)
        return cls(shift=s, roll=r[0], pitch=r[1], yaw=r[2])

    @property
    def R(self) -> np.ndarray:
        """3×3 rotation, reference → virtual coordinates."""
        return rotation_from_angles(self.roll, self.pitch, self.yaw)

    @property
    def C(self) -> np.ndarray:
        """The virtual camera centre in the reference frame (3-vector, metres)."""
        return np.asarray(self.shift, dtype=np.float64)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready ``{"shift": [dx, dy, dz], "roll", "pitch", "yaw"}``.

        Example:
            >>> VirtualPose.parse("0.5,0,0", "0,2,-1").to_dict()
            {'shift': [0.5, 0.0, 0.0], 'roll': 0.0, 'pitch': 2.0, 'yaw': -1.0}
        """
        return {"shift": list(self.shift), "roll": self.roll, "pitch": self.pitch, "yaw": self.yaw}


def _check_K(K: np.ndarray) -> np.ndarray:
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.isfinite(K).all() or abs(np.linalg.det(K)) < 1e-12:
        raise InvalidOptionError(f"K must be a finite, invertible 3×3 intrinsic matrix, got shape {K.shape}")
    return K


def virtual_homography(K: np.ndarray, plane: RoadPlane, pose: VirtualPose) -> np.ndarray:
    """``H = K·R·(I − C nᵀ/h)·K⁻¹``: reference pixels of road points → virtual-camera pixels.

    Args:
        K: 3×3 intrinsics (pixels), shared by the reference and the virtual camera.
        plane: the road plane in the reference frame. pose: the virtual camera.

    Raises:
        InvalidOptionError: a bad K, or a virtual camera centre on or under the road plane.

    Returns:
        3×3 float64, scaled by a positive factor so that ``H[2, 2] = ±1``: for a road point seen by
        both cameras the homogeneous scale ``(H p̃)[2]`` is positive (it is ``Z_virtual / Z_reference``).

    Example:
        >>> K = np.array([[700.0, 0, 600], [0, 700, 180], [0, 0, 1]])
        >>> H = virtual_homography(K, RoadPlane((0, 1, 0), 1.5), VirtualPose(shift=(0.5, 0.0, 0.0)))
        >>> (H @ [600, 330, 1]).round(6).tolist()  # 0.5 m to the right: the DS-Generator's right camera
        [550.0, 330.0, 1.0]
    """
    K = _check_K(K)
    if not plane.height - float(plane.n @ pose.C) > 1e-6:
        raise InvalidOptionError(f"the virtual camera at {tuple(pose.shift)} m is on or under the road plane (the "
                                 f"camera is {plane.height:.3f} m above it); give a smaller {param('shift')}")
    H = K @ pose.R @ (np.eye(3) - np.outer(pose.C, plane.n) / plane.height) @ np.linalg.inv(K)
    s = abs(H[2, 2])
    return H / s if s > 1e-12 else H


@overload
def virtual_view(image: np.ndarray, label: RoadLabel, K: np.ndarray, plane: RoadPlane, pose: VirtualPose, *,
                 ignore: int = ...) -> tuple[np.ndarray, RoadLabel, np.ndarray]: ...


@overload
def virtual_view(image: np.ndarray, label: np.ndarray, K: np.ndarray, plane: RoadPlane, pose: VirtualPose, *,
                 ignore: int = ...) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


@overload
def virtual_view(image: np.ndarray, label: None, K: np.ndarray, plane: RoadPlane, pose: VirtualPose, *,
                 ignore: int = ...) -> tuple[np.ndarray, None, np.ndarray]: ...


def virtual_view(image: np.ndarray, label: RoadLabel | np.ndarray | None, K: np.ndarray, plane: RoadPlane,
                 pose: VirtualPose, *, ignore: int = 255
                 ) -> tuple[np.ndarray, RoadLabel | np.ndarray | None, np.ndarray]:
    """The reference image and its road label seen from the virtual camera ``pose`` through the road plane.

    Virtual pixel ``q`` takes the reference pixel ``H⁻¹ q̃`` (``H`` = :func:`virtual_homography`): the image
    bilinearly, the label nearest. Where that source lies outside the reference image (``0 ≤ x ≤ W − 1``,
    ``0 ≤ y ≤ H − 1``) or on the other side of the horizon (negative homogeneous scale: the virtual
    ray meets the road plane behind one camera only), the pixel is not valid: image 0, label don't care.

    Args:
        image: ``H×W×C`` or ``H×W`` reference image, uint8 or float32.
        label: a :class:`~freespace.labels.RoadLabel` (road + valid), an ``H×W`` integer class map, or None.
        K: 3×3 intrinsics of the reference camera (pixels of ``image``). plane: the road plane in the
            reference frame. pose: the virtual camera (module conventions: ``X ↦ R·(X − C)``).
        ignore: the value written into a class-map label at invalid pixels (default 255).

    Returns:
        ``(image, label, valid)``: the virtual image (same shape and dtype), the label of the same kind
        (a RoadLabel with ``valid`` False where invalid, or a class map with ``ignore`` there; None for
        None), and ``valid`` (bool H×W, True where the source pixel exists).

    Example:
        >>> img = np.arange(12, dtype=np.uint8).reshape(3, 4)
        >>> K = np.array([[2.0, 0, 1.5], [0, 2.0, 1.0], [0, 0, 1]])
        >>> out, _, ok = virtual_view(img, None, K, RoadPlane((0, 1, 0), 1.0), VirtualPose())
        >>> bool((out == img).all() and ok.all())  # the identity pose gives the image back
        True
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)):
        raise InvalidOptionError(f"image must be H×W or H×W×C, got shape {image.shape}")
    if image.dtype not in (np.uint8, np.float32):
        raise InvalidOptionError(f"image must be uint8 or float32, got {image.dtype}")
    h, w = image.shape[:2]
    lab_shape = label.shape if label is not None else (h, w)
    if tuple(lab_shape) != (h, w):
        raise ShapeMismatchError(f"label is {lab_shape[1]}×{lab_shape[0]} but the image is {w}×{h}; give the "
                                 f"label of the reference image")
    H = virtual_homography(K, plane, pose)
    Hinv = np.linalg.inv(H)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    x = Hinv[0, 0] * u + Hinv[0, 1] * v + Hinv[0, 2]
    y = Hinv[1, 0] * u + Hinv[1, 1] * v + Hinv[1, 2]
    z = Hinv[2, 0] * u + Hinv[2, 1] * v + Hinv[2, 2]
    # H is scaled positively, so H⁻¹ keeps the sign: z > 0 ⇔ both rays meet the plane on the same side
    ok = z > 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        mx = np.where(ok, x / np.where(ok, z, 1.0), -1.0)
        my = np.where(ok, y / np.where(ok, z, 1.0), -1.0)
    eps = 1e-6
    valid = ok & (mx >= -eps) & (mx <= w - 1 + eps) & (my >= -eps) & (my <= h - 1 + eps)
    map_x = np.where(valid, np.clip(mx, 0, w - 1), -1).astype(np.float32)
    map_y = np.where(valid, np.clip(my, 0, h - 1), -1).astype(np.float32)
    out = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    out = out.reshape(image.shape)
    out[~valid] = 0

    def nearest(arr: np.ndarray) -> np.ndarray:  # labels: never interpolated
        return cv2.remap(arr, map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    out_label: RoadLabel | np.ndarray | None
    if label is None:
        out_label = None
    elif isinstance(label, RoadLabel):
        road = nearest(label.road.astype(np.uint8)) > 0
        lab_valid = (nearest(label.valid.astype(np.uint8)) > 0) & valid
        out_label = RoadLabel(road=road & lab_valid, valid=lab_valid)
    else:
        arr = np.asarray(label)
        if arr.ndim != 2 or arr.dtype.kind not in "uib":
            raise InvalidOptionError(f"label must be a RoadLabel or an H×W integer class map, got {arr.dtype} "
                                     f"{arr.shape}")
        work = arr if arr.dtype in (np.uint8, np.uint16, np.int16) else arr.astype(np.float32)  # what remap takes
        out_label = nearest(work).astype(arr.dtype)
        out_label[~valid] = ignore
    return out, out_label, valid
