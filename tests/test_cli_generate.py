"""`freespace generate`: one pair, a dataset (resumable, bad frames reported), user mistakes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.io.codecs import read_image, road_label_to_kitti, write_disparity, write_image

from helpers import synthetic_pair


@pytest.fixture
def pair_files(tmp_path: Path) -> dict[str, Path]:
    left, right, label, disp = synthetic_pair()
    files = {"left": tmp_path / "L.png", "right": tmp_path / "R.png", "gt": tmp_path / "gt.png",
             "disp": tmp_path / "D.png"}
    write_image(files["left"], left)
    write_image(files["right"], right)
    write_image(files["gt"], road_label_to_kitti(label))
    write_disparity(files["disp"], disp)
    return files


def _pair_args(f: dict[str, Path], out: Path, *extra: str) -> list[str]:
    return ["generate", "--reference", str(f["left"]), "--target", str(f["right"]), "--road-mask", str(f["gt"]),
            "--out", str(out), *extra]


def test_one_pair_with_disparity(pair_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out, js = tmp_path / "G.png", tmp_path / "M.json"
    assert main(_pair_args(pair_files, out, "--disparity", str(pair_files["disp"]), "--model-json", str(js))) == 0
    model = json.loads(js.read_text())
    assert {"roll_deg", "kappa_hat", "kappa", "affine", "homography", "num_inliers", "rms_px"} <= set(model)
    assert model["roll_deg"] == pytest.approx(1.0, abs=0.01)
    assert model["disparity_source"] == "file"
    generated, left = read_image(out).astype(float), read_image(pair_files["left"]).astype(float)
    right = read_image(pair_files["right"]).astype(float)
    road = read_image(pair_files["gt"])[:, :, 2] > 0
    # the right image was itself made by a bilinear warp: two resamplings of a noise texture remain
    assert np.abs(generated - left)[road].mean() < 0.15 * np.abs(right - left)[road].mean()
    assert "roll" in capsys.readouterr().out


def test_one_pair_with_sgbm(pair_files: dict[str, Path], tmp_path: Path) -> None:
    js = tmp_path / "M.json"
    assert main(_pair_args(pair_files, tmp_path / "G.png", "--model-json", str(js))) == 0
    model = json.loads(js.read_text())
    assert model["disparity_source"] == "sgbm"
    # SGBM's sub-pixel noise on this 320×160 pair: over 24 pairs (12 textures, roll 1° and −2°) the fitted
    # roll is off by 0.09° on average and 0.26° at most (0.14° and 0.32° before the matcher padded the pair)
    assert model["roll_deg"] == pytest.approx(1.0, abs=0.3)


def _run(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "freespace.cli", *args], capture_output=True, text=True,
                          env={**os.environ, "PYTHONWARNINGS": "ignore"})


@pytest.mark.parametrize("mistake", ["missing_target", "corrupt_target", "sizes", "disp_size", "empty_mask",
                                     "tiny_mask", "invalid_disp", "bad_suffix", "no_pair", "both_modes"])
def test_user_mistakes_exit_2_without_output(mistake: str, pair_files: dict[str, Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    f = dict(pair_files)
    out = tmp_path / "G.png"
    extra: list[str] = ["--disparity", str(f["disp"])]
    if mistake == "missing_target":
        f["right"] = tmp_path / "missing.png"
    elif mistake == "corrupt_target":
        f["right"] = tmp_path / "corrupt.png"
        f["right"].write_bytes(b"\x89PNG\r\n\x1a\nbroken")
    elif mistake == "sizes":
        f["right"] = tmp_path / "small.png"
        write_image(f["right"], np.zeros((100, 320, 3), np.uint8))
    elif mistake == "disp_size":
        write_disparity(tmp_path / "d2.npy", np.ones((160, 300), np.float32))
        extra = ["--disparity", str(tmp_path / "d2.npy")]
    elif mistake == "empty_mask":
        f["gt"] = tmp_path / "empty.png"
        write_image(f["gt"], np.zeros((160, 320), np.uint8))
    elif mistake == "tiny_mask":
        f["gt"] = tmp_path / "tiny.png"
        m = np.zeros((160, 320), np.uint8)
        m[150, 100:110] = 255
        write_image(f["gt"], m)
    elif mistake == "invalid_disp":
        write_disparity(tmp_path / "nan.npy", np.full((160, 320), np.nan, np.float32))
        extra = ["--disparity", str(tmp_path / "nan.npy")]
    elif mistake == "bad_suffix":
        out = tmp_path / "G.txt"
    args = _pair_args(f, out, *extra)
    if mistake == "no_pair":
        args = ["generate", "--reference", str(f["left"]), "--out", str(out)]
    elif mistake == "both_modes":
        args += ["--dataset", "kitti", "--root", str(tmp_path)]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("freespace: error: ") and "\n" not in err and "Traceback" not in err
    assert not out.exists()
    assert not list(tmp_path.glob(".*.tmp"))


def test_process_reports_one_line_and_never_imports_torch(pair_files: dict[str, Path], tmp_path: Path) -> None:
    res = _run(_pair_args(pair_files, tmp_path / "G.png", "--disparity", str(tmp_path / "nope.png")))
    assert res.returncode == 2
    assert res.stderr.strip().count("\n") == 0 and "disparity not found" in res.stderr
    code = ("import sys, freespace.cli, freespace.datagen.generate, freespace.geometry, freespace.data.kitti_road;"
            "freespace.cli.main(sys.argv[1:]); print('torch' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code, *_pair_args(pair_files, tmp_path / "G.png")],
                         capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.strip().endswith("False")


# --- dataset mode ------------------------------------------------------------------------------------

def _kitti_tree(root: Path, n: int = 4, with_disparity: bool = True) -> list[str]:
    names = []
    for i in range(n):
        cat = ("um", "umm", "uu")[i % 3]
        name = f"{cat}_{i:06d}"
        left, right, label, disp = synthetic_pair(roll_deg=0.5 * i, seed=i)
        write_image(root / "data_road/training/image_2" / f"{name}.png", left)
        write_image(root / "data_road/training/gt_image_2" / f"{cat}_road_{i:06d}.png", road_label_to_kitti(label))
        write_image(root / "data_road_right/training/image_3" / f"{name}.png", right)
        if with_disparity:
            write_disparity(root / "data_road/training/disparity" / f"{name}.png", disp)
        names.append(name)
    return names


def test_dataset_resumable_with_bad_frames(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root, out = tmp_path / "kitti", tmp_path / "out"
    names = _kitti_tree(root, n=5)
    gt_bad = root / "data_road/training/gt_image_2/umm_road_000001.png"
    good_gt = gt_bad.read_bytes()
    gt_bad.write_bytes(b"corrupt")
    (root / "data_road_right/training/image_3/uu_000002.png").unlink()
    args = ["generate", "--dataset", "kitti", "--root", str(root), "--out", str(out)]
    assert main(args) == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["generated"] == 3 and set(summary["failed"]) == {"umm_000001", "uu_000002"}
    assert "cannot decode road label" in summary["failed"]["umm_000001"]
    assert "missing right image" in summary["failed"]["uu_000002"]
    for name in ("um_000000", "um_000003", "umm_000004"):
        assert (out / f"{name}.png").is_file()
        report = json.loads((out / "reports" / f"{name}.json").read_text())
        assert report["roll_deg"] == pytest.approx(0.5 * names.index(name), abs=0.01)
        assert report["num_inliers"] > 0 and "total" in report["seconds"]
    assert not (out / "umm_000001.png").exists()
    rows = (out / "report.csv").read_text().splitlines()
    assert len(rows) == 6 and rows[0].startswith("frame,status,roll_deg")
    assert "failed" in capsys.readouterr().out
    # fix the bad label: the rerun only does the missing frames
    gt_bad.write_bytes(good_gt)
    before = (out / "um_000000.png").stat().st_mtime_ns
    assert main(args) == 1  # uu_000002 still has no right image
    summary = json.loads((out / "summary.json").read_text())
    assert summary["generated"] == 1 and summary["skipped"] == 3 and list(summary["failed"]) == ["uu_000002"]
    assert (out / "um_000000.png").stat().st_mtime_ns == before
    # a folder whose settings an earlier version recorded as "disparity" (now "disparity_source") is the same
    for path in [out / "settings.json", *(out / "reports").glob("*.json")]:
        path.write_text(path.read_text().replace('"disparity_source"', '"disparity"'))
    assert '"disparity"' in (out / "settings.json").read_text()
    assert main(args) == 1
    assert json.loads((out / "summary.json").read_text())["skipped"] == 4
    assert (out / "um_000000.png").stat().st_mtime_ns == before


def test_dataset_workers_and_sgbm(tmp_path: Path) -> None:
    root = tmp_path / "kitti"
    _kitti_tree(root, n=3, with_disparity=False)
    for workers, out in ((1, tmp_path / "a"), (2, tmp_path / "b")):
        assert main(["generate", "--dataset", "kitti", "--root", str(root), "--out", str(out),
                     "--workers", str(workers)]) == 0
    for name in ("um_000000", "umm_000001", "uu_000002"):
        np.testing.assert_array_equal(read_image(tmp_path / "a" / f"{name}.png"),
                                      read_image(tmp_path / "b" / f"{name}.png"))
        report = json.loads((tmp_path / "b" / "reports" / f"{name}.json").read_text())
        assert report["disparity_source"] == "sgbm"


def test_dataset_shards_are_disjoint_and_cover_every_frame(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root, whole, shared = tmp_path / "kitti", tmp_path / "whole", tmp_path / "shared"
    names = _kitti_tree(root, n=7)
    args = ["generate", "--dataset", "kitti", "--root", str(root)]
    assert main(args + ["--out", str(whole)]) == 0
    by_shard = []
    for k in (1, 2, 3):  # three shards into one folder, as a job array does
        before = {p.stem for p in (shared / "reports").glob("*.json")} if shared.is_dir() else set()
        assert main(args + ["--out", str(shared), "--shard", f"{k}/3"]) == 0
        assert f"of {(3, 2, 2)[k - 1]} frames (shard {k}/3)" in capsys.readouterr().out
        written = {p.stem for p in (shared / "reports").glob("*.json")} - before
        summary = json.loads((shared / f"summary.shard-{k}-of-3.json").read_text())
        rows = (shared / f"report.shard-{k}-of-3.csv").read_text().splitlines()[1:]
        assert summary["shard"] == f"{k}/3" and summary["generated"] == summary["frames"] == len(written)
        assert {r.split(",")[0] for r in rows} == written                # each shard writes only its frames
        by_shard.append(written)
    assert [len(s) for s in by_shard] == [3, 2, 2]
    assert set.union(*by_shard) == set(names) and sum(map(len, by_shard)) == len(names)   # disjoint, covering
    assert sorted(p.name for p in shared.glob("*.png")) == sorted(p.name for p in whole.glob("*.png"))
    for name in names:
        np.testing.assert_array_equal(read_image(shared / f"{name}.png"), read_image(whole / f"{name}.png"))
    assert not (shared / "summary.json").exists()
    settings = json.loads((shared / "settings.json").read_text())
    assert settings == json.loads((whole / "settings.json").read_text()) and "shard" not in settings
    # the settings check still guards the shared folder; an unsharded run then writes the totals
    assert main(args + ["--out", str(shared), "--shard", "1/3", "--inlier-threshold", "2"]) == 2
    assert "other settings (inlier_threshold 1.0 → 2.0)" in capsys.readouterr().err
    assert main(args + ["--out", str(shared)]) == 0
    summary = json.loads((shared / "summary.json").read_text())
    assert summary["frames"] == summary["skipped"] == 7 and summary["generated"] == 0
    # with --overwrite a shard replaces only its own frames; the others' are redone by their next run
    # (every report keeps its settings), never skipped
    assert main(args + ["--out", str(shared), "--shard", "2/3", "--inlier-threshold", "2", "--overwrite"]) == 0
    assert json.loads((shared / "summary.shard-2-of-3.json").read_text())["generated"] == 2
    assert not (shared / "summary.json").exists()                          # the old totals are stale
    assert main(args + ["--out", str(shared), "--inlier-threshold", "2"]) == 0
    summary = json.loads((shared / "summary.json").read_text())
    assert (summary["generated"], summary["skipped"]) == (5, 2)
    assert main(args + ["--out", str(shared), "--shard", "1/0"]) == 2
    assert "K/N with whole numbers" in capsys.readouterr().err


def test_dataset_user_mistakes(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["generate", "--dataset", "kitti", "--root", str(tmp_path / "none"), "--out", str(tmp_path)]) == 2
    assert "dataset root not found" in capsys.readouterr().err
    (tmp_path / "data_road/training/image_2").mkdir(parents=True)
    assert main(["generate", "--dataset", "kitti", "--root", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "no frames found for kitti" in capsys.readouterr().err
    assert main(["generate", "--dataset", "kitti", "--out", str(tmp_path / "o")]) == 2
    assert "--root" in capsys.readouterr().err


def test_unwritable_model_json_leaves_no_image(pair_files: dict[str, Path], tmp_path: Path) -> None:
    (tmp_path / "blocker").write_text("a file, not a folder")
    out = tmp_path / "G.png"
    args = _pair_args(pair_files, out, "--disparity", str(pair_files["disp"]), "--model-json",
                      str(tmp_path / "blocker" / "M.json"))
    assert main(args) == 2
    assert not out.exists()


def test_unusable_inputs_raise_typed_errors() -> None:
    from freespace.datagen.generate import generate_arrays
    from freespace.errors import RoadFitError

    image = np.zeros((40, 60, 3), np.uint8)
    road = np.zeros((40, 60), bool)
    with pytest.raises(RoadFitError, match="marks no road pixel"):
        generate_arrays(image, image, road, np.ones((40, 60), np.float32))
    road[30:, :] = True
    with pytest.raises(RoadFitError, match="no valid value"):
        generate_arrays(image, image, road, np.full((40, 60), np.nan, np.float32))


def test_library_names_parameters_and_the_command_line_names_flags(pair_files: dict[str, Path], tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    from freespace.datagen.generate import FitOptions, generate_pair
    from freespace.errors import InvalidOptionError

    with pytest.raises(InvalidOptionError) as caught:
        generate_pair(pair_files["left"], pair_files["right"], pair_files["gt"], out=tmp_path / "G.txt")
    assert str(caught.value).startswith("out ") and "--" not in str(caught.value)
    with pytest.raises(InvalidOptionError, match="^inlier_threshold must be"):
        FitOptions(inlier_threshold=0).check()
    assert main(_pair_args(pair_files, tmp_path / "G.txt")) == 2
    assert "error: --out " in capsys.readouterr().err
    assert main(_pair_args(pair_files, tmp_path / "G.png", "--inlier-threshold", "0")) == 2
    assert "error: --inlier-threshold must be" in capsys.readouterr().err
    # an output that is an input: both named by their flags
    assert main(_pair_args(pair_files, pair_files["gt"])) == 2
    assert f"--out {pair_files['gt']} is the input --road-mask" in capsys.readouterr().err


@pytest.mark.parametrize(("extra", "message"), [
    (["--calib", "c.txt"], "--calib is for --virtual, not for one pair; leave it out"),
    (["--shard", "1/2", "--workers", "2"], "--shard, --workers are for --dataset, not for one pair; leave them out"),
    (["--virtual", "--calib", "c.txt", "--label-out", "VL.png"], "--target is for one pair, not for --virtual"),
    (["--dataset", "synth", "--root", "."], "--reference, --target, --road-mask are for one pair or --virtual, not "
                                            "for --dataset"),
])
def test_each_mode_refuses_the_options_of_the_others(extra: list[str], message: str, pair_files: dict[str, Path],
                                                     tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(_pair_args(pair_files, tmp_path / "G.png", *extra)) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "G.png").exists()


def test_each_mode_names_what_it_lacks(pair_files: dict[str, Path], tmp_path: Path,
                                       capsys: pytest.CaptureFixture) -> None:
    assert main(["generate", "--reference", str(pair_files["left"]), "--out", str(tmp_path / "G.png")]) == 2
    assert "one pair needs --target, --road-mask (or --dataset and --root" in capsys.readouterr().err
    assert main(["generate", "--virtual", "--reference", str(pair_files["left"]), "--road-mask", str(pair_files["gt"]),
                 "--out", str(tmp_path / "V.png")]) == 2
    assert "--virtual needs --calib, --label-out" in capsys.readouterr().err
    assert main(["generate", "--dataset", "synth", "--out", str(tmp_path / "o")]) == 2
    assert "--dataset needs --root" in capsys.readouterr().err
