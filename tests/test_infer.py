"""Inference and deployment: the devkit's bird's-eye view, evaluate-kitti --bev, predict (checkpoint and
ONNX), export (ONNX, TorchScript), kitti-submit."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.evaluation.bev import BEV_SHAPE, bev_matrix, to_bev
from freespace.io.codecs import read_image, read_road_label, write_image
from freespace.io.kitti import read_kitti_calib

from helpers import TRAINED_FRAMES, shared_path


def _literal_bev_cell(calib: dict, row: int, col: int, shape: tuple[int, int]) -> tuple[int, int] | None:
    """The devkit's formula for one cell, written out in float64 (grid values rounded to float32 first)."""
    x = float(np.float32(-9.975 + 0.05 * col))
    z = float(np.float32(45.975 - 0.05 * row))
    R = np.eye(4)
    R[:3, :3] = calib["R0_rect"]
    T = np.eye(4)
    T[:3] = calib["Tr_cam_to_road"]
    u, v, w = (calib["P2"] @ R @ np.linalg.inv(T))[:, [0, 2, 3]] @ np.array([x, z, 1.0])
    u, v = u / w, v / w
    if 1 <= u <= shape[1] and 1 <= v <= shape[0]:
        return int(np.floor(v)) - 1, int(np.floor(u)) - 1
    return None


@pytest.mark.parametrize("name", ["um_000000", "uu_000001"])
def test_bev_matches_the_devkit_formula(name: str) -> None:
    calib = read_kitti_calib(shared_path("kitti_road_calib", f"{name}.txt"))
    shape = (375, 1242)
    index = np.arange(shape[0] * shape[1], dtype=np.int64).reshape(shape) + 1  # 0 is "outside"
    bev = to_bev(index, calib)
    assert bev.shape == BEV_SHAPE
    rng = np.random.default_rng(0)
    inside = 0
    for row, col in zip(rng.integers(0, 800, 3000), rng.integers(0, 400, 3000)):
        want = _literal_bev_cell(calib, int(row), int(col), shape)
        got = bev[row, col]
        if want is None:
            assert got == 0
        else:
            inside += 1
            assert got == index[want], (row, col)
    assert inside > 1000  # most of the grid is in view
    assert bev_matrix(calib).shape == (3, 3)


def test_bev_of_a_rendered_road_is_the_road_ahead(trained: dict[str, Path]) -> None:
    tr = trained["data"] / "data_road" / "training"
    name = sorted(p.stem for p in (tr / "calib").glob("*.txt"))[0]
    calib = read_kitti_calib(tr / "calib" / f"{name}.txt")
    cat, idx = name.split("_")
    label = read_road_label(tr / "gt_image_2" / f"{cat}_road_{idx}.png")
    bev = to_bev(label.road.astype(np.uint8), calib)
    # the ego lane, 1–2 m either side of the camera, 10–20 m ahead (rows 520–720), is road in the BEV
    assert bev[520:720, 180:220].mean() > 0.9


def test_evaluate_kitti_bev(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    tr = trained["data"] / "data_road" / "training"
    pred = tmp_path / "pred"
    for gt in (tr / "gt_image_2").glob("*.png"):
        write_image(pred / gt.name, (read_road_label(gt).road * 255).astype(np.uint8))
    out = tmp_path / "bev.json"
    assert main(["evaluate-kitti", "--bev", "--calib", str(tr / "calib"), "--gt", str(tr / "gt_image_2"),
                 "--pred", str(pred), "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    assert res["all"]["max_f"] == pytest.approx(1.0, abs=1e-9) and res["all"]["fpr"] == 0.0
    assert res["all"]["images"] == TRAINED_FRAMES and res["all"]["ap"] == pytest.approx(1.0, abs=1e-9)
    assert main(["evaluate-kitti", "--bev", "--gt", str(tr / "gt_image_2"), "--pred", str(pred),
                 "--out", str(tmp_path / "x.json")]) == 2
    assert "--bev needs --calib" in capsys.readouterr().err and not (tmp_path / "x.json").exists()


def test_export_and_predict(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    onnx, ts = tmp_path / "m.onnx", tmp_path / "m.pt"
    assert main(["export", "--checkpoint", str(trained["ckpt"]), "--format", "onnx", "--out", str(onnx)]) == 0
    out = capsys.readouterr().out
    assert "max abs difference to PyTorch" in out and float(out.split("PyTorch ")[1].split()[0]) < 1e-3
    assert main(["export", "--checkpoint", str(trained["ckpt"]), "--format", "torchscript", "--out", str(ts)]) == 0
    assert onnx.stat().st_size > 0 and ts.stat().st_size > 0
    images = trained["data"] / "data_road" / "training" / "image_2"
    a, b = tmp_path / "pa", tmp_path / "pb"
    assert main(["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(images), "--out", str(a),
                 "--no-progress"]) == 0
    assert main(["predict", "--onnx", str(onnx), "--input", str(images), "--out", str(b), "--no-progress"]) == 0
    for img in images.glob("*.png"):
        ca, cb = read_image(a / img.name), read_image(b / img.name)
        assert ca.dtype == np.uint8 and ca.ndim == 2 and ca.shape == read_image(img).shape[:2]
        assert np.abs(ca.astype(int) - cb.astype(int)).max() <= 1
        assert (a / "overlays" / img.name).is_file()
    summary = json.loads((a / "summary.json").read_text())
    assert summary["frames"] == TRAINED_FRAMES and summary["seconds_per_frame"] > 0
    assert summary["model"] == "segnet" and summary["image_size"] == [64, 64]  # the training size (TRAINED_ARGS)
    # one file works too, and gives that file's map of the folder run
    one = sorted(images.glob("*.png"))[3]
    assert main(["predict", "--onnx", str(onnx), "--input", str(one), "--out", str(tmp_path / "one"),
                 "--no-progress"]) == 0
    assert sorted(p.name for p in (tmp_path / "one").glob("*.png")) == [one.name]
    assert np.abs(read_image(tmp_path / "one" / one.name).astype(int) - read_image(b / one.name).astype(int)).max() <= 1
    assert json.loads((tmp_path / "one" / "summary.json").read_text())["frames"] == 1


def test_predict_then_evaluate_kitti_equals_evaluate(trained: dict[str, Path], tmp_path: Path) -> None:
    """Two paths to the same numbers: `predict` + `evaluate-kitti` on its 8-bit maps, and `evaluate`
    (the same predictor, the same confidence conversion, the same evaluator)."""
    tr = trained["data"] / "data_road" / "training"
    pred = tmp_path / "pred"
    assert main(["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(tr / "image_2"), "--out", str(pred),
                 "--batch-size", "1", "--no-progress"]) == 0
    assert main(["evaluate-kitti", "--gt", str(tr / "gt_image_2"), "--pred", str(pred), "--out",
                 str(tmp_path / "kitti.json")]) == 0
    assert main(["evaluate", "--checkpoint", str(trained["ckpt"]), "--dataset", "synth", "--root", str(trained["data"]),
                 "--subset", "all", "--out", str(tmp_path / "eval"), "--no-progress"]) == 0
    kitti = json.loads((tmp_path / "kitti.json").read_text())["all"]
    evaluated = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert kitti["images"] == evaluated["frames"] == TRAINED_FRAMES
    assert evaluated["subset"] == "all" and "split" not in evaluated  # the glossary's word (split: on disk)
    assert kitti["max_f"] == pytest.approx(evaluated["max_f"], abs=1e-12)
    assert kitti["ap"] == pytest.approx(evaluated["ap"], abs=1e-12)
    assert 0.3 < evaluated["max_f"] <= 1 and 0 < evaluated["ap"] <= 1  # better than no road at all (max_f 0)


def test_inference_mistakes(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "m.onnx"
    assert main(["export", "--checkpoint", str(tmp_path / "none.ckpt"), "--format", "onnx", "--out", str(out)]) == 2
    assert "checkpoint not found" in capsys.readouterr().err and not out.exists()
    images = trained["data"] / "data_road" / "training" / "image_2"
    assert main(["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(images), "--batch-size", "0",
                 "--out", str(tmp_path / "p")]) == 2
    assert "--batch-size must be an integer in [1, 1024], got 0" in capsys.readouterr().err \
        and not (tmp_path / "p").exists()
    assert main(["predict", "--checkpoint", str(trained["ckpt"]), "--input", str(tmp_path / "none"), "--out",
                 str(tmp_path / "p")]) == 2
    assert "input not found" in capsys.readouterr().err
    (tmp_path / "bad.onnx").write_bytes(b"junk")
    assert main(["predict", "--onnx", str(tmp_path / "bad.onnx"), "--input", str(images),
                 "--out", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("freespace: error:") and "cannot load" in err and "as an ONNX model" in err
    assert not (tmp_path / "p").exists()


def test_kitti_submit(trained: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = tmp_path / "kitti"
    src = trained["data"] / "data_road" / "training"
    for sub in ("image_2", "calib"):
        shutil.copytree(src / sub, root / "data_road" / "testing" / sub)
    out = tmp_path / "submit"
    assert main(["kitti-submit", "--checkpoint", str(trained["ckpt"]), "--root", str(root), "--out", str(out),
                 "--no-progress"]) == 0
    maps = sorted(out.glob("*_road_*.png"))
    assert len(maps) == TRAINED_FRAMES and read_image(maps[0]).shape == BEV_SHAPE
    with zipfile.ZipFile(out / "submission.zip") as zf:
        assert sorted(zf.namelist()) == [m.name for m in maps]
    bev = read_image(maps[0])
    assert bev.dtype == np.uint8 and 0 < np.count_nonzero(bev) < bev.size  # the camera's field of view only
    (root / "data_road" / "testing" / "calib" / maps[0].name.replace("_road_", "_").replace(".png", ".txt")).unlink()
    assert main(["kitti-submit", "--checkpoint", str(trained["ckpt"]), "--root", str(root), "--out",
                 str(tmp_path / "s2")]) == 2
    assert "have no calibration" in capsys.readouterr().err and not (tmp_path / "s2").exists()
