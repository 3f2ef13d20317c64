"""Stereo road datasets.

``base`` (the interface: :class:`FrameRef`, :class:`Sample`, :class:`StereoRoadDataset`), ``disparity``
(disparity sources and the SGBM cache), ``registry`` (layouts by name), the layouts ``kitti_road``
(KITTI road and the renderer's output), ``kitti_raw`` (KITTI raw drives) and ``folder`` (SYNTHIA, CARLA/SYN-Stereo,
generic), ``splits`` (the paper's train/val/test split), ``info`` (counts and the integrity scan), ``synthetic`` (the
built-in renderer) and ``torch_dataset`` (a torch ``Dataset``; the only module here that needs torch, imported on its
own). Importing the package registers every layout.
"""

from freespace.data import folder, kitti_raw, kitti_road  # noqa: F401  (each layout registers itself)
from freespace.data.base import FrameRef, Sample, StereoRoadDataset
from freespace.data.registry import get_dataset, list_datasets, register_dataset

__all__ = ["FrameRef", "Sample", "StereoRoadDataset", "get_dataset", "list_datasets", "register_dataset"]
