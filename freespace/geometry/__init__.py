"""Road geometry: the road disparity model, its robust fit, homographies, the DS-Generator warp and
stereo matching. NumPy + OpenCV only — this package never imports torch.

Conventions: pixels are 0-based, ``u`` = column (right), ``v`` = row (down), pixel centres at
integers; ``H_tr`` maps reference (left) pixels to target (right) pixels; images are ``H×W×3 uint8``
RGB; disparity maps are ``float32 H×W`` with NaN for "no value".
"""

from freespace.geometry.homography import StereoCalibration, homography_from_pose
from freespace.geometry.road_model import (
    RoadModel,
    fit_road_model,
    fit_road_model_closed_form,
    road_energy,
    road_pixels,
)
from freespace.geometry.stereo import SGBM_MAX_DISPARITY, compute_disparity
from freespace.geometry.warp import generate_view, valid_column_ranges

__all__ = [
    "SGBM_MAX_DISPARITY",
    "RoadModel",
    "StereoCalibration",
    "compute_disparity",
    "fit_road_model",
    "fit_road_model_closed_form",
    "generate_view",
    "homography_from_pose",
    "road_energy",
    "road_pixels",
    "valid_column_ranges",
]
