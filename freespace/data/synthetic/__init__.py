"""The built-in procedural stereo road scene renderer (a SYN-Stereo-like dataset made on the spot).

``render_sample(i, seed)`` returns one :class:`StereoSample` in memory; ``render_view(frame, config, pose)``
the same frame from a moved left camera (the truth of a virtual view); ``write_dataset`` writes a
KITTI-road tree (``freespace synth``). NumPy + OpenCV only.
"""

from freespace.data.synthetic.dataset import format_kitti_calib, write_dataset, write_sample
from freespace.data.synthetic.render import (
    StereoSample,
    ViewRender,
    kitti_calibration,
    render_frame,
    render_sample,
    render_view,
)
from freespace.data.synthetic.scene import CATEGORIES, WEATHERS, SynthConfig, sample_frame, sample_scenario

__all__ = ["CATEGORIES", "WEATHERS", "StereoSample", "SynthConfig", "kitti_calibration", "render_frame",
           "render_sample", "render_view", "ViewRender", "sample_frame", "sample_scenario", "format_kitti_calib",
           "write_dataset", "write_sample"]
