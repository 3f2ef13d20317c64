"""Ray casting and shading of the built-in stereo road scenes (NumPy + OpenCV, no torch).

Both cameras of the rig cast one ray per pixel into the same 3D scene (:mod:`.scene`): the road
surface with lane markings, curbs and raised sidewalks, building facades with windows, hedges,
vehicles, pedestrians, poles and trees. The ray parameter is the depth along the camera's optical
axis, so the ground-truth disparity of the left image is exactly ``f·B / t``. Shading: Lambertian with
a sun, ambient sky light, ground shadows cast by every object (rasterised in a top-down shadow map
shared by both views), fog and rain; then each camera adds its own gain, bias, vignetting and noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from freespace.data.synthetic.scene import (
    CURB,
    FACADE,
    FOLIAGE,
    GLASS,
    GRASS,
    HEDGE,
    MARKING,
    PERSON,
    POLE,
    ROAD,
    SIDEWALK,
    TRUNK,
    VEHICLE,
    Box,
    Frame,
    Scenario,
    Sphere,
    SynthConfig,
    sample_frame,
)
from freespace.geometry.homography import StereoCalibration
from freespace.geometry.virtual import VirtualPose
from freespace.labels import RoadLabel

__all__ = ["StereoSample", "ViewRender", "render_frame", "render_sample", "render_view", "kitti_calibration"]

F32 = np.float32
FAR = 400.0

# texture amplitudes (fine 2.5 cm, medium 17 cm, coarse 1.3 m) per material
_AMPLITUDES = {
    ROAD: (0.30, 0.16, 0.12), MARKING: (0.08, 0.06, 0.05), CURB: (0.15, 0.10, 0.05), SIDEWALK: (0.22, 0.14, 0.10),
    GRASS: (0.40, 0.30, 0.20), FACADE: (0.14, 0.10, 0.15), VEHICLE: (0.03, 0.03, 0.03), GLASS: (0.05, 0.08, 0.10),
    PERSON: (0.15, 0.10, 0.05), POLE: (0.06, 0.05, 0.05), TRUNK: (0.35, 0.25, 0.10), FOLIAGE: (0.55, 0.45, 0.25),
    HEDGE: (0.50, 0.40, 0.20),
}
_AMPS = np.zeros((14, 3), F32)
_AMPS[list(_AMPLITUDES)] = list(_AMPLITUDES.values())

# weather: ambient RGB, sun RGB, shadow strength, fog visibility (m), fog RGB, horizon RGB, zenith RGB
_WEATHER: dict[str, dict[str, Any]] = {
    "clear": dict(ambient=(0.42, 0.45, 0.52), sun=(1.0, 0.97, 0.9), shadow=1.0, fog=900.0, fog_rgb=(0.75, 0.8, 0.88),
                  horizon=(0.78, 0.85, 0.95), zenith=(0.3, 0.5, 0.85), exposure=1.05),
    "cloudy": dict(ambient=(0.75, 0.76, 0.8), sun=(0.25, 0.25, 0.25), shadow=0.3, fog=500.0, fog_rgb=(0.75, 0.76, 0.78),
                   horizon=(0.8, 0.8, 0.82), zenith=(0.6, 0.62, 0.66), exposure=1.0),
    "rain": dict(ambient=(0.55, 0.57, 0.62), sun=(0.12, 0.12, 0.12), shadow=0.15, fog=160.0, fog_rgb=(0.55, 0.57, 0.6),
                 horizon=(0.6, 0.61, 0.64), zenith=(0.42, 0.44, 0.48), exposure=0.9),
    "sunset": dict(ambient=(0.38, 0.33, 0.36), sun=(1.0, 0.62, 0.35), shadow=0.9, fog=600.0, fog_rgb=(0.9, 0.65, 0.5),
                   horizon=(1.0, 0.62, 0.38), zenith=(0.35, 0.35, 0.6), exposure=1.1),
    "dusk": dict(ambient=(0.18, 0.19, 0.26), sun=(0.35, 0.25, 0.2), shadow=0.4, fog=400.0, fog_rgb=(0.25, 0.25, 0.33),
                 horizon=(0.35, 0.3, 0.4), zenith=(0.08, 0.1, 0.22), exposure=1.6),
    "fog": dict(ambient=(0.7, 0.7, 0.72), sun=(0.15, 0.15, 0.15), shadow=0.2, fog=60.0, fog_rgb=(0.78, 0.78, 0.8),
                horizon=(0.8, 0.8, 0.82), zenith=(0.72, 0.72, 0.75), exposure=1.0),
}


@dataclass
class StereoSample:
    """One rendered stereo frame.

    Attributes:
        name: ``<cat>_<6 digits>``; category: ``um``/``umm``/``uu``; scenario: scenario id; index: frame i.
        left, right: ``H×W×3 uint8`` RGB images of the left (reference) and right cameras.
        disparity: ``float32 H×W`` exact left disparity in pixels, NaN where the ray hits nothing (sky).
        label: road label of the left image (road = road surface incl. markings, everything else
            non-road; every pixel valid).
        noc: ``bool H×W``, left pixels visible in the right image too (not occluded).
        calibration: the rig and its road plane (planar mode: the exact road plane).
        kitti_calib: KITTI calibration matrices (P0–P3, R0_rect, Tr_velo_to_cam, Tr_cam_to_road).
        meta: weather, rig and road parameters.
    """

    name: str
    category: str
    scenario: int
    index: int
    left: np.ndarray
    right: np.ndarray
    disparity: np.ndarray
    label: RoadLabel
    noc: np.ndarray
    calibration: StereoCalibration
    kitti_calib: dict[str, np.ndarray]
    meta: dict[str, Any] = field(default_factory=dict)


class _Palette:
    """The frame's surface colours; every hit stores an index into it (shared by both views)."""

    def __init__(self, sc: Scenario) -> None:
        self.colours: list[tuple[float, float, float]] = []
        self._ids: dict[tuple[float, float, float], int] = {}
        self.ground = np.zeros(GRASS + 1, np.uint16)
        for m, rgb in ((ROAD, sc.road_colour), (MARKING, (0.85, 0.85, 0.82)), (CURB, (0.6, 0.6, 0.58)),
                       (SIDEWALK, sc.sidewalk_colour), (GRASS, (0.22, 0.38, 0.14))):
            self.ground[m] = self.add(rgb)
        self.tile = self.add(tuple(0.7 * c for c in sc.sidewalk_colour))  # type: ignore[arg-type]
        self.hedge = self.add((0.18, 0.33, 0.12))
        self.window = self.add((0.12, 0.14, 0.17))
        self.facades = np.array([self.add(tuple(float(c) for c in rgb)) for rgb in sc.facade_colours], np.uint16)

    def add(self, rgb: tuple[float, float, float]) -> int:
        """Index of colour ``rgb`` (added once)."""
        key = tuple(round(float(c), 6) for c in rgb)
        if key not in self._ids:
            self._ids[key] = len(self.colours)
            self.colours.append(key)  # type: ignore[arg-type]
        return self._ids[key]

    def array(self) -> np.ndarray:
        return np.array(self.colours, F32)


@dataclass
class _Hits:
    """Nearest hit per pixel of one view, as flat arrays of length H·W: depth, material, colour index
    in the palette, sun-facing factor ``max(0, n·L)`` and texture coordinates (metres)."""

    t: np.ndarray
    mat: np.ndarray
    sid: np.ndarray
    lam: np.ndarray
    tu: np.ndarray
    tv: np.ndarray

    @classmethod
    def empty(cls, n: int) -> _Hits:
        return cls(t=np.full(n, np.inf, F32), mat=np.zeros(n, np.uint8), sid=np.zeros(n, np.uint16),
                   lam=np.zeros(n, F32), tu=np.zeros(n, F32), tv=np.zeros(n, F32))

    def write(self, idx: np.ndarray, t: np.ndarray, mat: int | np.ndarray, sid: int | np.ndarray,
              lam: float | np.ndarray, tu: np.ndarray, tv: np.ndarray) -> None:
        """Keep the hits at flat pixel indices ``idx`` (values aligned with ``idx``) that are nearer."""
        m = t < self.t[idx]
        if not m.any():
            return
        sel = idx[m]
        self.t[sel] = t[m]
        for name, value in (("mat", mat), ("sid", sid), ("lam", lam)):
            getattr(self, name)[sel] = value[m] if isinstance(value, np.ndarray) else value
        self.tu[sel] = tu[m]
        self.tv[sel] = tv[m]


def _directions(sc: Scenario, R: np.ndarray, h: int, w: int) -> np.ndarray:
    """World directions of the pixel rays (``3×(H·W)``), scaled so the camera-z component is 1."""
    x = (np.arange(w, dtype=F32) - F32(sc.cx)) / F32(sc.focal)
    y = (np.arange(h, dtype=F32) - F32(sc.cy)) / F32(sc.focal)
    R = R.astype(F32)
    return np.stack([(R[i, 0] * x[None, :] + R[i, 1] * y[:, None] + R[i, 2]).ravel() for i in range(3)])


def _ground(hits: _Hits, sc: Scenario, o: tuple[float, float, float], d: np.ndarray, pal: _Palette,
            sun: np.ndarray) -> np.ndarray:
    """Road, lane markings, curbs, sidewalks and verges. Returns the lateral offset s of every pixel's
    ground hit (inf where the ray does not hit the ground)."""
    idx = np.flatnonzero(d[1] > 1e-6)
    dx, dy, dz = d[0][idx], d[1][idx], d[2][idx]
    inv = 1.0 / dy
    planar = sc.vcurve == 0 and sc.grade == 0 and sc.camber == 0

    def intersect(lift: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = (-lift - o[1]) * inv  # plane Y = −lift
        for _ in range(0 if planar else 6):
            z = o[2] + t * dz
            s = o[0] + t * dx - sc.centre_x(z)
            t = (-(sc.elevation(s, z) + lift) - o[1]) * inv
        z = o[2] + t * dz
        return t, o[0] + t * dx - sc.centre_x(z), z

    with np.errstate(invalid="ignore", over="ignore"):  # rays grazing the ground diverge: dropped below
        hw, hc = sc.half_width, sc.curb_height
        t_r, s_r, z_r = intersect(0.0)
        t_s, s_s, z_s = intersect(hc)
        on_side = np.abs(s_s) > hw
        on_road = ~on_side & (np.abs(s_r) <= hw)
        on_curb = ~on_side & ~on_road
        frac = np.clip((hw - np.abs(s_s)) / np.maximum(np.abs(s_r) - np.abs(s_s), F32(1e-6)), 0, 1)
        t = np.where(on_side, t_s, np.where(on_road, t_r, t_s + frac * (t_r - t_s)))
        s = np.where(on_side, s_s, s_r)
        z = np.where(on_side, z_s, z_r)
    ok = (t > 0) & (t < FAR)
    idx, t, s, z = idx[ok], t[ok], s[ok], z[ok]
    on_side, on_curb = on_side[ok], on_curb[ok]
    mat = np.full(t.shape, ROAD, np.uint8)
    mat[on_side] = SIDEWALK
    mat[on_side & (np.abs(s) > sc.facade_offset)] = GRASS
    mat[on_curb] = CURB
    on_road = mat == ROAD
    if sc.category != "uu":
        zm = np.mod(z, F32(9.0))
        marks = np.abs(np.abs(s) - (hw - 0.3)) < 0.07  # edge lines
        for k in range(1, sc.lanes):
            marks |= (np.abs(s - (-hw + k * sc.lane_width)) < 0.07) & (zm < 3.0)
        mat[on_road & marks] = MARKING
    sid = pal.ground[mat]
    side = np.flatnonzero(mat == SIDEWALK)
    tiles = (np.mod(s[side], F32(0.6)) < 0.03) | (np.mod(z[side], F32(0.6)) < 0.03)
    sid[side[tiles]] = pal.tile
    hits.write(idx, t, mat, sid, max(0.0, float(-sun[1])), o[0] + t * dx[ok], z)
    lateral = np.full(hits.t.shape, np.inf, F32)
    lateral[idx] = s
    return lateral


def _solve_lateral(sc: Scenario, o: tuple[float, float, float], dx: np.ndarray, dz: np.ndarray,
                   offset: float) -> np.ndarray:
    """Smallest positive t with ``s(o + t d) = offset`` (the road's parallel curves), inf if none."""
    c0, c1, c2 = sc.centre
    B = dx - (c1 + 2 * c2 * o[2]) * dz
    C = o[0] - c0 - c1 * o[2] - c2 * o[2] ** 2 - offset
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if abs(c2) < 1e-12:
            t = -C / B
            return np.where(t > 0, t, np.inf).astype(F32)
        A = -c2 * dz * dz
        disc = B * B - 4 * A * C
        q = -0.5 * (B + np.copysign(np.sqrt(np.maximum(disc, 0)), B))  # numerically stable roots
        r1, r2 = q / A, C / q
        t = np.minimum(np.where(r1 > 0, r1, np.inf), np.where(r2 > 0, r2, np.inf))
        return np.where(disc >= 0, t, np.inf).astype(F32)


def _facades(hits: _Hits, sc: Scenario, o: tuple[float, float, float], d: np.ndarray, z_cam: float,
             lateral: np.ndarray, pal: _Palette, sun: np.ndarray) -> None:
    """Building facades (with windows) and hedges along both sides of the road.

    Only rays whose ground hit lies beyond the building line (or that miss the ground) can reach a
    facade: the street is a corridor the rays leave only through its walls.
    """
    nseg = len(sc.building_heights)
    heights = sc.building_heights.astype(F32)
    for side in (-1.0, 1.0):
        off = side * sc.facade_offset
        cand = np.flatnonzero(np.isinf(lateral) | (side * lateral >= sc.facade_offset - 0.01))
        if cand.size == 0:
            continue
        dx, dy, dz = d[0][cand], d[1][cand], d[2][cand]
        t = _solve_lateral(sc, o, dx, dz, off)
        with np.errstate(invalid="ignore"):
            z = o[2] + t * dz
            y = o[1] + t * dy
            ok = np.isfinite(t) & (t < FAR) & (z > z_cam - 20) & (z < 260)
        cand, t, z, y = cand[ok], t[ok], z[ok], y[ok]
        seg = np.clip((z / F32(sc.segment_length)).astype(np.intp), 0, nseg - 1)
        height = heights[seg]
        above = -(sc.elevation(off, z) + sc.curb_height) - y  # height of the hit above the ground
        ok = (above >= -0.05) & (above <= height)
        cand, t, z, y, seg, height, above = cand[ok], t[ok], z[ok], y[ok], seg[ok], height[ok], above[ok]
        if cand.size == 0:
            continue
        hedge = height <= 2.5
        mat = np.where(hedge, HEDGE, FACADE).astype(np.uint8)
        sid = pal.facades[seg]
        sid[hedge] = pal.hedge
        zm, am = np.mod(z, F32(3.2)), np.mod(above, F32(3.0))
        window = ~hedge & (zm > 0.9) & (zm < 2.3) & (am > 0.9) & (am < 2.3) & (above > 3.0) & (above < height - 0.6)
        sid[window] = pal.window
        mat[window] = GLASS
        slope = sc.centre[1] + 2 * sc.centre[2] * z  # normal (−side, 0, side·slope)/‖·‖, towards the road
        lam = np.maximum(side * (slope * float(sun[2]) - float(sun[0])) / np.sqrt(1 + slope * slope), 0)
        hits.write(cand, t, mat, sid, lam, z, y)


def _bbox(corners: np.ndarray, o: tuple[float, float, float], R: np.ndarray, sc: Scenario, h: int, w: int
          ) -> np.ndarray | None:
    """Flat indices of the image box covering world points ``corners`` (N×3), None when not visible."""
    cam = (corners - np.asarray(o)) @ R  # Rᵀ (p − o), row-wise
    if (cam[:, 2] < 0.05).all():
        return None
    if (cam[:, 2] < 0.05).any():
        u0, u1, v0, v1 = 0, w, 0, h
    else:
        u = sc.focal * cam[:, 0] / cam[:, 2] + sc.cx
        v = sc.focal * cam[:, 1] / cam[:, 2] + sc.cy
        u0, u1 = int(max(math.floor(u.min()) - 1, 0)), int(min(math.ceil(u.max()) + 2, w))
        v0, v1 = int(max(math.floor(v.min()) - 1, 0)), int(min(math.ceil(v.max()) + 2, h))
        if u0 >= u1 or v0 >= v1:
            return None
    return (np.arange(v0, v1)[:, None] * w + np.arange(u0, u1)[None, :]).ravel()


def _box_corners(b: Box) -> np.ndarray:
    c, s = math.cos(b.yaw), math.sin(b.yaw)
    pts = []
    for lx in (-0.5 * b.width, 0.5 * b.width):
        for lz in (-0.5 * b.length, 0.5 * b.length):
            for ly in (0.0, -b.height):
                pts.append((b.x + c * lx + s * lz, b.y + ly, b.z - s * lx + c * lz))
    return np.array(pts)


def _sphere_corners(sp: Sphere) -> np.ndarray:
    r = sp.radius
    return np.array([(sp.x + a * r, sp.y + b * r, sp.z + c * r) for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)])


def _objects(hits: _Hits, objects: list[Box | Sphere], sc: Scenario, o: tuple[float, float, float],
             d: np.ndarray, R: np.ndarray, w: int, pal: _Palette, sun: np.ndarray) -> None:
    """Boxes (vehicles, pedestrians, poles, trunks) and spheres (tree canopies), each in its image box."""
    h = hits.t.size // w
    for ob in objects:
        corners = _box_corners(ob) if isinstance(ob, Box) else _sphere_corners(ob)
        idx = _bbox(corners, o, R, sc, h, w)
        if idx is None:
            continue
        dx, dy, dz = d[0][idx], d[1][idx], d[2][idx]
        with np.errstate(divide="ignore", invalid="ignore"):
            if isinstance(ob, Box):
                c, s = math.cos(ob.yaw), math.sin(ob.yaw)
                ox, oy, oz = o[0] - ob.x, o[1] - (ob.y - 0.5 * ob.height), o[2] - ob.z
                # world → box frame: rotate by −yaw about Y
                lox, loz = c * ox - s * oz, s * ox + c * oz
                ldx, ldz = c * dx - s * dz, s * dx + c * dz
                half = (0.5 * ob.width, 0.5 * ob.height, 0.5 * ob.length)
                tmin, tmax = [], []
                for oo, dd, hh in ((lox, ldx, half[0]), (oy, dy, half[1]), (loz, ldz, half[2])):
                    t1, t2 = (-hh - oo) / dd, (hh - oo) / dd
                    tmin.append(np.minimum(t1, t2))
                    tmax.append(np.maximum(t1, t2))
                tmin_a = np.nan_to_num(np.stack(tmin), nan=-np.inf)
                axis = np.argmax(tmin_a, axis=0)
                t = np.take_along_axis(tmin_a, axis[None], 0)[0]
                tfar = np.nanmin(np.stack(tmax), axis=0)
                ok = (t <= tfar) & (t > 0)
                if not ok.any():
                    continue
                idx, t, axis = idx[ok], t[ok], axis[ok]
                ldx, dy, ldz = ldx[ok], dy[ok], ldz[ok]
                sign = -np.sign(np.choose(axis, (ldx, dy, ldz))).astype(F32)
                # n·L of the six faces: the sun in the box frame, one component per axis
                sun_local = (c * sun[0] - s * sun[2], sun[1], s * sun[0] + c * sun[2])
                lam = np.maximum(sign * np.choose(axis, sun_local).astype(F32), 0)
                px, py, pz = lox + t * ldx, oy + t * dy, loz + t * ldz
                tu = np.choose(axis, (pz, px, px))
                tv = np.choose(axis, (py, pz, py))
                sid = np.full(t.size, pal.add(ob.colour), np.uint16)
                if ob.material == VEHICLE:  # dark lower band: wheels and the shade under the body
                    sid[py > half[1] - 0.35] = pal.add(tuple(0.35 * x for x in ob.colour))
            else:
                ox, oy, oz = o[0] - ob.x, o[1] - ob.y, o[2] - ob.z
                b = ox * dx + oy * dy + oz * dz
                a = dx * dx + dy * dy + dz * dz
                disc = b * b - a * (ox * ox + oy * oy + oz * oz - ob.radius ** 2)
                ok = disc >= 0
                if not ok.any():
                    continue
                idx, a, b, disc, dx, dy, dz = idx[ok], a[ok], b[ok], disc[ok], dx[ok], dy[ok], dz[ok]
                t = (-b - np.sqrt(disc)) / a
                n_dot_l = ((ox + t * dx) * sun[0] + (oy + t * dy) * sun[1] + (oz + t * dz) * sun[2]) / ob.radius
                lam = np.maximum(n_dot_l, 0)
                tu = o[0] + t * dx + 0.3 * (o[2] + t * dz)
                tv = o[1] + t * dy + 0.3 * (o[2] + t * dz)
                sid = pal.add(ob.colour)
                keep = t > 0
                idx, t, lam, tu, tv = idx[keep], t[keep], lam[keep], tu[keep], tv[keep]
        hits.write(idx, t.astype(F32), ob.material, sid, lam.astype(F32), tu.astype(F32), tv.astype(F32))


def _sun(sc: Scenario) -> np.ndarray:
    el, az = sc.sun_elevation, sc.sun_azimuth
    return np.array([math.cos(el) * math.sin(az), -math.sin(el), math.cos(el) * math.cos(az)])


class _ShadowMap:
    """Top-down map of the ground (0.1 m cells) with 1 where an object's shadow falls."""

    cell = 0.1

    def __init__(self, frame: Frame, origin: np.ndarray) -> None:
        sc = frame.scenario
        self.x0, self.z0 = origin[0] - 45.0, frame.z_cam - 5.0
        grid = np.zeros((int(165 / self.cell), int(90 / self.cell)), np.uint8)  # rows = z, cols = x
        self.grid = grid.astype(F32)
        sun = _sun(sc)
        if sun[1] > -0.02:
            return
        polys = []
        for ob in sc.static_objects + frame.objects:
            pts = _box_corners(ob) if isinstance(ob, Box) else self._sphere_points(ob)
            polys.append(self._project(pts, sun))
        nseg = len(sc.building_heights)
        for side in (-1.0, 1.0):
            off = side * sc.facade_offset
            for k in range(nseg):
                za, zb = k * sc.segment_length, (k + 1) * sc.segment_length
                if zb < self.z0 - 50 or za > self.z0 + 200:
                    continue
                hgt = sc.building_heights[k]
                base = [(sc.centre_x(z) + off, -sc.curb_height, z) for z in (za, zb)]
                top = [(x, y - hgt, z) for x, y, z in base]
                polys.append(self._project(np.array(base + top), sun))
        for poly in polys:
            pts = np.round(poly * 16).astype(np.int32)
            cv2.fillConvexPoly(grid, cv2.convexHull(pts), 1, lineType=cv2.LINE_8, shift=4)
        self.grid = grid.astype(F32)

    @staticmethod
    def _sphere_points(sp: Sphere) -> np.ndarray:
        a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        r = sp.radius
        ring = [np.stack([sp.x + r * np.cos(a), sp.y + r * np.sin(a), np.full_like(a, sp.z)], 1),
                np.stack([np.full_like(a, sp.x), sp.y + r * np.sin(a), sp.z + r * np.cos(a)], 1),
                np.stack([sp.x + r * np.cos(a), np.full_like(a, sp.y), sp.z + r * np.sin(a)], 1)]
        return np.concatenate(ring)

    def _project(self, pts: np.ndarray, sun: np.ndarray) -> np.ndarray:
        mu = pts[:, 1] / sun[1]  # to the ground Y = 0 along −sun
        g = pts - mu[:, None] * sun[None, :]
        return np.stack([(g[:, 0] - self.x0) / self.cell, (g[:, 2] - self.z0) / self.cell], 1)

    def lookup(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Shadow (0..1, bilinear) at ground points (x, z), flat arrays."""
        return _remap_flat(self.grid, (x - self.x0) / self.cell, (z - self.z0) / self.cell, cv2.BORDER_CONSTANT)


def _remap_flat(src: np.ndarray, mx: np.ndarray, my: np.ndarray, border: int) -> np.ndarray:
    """cv2.remap at flat coordinate arrays (OpenCV wants maps under 32767 columns: fold them)."""
    n = mx.size
    cols = 1024
    pad = (-n) % cols
    mx = np.pad(mx.astype(F32, copy=False), (0, pad)).reshape(-1, cols)
    my = np.pad(my.astype(F32, copy=False), (0, pad)).reshape(-1, cols)
    return cv2.remap(src, mx, my, cv2.INTER_LINEAR, borderMode=border, borderValue=0).ravel()[:n]


def _noise_tile(seed: tuple[int, ...]) -> np.ndarray:
    rng = np.random.default_rng([*seed, 7])
    padded = np.pad(rng.standard_normal((256, 256)).astype(F32), 8, mode="wrap")  # blur that tiles seamlessly
    tile = cv2.GaussianBlur(padded, (0, 0), 0.8)[8:-8, 8:-8]
    return (tile / tile.std()).astype(F32)


def _texture(tile: np.ndarray, tu: np.ndarray, tv: np.ndarray, scale: float, shift: float) -> np.ndarray:
    with np.errstate(over="ignore", invalid="ignore"):  # far hits: huge coordinates, wrapped anyway
        return cv2.remap(tile, (tu * scale + shift).astype(F32), (tv * scale + 0.37 * shift).astype(F32),
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


def _shade(hits: _Hits, frame: Frame, o: tuple[float, float, float], d: np.ndarray, tile: np.ndarray,
           shadows: _ShadowMap, palette: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Linear RGB radiance (float32 H×W×3) of one view."""
    sc = frame.scenario
    wx = _WEATHER[sc.weather]
    h, w = shape
    hit = np.isfinite(hits.t)
    tt = np.where(hit, hits.t, F32(FAR))
    footprint = tt / F32(sc.focal)
    tu, tv = hits.tu.reshape(h, w), hits.tv.reshape(h, w)
    n = (_AMPS[:, 0][hits.mat] * np.minimum(F32(0.03) / footprint, 1) * _texture(tile, tu, tv, 40.0, 0.0).ravel()
         + _AMPS[:, 1][hits.mat] * np.minimum(F32(0.2) / footprint, 1) * _texture(tile, tu, tv, 6.0, 91.0).ravel()
         + _AMPS[:, 2][hits.mat] * _texture(tile, tu, tv, 0.8, 17.0).ravel())
    ground = np.flatnonzero((hits.mat >= ROAD) & (hits.mat <= GRASS))
    if sc.weather == "rain":  # wet, darker ground
        n[ground] = (1.0 + n[ground]) * 0.7 - 1.0
    colour = palette[hits.sid] * np.clip(1.0 + n, 0.2, 2.0)[:, None]
    lambert = hits.lam
    if ground.size and wx["shadow"] > 0:
        shadow = shadows.lookup(o[0] + tt[ground] * d[0][ground], o[2] + tt[ground] * d[2][ground])
        lambert[ground] *= 1 - F32(wx["shadow"]) * shadow
    rad = colour * (np.array(wx["ambient"], F32) + lambert[:, None] * np.array(wx["sun"], F32))
    fog = (1.0 - np.exp(-tt / F32(wx["fog"])))[:, None]  # aerial perspective
    rad += fog * (np.array(wx["fog_rgb"], F32) - rad)
    sky = np.flatnonzero(~hit)
    if sky.size:
        dx, dy, dz = d[0][sky], d[1][sky], d[2][sky]
        up = np.clip(-dy / np.sqrt(dx * dx + dy * dy + dz * dz), 0, 1)
        k = np.clip(up * 2.5, 0, 1)[:, None]
        colour = np.array(wx["horizon"], F32) * (1 - k) + np.array(wx["zenith"], F32) * k
        lift = np.maximum(-dy + F32(0.05), F32(0.05))
        clouds = _remap_flat(tile, dx / lift * 3.0 + 5.0, dz / lift * 3.0, cv2.BORDER_WRAP)
        rad[sky] = colour + F32(0.06) * clouds[:, None]
    return (rad * F32(wx["exposure"])).reshape(h, w, 3)


def _camera(rad: np.ndarray, rng: np.random.Generator, weather: str) -> np.ndarray:
    """This camera's response: gain and white balance, bias, vignetting, gamma, noise (uint8 RGB)."""
    h, w = rad.shape[:2]
    gain = rng.uniform(0.9, 1.1) * rng.uniform(0.96, 1.04, 3)
    sigma = rng.uniform(1.0, 3.5)
    bias = rng.uniform(-8, 8)
    yy, xx = np.ogrid[:h, :w]
    r2 = ((xx - w / 2) / (w / 2)) ** 2 + ((yy - h / 2) / (h / 2)) ** 2
    vignette = (1 - rng.uniform(0.05, 0.35) * r2 / 2).astype(F32)
    img = cv2.pow(np.clip(rad * gain.astype(F32) * vignette[..., None], 0, 1), 1 / 2.2) * 255 + F32(bias)
    # sensor noise: triangular (sum of two uniforms), standard deviation sigma grey levels
    n = rad.size
    noise = np.frombuffer(rng.bytes(n), np.uint8).astype(F32) + np.frombuffer(rng.bytes(n), np.uint8) - F32(255)
    img += (noise * F32(sigma / (255 * math.sqrt(1 / 6)))).reshape(img.shape)
    if weather == "rain":  # streaks differ between the cameras
        streaks = np.zeros((h, w), np.uint8)
        for _ in range(int(rng.integers(60, 160))):
            x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
            ln = int(rng.integers(8, 25))
            cv2.line(streaks, (x, y), (x + ln // 6, y + ln), 1, 1)
        img += (streaks[..., None] * 25).astype(F32)
    return np.clip(img, 0, 255).astype(np.uint8)


def kitti_calibration(frame: Frame) -> dict[str, np.ndarray]:
    """KITTI calibration matrices of the frame's rig (camera 0 = 2 = left, 1 = 3 = right, rectified).

    ``Tr_cam_to_road`` maps left-camera coordinates to the road frame (origin on the road under the
    camera, Y down, Z along the rig's heading): ``[Rx(−pitch)·Rz(−roll) | (0, −h, 0)]`` (pitch positive
    down, roll the paper's Φ; see :meth:`~freespace.data.synthetic.scene.Frame.rotation`).
    """
    sc = frame.scenario
    K = np.array([[sc.focal, 0, sc.cx], [0, sc.focal, sc.cy], [0, 0, 1.0]])
    P_left = np.hstack([K, np.zeros((3, 1))])
    P_right = P_left.copy()
    P_right[0, 3] = -sc.focal * sc.baseline
    R_wc = frame.rotation()
    cy_, sy_ = math.cos(frame.yaw), math.sin(frame.yaw)
    Ry = np.array([[cy_, 0, sy_], [0, 1, 0], [-sy_, 0, cy_]])
    road = np.hstack([Ry.T @ R_wc, np.array([[0.0], [-sc.cam_height], [0.0]])])
    velo = np.array([[0, -1, 0, 0], [0, 0, -1, -0.08], [1, 0, 0, -0.27]], float)
    return {"P0": P_left, "P1": P_right, "P2": P_left, "P3": P_right, "R0_rect": np.eye(3),
            "Tr_velo_to_cam": velo, "Tr_cam_to_road": road}


def _render(frame: Frame, o: tuple[float, float, float], R: np.ndarray, d: np.ndarray, tile: np.ndarray,
            shadows: _ShadowMap, pal: _Palette, sun: np.ndarray, rng: np.random.Generator,
            shape: tuple[int, int]) -> tuple[_Hits, np.ndarray]:
    """Cast and shade one view from centre ``o`` with rotation ``R`` (camera → world): hits and uint8 image."""
    sc = frame.scenario
    hits = _Hits.empty(shape[0] * shape[1])
    lateral = _ground(hits, sc, o, d, pal, sun)
    _facades(hits, sc, o, d, frame.z_cam, lateral, pal, sun)
    _objects(hits, sc.static_objects + frame.objects, sc, o, d, R, shape[1], pal, sun)
    return hits, _camera(_shade(hits, frame, o, d, tile, shadows, pal.array(), shape), rng, sc.weather)


@dataclass
class ViewRender:
    """One view of a frame rendered from a moved left camera (:func:`render_view`).

    Attributes:
        image: ``H×W×3 uint8`` RGB, with the left camera's response (gain, bias, vignetting, noise draw).
        label: road label of this view (every pixel valid).
        depth: ``float32 H×W`` depth along this camera's optical axis in metres, NaN where nothing is hit.
    """

    image: np.ndarray
    label: RoadLabel
    depth: np.ndarray


def render_view(frame: Frame, config: SynthConfig, pose: VirtualPose) -> ViewRender:
    """Render the frame from the left camera moved to ``pose`` (the ground truth of a virtual view).

    ``pose`` follows :mod:`freespace.geometry.virtual`: in the left camera's frame (x right, y down,
    z forward, metres) the camera centre moves to ``C = pose.shift`` and a point X is ``R·(X − C)`` in
    the moved camera's frame, ``R = R_yaw·R_pitch·R_roll``. The same scene, light, shadow map and camera
    response as the left image: ``VirtualPose()`` gives the left image exactly, and ``shift = (B, 0, 0)``
    the right camera's geometry.
    """
    sc = frame.scenario
    h, w = config.height, config.width
    R_left = frame.rotation()
    R = R_left @ pose.R.T  # camera → world of the moved camera
    o_left = np.asarray(frame.camera_centre())
    o = tuple(float(x) for x in o_left + R_left @ pose.C)
    rng = np.random.default_rng([*frame.seed, 3])  # the left camera's response: it is drawn first
    hits, image = _render(frame, o, R, _directions(sc, R, h, w), _noise_tile((frame.seed[0], sc.index)),
                          _ShadowMap(frame, o_left), _Palette(sc), _sun(sc), rng, (h, w))
    mat = hits.mat.reshape(h, w)
    road = (mat == ROAD) | (mat == MARKING)
    depth = hits.t.reshape(h, w).astype(F32)
    depth[~np.isfinite(depth)] = np.nan
    return ViewRender(image=image, label=RoadLabel(road=road, valid=np.ones_like(road)), depth=depth)


def render_frame(frame: Frame, config: SynthConfig) -> StereoSample:
    """Render a sampled :class:`~freespace.data.synthetic.scene.Frame` from both cameras."""
    sc = frame.scenario
    h, w = config.height, config.width
    R = frame.rotation()
    d = _directions(sc, R, h, w)
    o_left = tuple(float(x) for x in frame.camera_centre())  # Python floats keep float32 arithmetic
    o_right = tuple(float(x) for x in np.asarray(o_left) + R @ np.array([sc.baseline, 0.0, 0.0]))
    tile = _noise_tile((frame.seed[0], sc.index))
    shadows = _ShadowMap(frame, np.asarray(o_left))
    rng = np.random.default_rng([*frame.seed, 3])
    pal = _Palette(sc)
    sun = _sun(sc)
    views, images = [], []
    for o in (o_left, o_right):
        hits, image = _render(frame, o, R, d, tile, shadows, pal, sun, rng, (h, w))
        views.append(hits)
        images.append(image)
    t_left, t_right = views[0].t.reshape(h, w), views[1].t.reshape(h, w)
    seen = np.isfinite(t_left)
    disparity = np.full((h, w), np.nan, F32)
    disparity[seen] = F32(sc.focal * sc.baseline) / t_left[seen]
    # visible in the right view: the right ray at u − d sees the same depth
    ur = np.rint(np.arange(w, dtype=F32)[None, :] - np.where(seen, disparity, F32(1e9)))
    t_at = np.take_along_axis(t_right, np.clip(ur, 0, w - 1).astype(np.intp), axis=1)
    with np.errstate(invalid="ignore"):
        noc = seen & (ur >= 0) & (np.abs(t_at - t_left) <= 0.02 * t_left + 0.05)
    mat = views[0].mat.reshape(h, w)
    road = (mat == ROAD) | (mat == MARKING)
    kitti = kitti_calibration(frame)
    meta = {"weather": sc.weather, "planar": config.planar, "roll_deg": math.degrees(sc.roll),
            "pitch_deg": math.degrees(sc.pitch), "baseline_m": sc.baseline, "focal_px": sc.focal,
            "camera_height_m": sc.cam_height, "lanes": sc.lanes, "seed": frame.seed[0]}
    return StereoSample(name=frame.name, category=sc.category, scenario=sc.index, index=frame.index,
                        left=images[0], right=images[1], disparity=disparity,
                        label=RoadLabel(road=road, valid=np.ones_like(road)), noc=noc,
                        calibration=StereoCalibration.from_kitti(kitti), kitti_calib=kitti, meta=meta)


def render_sample(index: int, seed: int = 0, config: SynthConfig = SynthConfig()) -> StereoSample:
    """Render frame ``index`` of the built-in dataset (a function of ``(seed, index, config)`` only).

    Example:
        >>> s = render_sample(0, seed=1, config=SynthConfig(width=160, height=120))
        >>> s.left.shape, s.disparity.dtype, s.name[:3] in ("um_", "umm", "uu_")
        ((120, 160, 3), dtype('float32'), True)
    """
    config.check()
    return render_frame(sample_frame(config, seed, index), config)
