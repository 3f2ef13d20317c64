"""The real labelled test set (:mod:`freespace.evaluation.real_frames`): every drawn polygon lies on one road plane,
and the full masks are the road.

A polygon that strayed onto a car, a kerb or the grass would fit the road model of section 2 badly: the
disparity inside it (SGBM from the real pair, or the frame's LiDAR depth) must be explained by one road plane
for most of its pixels. Skipped when ../shared/data is absent.
"""

from __future__ import annotations

import numpy as np
import pytest

from freespace.evaluation import real_frames
from freespace.geometry import compute_disparity, fit_road_model
from freespace.io.codecs import read_image

from helpers import SHARED, disparity_from_depth_file

pytestmark = pytest.mark.skipif(not SHARED.is_dir(), reason=f"shared sample data not available ({SHARED})")


def _frames(kind: str) -> list:
    return [f for f in real_frames.available() if f.kind == kind]


def _disparity(frame) -> np.ndarray:
    """The frame's disparity: SGBM from its pair, else its LiDAR depth (KITTI road frames)."""
    left = read_image(frame.image)
    if frame.right is not None:
        return compute_disparity(left, read_image(frame.right))
    root = frame.image.parents[1]
    if not (root / "depth_u16").is_dir():
        pytest.skip(f"{frame.name}: no right image and no depth here (its LiDAR scan needs the kitti-raw reader)")
    disparity, _ = disparity_from_depth_file(root / "depth_u16" / frame.image.name,
                                             root / "calib" / frame.image.with_suffix(".txt").name)
    return disparity


def test_the_shared_frames_are_all_found() -> None:
    names = {f.name for f in real_frames.available()}
    assert {"000000_10", "000001_10", "um_000000", "uu_000000", "uu_000001",
            "2011_09_26_drive_0001_sync/0000000090", "2011_09_26_drive_0001_sync/0000000105"} <= names


@pytest.mark.parametrize("name", [n for n in real_frames.ROAD_POLYGONS])
def test_each_polygon_lies_on_one_road_plane(name: str) -> None:
    frame = next((f for f in _frames("polygon") if f.name == name), None)
    if frame is None:
        pytest.skip(f"{name}: its image is not here")
    assert frame.road.shape == read_image(frame.image).shape[:2]
    assert 3000 < frame.road.sum() < 0.2 * frame.road.size
    model = fit_road_model(_disparity(frame), frame.road)
    # a polygon on the road: most of its valid disparities are road-plane inliers, the plane slopes down
    # the image (ϰ > 0: nearer rows, larger disparity) and the camera stands about level (|roll| < 5°)
    assert model.num_valid > 0.3 * frame.road.sum()
    # measured: 85.2–100 % (uu_000001 85.2, uu_000000 87.7: LiDAR depth interpolated across a kerb)
    assert model.num_inliers > 0.8 * model.num_valid, (model.num_inliers, model.num_valid)
    assert model.kappa_hat > 0 and abs(model.roll_deg) < 5


def test_full_masks_cover_the_lower_centre() -> None:
    frames = _frames("mask")
    if not frames:
        pytest.skip("the KITTI stereo 2015 masks are not here")
    for frame in frames:
        road = frame.road
        assert 0.15 < road.mean() < 0.4
        h, w = road.shape
        assert road[int(0.9 * h), w // 2]  # the road in front of the car
        assert road[: h // 3].mean() < 0.001  # next to nothing in the sky (000000_10: 24 px of a far road)
