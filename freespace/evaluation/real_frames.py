"""The real labelled frames every real-road figure is measured on (KITTI; nothing here is ever trained on).

Two kinds of real label:

* **full masks** — the two KITTI stereo 2015 frames of ``shared/data/kitti_stereo_2015`` (``road_mask/``: the
  KITTI semantic benchmark's *road* class at full resolution). Precision, recall, F and IoU are measured on
  every pixel.
* **drawn polygons** — :data:`ROAD_POLYGONS`: conservative road regions drawn by hand on real frames that no
  training set here contains. Only *recall inside the polygon* is measured on them (a polygon says where road
  certainly is, not where it ends). How they were drawn: the frame was shown with a 50 px grid; each vertex was
  placed on road surface at least about 20 px inside the visible road edge (kerb, kerb stone, lane of parked
  cars, a vehicle's shadow edge counted as road), stopping below the row where the road meets the first
  obstacle or the vanishing point; then the filled polygon was overlaid on the frame and checked by eye (the
  three KITTI road frames' polygons are older, drawn the same way for the autolabel's quality in issue 22).
  They cover about half of the frame's road; a model that marks the polygon fully can still miss the road's
  edges.

Frames and sources (all CC BY-NC-SA 3.0, KITTI):

===========================================  ===========================================================
frame                                        where it lies
===========================================  ===========================================================
``um_000000``, ``uu_000000``, ``uu_000001``  ``shared/data/kitti_road_depth`` (KITTI road, left image only)
``2011_09_26_drive_0001_sync/0000000090``    ``shared/data/kitti_raw`` — drive 0001's last time block
``2011_09_26_drive_0001_sync/0000000105``    (frames 87–107), held out of the time-block subsets
``2011_09_26_drive_0000_sync/0000000065``    the second drive of that day (stop-and-go traffic), under
                                             ``$FREESPACE_KITTI_RAW``: frames 60–77 are its held-out block
===========================================  ===========================================================

Frames whose files are absent are skipped by :func:`available`. The tests, the benchmarks (``bench/``) and the
studies read this one module. The files are found under :data:`SHARED` (``FREESPACE_SHARED_DATA``, else
``shared/data`` beside a checkout of the repository) and :data:`KITTI_RAW`, read when this module is imported.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: the repository's folder, for a checkout (``freespace/evaluation/real_frames.py`` lies two folders down)
ROOT = Path(__file__).resolve().parents[2]
#: the shared real samples (as the tests find them)
SHARED = Path(os.environ.get("FREESPACE_SHARED_DATA") or ROOT.parent / "shared" / "data")
#: a KITTI raw root with the whole drives (fetched, never in the repository); default: none
KITTI_RAW = Path(os.environ["FREESPACE_KITTI_RAW"]) if os.environ.get("FREESPACE_KITTI_RAW") else None

#: frame → (image path relative to its root, root name) for the polygon frames
_POLYGON_FRAMES = {
    "um_000000": ("kitti_road_depth/testing/image_2/um_000000.png", "shared"),
    "uu_000000": ("kitti_road_depth/unknown_split/image_2/uu_000000.png", "shared"),
    "uu_000001": ("kitti_road_depth/unknown_split/image_2/uu_000001.png", "shared"),
    "2011_09_26_drive_0001_sync/0000000090":
        ("kitti_raw/2011_09_26/2011_09_26_drive_0001_sync/image_02/data/0000000090.png", "shared"),
    "2011_09_26_drive_0001_sync/0000000105":
        ("kitti_raw/2011_09_26/2011_09_26_drive_0001_sync/image_02/data/0000000105.png", "shared"),
    "2011_09_26_drive_0000_sync/0000000065":
        ("2011_09_26/2011_09_26_drive_0000_sync/image_02/data/0000000065.png", "kitti_raw"),
}

#: conservative road polygons, (u, v) pixel vertices on the 1242×375 left image (see the module docstring)
ROAD_POLYGONS: dict[str, list[tuple[int, int]]] = {
    # the three KITTI road frames: the polygons of tests/test_depth.py (drawn for issue 22's label quality)
    "um_000000": [(230, 370), (560, 200), (625, 200), (770, 370)],
    "uu_000000": [(200, 370), (510, 205), (630, 205), (790, 370)],
    "uu_000001": [(200, 370), (330, 290), (490, 215), (620, 215), (720, 300), (720, 370)],
    "2011_09_26_drive_0001_sync/0000000090":
        [(150, 374), (300, 300), (540, 200), (600, 200), (660, 230), (725, 330), (725, 374)],
    "2011_09_26_drive_0001_sync/0000000105":
        [(150, 374), (300, 300), (540, 205), (600, 205), (660, 230), (715, 320), (720, 374)],
    "2011_09_26_drive_0000_sync/0000000065":
        [(430, 374), (475, 290), (515, 255), (540, 255), (528, 300), (522, 374)],
}

#: the KITTI road frames' polygons by (split folder of ``kitti_road_depth``, frame)
KITTI_ROAD_POLYGONS = {("testing" if name.startswith("um") else "unknown_split", name): ROAD_POLYGONS[name]
                       for name in ("um_000000", "uu_000000", "uu_000001")}

#: the two fully labelled KITTI stereo 2015 frames
FULL_MASK_FRAMES = ("000000_10", "000001_10")


@dataclass(frozen=True)
class RealFrame:
    """One real labelled frame.

    Attributes:
        name: the frame's name (KITTI's, or ``<drive>/<frame>`` for KITTI raw).
        image: path of the left colour image (1242×375 PNG).
        road: ``H×W bool`` — the full road mask (``kind == "mask"``) or the drawn polygon (``"polygon"``).
        kind: ``"mask"`` (every pixel labelled: precision, recall, F, IoU) or ``"polygon"`` (recall only).
        right: path of the right image, when the frame has one.
    """

    name: str
    image: Path
    road: np.ndarray
    kind: str
    right: Path | None = None


def polygon_mask(vertices: list[tuple[int, int]], shape: tuple[int, int] = (375, 1242)) -> np.ndarray:
    """The ``H×W bool`` mask of a filled polygon given as (u, v) pixel vertices."""
    import cv2

    mask = np.zeros(shape, np.uint8)
    cv2.fillPoly(mask, [np.asarray(vertices, np.int32)], 1)
    return mask.astype(bool)


def available() -> list[RealFrame]:
    """The real labelled frames whose files are here (full masks first), in a fixed order."""
    from freespace.io.codecs import read_image

    frames: list[RealFrame] = []
    stereo = SHARED / "kitti_stereo_2015"
    for name in FULL_MASK_FRAMES:
        mask = stereo / "road_mask" / f"{name}.png"
        if mask.is_file():
            road = read_image(mask)
            road = (road if road.ndim == 2 else road[..., 0]) > 127
            frames.append(RealFrame(name, stereo / "image_2" / f"{name}.png", road, "mask",
                                    stereo / "image_3" / f"{name}.png"))
    for name, (rel, root) in _POLYGON_FRAMES.items():
        base = SHARED if root == "shared" else KITTI_RAW
        if base is None or not (base / rel).is_file():
            continue
        image = base / rel
        right = Path(str(image).replace("/image_02/", "/image_03/"))
        frames.append(RealFrame(name, image, polygon_mask(ROAD_POLYGONS[name]), "polygon",
                                right if right.is_file() and right != image else None))
    return frames
