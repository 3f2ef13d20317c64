"""Road geometry: the road disparity model, its robust fit, homographies, the DS-Generator warp,
road-plane virtual views and stereo matching. NumPy + OpenCV only — this package never imports torch.

Conventions: pixels are 0-based, ``u`` = column (right), ``v`` = row (down), pixel centres at
integers; ``H_tr`` maps reference (left) pixels to target (right) pixels; images are ``H×W×3 uint8``
RGB; disparity maps are ``float32 H×W`` with NaN for "no value"; the road plane is a :class:`RoadPlane`
``n·X = h`` with ``n`` pointing from the camera to the road (:mod:`freespace.geometry.plane`).
"""

from freespace.geometry.homography import StereoCalibration, homography_from_pose
from freespace.geometry.plane import RoadPlane, pose_ranges, rotation_from_angles
from freespace.geometry.road_model import (
    RoadModel,
    fit_road_model,
    fit_road_model_closed_form,
    road_energy,
    road_pixels,
)
from freespace.geometry.stereo import SGBM_MAX_DISPARITY, compute_disparity
from freespace.geometry.virtual import VirtualPose, virtual_homography, virtual_view
from freespace.geometry.warp import generate_view, valid_column_ranges

__all__ = [
    "SGBM_MAX_DISPARITY",
    "RoadModel",
    "RoadPlane",
    "StereoCalibration",
    "VirtualPose",
    "compute_disparity",
    "fit_road_model",
    "fit_road_model_closed_form",
    "generate_view",
    "homography_from_pose",
    "pose_ranges",
    "road_energy",
    "road_pixels",
    "rotation_from_angles",
    "valid_column_ranges",
    "virtual_homography",
    "virtual_view",
]
