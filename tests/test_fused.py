"""The ``fused`` disparity source: a LiDAR scan and SGBM joined (agreeing pixels keep the scan's value,
disagreeing ones become invalid, a pixel measured once keeps that value), and a frame with one of the two
gets that one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from freespace.data import get_dataset
from freespace.data.disparity import FUSE_TOLERANCE_PX, FUSE_TOLERANCE_REL, fuse_disparities
from freespace.errors import DatasetError

from test_kitti_raw import make_drive


def test_the_rule_pixel_by_pixel() -> None:
    nan = np.nan
    lidar = np.array([[20.0, 20.0, 20.0, 60.0, 60.0, nan, nan]], np.float32)
    sgbm = np.array([[20.9, 21.1, nan, 62.9, 63.1, 7.5, nan]], np.float32)
    fused = fuse_disparities(lidar, sgbm)
    assert fused.dtype == np.float32 and fused.shape == lidar.shape
    # 20 px: 1 px tolerance (0.9 agrees, 1.1 does not); 60 px: 5 % = 3 px (2.9 agrees, 3.1 does not)
    assert FUSE_TOLERANCE_PX == 1.0 and FUSE_TOLERANCE_REL == 0.05
    np.testing.assert_array_equal(fused, np.array([[20.0, nan, 20.0, 60.0, nan, 7.5, nan]], np.float32))
    with pytest.raises(ValueError, match="give maps of one image"):
        fuse_disparities(lidar, sgbm[:, :3])


def test_a_kitti_raw_frame_fuses_its_scan_with_sgbm(tmp_path: Path) -> None:
    drive = make_drive(tmp_path, frames=1, velodyne=True)
    ds = get_dataset("kitti-raw", tmp_path, disparity_source="fused")
    sample = ds.load(0, label=False)
    lidar = get_dataset("kitti-raw", tmp_path, disparity_source="lidar").load(0, label=False).disparity
    sgbm = get_dataset("kitti-raw", tmp_path, disparity_source="sgbm").load(0, label=False).disparity
    assert sample.disparity_source == "fused"
    np.testing.assert_array_equal(sample.disparity, fuse_disparities(lidar, sgbm))
    # the black test images give SGBM nothing, so every fused pixel is the scan's
    assert np.isfinite(sample.disparity).sum() == np.isfinite(lidar).sum() > 1000
    assert drive.is_dir()


def test_one_source_alone_and_none(tmp_path: Path) -> None:
    make_drive(tmp_path / "a", frames=1, velodyne=True, right=False)
    sample = get_dataset("kitti-raw", tmp_path / "a", disparity_source="fused").load(0, label=False)
    assert sample.disparity_source == "lidar"
    make_drive(tmp_path / "b", frames=1)
    sample = get_dataset("kitti-raw", tmp_path / "b", disparity_source="fused").load(0, label=False)
    assert sample.disparity_source == "sgbm"
    make_drive(tmp_path / "c", frames=1, right=False)
    with pytest.raises(DatasetError, match="has a Velodyne scan or a right image"):
        get_dataset("kitti-raw", tmp_path / "c", disparity_source="fused")
