"""Real KITTI stereo 2015 frames: the road plane from LiDAR and from SGBM agree, and the generated view
matches the left image on the road far better than the raw right image.

The road regions are polygons drawn by hand on the two frames (lower central road, clear of cars and
the right-hand sidewalk). Skipped when ../shared/data is absent.
"""

from __future__ import annotations

import numpy as np
import pytest

from freespace.geometry import compute_disparity, fit_road_model, generate_view
from freespace.io.codecs import read_disparity, read_image

from helpers import shared_path

ROAD_POLYGONS = {
    "000000_10": [(400, 374), (400, 240), (570, 190), (615, 190), (700, 225), (880, 300), (880, 374)],
    "000001_10": [(250, 374), (250, 240), (530, 195), (610, 195), (690, 215), (800, 290), (850, 374)],
}


@pytest.fixture(params=sorted(ROAD_POLYGONS))
def frame(request: pytest.FixtureRequest):
    import cv2

    name = request.param
    left = read_image(shared_path("kitti_stereo_2015", "image_2", f"{name}.png"))
    right = read_image(shared_path("kitti_stereo_2015", "image_3", f"{name}.png"))
    lidar = read_disparity(shared_path("kitti_stereo_2015", "disp_occ_0", f"{name}.png"))
    road = np.zeros(left.shape[:2], np.uint8)
    cv2.fillPoly(road, [np.array(ROAD_POLYGONS[name], np.int32)], 1)
    return left, right, lidar, road.astype(bool)


def test_lidar_and_sgbm_road_planes_agree(frame) -> None:
    left, right, lidar, road = frame
    from_lidar = fit_road_model(lidar, road)
    from_sgbm = fit_road_model(compute_disparity(left, right), road)
    assert from_lidar.num_inliers > 0.8 * from_lidar.num_valid
    assert from_sgbm.num_inliers > 0.75 * from_sgbm.num_valid
    # measured: roll 0.13° / 0.05° apart, ϰ 1.6 % / 2.5 %, mean |Δd| 0.26 / 0.33 px over the road
    assert abs(from_lidar.roll_deg - from_sgbm.roll_deg) < 0.25
    assert from_sgbm.kappa_hat == pytest.approx(from_lidar.kappa_hat, rel=0.04)
    diff = np.abs(from_lidar.disparity(road.shape) - from_sgbm.disparity(road.shape))[road]
    assert diff.mean() < 0.5 and diff.max() < 1.2


def test_generated_view_matches_left_on_the_road(frame) -> None:
    left, right, lidar, road = frame
    generated, inside = generate_view(left, right, fit_road_model(lidar, road), return_mask=True)
    on_road = road & inside

    def mae(img: np.ndarray) -> float:
        return float(np.abs(img.astype(np.float64) - left.astype(np.float64))[on_road].mean())

    # measured: raw right 36.9 / 22.7 grey levels, generated 9.3 / 9.0 (the rest is photometric)
    assert mae(generated) < 0.5 * mae(right)
    assert mae(generated) < 12
