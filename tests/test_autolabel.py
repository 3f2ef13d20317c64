"""`freespace autolabel`: road labels from disparity alone — flat roads, curbs, missing disparity, rendered
frames against their truth, real KITTI frames against human labels, the one-image and dataset commands
(resumable, sharded, settings recorded), user mistakes, `train --labels`' dataset view, no torch."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.data.label_tree import apply_label_tree
from freespace.data.registry import get_dataset
from freespace.data.synthetic import SynthConfig, render_sample, write_dataset
from freespace.datagen.autolabel import AutolabelOptions, autolabel
from freespace.errors import DatasetError, InputFileError, InvalidOptionError, RoadFitError
from freespace.io.codecs import read_disparity, read_image, read_road_label, write_disparity

from helpers import plane_disparity, shared_path

SHAPE = (240, 320)


def _flat_road(roll_deg: float = 1.0, kappa_hat: float = 0.3, kappa: float = -100.0) -> np.ndarray:
    """Exact disparity of a flat road filling the image below its horizon; NaN above (the sky)."""
    d = plane_disparity(SHAPE, roll_deg, kappa_hat, kappa)
    d[d <= 0] = np.nan
    return d


def _scores(auto, truth) -> tuple[float, float, float]:
    covered = auto.valid & truth.valid
    tp = np.count_nonzero(auto.road & truth.road & covered)
    precision = tp / np.count_nonzero(auto.road & covered)
    recall = tp / np.count_nonzero(truth.road & covered)
    return precision, recall, np.count_nonzero(covered) / np.count_nonzero(truth.valid)


# --- the labeller -------------------------------------------------------------------------------------


def test_flat_road_is_road_below_the_horizon_and_non_road_well_above() -> None:
    d = _flat_road()
    result = autolabel(d)
    m = result.model.disparity(SHAPE)
    label = result.label
    assert result.model.roll_deg == pytest.approx(1.0, abs=1e-3)
    assert label.road[m > 2].all() and label.valid[m > 2].all()     # 2 px ≈ 7 rows below the horizon
    assert not label.road[m <= 0].any()
    assert label.valid[m < -2].all()                                 # the sky above the horizon band: non-road
    assert not label.valid[np.abs(m) < 1].any()                      # the band itself: don't care
    assert (result.confidence[~label.valid] == 0).all() and (result.confidence[label.valid] >= 0.5).all()


def test_curb_and_obstacle_are_non_road() -> None:
    """A sidewalk 15 cm above the road on the right, a box standing on the road: non-road near the camera."""
    baseline = 0.5
    d = _flat_road(roll_deg=0.0)
    m = d.copy()
    height = baseline / 0.3                                          # H = B/ϰ
    h, w = SHAPE
    d[:, 3 * w // 4:] *= height / (height - 0.15)                    # the raised sidewalk
    d[150:200, 100:140] = m[200, 120]                                # an upright box: one depth
    label = autolabel(d, baseline=baseline).label
    near = np.nan_to_num(m) > 20
    sidewalk = np.zeros(SHAPE, bool)
    sidewalk[:, 3 * w // 4 + 3:] = True
    assert label.valid[near & sidewalk].all() and not label.road[near & sidewalk].any()
    assert not label.road[150:195, 103:137].any() and label.valid[150:195, 103:137].all()
    assert label.road[near & ~sidewalk].mean() > 0.9


def test_missing_disparity_is_dont_care_and_small_holes_are_filled() -> None:
    d = _flat_road()
    d[120:, :40] = np.nan                                            # a matcher's empty left margin
    d[200:203, 150:153] = np.nan                                     # a small hole in the road
    label = autolabel(d).label
    assert not label.valid[125:, :35].any()
    assert label.road[200:203, 150:153].all()


def test_rendered_frames_agree_with_their_truth() -> None:
    """The renderer's exact disparity, six frames of two drives; measured precision 99.0 %, recall 99.7 %,
    coverage 97.6 % on these (bench/autolabel.py: 40 frames)."""
    config = SynthConfig(width=320, height=240, frames_per_scenario=5)
    counts = np.zeros(3)
    for i in (0, 2, 4, 5, 7, 9):
        s = render_sample(i, 0, config)
        auto = autolabel(s.disparity, baseline=s.calibration.baseline).label
        covered = auto.valid & s.label.valid
        counts += [np.count_nonzero(auto.road & s.label.road & covered), np.count_nonzero(auto.road & covered),
                   np.count_nonzero(s.label.road & covered)]
        assert np.count_nonzero(covered) >= 0.9 * s.label.valid.sum()
    assert counts[0] / counts[1] >= 0.97
    assert counts[0] / counts[2] >= 0.97


def test_no_road_plane_is_a_road_fit_error() -> None:
    with pytest.raises(RoadFitError, match="lower half"):
        autolabel(np.full(SHAPE, np.nan, np.float32))
    wall = np.full(SHAPE, 5.0, np.float32) + np.arange(SHAPE[1], dtype=np.float32)[None, :] * 0.01
    with pytest.raises(RoadFitError):
        autolabel(wall)


@pytest.mark.parametrize("options", [AutolabelOptions(curb_height=0), AutolabelOptions(band=1.0),
                                     AutolabelOptions(window=4), AutolabelOptions(noise=-1.0)])
def test_bad_options_are_refused(options: AutolabelOptions) -> None:
    with pytest.raises(InvalidOptionError):
        autolabel(_flat_road(), options=options)


def test_real_kitti_frames_against_human_labels() -> None:
    """LiDAR disparity (disp_occ_0) of the two KITTI stereo 2015 frames; measured F 95.2 / 91.2 %."""
    root = shared_path("kitti_stereo_2015")
    for name in ("000000_10", "000001_10"):
        truth = read_road_label(root / "road_mask" / f"{name}.png")
        auto = autolabel(read_disparity(root / "disp_occ_0" / f"{name}.png"), baseline=0.54).label
        precision, recall, coverage = _scores(auto, truth)
        assert 2 * precision * recall / (precision + recall) >= 0.88
        assert coverage >= 0.7


# --- the command --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("syn")
    write_dataset(root, 4, seed=0, config=SynthConfig(width=320, height=240, frames_per_scenario=2))
    return root


def _frame(root: Path, name: str = "um_000000") -> dict[str, Path]:
    frame = get_dataset("synth", root).frames[0]
    return {"left": frame.left, "right": frame.right, "disp": frame.disparity, "calib": frame.calib}


def test_one_image_from_disparity_and_from_the_pair(rendered: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    f = _frame(rendered)
    out, conf, js = tmp_path / "L.png", tmp_path / "C.png", tmp_path / "M.json"
    assert main(["autolabel", "--reference", str(f["left"]), "--disparity", str(f["disp"]), "--out", str(out),
                 "--confidence", str(conf), "--calib", str(f["calib"]), "--model-json", str(js)]) == 0
    label, confidence = read_road_label(out), read_image(conf)
    assert label.shape == confidence.shape == (240, 320)
    assert label.road.any() and (~label.valid).any() and (label.valid & ~label.road).any()
    assert (confidence[~label.valid] == 0).all() and (confidence[label.valid] >= 127).all()
    report = json.loads(js.read_text())
    assert report["disparity_source"] == "file" and 0.8 < report["coverage"] <= 1
    assert "road" in capsys.readouterr().out
    sgbm = tmp_path / "S.png"
    assert main(["autolabel", "--reference", str(f["left"]), "--target", str(f["right"]), "--out", str(sgbm),
                 "--max-disparity", "64"]) == 0
    assert read_road_label(sgbm).road.any()


def _one_line_error(args: list[str], capsys: pytest.CaptureFixture, match: str) -> None:
    capsys.readouterr()
    assert main(["-q", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and match in err


def test_user_mistakes_end_in_one_line_and_write_nothing(rendered: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture) -> None:
    f = _frame(rendered)
    out = tmp_path / "L.png"
    ref = ["autolabel", "--reference", str(f["left"])]
    _one_line_error(ref + ["--out", str(out)], capsys, "--target")
    _one_line_error(ref + ["--target", str(f["right"]), "--disparity", str(f["disp"]), "--out", str(out)], capsys,
                    "one of them")
    _one_line_error(ref + ["--disparity", str(f["disp"]), "--out", str(tmp_path / "L.jpg")], capsys, ".png")
    _one_line_error(ref + ["--disparity", str(f["disp"]), "--out", str(f["left"])], capsys, "overwrite")
    _one_line_error(ref + ["--disparity", str(tmp_path / "none.png"), "--out", str(out)], capsys, "not found")
    small = tmp_path / "small.png"
    write_disparity(small, np.ones((10, 10), np.float32))
    _one_line_error(ref + ["--disparity", str(small), "--out", str(out)], capsys, "10×10")
    _one_line_error(ref + ["--disparity", str(f["disp"]), "--out", str(out), "--calib", str(f["calib"]),
                           "--baseline", "0.5"], capsys, "not both")
    _one_line_error(ref + ["--disparity", str(f["disp"]), "--out", str(out), "--shard", "1/2"], capsys, "--dataset")
    _one_line_error(["autolabel", "--dataset", "synth", "--root", str(rendered), "--out", str(tmp_path / "o"),
                     "--disparity", str(f["disp"])], capsys, "one image")
    _one_line_error(["autolabel", "--dataset", "synth", "--root", str(tmp_path / "nowhere"), "--out",
                     str(tmp_path / "o")], capsys, "not found")
    assert not out.exists() and not (tmp_path / "o").exists()


def test_dataset_tree_resumes_refuses_other_settings_and_shards(rendered: Path, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "labels"
    args = ["autolabel", "--dataset", "synth", "--root", str(rendered), "--out", str(out)]
    assert main(args) == 0
    names = [f.name for f in get_dataset("synth", rendered).frames]
    for name in names:
        assert read_road_label(out / f"{name}.png").road.any()
        assert (out / "confidence" / f"{name}.png").is_file()
        assert json.loads((out / "reports" / f"{name}.json").read_text())["status"] == "done"
    settings = json.loads((out / "settings.json").read_text())
    assert settings["curb_height"] == 0.1
    assert json.loads((out / ".freespace" / "manifest.json").read_text())["command"] == "autolabel"
    capsys.readouterr()
    assert main(args) == 0
    assert "0 labelled, 4 already done" in capsys.readouterr().out
    _one_line_error(args + ["--curb-height", "0.2"], capsys, "other settings")
    assert main(args + ["--curb-height", "0.2", "--overwrite"]) == 0
    assert json.loads((out / "settings.json").read_text())["curb_height"] == 0.2
    sharded = tmp_path / "sharded"
    for k in (1, 2):
        assert main(["autolabel", "--dataset", "synth", "--root", str(rendered), "--out", str(sharded),
                     "--shard", f"{k}/2"]) == 0
    assert sorted(p.stem for p in sharded.glob("*.png")) == sorted(names)
    assert (sharded / "summary.shard-2-of-2.json").is_file()
    # a folder of someone else's files, and one another command wrote, are refused
    other = tmp_path / "other"
    other.mkdir()
    (other / "settings.json").write_text(json.dumps({"dataset": "synth"}))
    _one_line_error(["autolabel", "--dataset", "synth", "--root", str(rendered), "--out", str(other)], capsys,
                    "did not write")
    generated = tmp_path / "generated"
    assert main(["generate", "--dataset", "synth", "--root", str(rendered), "--out", str(generated)]) == 0
    _one_line_error(["autolabel", "--dataset", "synth", "--root", str(rendered), "--out", str(generated)], capsys,
                    "output of freespace generate")


def test_a_tree_labelled_with_the_old_matcher_is_not_resumed(rendered: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture) -> None:
    # SGBM version 2 pads the pair (freespace.geometry.stereo); a tree from version 1 recorded no version
    out = tmp_path / "labels"
    args = ["autolabel", "--dataset", "synth", "--root", str(rendered), "--out", str(out), "--disparity-source",
            "sgbm", "--max-disparity", "64", "--cache-dir", str(tmp_path / "cache")]
    assert main(args) == 0
    settings = json.loads((out / "settings.json").read_text())
    assert settings["sgbm_version"] == 2
    del settings["sgbm_version"]
    (out / "settings.json").write_text(json.dumps(settings))
    _one_line_error(args, capsys, "sgbm_version")
    assert main(args + ["--overwrite"]) == 0
    # a tree whose disparities cannot come from SGBM records no matcher version: with source auto every
    # rendered frame has its disparity file
    exact = tmp_path / "exact"
    assert main(["autolabel", "--dataset", "synth", "--root", str(rendered), "--out", str(exact)]) == 0
    assert "sgbm_version" not in json.loads((exact / "settings.json").read_text())


def test_train_labels_view_reads_the_tree_for_the_named_frames(rendered: Path, tmp_path: Path) -> None:
    out = tmp_path / "labels"
    assert main(["autolabel", "--dataset", "synth", "--root", str(rendered), "--out", str(out)]) == 0
    ds = get_dataset("synth", rendered)
    first, second = ds.frames[0].name, ds.frames[1].name
    view = apply_label_tree(ds, out, [first])
    auto, own = read_road_label(out / f"{first}.png"), ds.load(0, right=False, disparity=False).label
    got = view.load(0, right=False, disparity=False).label
    assert np.array_equal(got.valid, auto.valid) and not np.array_equal(got.valid, own.valid)
    assert np.array_equal(view.load(1, right=False, disparity=False).label.road,
                          ds.load(1, right=False, disparity=False).label.road)  # other frames keep theirs
    (out / f"{second}.png").unlink()
    with pytest.raises(DatasetError, match=second):
        apply_label_tree(ds, out, [second])
    from freespace.engine.config import TrainConfig

    with pytest.raises(InputFileError, match="labels .* not found"):
        TrainConfig(dataset="synth", root=str(rendered), out=str(tmp_path / "run"), labels=str(tmp_path / "no")).check()


def test_autolabel_never_imports_torch() -> None:
    code = ("import sys, freespace.datagen.autolabel, freespace.cli; freespace.cli.build_parser({'autolabel'}); "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_human_share_keeps_the_datasets_labels_on_whole_drives(tmp_path: Path) -> None:
    """X-mix (--human-share P): every frame of round(P · drives) training drives keeps its own label, the
    others read the label tree; the drives depend on the seed only."""
    from freespace.engine.config import TrainConfig
    from freespace.engine.data import _human_drives, prepare_data

    root = tmp_path / "syn"
    write_dataset(root, 20, seed=1, config=SynthConfig(width=160, height=128, frames_per_scenario=2), progress=False)
    labels = tmp_path / "labels"
    assert main(["autolabel", "--dataset", "synth", "--root", str(root), "--out", str(labels)]) == 0
    ds = get_dataset("synth", root)
    config = TrainConfig(dataset="synth", root=str(root), out=str(tmp_path / "run"), model="segnet", seed=4,
                         labels=str(labels), human_share=0.5)
    config.check()
    data = prepare_data(config, tmp_path / "run")
    train = [it.name for it in data["train"]]
    human = _human_drives(ds.frames, train, 0.5, 4)
    drives = {f.name: f.scenario for f in ds.frames}
    assert human and len({drives[n] for n in human}) == round(0.5 * len({drives[n] for n in train}))
    assert all(drives[n] not in {drives[h] for h in human} for n in set(train) - human)  # whole drives
    assert set(data["dataset"].label_files) == {n for n in train if n not in human}
    assert _human_drives(ds.frames, train, 0.5, 4) == human and _human_drives(ds.frames, train, 0.0, 4) == set()
    with pytest.raises(InvalidOptionError, match="give labels too"):
        TrainConfig(dataset="synth", root=str(root), out=str(tmp_path / "r2"), human_share=0.2).check()


def _crowned_street(camber: float, kerb: float, shape: tuple[int, int] = (240, 640)) -> np.ndarray:
    """The disparity of a street seen from 1.5 m (f 700 px, B 0.5 m, principal point (320, 120)): the road
    falls away left of its crown at X = −1 m with the slope ``camber``; a pavement ``kerb`` metres high starts
    at X = 3.5 m."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = (u - 320) / 700, (v - 120) / 700
    with np.errstate(divide="ignore", invalid="ignore"):
        z = 1.5 / y                                            # the level road
        left = (1.5 - camber * 1.0) / (y + camber * x)         # Y = 1.5 + camber·(−1 − X) left of the crown
        z = np.where(x * z < -1.0, left, z)
        pavement = (1.5 - kerb) / y
        z = np.where(x * pavement > 3.5, pavement, z)
        d = 700 * 0.5 / z
    return np.where((y > 0.02) & (d > 0), d, np.nan).astype(np.float32)


def test_a_cambered_street_is_road_and_a_pavement_is_not() -> None:
    from freespace.datagen.labeller import AutolabelOptions, autolabel

    disparity = _crowned_street(camber=0.04, kerb=0.15)
    h, w = disparity.shape
    v, u = np.mgrid[0:h, 0:w]
    x = (u - 320) / 700 * 1.5 / np.maximum((v - 120) / 700, 1e-6)  # X on the level road, metres
    falling = (x < -3.0) & (v > 170)        # the lanes 2 m and more left of the crown: 8 cm and more below the plane
    pavement = (x > 4.0) & (v > 170)
    one_plane = autolabel(disparity, baseline=0.5, options=AutolabelOptions(max_camber_deg=0))
    both = autolabel(disparity, baseline=0.5)
    assert (one_plane.label.road & falling).sum() < 0.5 * falling.sum()   # one plane loses the falling lanes
    assert (both.label.road & falling).sum() > 0.9 * falling.sum()        # a second plane finds them
    assert not (both.label.road & pavement).any()                          # and the pavement stays off the road
    assert not (one_plane.label.road & pavement).any()
