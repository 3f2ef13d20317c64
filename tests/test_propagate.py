"""Carrying road labels back along a drive: ego-motion, source frames, the plane-induced votes, the label tree."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.datagen.propagate import Motion, PropagateOptions, compose, ego_motion, propagate_frame, source_frames
from freespace.errors import InvalidOptionError
from freespace.geometry import RoadModel
from freespace.geometry.homography import homography_from_pose
from freespace.geometry.plane import RoadPlane
from freespace.io.codecs import read_road_label
from freespace.labels import RoadLabel

from helpers import refused, textured_image

K = np.array([[700.0, 0, 320], [0, 700, 120], [0, 0, 1]])
BASELINE = 0.5
SHAPE = (240, 640)
#: a level camera 1.5 m above a flat road: d = (v − 120)·B/h, zero on the horizon row 120
MODEL = RoadModel.from_affine(0.0, BASELINE / 1.5, -120 * BASELINE / 1.5)


def forward(metres: float) -> Motion:
    """The camera moves ``metres`` straight ahead: points come ``metres`` nearer."""
    return Motion(np.eye(3), np.array([0.0, 0.0, -metres]), 100)


def test_motion_composition_and_travel() -> None:
    turn = Motion(cv2.Rodrigues(np.array([0.0, 0.1, 0.0]))[0], np.array([0.3, 0.0, -2.0]), 50)
    both = compose(forward(3.0), turn)
    X = np.array([1.0, 2.0, 15.0])
    assert np.allclose(both.R @ X + both.t, turn.R @ (X + [0, 0, -3.0]) + turn.t)
    assert forward(3.0).travel == pytest.approx(3.0) and both.inliers == 50


def test_source_frames_follow_the_travel_range_and_stop_at_a_lost_motion() -> None:
    steps = [forward(1.0)] * 60
    opts = PropagateOptions(min_travel=4, max_travel=20, sources=3, window=40)
    picked = source_frames(steps, 0, opts)
    assert [s for s, _ in picked] == [4, 12, 20] and [round(m.travel) for _, m in picked] == [4, 12, 20]
    assert source_frames(steps[:10] + [None] + steps[11:], 0, opts)[-1][0] <= 10  # the chain stops at a lost motion
    assert source_frames(steps, 58, opts) == []  # the drive ends before 4 m


def _scene(travel: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A textured road seen from a camera ``travel`` metres behind: frame t (earlier), frame s (later, its image)
    and where t's pixels lie in s (the road homography)."""
    image_s = textured_image(SHAPE, seed=seed)
    plane = RoadPlane.from_road_model(MODEL, K[0, 0], BASELINE, K[0, 2], K[1, 2])
    H = homography_from_pose(K, K, forward(travel).R, forward(travel).t, plane)
    image_t = cv2.warpPerspective(image_s, H, SHAPE[::-1], flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    return image_t, image_s, H


def test_far_road_is_carried_back_and_a_moved_car_is_not() -> None:
    image_t, image_s, H = _scene(10.0)
    h, w = SHAPE
    rows = np.arange(h)[:, None] * np.ones((1, w))
    # each frame labels the road in its bottom 60 rows only (row v lies 1050/(v − 120) m ahead: within 17.5 m);
    # farther is don't care; s's label is taken within 15 m (rows ≥ 190), i.e. t's rows 162–174 (25–19 m: nearer
    # than 18.8 m, t's road is below s's image)
    near = rows >= 180
    own = RoadLabel(road=near.copy(), valid=near | (rows < 110))
    src = RoadLabel(road=near.copy(), valid=near | (rows < 110))
    image_t[165:173, 300:340] = 255  # a car on the road in t that has gone by s: t's image differs there
    new, change = propagate_frame(image_t, own, MODEL, K, BASELINE, [(image_s, src, MODEL, forward(10.0))],
                                  options=PropagateOptions(near_depth=15.0))
    gained = change == 1
    road_ahead = np.zeros(SHAPE, bool)
    road_ahead[163:175, 200:440] = True
    road_ahead[165:173, 300:340] = False
    assert gained[road_ahead].mean() > 0.95, gained[road_ahead].mean()
    assert not gained[:160].any() and not gained[176:].any()  # nothing farther than 25 m or out of s's view
    assert not gained[165:173, 300:340].any()  # the car: its grey levels differ from the road's in s
    assert (new.road == (own.road | gained)).all() and not (change == 2).any()


def test_a_contradicting_source_makes_a_conflict_not_a_guess() -> None:
    image_t, image_s, _ = _scene(8.0, seed=3)
    h, w = SHAPE
    rows = np.arange(h)[:, None] * np.ones((1, w))
    own = RoadLabel(road=rows >= 150, valid=rows >= 150)  # t labels rows 150–239 road
    src = RoadLabel(road=np.zeros(SHAPE, bool), valid=rows >= 150)  # s says non-road near its camera
    new, change = propagate_frame(image_t, own, MODEL, K, BASELINE, [(image_s, src, MODEL, forward(8.0))])
    conflict = change == 2
    assert conflict.any() and not (new.valid & conflict).any()
    assert not (change == 1).any()  # non-road votes never create road (nor non-road)


def test_options_are_checked() -> None:
    for bad in (dict(min_travel=5, max_travel=4), dict(window=0), dict(near_depth=0), dict(min_inliers=3)):
        with pytest.raises(InvalidOptionError):
            PropagateOptions(**bad).check()


WALL = 30.0  # metres: a textured wall across the road ends the scene (rows above 155 of the first frame)
DRIVE = "2011_09_26_drive_0001_sync"


def _view(world: dict[str, np.ndarray], z: float, x: float = 0.0) -> np.ndarray:
    """The scene seen from ``z`` metres along the road and ``x`` to the right: the road and the wall of
    ``world`` (their images from z = 0, x = 0) warped by their planes' homographies."""
    h, w = SHAPE
    motion = Motion(np.eye(3), np.array([-x, 0.0, -z]))
    out = np.zeros((h, w, 3), np.uint8)
    boundary = 120 + 1050 / (WALL - z)  # the row where the road meets the wall
    rows = np.arange(h)[:, None]
    for name, plane in (("road", RoadPlane((0, 1, 0), 1.5)), ("wall", RoadPlane((0, 0, 1), WALL))):
        H = homography_from_pose(K, K, motion.R, motion.t, plane)
        part = cv2.warpPerspective(world[name], H, (w, h), flags=cv2.INTER_LINEAR)
        inside = (rows >= boundary) if name == "road" else (rows < boundary)
        out[np.broadcast_to(inside, (h, w))] = part[np.broadcast_to(inside, (h, w))]
    return out


def _world(seed: int = 5) -> dict[str, np.ndarray]:
    from helpers import noise_texture

    return {"road": np.dstack([noise_texture(SHAPE, seed)] * 3),
            "wall": np.dstack([noise_texture(SHAPE, seed + 1), noise_texture(SHAPE, seed + 2),
                               noise_texture(SHAPE, seed + 3)])}


def _disparity(z: float) -> np.ndarray:
    h, w = SHAPE
    rows = np.arange(h, dtype=np.float32)[:, None] * np.ones((1, w), np.float32)
    boundary = 120 + 1050 / (WALL - z)
    return np.where(rows >= boundary, (rows - 120) * BASELINE / 1.5, K[0, 0] * BASELINE / (WALL - z)).astype(np.float32)


def test_ego_motion_of_a_rendered_scene() -> None:
    world = _world()
    m = ego_motion(_view(world, 0.0), _view(world, 1.0), _disparity(0.0), K, BASELINE)
    assert m is not None and m.inliers >= 40
    assert np.allclose(m.t, [0, 0, -1.0], atol=0.05) and np.allclose(m.R, np.eye(3), atol=0.01)
    assert ego_motion(_view(world, 0.0), np.zeros(SHAPE + (3,), np.uint8), _disparity(0.0), K, BASELINE) is None


def _synthetic_drive(tmp_path: Path, frames: int, step: float) -> Path:
    """A KITTI raw tree with one drive: the camera drives ``step`` metres a frame towards the wall."""
    from freespace.io.codecs import write_image

    root, world = tmp_path / "raw", _world()
    day = root / "2011_09_26"
    for k in range(frames):
        for cam, x in (("image_02", 0.0), ("image_03", BASELINE)):
            write_image(day / DRIVE / cam / "data" / f"{k:010d}.png", _view(world, k * step, x))
    P2 = np.hstack([K, np.zeros((3, 1))])
    P3 = P2.copy()
    P3[0, 3] = -K[0, 0] * BASELINE
    num = lambda a: " ".join(f"{v:.6e}" for v in np.ravel(a))  # noqa: E731
    (day / "calib_cam_to_cam.txt").write_text(
        f"S_rect_02: {SHAPE[1]} {SHAPE[0]}\nR_rect_00: {num(np.eye(3))}\nP_rect_02: {num(P2)}\n"
        f"S_rect_03: {SHAPE[1]} {SHAPE[0]}\nP_rect_03: {num(P3)}\n")
    return root


def test_propagate_a_drive_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = _synthetic_drive(tmp_path, 12, 1.0)
    common = ["--dataset", "kitti-raw", "--root", str(root), "--disparity-source", "sgbm", "--cache-dir",
              str(tmp_path / "cache")]
    assert main(["autolabel", *common, "--out", str(tmp_path / "single")]) == 0
    assert main(["autolabel", *common, "--propagate-from", str(tmp_path / "single"),
                 "--out", str(tmp_path / "prop")]) == 0
    assert "labelled" in capsys.readouterr().out
    summary = json.loads((tmp_path / "prop" / "summary.json").read_text())
    assert summary["frames"] == 12 and summary["mean_gained"] > 0
    settings = json.loads((tmp_path / "prop" / "settings.json").read_text())
    assert settings["propagation"]["window"] == 40 and settings["source_labels"] == str((tmp_path / "single").resolve())
    first = json.loads((tmp_path / "prop" / "reports" / DRIVE / "0000000000.json").read_text())["propagation"]
    assert first["sources"] >= 1 and first["gained"] > 0
    old = read_road_label(tmp_path / "single" / DRIVE / "0000000000.png")
    new = read_road_label(tmp_path / "prop" / DRIVE / "0000000000.png")
    gained = new.road & new.valid & ~old.valid
    assert gained.any() and (np.nonzero(gained)[0] > 120).all()  # below the horizon only
    # training reads the propagated tree as a label tree of the dataset
    from freespace.data.label_tree import check_label_tree

    check_label_tree(tmp_path / "prop", "kitti-raw", root, None)
    # a propagated tree is not propagated again; the output may not be the input; method options are refused
    refused(capsys, ["autolabel", *common, "--propagate-from", str(tmp_path / "prop"), "--out", str(tmp_path / "p2")],
            match="already propagated")
    refused(capsys, ["autolabel", *common, "--propagate-from", str(tmp_path / "single"), "--out",
                     str(tmp_path / "single")])
    refused(capsys, ["autolabel", *common, "--propagate-from", str(tmp_path / "single"), "--curb-height", "0.2",
                     "--out", str(tmp_path / "p3")], match="--curb-height")
    refused(capsys, ["autolabel", *common, "--propagate-from", str(tmp_path / "single"), "--workers", "2",
                     "--out", str(tmp_path / "p3")], match="--workers")
    refused(capsys, ["autolabel", *common, "--propagate-from", str(tmp_path / "none"), "--out", str(tmp_path / "p3")],
            match="not found")
    assert not (tmp_path / "p2").exists() and not (tmp_path / "p3").exists()
    # the road-look pass over the propagated tree: road only lost, to don't care; not road untouched
    assert main(["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--look-from", str(tmp_path / "prop"),
                 "--out", str(tmp_path / "look")]) == 0
    assert "vetoed" in capsys.readouterr().out
    summary = json.loads((tmp_path / "look" / "summary.json").read_text())
    assert summary["frames"] == 12 and summary["mean_road_fraction"] <= summary["mean_road_before"]
    assert set(summary["drives"][DRIVE]) >= {"road_examples", "not_road_examples", "road_recall"}
    settings = json.loads((tmp_path / "look" / "settings.json").read_text())
    assert settings["look"]["veto"] == 0.5 and "propagation" in settings
    for k in (0, 11):
        before = read_road_label(tmp_path / "prop" / DRIVE / f"{k:010d}.png")
        after = read_road_label(tmp_path / "look" / DRIVE / f"{k:010d}.png")
        assert not (after.road & ~before.road).any() and np.array_equal(after.valid & ~after.road,
                                                                         before.valid & ~before.road)
    refused(capsys, ["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--look-from",
                     str(tmp_path / "look"), "--out", str(tmp_path / "l2")], match="already look-checked")
    refused(capsys, ["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--look-from",
                     str(tmp_path / "prop"), "--out", str(tmp_path / "prop")])
    refused(capsys, ["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--look-from",
                     str(tmp_path / "prop"), "--look-veto", "1.5", "--out", str(tmp_path / "l2")], match="--look-veto")
    refused(capsys, ["autolabel", *common, "--look-from", str(tmp_path / "prop"), "--out", str(tmp_path / "l2")],
            match="--disparity-source")
    refused(capsys, ["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--look-from",
                     str(tmp_path / "prop"), "--curb-height", "0.2", "--out", str(tmp_path / "l2")],
            match="--curb-height")
    refused(capsys, ["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--look-veto", "0.3",
                     "--out", str(tmp_path / "l2")], match="--look-veto")
    assert not (tmp_path / "l2").exists()
