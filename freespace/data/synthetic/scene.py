"""Random scenario and frame parameters of the built-in stereo road scene renderer.

A *scenario* is one drive: the rig (focal length, baseline, height, pitch, roll), the road (lanes,
curvature, sidewalks, curbs), the buildings and trees along it, and the weather. Its frames are taken
along the road at increasing distance, with vehicles and pedestrians placed anew in each.
Everything is drawn from ``numpy.random.default_rng((seed, stream, id))``, so frame ``i`` depends only
on ``(seed, i)`` and the configuration.

World frame: X right, Y down, Z forward (metres); the road surface at the ego position has Y = 0 and
its centre line is ``x_c(z) = c0 + c1 z + c2 z²``. The lateral offset of a point from the centre line
is ``s = x − x_c(z)``.
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass, field

import numpy as np

from freespace.errors import InvalidOptionError, param

__all__ = ["SynthConfig", "Scenario", "Frame", "Solid", "Box", "Sphere", "sample_scenario", "sample_frame",
           "WEATHERS", "CATEGORIES"]

WEATHERS = ("clear", "cloudy", "rain", "sunset", "dusk", "fog")
CATEGORIES = ("um", "umm", "uu")  # KITTI road: urban marked, urban multiple marked lanes, urban unmarked

#: the rigs the renderer may draw: inside the bounds a road fit must keep
#: (:meth:`freespace.geometry.RoadModel.check_plausible`: roll ±20°, camera 0.1–8 m), with a margin for
#: the fit of a non-planar road
MAX_ROLL_DEG = 15.0
CAMERA_HEIGHTS_M = (0.3, 6.0)

# materials (surface classes); the road label is ROAD | MARKING
SKY, ROAD, MARKING, CURB, SIDEWALK, GRASS, FACADE, VEHICLE, GLASS, PERSON, POLE, TRUNK, FOLIAGE, HEDGE = range(14)


@dataclass(frozen=True)
class SynthConfig:
    """What the renderer makes.

    Attributes:
        width, height: image size in pixels (SYN-Stereo: 640×480).
        frames_per_scenario: frames taken along one drive (one scenario id).
        planar: True = planar road (the paper's model holds exactly); False = slopes and camber.
        baseline: fixed baseline in metres, or None to draw it per scenario from ``baselines``.
        baselines: (min, max) baseline in metres drawn per scenario when ``baseline`` is None.
        camera_heights: (min, max) height of the rig above the road in metres, per scenario.
        pitches_deg: (min, max) rig pitch in degrees, per scenario: positive = the optical axis tilted down,
            towards the road (as a virtual view's ``rotate``, ``RoadPlane.from_camera`` and ``freespace.yaml``'s
            ``camera``).
        max_roll_deg: rig roll drawn in ±this (degrees).
        weathers: weathers to draw from.
        vehicles, pedestrians: (min, max) counts per frame.
    """

    width: int = 640
    height: int = 480
    frames_per_scenario: int = 10
    planar: bool = True
    baseline: float | None = None
    baselines: tuple[float, float] = (0.3, 1.6)
    camera_heights: tuple[float, float] = (1.4, 2.0)
    pitches_deg: tuple[float, float] = (-2.0, 2.0)
    max_roll_deg: float = 3.0
    weathers: tuple[str, ...] = WEATHERS
    vehicles: tuple[int, int] = (2, 7)
    pedestrians: tuple[int, int] = (1, 6)

    def check(self) -> None:
        """Raise InvalidOptionError for values the renderer cannot use."""
        if not (32 <= self.width <= 8192 and 32 <= self.height <= 8192):
            raise InvalidOptionError(f"{param('width')}/{param('height')} must be 32..8192 pixels, got "
                                     f"{self.width}×{self.height}")
        if self.frames_per_scenario < 1:
            raise InvalidOptionError(f"{param('frames_per_scenario')} must be ≥ 1")
        if self.baseline is not None and not 0.01 <= self.baseline <= 10:
            raise InvalidOptionError(f"{param('baseline')} must be 0.01..10 m, got {self.baseline}")
        for name, (lo, hi), (least, most) in (("baselines", self.baselines, (0.01, 10.0)),
                                               ("camera_heights", self.camera_heights, CAMERA_HEIGHTS_M),
                                               ("pitches_deg", self.pitches_deg, (-20.0, 20.0))):
            if not least <= lo <= hi <= most:
                raise InvalidOptionError(f"{param(name)} must be MIN,MAX with {least} ≤ MIN ≤ MAX ≤ {most}, "
                                         f"got {lo},{hi}")
        if not 0 <= self.max_roll_deg <= MAX_ROLL_DEG:
            raise InvalidOptionError(f"{param('max_roll_deg')} must be 0..{MAX_ROLL_DEG:g} degrees, got "
                                     f"{self.max_roll_deg}")
        bad = [w for w in self.weathers if w not in WEATHERS]
        if bad or not self.weathers:
            raise InvalidOptionError(f"unknown weather {bad}; choose from {', '.join(WEATHERS)}")
        for name, (lo, hi) in (("vehicles", self.vehicles), ("pedestrians", self.pedestrians)):
            if not 0 <= lo <= hi <= 50:
                raise InvalidOptionError(f"{name} counts must satisfy 0 ≤ min ≤ max ≤ 50, got {lo}..{hi}")


@dataclass(frozen=True)
class Solid:
    """An object of the scene (a :class:`Box` or a :class:`Sphere`): the point it stands at and its surface.

    Attributes:
        x, y, z: the object's anchor in the world frame (metres; see the subclass for which point it is).
        material: its material (one of the material constants above: ``VEHICLE``, ``POLE``, …).
        colour: RGB albedo, 0..1 each.
        group: the object it is part of: parts stacked on one object (a car's body and cabin, a tree's
            trunk and canopy) share it.

    The surface (``material``, ``colour``, ``group``) is given by keyword, after the subclass's own sizes:
    ``Sphere(x, y, z, r, material=FOLIAGE, colour=rgb, group=g)``.
    """

    x: float
    y: float
    z: float
    _: KW_ONLY
    material: int
    colour: tuple[float, float, float]
    group: int = 0


@dataclass(frozen=True)
class Box(Solid):
    """An upright box: (x, y, z) is the centre of its bottom face, (width, height, length) its size in metres
    along its own x, y, z (the height upwards, towards −Y), and ``yaw`` its rotation about Y in radians."""

    width: float
    height: float
    length: float
    yaw: float


@dataclass(frozen=True)
class Sphere(Solid):
    """A sphere (tree canopy): (x, y, z) is its centre and ``radius`` its radius in metres."""

    radius: float


@dataclass
class Scenario:
    """One drive: rig, road, roadside and weather (see the module docstring for the world frame)."""

    index: int
    category: str
    weather: str
    # rig
    focal: float
    cx: float
    cy: float
    baseline: float
    cam_height: float
    pitch: float  # radians, positive = optical axis tilted down (towards the road)
    roll: float  # radians, the paper's Φ (see Frame.rotation)
    # road
    lanes: int
    lane_width: float
    centre: tuple[float, float, float]  # c0, c1, c2 of x_c(z)
    ego_offset: float  # lateral offset of the rig from the road centre (m)
    sidewalk: float
    curb_height: float
    setback: float
    segment_length: float
    building_heights: np.ndarray  # per segment along z; ≤ 2.5 = hedge/wall, no building
    facade_colours: np.ndarray  # segments × 3
    road_colour: tuple[float, float, float]
    sidewalk_colour: tuple[float, float, float]
    # non-planar terms (0 in planar mode): elevation e = grade z + vcurve z² / 2 − camber s²
    grade: float
    vcurve: float
    camber: float
    # light
    sun_elevation: float
    sun_azimuth: float
    static_objects: list[Box | Sphere] = field(default_factory=list)

    @property
    def half_width(self) -> float:
        """Half the road width (curb to curb), metres."""
        return 0.5 * self.lanes * self.lane_width

    @property
    def facade_offset(self) -> float:
        """Lateral distance of the building line from the road centre, metres."""
        return self.half_width + self.sidewalk + self.setback

    def centre_x(self, z: np.ndarray | float) -> np.ndarray | float:
        """x of the road centre line at depth z."""
        c0, c1, c2 = self.centre
        return c0 + c1 * z + c2 * z * z

    def heading(self, z: float) -> float:
        """Road direction (yaw about Y, radians) at depth z."""
        return math.atan(self.centre[1] + 2 * self.centre[2] * z)

    def elevation(self, s: np.ndarray | float, z: np.ndarray | float) -> np.ndarray | float:
        """Height of the road surface above Y = 0 at lateral offset s and depth z (metres, up)."""
        return self.grade * z + 0.5 * self.vcurve * z * z - self.camber * s * s


@dataclass
class Frame:
    """One stereo frame of a scenario: the rig position and the moving objects."""

    index: int
    scenario: Scenario
    z_cam: float
    yaw: float
    objects: list[Box | Sphere]
    seed: tuple[int, ...]

    @property
    def name(self) -> str:
        """KITTI-style frame name ``<cat>_<6 digits>``."""
        return f"{self.scenario.category}_{self.index:06d}"

    def camera_centre(self) -> np.ndarray:
        """Left camera centre in world coordinates."""
        sc = self.scenario
        s = sc.ego_offset
        ground = sc.elevation(s, self.z_cam)
        return np.array([sc.centre_x(self.z_cam) + s, -(ground + sc.cam_height), self.z_cam])

    def rotation(self) -> np.ndarray:
        """R_wc (camera → world): yaw about Y, then pitch about X, then roll about the optical axis:
        ``Ry(yaw)·Rx(−pitch)·Rz(−roll)``.

        The pitch is positive when the optical axis points down at the road. The roll is signed like the
        paper's Φ: the road disparity model fitted to the frame has ``Φ = roll`` (a rotation of the rig by
        −Φ about its optical axis). So the road normal in the camera frame is
        ``Rz(roll)·Rx(pitch)·(0, 1, 0)``, the plane of :meth:`freespace.geometry.RoadPlane.from_camera` with
        the same height, pitch and roll.
        """
        sc = self.scenario
        cy, sy = math.cos(self.yaw), math.sin(self.yaw)
        cp, sp = math.cos(-sc.pitch), math.sin(-sc.pitch)
        cr, sr = math.cos(-sc.roll), math.sin(-sc.roll)
        Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        Rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
        Rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
        return Ry @ Rx @ Rz


def _colour(rng: np.random.Generator, base: tuple[float, float, float], spread: float) -> tuple[float, float, float]:
    return tuple(float(np.clip(b + rng.uniform(-spread, spread), 0.02, 0.98)) for b in base)  # type: ignore[return-value]


CAR_COLOURS = [(0.75, 0.75, 0.78), (0.1, 0.1, 0.12), (0.55, 0.08, 0.07), (0.1, 0.2, 0.5), (0.85, 0.85, 0.82),
               (0.35, 0.37, 0.4), (0.15, 0.35, 0.2), (0.8, 0.6, 0.1)]


def sample_scenario(config: SynthConfig, seed: int, index: int) -> Scenario:
    """Draw scenario ``index`` (a function of ``(seed, index)`` and the configuration only)."""
    rng = np.random.default_rng([seed, 1, index])
    category = CATEGORIES[int(rng.integers(0, 3))]
    lanes = {"um": 2, "umm": int(rng.integers(3, 5)), "uu": int(rng.integers(1, 3))}[category]
    lane_width = float(rng.uniform(2.8, 3.6))
    hfov = math.radians(rng.uniform(70, 90))
    focal = 0.5 * config.width / math.tan(0.5 * hfov)
    weather = config.weathers[int(rng.integers(0, len(config.weathers)))]
    half = 0.5 * lanes * lane_width
    ego_lane = int(rng.integers(0, lanes))
    ego_offset = -half + (ego_lane + 0.5) * lane_width + float(rng.uniform(-0.4, 0.4))
    seg = float(rng.uniform(8, 16))
    nseg = int(260 / seg) + 2
    heights = rng.uniform(5, 22, nseg)
    heights[rng.random(nseg) < 0.25] = rng.uniform(0.8, 2.2)  # hedges and walls between buildings
    facade_colours = np.clip(rng.uniform(0.25, 0.85, (nseg, 3)) * rng.uniform(0.85, 1.0, (nseg, 1)), 0, 1)
    sun_elevation = math.radians({"sunset": rng.uniform(4, 12), "dusk": rng.uniform(1, 5)}.get(weather,
                                                                                                rng.uniform(25, 65)))
    planar = config.planar
    sc = Scenario(
        index=index, category=category, weather=weather,
        focal=focal, cx=0.5 * config.width + float(rng.uniform(-6, 6)),
        cy=0.5 * config.height + float(rng.uniform(-6, 6)),
        baseline=config.baseline if config.baseline is not None else float(rng.uniform(*config.baselines)),
        cam_height=float(rng.uniform(*config.camera_heights)),
        # drawn as the upward angle, uniform in (−max, −min), as when positive meant up: the same rigs as
        # before for symmetric ranges
        pitch=-math.radians(rng.uniform(-config.pitches_deg[1], -config.pitches_deg[0])),
        roll=math.radians(rng.uniform(-config.max_roll_deg, config.max_roll_deg)),
        lanes=lanes, lane_width=lane_width,
        centre=(-ego_offset, float(rng.uniform(-0.04, 0.04)), float(rng.uniform(-1.5e-3, 1.5e-3))),
        ego_offset=ego_offset,
        sidewalk=float(rng.uniform(1.8, 4.0)), curb_height=float(rng.uniform(0.1, 0.18)),
        setback=float(rng.uniform(0.0, 3.0)), segment_length=seg, building_heights=heights,
        facade_colours=facade_colours,
        road_colour=_colour(rng, (0.3, 0.3, 0.31), 0.06),
        sidewalk_colour=_colour(rng, (0.55, 0.52, 0.48), 0.1),
        grade=0.0 if planar else float(rng.uniform(-0.04, 0.04)),
        vcurve=0.0 if planar else float(rng.uniform(-8e-4, 8e-4)),
        camber=0.0 if planar else float(rng.uniform(0.002, 0.006)),
        sun_elevation=sun_elevation, sun_azimuth=math.radians(rng.uniform(-120, 120)),
    )
    # trees and poles along the sidewalks (static for the whole drive)
    objects: list[Box | Sphere] = []
    group = 1000
    for side in (-1, 1):
        z = float(rng.uniform(0, 15))
        while z < 260:
            kind = rng.random()
            s = side * (sc.half_width + (0.4 if kind < 0.5 else sc.sidewalk - 0.6))
            x = sc.centre_x(z) + s
            y = -sc.elevation(s, z) - sc.curb_height
            if kind < 0.5:  # pole, sometimes with a sign
                ph = float(rng.uniform(3, 7))
                objects.append(Box(x, y, z, 0.14, ph, 0.14, 0.0, material=POLE,
                                   colour=_colour(rng, (0.45, 0.45, 0.47), 0.1), group=group))
                if rng.random() < 0.4:
                    objects.append(Box(x, y - ph + 0.9, z, 0.7, 0.6, 0.06, 0.0, material=POLE,
                                       colour=_colour(rng, (0.6, 0.15, 0.15), 0.2), group=group))
            else:  # tree
                th = float(rng.uniform(2.0, 3.0))
                r = float(rng.uniform(1.2, 2.4))
                objects.append(Box(x, y, z, 0.3, th + 0.5 * r, 0.3, 0.0, material=TRUNK,
                                   colour=_colour(rng, (0.3, 0.2, 0.12), 0.05), group=group))
                objects.append(Sphere(x, y - th - 0.8 * r, z, r, material=FOLIAGE,
                                      colour=_colour(rng, (0.2, 0.4, 0.12), 0.08), group=group))
            group += 1
            z += float(rng.uniform(8, 25))
    sc.static_objects = objects
    return sc


def sample_frame(config: SynthConfig, seed: int, index: int) -> Frame:
    """Draw frame ``index``: its scenario, the rig position along the road, vehicles and pedestrians."""
    scenario = sample_scenario(config, seed, index // config.frames_per_scenario)
    k = index % config.frames_per_scenario
    rng = np.random.default_rng([seed, 2, index])
    z_cam = 6.0 * k + float(rng.uniform(0, 3))
    yaw = scenario.heading(z_cam) + math.radians(rng.uniform(-1.5, 1.5))
    sc = scenario
    objects: list[Box | Sphere] = []
    group = 1
    for _ in range(int(rng.integers(config.vehicles[0], config.vehicles[1] + 1))):
        z = z_cam + float(rng.uniform(7, 60))
        if rng.random() < 0.35:  # parked at the curb
            s = float(rng.choice([-1, 1])) * (sc.half_width - 1.0)
        else:
            lane = int(rng.integers(0, sc.lanes))
            s = -sc.half_width + (lane + 0.5) * sc.lane_width + float(rng.uniform(-0.3, 0.3))
        if abs(s - sc.ego_offset) < 1.5 and z - z_cam < 10:
            z += 10.0  # keep the ego lane clear just ahead
        van = rng.random() < 0.2
        w, length = (float(rng.uniform(1.9, 2.2)), float(rng.uniform(5, 7))) if van else \
            (float(rng.uniform(1.65, 1.9)), float(rng.uniform(3.8, 4.8)))
        body_h = float(rng.uniform(1.6, 2.4)) if van else float(rng.uniform(0.75, 0.95))
        x = sc.centre_x(z) + s
        y = -sc.elevation(s, z)
        yaw_o = sc.heading(z) + (math.pi if rng.random() < 0.3 else 0.0) + math.radians(rng.uniform(-4, 4))
        colour = CAR_COLOURS[int(rng.integers(0, len(CAR_COLOURS)))]
        objects.append(Box(x, y, z, w, body_h, length, yaw_o, material=VEHICLE, colour=_colour(rng, colour, 0.05),
                           group=group))
        if not van:
            cab_l = 0.55 * length
            dz = -0.08 * length
            objects.append(Box(x + dz * math.sin(yaw_o), y - body_h, z + dz * math.cos(yaw_o), 0.92 * w,
                               float(rng.uniform(0.45, 0.6)), cab_l, yaw_o, material=GLASS, colour=(0.08, 0.1, 0.12),
                               group=group))
        group += 1
    for _ in range(int(rng.integers(config.pedestrians[0], config.pedestrians[1] + 1))):
        z = z_cam + float(rng.uniform(5, 40))
        side = float(rng.choice([-1, 1]))
        crossing = rng.random() < 0.15
        s = float(rng.uniform(-sc.half_width, sc.half_width)) if crossing else \
            side * (sc.half_width + float(rng.uniform(0.4, sc.sidewalk - 0.3)))
        x = sc.centre_x(z) + s
        y = -sc.elevation(s, z) - (0.0 if crossing else sc.curb_height)
        height = float(rng.uniform(1.55, 1.9))
        yaw_o = float(rng.uniform(-math.pi, math.pi))
        legs = 0.47 * height
        objects.append(Box(x, y, z, 0.36, legs, 0.25, yaw_o, material=PERSON,
                           colour=_colour(rng, (0.2, 0.2, 0.3), 0.15), group=group))
        objects.append(Box(x, y - legs, z, 0.46, 0.4 * height, 0.28, yaw_o, material=PERSON,
                           colour=_colour(rng, (0.5, 0.4, 0.4), 0.35), group=group))
        objects.append(Box(x, y - 0.87 * height, z, 0.2, 0.13 * height, 0.22, yaw_o, material=PERSON,
                           colour=_colour(rng, (0.75, 0.58, 0.45), 0.15), group=group))
        group += 1
    return Frame(index=index, scenario=scenario, z_cam=z_cam, yaw=yaw, objects=objects,
                 seed=(seed, index))
