"""KITTI raw as a dataset (issue 45 §1 and §5): listing, naming, roots at three levels, calibration, the
Velodyne projection, splits by drive and by time blocks, ``datasets info``/``split``, drives without right
images, and every bad input of the tree.

The eight real pairs of ``../shared/data/kitti_raw`` are used where there (skipped otherwise); the other
tests build tiny trees in ``tmp_path`` with the real calibration of 2011_09_26 (the constants below, checked
against the shared files).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.data import get_dataset
from freespace.data.kitti_raw import KittiRaw
from freespace.data.label_tree import check_label_tree, label_files
from freespace.data.splits import make_block_splits, read_splits
from freespace.errors import CorruptFileError, DatasetError, InputFileError, InvalidOptionError, ShapeMismatchError
from freespace.io.kitti import read_kitti_raw_calib

from helpers import shared_path

DATE = "2011_09_26"
SIZE = (1242, 375)  # S_rect_02 of 2011_09_26: W, H
CAM_TO_CAM = """calib_time: 09-Jan-2012 13:57:47
corner_dist: 9.950000e-02
S_rect_00: 1.242000e+03 3.750000e+02
R_rect_00: 9.999239e-01 9.837760e-03 -7.445048e-03 -9.869795e-03 9.999421e-01 -4.278459e-03 7.402527e-03 4.351614e-03 9.999631e-01
P_rect_00: 7.215377e+02 0.000000e+00 6.095593e+02 0.000000e+00 0.000000e+00 7.215377e+02 1.728540e+02 0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00
S_rect_02: 1.242000e+03 3.750000e+02
R_rect_02: 9.998817e-01 1.511453e-02 -2.841595e-03 -1.511724e-02 9.998853e-01 -9.338510e-04 2.827154e-03 9.766976e-04 9.999955e-01
P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03
S_rect_03: 1.242000e+03 3.750000e+02
P_rect_03: 7.215377e+02 0.000000e+00 6.095593e+02 -3.395242e+02 0.000000e+00 7.215377e+02 1.728540e+02 2.199936e+00 0.000000e+00 0.000000e+00 1.000000e+00 2.729905e-03
"""  # noqa: E501  (KITTI raw's calibration lines as the files have them)
VELO_TO_CAM = """calib_time: 15-Mar-2012 11:37:16
R: 7.533745e-03 -9.999714e-01 -6.166020e-04 1.480249e-02 7.280733e-04 -9.998902e-01 9.998621e-01 7.523790e-03 1.480755e-02
T: -4.069766e-03 -7.631618e-02 -2.717806e-01
delta_f: 0.000000e+00 0.000000e+00
delta_c: 0.000000e+00 0.000000e+00
"""  # noqa: E501  (KITTI raw's calibration lines as the files have them)
CAMERA_HEIGHT = 1.65  # metres of the left colour camera above the road (KITTI's rig)


def _calib_values(text: str) -> dict[str, np.ndarray]:
    return {k.strip(): np.array(v.split(), float) for k, v in (line.split(":", 1) for line in text.splitlines())
            if k.strip() != "calib_time"}


def road_scan(n_side: int = 121, n_depth: int = 145) -> np.ndarray:
    """``float32 N×4`` Velodyne points of a flat road 1.65 m under the left colour camera, 4–40 m ahead and
    ±6 m to the side, found by inverting KITTI's devkit chain (``P_rect_02 · R_rect_00 · [R | T]``) with the
    constants above; plus points behind the car and far to the side, which must land nowhere."""
    cam, velo = _calib_values(CAM_TO_CAM), _calib_values(VELO_TO_CAM)
    P2, R0 = cam["P_rect_02"].reshape(3, 4), cam["R_rect_00"].reshape(3, 3)
    R, T = velo["R"].reshape(3, 3), velo["T"]
    t_left = np.linalg.solve(P2[:, :3], P2[:, 3])  # the left camera's centre offset: P2 = K [I | t]
    x, z = np.meshgrid(np.linspace(-6, 6, n_side), np.linspace(4, 40, n_depth))
    road = np.stack([x.ravel(), np.full(x.size, CAMERA_HEIGHT), z.ravel()], 1)  # left camera frame, y down
    behind = road[:50] * [1, 1, -1]
    side = road[:50] + [200, 0, 0]
    cam2 = np.vstack([road, behind, side])
    rect0 = cam2 - t_left
    cam0 = rect0 @ R0  # R0ᵀ · X
    points = (cam0 - T) @ R  # Rᵀ · (X − T)
    return np.hstack([points, np.full((len(points), 1), 0.3)]).astype("<f4")


def make_drive(root: Path, number: int = 1, frames: int = 3, *, right: bool = True, velodyne: bool = False,
               calib: bool = True, date: str = DATE, first: int = 0) -> Path:
    """A KITTI raw drive under ``root/<date>`` with ``frames`` black frames of 1242×375 (and the day's
    calibration files unless ``calib`` is False); returns the drive folder."""
    day = root / date
    drive = day / f"{date}_drive_{number:04d}_sync"
    day.mkdir(parents=True, exist_ok=True)
    if calib:
        (day / "calib_cam_to_cam.txt").write_text(CAM_TO_CAM)
        (day / "calib_velo_to_cam.txt").write_text(VELO_TO_CAM)
    image = np.zeros((SIZE[1], SIZE[0], 3), np.uint8)
    ok, png = cv2.imencode(".png", image)
    assert ok
    scan = road_scan().tobytes()
    for cam, wanted in (("image_02", True), ("image_03", right)):
        if wanted:
            folder = drive / cam / "data"
            folder.mkdir(parents=True)
            for i in range(first, first + frames):
                (folder / f"{i:010d}.png").write_bytes(png.tobytes())
    if velodyne:
        folder = drive / "velodyne_points" / "data"
        folder.mkdir(parents=True)
        for i in range(first, first + frames):
            (folder / f"{i:010d}.bin").write_bytes(scan)
    return drive


def _tree_state(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(root.rglob("*"))}


def _one_line_error(capsys: pytest.CaptureFixture) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("freespace: error: "), captured.err
    return lines[0]


# --- the eight shared pairs -----------------------------------------------------------------------------

def test_shared_pairs_are_listed_named_and_loaded() -> None:
    root = shared_path("kitti_raw")
    ds = get_dataset("kitti-raw", root)
    assert isinstance(ds, KittiRaw) and len(ds) == 8
    drive = "2011_09_26_drive_0001_sync"
    assert [f.name for f in ds.frames] == [f"{drive}/{i:010d}" for i in range(0, 106, 15)]
    assert {f.scenario for f in ds.frames} == {drive} and {f.category for f in ds.frames} == {DATE}
    assert ds.frames[3].left == root / DATE / drive / "image_02" / "data" / "0000000045.png"
    assert ds.frames[3].right == root / DATE / drive / "image_03" / "data" / "0000000045.png"
    assert ds.index(f"{drive}/0000000045") == 3
    sample = ds.load(3, disparity=False)
    assert sample.left.shape == sample.right.shape == (375, 1242, 3)
    assert sample.name == f"{drive}/0000000045" and sample.label is None
    assert not np.array_equal(sample.left, sample.right)  # two cameras, not one image twice


def test_root_may_be_the_root_a_date_or_a_drive() -> None:
    root = shared_path("kitti_raw")
    names = [f.name for f in get_dataset("kitti-raw", root).frames]
    assert [f.name for f in get_dataset("kitti-raw", root / DATE).frames] == names
    assert [f.name for f in get_dataset("kitti_raw", root / DATE / "2011_09_26_drive_0001_sync").frames] == names


def test_shared_calibration_is_the_constants_here_and_gives_kitti_s_rig() -> None:
    day = shared_path("kitti_raw", DATE)
    for name, text in (("calib_cam_to_cam.txt", CAM_TO_CAM), ("calib_velo_to_cam.txt", VELO_TO_CAM)):
        shared = _calib_values("\n".join(line for line in (day / name).read_text().splitlines() if line.strip()))
        for key, value in _calib_values(text).items():
            np.testing.assert_array_equal(shared[key], value, err_msg=f"{name} {key}")
    ds = get_dataset("kitti-raw", day.parent)
    rig = ds.calibration(ds.frames[0])
    P2, P3 = _calib_values(CAM_TO_CAM)["P_rect_02"].reshape(3, 4), _calib_values(CAM_TO_CAM)["P_rect_03"].reshape(3, 4)
    assert rig.fx == pytest.approx(721.5377) and rig.fy == pytest.approx(721.5377)
    assert (rig.cx, rig.cy) == pytest.approx((609.5593, 172.854))
    assert rig.baseline == pytest.approx(-(P3[0, 3] - P2[0, 3]) / P2[0, 0], abs=2e-3)  # the brief's formula
    assert rig.baseline == pytest.approx(0.5327, abs=1e-3) and rig.road_plane is None  # K⁻¹ of P's 4th columns
    calib = ds.kitti_calib(ds.frames[0])
    assert tuple(calib["S_rect_02"]) == SIZE and calib["Tr_velo_to_cam"].shape == (3, 4)


def test_split_cli_on_the_shared_pairs_by_time_blocks(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = shared_path("kitti_raw")
    out = tmp_path / "splits"
    assert main(["datasets", "split", "--dataset", "kitti-raw", "--root", str(root), "--by", "time",
                 "--fractions", "0.8,0,0.2", "--gap", "1", "--out", str(out)]) == 0
    assert "train 5 val 0 test 2" in capsys.readouterr().out
    names = [f.name for f in get_dataset("kitti-raw", root).frames]
    splits = read_splits(out, known=names)
    assert splits == {"train": names[:5], "val": [], "test": names[6:]}  # 0000000090 is the gap
    assert main(["datasets", "info", "--dataset", "kitti-raw", "--root", str(root), "--no-progress",
                 "--by", "time", "--fractions", "0.8,0,0.2", "--gap", "1"]) == 0
    out_text = capsys.readouterr().out
    assert "8 frames" in out_text and "1242×375 (8)" in out_text and "right 8/8" in out_text
    assert "train/val/test by time blocks: 5/0/2" in out_text and "0 problems" in out_text


# --- the Velodyne projection ------------------------------------------------------------------------------

def test_road_scan_projects_to_the_rig_s_road_plane_disparity(tmp_path: Path) -> None:
    make_drive(tmp_path, frames=1, velodyne=True)
    ds = get_dataset("kitti-raw", tmp_path, disparity_source="lidar")
    sample = ds.load(0)
    assert sample.disparity_source == "lidar" and sample.disparity.shape == (375, 1242)
    rig = sample.calibration
    v, u = np.nonzero(np.isfinite(sample.disparity))
    assert len(v) > 5000  # the road points cover the lower image; those behind or far to the side land nowhere
    assert v.min() > rig.cy  # the road is below the horizon
    # the plane n·X = h (n = (0, 1, 0), h = 1.65 m) seen by the rig: d = fx·B·(v − cy) / (fy·h)
    expected = rig.fx * rig.baseline * (v - rig.cy) / (rig.fy * CAMERA_HEIGHT)
    error = np.abs(sample.disparity[v, u] - expected)
    assert error.max() < 0.5, error.max()  # rounding a point to its pixel moves it at most half a row
    # points behind the car and 200 m to the side land nowhere: the nearest road point is 4 m ahead
    assert np.nanmax(sample.disparity) <= rig.fx * rig.baseline / 4.0 + 0.5
    densified = get_dataset("kitti-raw", tmp_path, disparity_source="lidar", lidar_densify=3).load(0).disparity
    assert np.isfinite(densified).sum() > len(v)


def test_raw_calibration_parser_refuses_what_is_not_kitti_raw(tmp_path: Path) -> None:
    cam, velo = tmp_path / "cam.txt", tmp_path / "velo.txt"
    cam.write_text(CAM_TO_CAM.replace("P_rect_02", "P_rect_2"))
    velo.write_text(VELO_TO_CAM)
    with pytest.raises(CorruptFileError, match="has no P_rect_02 line"):
        read_kitti_raw_calib(cam, velo)
    cam.write_text(CAM_TO_CAM.replace("S_rect_02: 1.242000e+03 3.750000e+02", "S_rect_02: 1.242000e+03"))
    with pytest.raises(CorruptFileError, match="S_rect_02 has 1 numbers"):
        read_kitti_raw_calib(cam, velo)
    cam.write_text(CAM_TO_CAM)
    velo.write_text(VELO_TO_CAM.replace("T:", "X:"))
    with pytest.raises(CorruptFileError, match=f"{velo}.*no T line"):
        read_kitti_raw_calib(cam, velo)
    calib = read_kitti_raw_calib(cam)  # without the Velodyne file: the cameras alone
    assert "Tr_velo_to_cam" not in calib and calib["P2"].shape == calib["P3"].shape == (3, 4)


# --- splits ---------------------------------------------------------------------------------------------

def test_splits_by_drive_never_separate_a_drive(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    for number in (1, 2, 5, 9, 11):
        make_drive(tmp_path / "raw", number, frames=2, right=False)
    out = tmp_path / "splits"
    assert main(["datasets", "split", "--dataset", "kitti-raw", "--root", str(tmp_path / "raw"),
                 "--out", str(out)]) == 0
    splits = read_splits(out)
    assert sum(len(v) for v in splits.values()) == 10 and all(splits.values())
    drives = {k: {n.split("/")[0] for n in v} for k, v in splits.items()}
    assert not (drives["train"] & drives["val"]) and not (drives["train"] & drives["test"]) \
        and not (drives["val"] & drives["test"])


def test_time_blocks_are_contiguous_per_drive_with_the_gap() -> None:
    frames = [(f"d{d}/{i:010d}", f"d{d}") for d in (1, 2) for i in range(20 + 10 * d)]
    splits = make_block_splits(frames, (0.6, 0.2, 0.2), gap=2)
    for d, n in ((1, 30), (2, 40)):
        index = {k: [int(name.split("/")[1]) for name in v if name.startswith(f"d{d}/")] for k, v in splits.items()}
        train, val, test = index["train"], index["val"], index["test"]
        for block in (train, val, test):  # contiguous: one block each, no interleaving
            assert block == list(range(block[0], block[-1] + 1))
        assert train[0] == 0 and test[-1] == n - 1
        assert val[0] - train[-1] == 3 and test[0] - val[-1] == 3  # two frames of gap between blocks
        assert len(test) == round(0.2 * n) and len(val) == round(0.2 * n) - 2
    assert make_block_splits(frames, "0.8,0,0.2")["val"] == []
    with pytest.raises(DatasetError, match="scenario d1 has 30 frames: too few"):
        make_block_splits(frames, (0.6, 0.2, 0.2), gap=6)
    with pytest.raises(InvalidOptionError, match="fractions"):
        make_block_splits(frames, (0.5, 0.2, 0.2))
    with pytest.raises(InvalidOptionError, match="gap"):
        make_block_splits(frames, gap=-1)


def test_split_options_are_refused_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    make_drive(tmp_path / "raw", frames=3)
    for extra, message in ((["--gap", "2"], "--gap is for --by time"),
                           (["--by", "time", "--fractions", "0.9,0.2"], "--fractions must be three numbers"),
                           (["--by", "time", "--gap", "-1"], "--gap must be an integer in [0, ")):
        assert main(["datasets", "split", "--dataset", "kitti-raw", "--root", str(tmp_path / "raw"), "--out",
                     str(tmp_path / "s"), *extra]) == 2
        assert message in _one_line_error(capsys)
        assert main(["datasets", "info", "--dataset", "kitti-raw", "--root", str(tmp_path / "raw"), "--no-progress",
                     *extra]) == 2
        assert message in _one_line_error(capsys)
    assert not (tmp_path / "s").exists()


# --- drives without right images (LiDAR only) -------------------------------------------------------------

def test_a_drive_without_image_03_loads_and_labels_from_lidar(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "raw"
    make_drive(root, number=7, frames=2, right=False, velodyne=True)
    ds = get_dataset("kitti-raw", root, disparity_source="lidar")
    sample = ds.load(1)
    assert sample.right is None and sample.disparity_source == "lidar" and np.isfinite(sample.disparity).any()
    auto = get_dataset("kitti-raw", root).load(0)  # auto never takes a scan; no right image: no disparity
    assert auto.right is None and auto.disparity is None and auto.disparity_source == "none"
    out = tmp_path / "labels"
    assert main(["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--disparity-source", "lidar",
                 "--out", str(out)]) == 0
    assert "2 labelled" in capsys.readouterr().out
    frames = [f"{DATE}_drive_0007_sync/0000000000", f"{DATE}_drive_0007_sync/0000000001"]
    assert sorted(p.relative_to(out).as_posix() for p in out.glob(f"{DATE}*/*.png")) == [f"{f}.png" for f in frames]
    # the confidences lie apart, as OUT/confidence/<frame>.png, so that the tree trains as it is (once they
    # were written into OUT/<drive>/confidence/, which training refused as labels that are no labels)
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("confidence/**/*.png")) == [
        f"confidence/{f}.png" for f in frames]
    assert sorted(label_files(out)) == frames
    check_label_tree(out, "kitti-raw", root, None)


@pytest.mark.parametrize("command", [["generate"], ["autolabel", "--disparity-source", "sgbm"]])
def test_commands_needing_the_right_image_refuse_a_drive_without_it(command: list[str], tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "raw"
    make_drive(root, number=1, frames=2)
    make_drive(root, number=2, frames=2, right=False)
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("earlier work")
    before = _tree_state(tmp_path)
    assert main([*command, "--dataset", "kitti-raw", "--root", str(root), "--out", str(out)]) == 2
    line = _one_line_error(capsys)
    assert f"{root / DATE / f'{DATE}_drive_0002_sync' / 'image_03' / 'data'} not found" in line
    assert "has no right images" in line and "--root" in line
    assert _tree_state(tmp_path) == before  # nothing written, nothing lost
    code = main([*command, "--dataset", "kitti-raw", "--root", str(root / DATE / f"{DATE}_drive_0001_sync"),
                 "--out", str(tmp_path / "other"), "--cache-dir", str(tmp_path / "cache")])
    err = capsys.readouterr().err
    assert "has no right images" not in err  # the drive with image_03 is accepted; generate then asks for labels
    assert code in (0, 1) or (command == ["generate"] and code == 2 and "give --labels TREE" in err)


# --- §5: bad input, one line naming the file ----------------------------------------------------------------

def _refused(capsys: pytest.CaptureFixture, tmp_path: Path, root: Path, *extra: str) -> str:
    """Run autolabel on ``root`` (expecting a refusal) and return its one line; nothing may be written."""
    before = _tree_state(tmp_path)
    assert main(["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--out", str(tmp_path / "out"),
                 *extra]) == 2
    assert _tree_state(tmp_path) == before and not (tmp_path / "out").exists()
    return _one_line_error(capsys)


def test_missing_calibration_files_are_named(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "raw"
    make_drive(root, frames=2, velodyne=True)
    (root / DATE / "calib_cam_to_cam.txt").unlink()
    line = _refused(capsys, tmp_path, root)
    assert f"{root / DATE / 'calib_cam_to_cam.txt'} not found" in line and "calib.zip" in line
    with pytest.raises(InputFileError, match="calib_cam_to_cam.txt not found"):
        get_dataset("kitti-raw", root / DATE / f"{DATE}_drive_0001_sync")
    (root / DATE / "calib_cam_to_cam.txt").write_text(CAM_TO_CAM)
    (root / DATE / "calib_velo_to_cam.txt").unlink()
    line = _refused(capsys, tmp_path, root, "--disparity-source", "lidar")
    assert f"{root / DATE / 'calib_velo_to_cam.txt'} not found" in line and "Velodyne" in line
    assert len(get_dataset("kitti-raw", root)) == 2  # the cameras alone need no Velodyne calibration


def test_left_and_right_lists_that_differ_name_the_first_missing_frame(tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "raw"
    drive = make_drive(root, frames=5)
    for i in (3, 1):
        (drive / "image_03" / "data" / f"{i:010d}.png").unlink()
    line = _refused(capsys, tmp_path, root)
    assert f"{drive / 'image_03' / 'data' / '0000000001.png'} not found" in line
    assert "2 left images" in line and "first 0000000001" in line
    with pytest.raises(DatasetError, match="0000000001.png not found"):
        get_dataset("kitti-raw", drive, disparity_source="none")


def test_a_velodyne_file_of_a_bad_size_is_named(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "raw"
    drive = make_drive(root, frames=3, velodyne=True)
    bad = drive / "velodyne_points" / "data" / "0000000002.bin"
    bad.write_bytes(bad.read_bytes()[:-5])
    line = _refused(capsys, tmp_path, root, "--disparity-source", "lidar")
    assert f"Velodyne scan {bad} has {bad.stat().st_size} bytes" in line and "multiple of 16" in line
    with pytest.raises(CorruptFileError, match="0000000002.bin"):
        get_dataset("kitti-raw", root, disparity_source="lidar")
    assert len(get_dataset("kitti-raw", root)) == 3  # without the scans the drive is usable


def test_an_image_of_another_size_than_s_rect_02_is_named(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "raw"
    drive = make_drive(root, frames=3)
    wrong = drive / "image_03" / "data" / "0000000001.png"
    cv2.imwrite(str(wrong), np.zeros((512, 1392, 3), np.uint8))  # an unrectified (_extract) frame
    line = _refused(capsys, tmp_path, root)
    assert f"{wrong} is 1392×512" in line and "S_rect_02 1242×375" in line and "_sync" in line
    with pytest.raises(ShapeMismatchError, match="is 1392×512"):
        get_dataset("kitti-raw", root)
    lenient = get_dataset("kitti-raw", root, strict=False)  # opened as datasets info opens it: load still refuses
    with pytest.raises(ShapeMismatchError, match="S_rect_02"):
        lenient.load(1, disparity=False)


def test_an_empty_drive_folder_is_named(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "raw"
    make_drive(root, number=1, frames=2)
    empty = root / DATE / f"{DATE}_drive_0002_sync"
    (empty / "image_02" / "data").mkdir(parents=True)
    line = _refused(capsys, tmp_path, root)
    assert f"drive folder {empty} holds no left image" in line
    assert main(["autolabel", "--dataset", "kitti-raw", "--root", str(tmp_path / "nothing"), "--out",
                 str(tmp_path / "out")]) == 2
    assert "dataset root not found" in _one_line_error(capsys)
    (tmp_path / "nothing").mkdir()
    with pytest.raises(InputFileError, match="no KITTI raw drive under"):
        get_dataset("kitti-raw", tmp_path / "nothing")


def test_datasets_info_lists_every_problem_of_the_tree(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "raw"
    good = make_drive(root, number=1, frames=4, velodyne=True)
    (good / "image_03" / "data" / "0000000002.png").unlink()
    bad_scan = good / "velodyne_points" / "data" / "0000000003.bin"
    bad_scan.write_bytes(b"\0" * 17)
    (root / DATE / f"{DATE}_drive_0003_sync").mkdir()
    make_drive(root, number=1, frames=2, date="2011_09_28", calib=False)
    before = _tree_state(tmp_path)
    assert main(["datasets", "info", "--dataset", "kitti-raw", "--root", str(root), "--no-progress"]) == 1
    out = capsys.readouterr().out
    assert _tree_state(tmp_path) == before
    assert "6 frames" in out and "2 scenarios" in out and "right 5/6" in out and "velodyne 4/6" in out
    assert f"{good / 'image_03' / 'data' / '0000000002.png'} not found" in out
    assert f"Velodyne scan {bad_scan} has 17 bytes" in out
    assert f"drive folder {root / DATE / f'{DATE}_drive_0003_sync'} holds no left image" in out
    assert f"{root / '2011_09_28' / 'calib_cam_to_cam.txt'} not found" in out
    assert "5 problems" in out  # the four above and the by-scenario split that leaves val or test empty
    with pytest.raises(DatasetError, match=r"\(3 more problems: `freespace datasets info"):
        get_dataset("kitti-raw", root, disparity_source="lidar")


def test_a_drive_without_image_03_gets_virtual_views_from_its_scan_when_asked(tmp_path: Path,
                                                                               capsys: pytest.CaptureFixture) -> None:
    """The road planes of the virtual views: a frame with no right image has no disparity under ``auto`` (a scan is
    never taken unasked), and the reason it gets no views says which source would fit one."""
    from freespace.data.label_tree import apply_label_tree
    from freespace.engine.data import _road_planes

    root, out = tmp_path / "raw", tmp_path / "labels"
    make_drive(root, number=7, frames=2, right=False, velodyne=True)
    assert main(["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--disparity-source", "lidar",
                 "--out", str(out)]) == 0
    names = [f"{DATE}_drive_0007_sync/000000000{i}" for i in range(2)]
    shift = ((-0.5, 0.5), (-0.2, 0.2), (0.0, 0.0))
    auto = apply_label_tree(get_dataset("kitti-raw", root), out, names)
    with pytest.raises(DatasetError, match=r"no disparity .*LiDAR scan: (--)?disparity.source lidar or fused fits one"):
        _road_planes(auto, [0, 1], shift)
    lidar = apply_label_tree(get_dataset("kitti-raw", root, disparity_source="lidar"), out, names)
    planes = _road_planes(lidar, [0, 1], shift)
    assert sorted(planes) == [0, 1] and all(1.4 < plane.height < 1.9 for _, plane in planes.values())
