"""The real test bench's scoring: label formats, pairing, bootstrap intervals, `freespace evaluate` on a labelled
folder."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.errors import CorruptFileError, DatasetError, InputFileError, InvalidOptionError
from freespace.evaluation.labelled import LabelFormat, bootstrap_intervals, pair_labelled_frames, parse_label_format
from freespace.io.codecs import write_image

from helpers import refused, road_frame, tiny_road_checkpoint

CAMVID = parse_label_format("class-id", "3", "11")


def test_class_ids_road_and_ignore() -> None:
    ids = np.array([[3, 11, 0], [3, 4, 11]], np.uint8)
    label = CAMVID.decode(ids)
    assert label.road.tolist() == [[True, False, False], [True, False, False]]
    assert label.valid.tolist() == [[True, False, True], [True, True, False]]
    two = parse_label_format("class-id", "3,4").decode(ids)
    assert two.road.tolist() == [[True, False, False], [True, True, False]] and two.valid.all()


def test_palette_tolerance_and_ignore() -> None:
    img = np.zeros((1, 4, 3), np.uint8)
    img[0, 0] = (128, 64, 128)          # road
    img[0, 1] = (133, 60, 125)          # road, blended within 8 levels
    img[0, 2] = (150, 64, 128)          # beyond the tolerance: not road
    img[0, 3] = (0, 0, 0)               # ignored
    fmt = parse_label_format("palette", "128,64,128", "0,0,0")
    label = fmt.decode(img)
    assert label.road.tolist() == [[True, True, False, False]] and label.valid.tolist() == [[True, True, True, False]]
    strict = parse_label_format("palette", "128,64,128", tolerance=0).decode(img)
    assert strict.road.tolist() == [[True, False, False, False]]
    two = parse_label_format("palette", "128,64,128;150,64,128", tolerance=0).decode(img)
    assert two.road.tolist() == [[True, False, True, False]]


def test_binary_and_kitti() -> None:
    grey = np.array([[0, 1, 255, 7]], np.uint8)
    assert parse_label_format("binary").decode(grey).road.tolist() == [[False, True, True, True]]
    masked = parse_label_format("binary", ignore="7").decode(grey)
    assert masked.road.tolist() == [[False, True, True, False]] and masked.valid.tolist() == [[True, True, True, False]]
    kitti = np.array([[[255, 0, 255], [255, 0, 0], [0, 0, 0]]], np.uint8)  # road, non-road, don't care
    label = parse_label_format("kitti").decode(kitti)
    assert label.road.tolist() == [[True, False, False]] and label.valid.tolist() == [[True, True, False]]


@pytest.mark.parametrize("fmt, img, match", [
    (CAMVID, np.dstack([np.zeros((2, 2), np.uint8), np.ones((2, 2), np.uint8), np.zeros((2, 2), np.uint8)]),
     "colour image"),
    (parse_label_format("palette", "128,64,128"), np.zeros((2, 2), np.uint8), "grey image"),
    (parse_label_format("kitti"), np.zeros((2, 2), np.uint8), "grey image"),
])
def test_a_label_of_the_wrong_kind(fmt: LabelFormat, img: np.ndarray, match: str) -> None:
    with pytest.raises(CorruptFileError, match=match):
        fmt.decode(img, "x.png")


@pytest.mark.parametrize("args, match", [
    (("class-id",), "needs road"), (("palette",), "needs road"), (("binary", "3"), "is for label_format"),
    (("kitti", None, "0"), "not for label_format kitti"), (("class-id", "road"), "comma-separated integers"),
    (("class-id", "70000"), r"\[0, 65535\]"), (("palette", "300,0,0"), r"\[0, 255\]"), (("palette", "128,64"), "R,G,B"),
    (("class-id", "3", None, 4), "palette"),
    (("palette", "1,2,3", None, 99), "0 to 64"), (("mask",), "must be one of"),
])
def test_bad_label_format_options(args: tuple, match: str) -> None:
    with pytest.raises(InvalidOptionError, match=match):
        parse_label_format(*args)


def _folder(tmp_path: Path, n: int = 4, shape: tuple[int, int] = (64, 96)) -> tuple[Path, Path, list[np.ndarray]]:
    """n road frames as images/*.png and class-id labels (road 3, else 1; a don't-care corner of 11)."""
    images, labels, roads = tmp_path / "images", tmp_path / "labels", []
    for i in range(n):
        img, road = road_frame(shape, 200 + i)
        ids = np.where(road, 3, 1).astype(np.uint8)
        ids[:4, :4] = 11
        write_image(images / f"f{i:02d}.png", img)
        write_image(labels / f"f{i:02d}.png", ids)
        roads.append(road)
    return images, labels, roads


def test_pairing(tmp_path: Path) -> None:
    images, labels, _ = _folder(tmp_path, 3)
    write_image(images / "unlabelled.png", np.zeros((8, 8, 3), np.uint8))  # images without a label are not scored
    frames = pair_labelled_frames(images, labels, CAMVID)
    assert [f.name for f in frames] == ["f00", "f01", "f02"]
    write_image(labels / "orphan.png", np.zeros((8, 8), np.uint8))
    with pytest.raises(InputFileError, match=r"1 label .* has no image of the same name .*\(orphan.png\)"):
        pair_labelled_frames(images, labels, CAMVID)
    (labels / "orphan.png").unlink()
    write_image(images / "f01.jpg", np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(DatasetError, match="two images are named 'f01'"):
        pair_labelled_frames(images, labels, CAMVID)
    with pytest.raises(InvalidOptionError, match="same folder"):
        pair_labelled_frames(images, images, CAMVID)
    (images / "f01.jpg").unlink()
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match="no label images"):
        pair_labelled_frames(images, tmp_path / "empty", CAMVID)
    with pytest.raises(InputFileError, match="not found"):
        pair_labelled_frames(tmp_path / "none", labels, CAMVID)


def test_kitti_ground_truth_names(tmp_path: Path) -> None:
    images, gt = tmp_path / "image_2", tmp_path / "gt_image_2"
    for name in ("um_000000", "uu_000003"):
        write_image(images / f"{name}.png", np.zeros((8, 8, 3), np.uint8))
    label = np.zeros((8, 8, 3), np.uint8)
    label[..., 0] = 255
    write_image(gt / "um_road_000000.png", label)
    write_image(gt / "um_lane_000000.png", label)  # lane ground truth: not a road label, skipped
    write_image(gt / "uu_road_000003.png", label)
    frames = pair_labelled_frames(images, gt, parse_label_format("kitti"))
    assert [(f.name, f.label.name) for f in frames] == [("um_000000", "um_road_000000.png"),
                                                         ("uu_000003", "uu_road_000003.png")]


def test_bootstrap_intervals() -> None:
    assert bootstrap_intervals(np.array([[80, 20, 20]])) is None  # one frame: no interval (issue 72)
    rng = np.random.default_rng(1)
    counts = np.column_stack([rng.integers(50, 100, 40), rng.integers(0, 40, 40), rng.integers(0, 40, 40)])
    ci = bootstrap_intervals(counts)
    tp, fp, fn = counts.sum(0)
    pooled_f = 2 * tp / (2 * tp + fp + fn)
    assert ci["f_score"][0] < pooled_f < ci["f_score"][1]
    assert ci == bootstrap_intervals(counts)  # seeded: the same counts give the same interval
    wider = bootstrap_intervals(counts[:8])
    assert wider["f_score"][1] - wider["f_score"][0] > ci["f_score"][1] - ci["f_score"][0]


@pytest.fixture(scope="module")
def road_ckpt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_road_checkpoint(tmp_path_factory.mktemp("ckpt") / "road.ckpt", (64, 96), 0.25)


def test_evaluate_a_labelled_folder(road_ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, labels, roads = _folder(tmp_path, 4)
    out = tmp_path / "eval"
    assert main(["evaluate", "--checkpoint", str(road_ckpt), "--images", str(images), "--labels", str(labels),
                 "--label-format", "class-id", "--road", "3", "--ignore", "11", "--out", str(out),
                 "--no-progress"]) == 0
    line = capsys.readouterr().out
    assert "F 95 %" in line and "(4 frames)" in line
    m = json.loads((out / "metrics.json").read_text())
    assert m["frames"] == 4 and m["label_format"] == {"kind": "class-id", "road": [3], "ignore": [11], "tolerance": 0}
    assert m["f_score"] > 0.8, m  # the tiny network was trained on frames like these
    lo, hi = m["intervals"]["f_score"]
    assert lo <= m["f_score"] <= hi
    rows = list(csv.DictReader((out / "per_frame.csv").open()))
    assert [r["frame"] for r in rows] == ["f00", "f01", "f02", "f03"]
    tp, fp, fn = (sum(int(r[k]) for r in rows) for k in ("tp", "fp", "fn"))
    assert tp + fn == sum(int(r.sum() - r[:4, :4].sum()) for r in roads)  # the don't-care corner is left out
    assert m["f_score"] == pytest.approx(2 * tp / (2 * tp + fp + fn))
    assert sorted(p.stem for p in (out / "overlays").glob("*.png")) == ["f00", "f01", "f02", "f03"]


def test_evaluate_onnx_on_a_labelled_folder(road_ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, labels, _ = _folder(tmp_path, 2)
    onnx = tmp_path / "m.onnx"
    assert main(["export", "--checkpoint", str(road_ckpt), "--format", "onnx", "--out", str(onnx)]) == 0
    out = tmp_path / "eval"
    assert main(["evaluate", "--onnx", str(onnx), "--images", str(images), "--labels", str(labels),
                 "--label-format", "class-id", "--road", "3", "--no-overlays", "--out", str(out), "--no-progress"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["onnx"] == str(onnx) and m["frames"] == 2 and not (out / "overlays").exists()


def test_evaluate_labelled_folder_mistakes(road_ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, labels, _ = _folder(tmp_path, 2)
    base = ["evaluate", "--checkpoint", str(road_ckpt), "--no-progress"]
    out = tmp_path / "eval"
    refused(capsys, [*base, "--images", str(images), "--labels", str(labels), "--out", str(out)],
            match="add --label-format")
    refused(capsys, [*base, "--images", str(images), "--labels", str(labels), "--label-format", "class-id",
                     "--out", str(out)], match="needs --road")
    refused(capsys, [*base, "--images", str(images), "--labels", str(labels), "--label-format", "binary",
                     "--dataset", "synth", "--root", str(images), "--out", str(out)], match="not both")
    refused(capsys, [*base, "--out", str(out)], match="give the frames to evaluate on")
    refused(capsys, [*base, "--images", str(images), "--labels", str(labels), "--label-format", "class-id",
                     "--road", "3", "--out", str(labels / "eval")], match="inside")
    refused(capsys, [*base, "--images", str(images), "--labels", str(labels), "--label-format", "palette",
                     "--road", "128,64,128", "--out", str(out)], match="grey image")
    write_image(labels / "f01.png", np.zeros((10, 10), np.uint8))  # a label of another size than its image
    refused(capsys, [*base, "--images", str(images), "--labels", str(labels), "--label-format", "class-id",
                     "--road", "3", "--out", str(out)], match="pair each image with its own label")
    assert not out.exists()


def test_evaluate_a_dataset_without_labels(road_ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """KITTI raw has no road labels: one line that says to evaluate on a labelled folder (was an AttributeError)."""
    from test_kitti_raw import make_drive

    make_drive(tmp_path / "raw", frames=2)
    refused(capsys, ["evaluate", "--checkpoint", str(road_ckpt), "--dataset", "kitti-raw", "--root",
                     str(tmp_path / "raw"), "--subset", "all", "--out", str(tmp_path / "eval")],
            match="has no road labels")
