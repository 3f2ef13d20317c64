"""Hostile probe 5 (issue 72): label decoding and `freespace evaluate` on labelled sets.

* Nothing evaluated is not a score: a frame whose label has no evaluated pixel (don't care everywhere) is listed,
  not scored, and enters no pooled count nor the bootstrap; a set of such frames is refused in one line, nothing
  written — in a labelled folder of any format and in a KITTI tree. A frame with evaluated pixels but no road in
  label nor prediction adds nothing to the pooled scores and no 1.0 to the interval.
* Labels are read with their own values: 16-bit masks, ids and palettes, the options up to 65535.
* A road value that no label holds, or a value that is both road and don't care, is refused, naming it (and the
  values the labels hold); a label of the wrong kind still is.
* A run's subset lists are looked for only in a run folder; the lists used are recorded.
* One scored frame has no interval (not one of zero width), wherever an interval is written.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from freespace.cli import main
from freespace.errors import CorruptFileError, DatasetError, InvalidOptionError
from freespace.evaluation.labelled import (
    PooledScores,
    bootstrap_intervals,
    check_labels,
    pair_labelled_frames,
    parse_label_format,
    read_label,
    scan_labels,
)
from freespace.evaluation.metrics import Counts
from freespace.inference.evaluate import evaluate_report, run_subset_lists
from freespace.io.codecs import write_image

from helpers import refused, road_frame, tiny_road_checkpoint

SHAPE = (64, 96)
ROAD_COLOUR, OTHER_COLOUR = (128, 64, 128), (70, 70, 70)


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tiny_road_checkpoint(tmp_path_factory.mktemp("ckpt") / "road.ckpt", SHAPE, 0.25)


def _label(kind: str, road: np.ndarray) -> np.ndarray:
    """The label of a road mask in ``kind``: binary 0/255, class-id 3/1, palette colours, kitti colours."""
    if kind == "binary":
        return np.where(road, 255, 0).astype(np.uint8)
    if kind == "class-id":
        return np.where(road, 3, 1).astype(np.uint8)
    if kind == "palette":
        return np.where(road[..., None], ROAD_COLOUR, OTHER_COLOUR).astype(np.uint8)
    out = np.zeros(road.shape + (3,), np.uint8)
    out[..., 0] = 255
    out[road, 2] = 255
    return out


def _folder(tmp_path: Path, kind: str, n: int = 3, label=None) -> tuple[Path, Path]:  # noqa: ANN001
    """n road frames in images/ with their labels in labels/ (``label(i, road)``: the label of frame i)."""
    images, labels = tmp_path / "images", tmp_path / "labels"
    for i in range(n):
        img, road = road_frame(SHAPE, 300 + i)
        name = f"um_{i:06d}"
        write_image(images / f"{name}.png", img)
        lab = label(i, road) if label is not None else _label(kind, road)
        path = labels / (f"um_road_{i:06d}.png" if kind == "kitti" else f"{name}.png")
        path.parent.mkdir(parents=True, exist_ok=True)
        if lab.dtype == np.uint16 and lab.ndim == 3:
            assert cv2.imwrite(str(path), lab[..., ::-1])
        else:
            write_image(path, lab)
    return images, labels


def _evaluate(ckpt: Path, images: Path, labels: Path, out: Path, *fmt: str) -> list[str]:
    return ["evaluate", "--checkpoint", str(ckpt), "--images", str(images), "--labels", str(labels),
            "--label-format", *fmt, "--out", str(out), "--no-progress"]


# --- 1: nothing evaluated is no score ---------------------------------------------------------------------------


@pytest.mark.parametrize("fmt, label", [
    (("binary", "--ignore", "7"), lambda i, road: np.full(SHAPE, 7, np.uint8)),
    (("class-id", "--road", "3", "--ignore", "11"), lambda i, road: np.full(SHAPE, 11, np.uint8)),
    (("class-id", "--road", "3", "--ignore", "11,12"), lambda i, road: np.where(road, 11, 12).astype(np.uint8)),
    (("palette", "--road", "128,64,128", "--ignore", "0,0,0"), lambda i, road: np.zeros(SHAPE + (3,), np.uint8)),
    (("kitti",), lambda i, road: np.zeros(SHAPE + (3,), np.uint8)),
])
def test_a_set_without_an_evaluated_pixel_is_refused(fmt: tuple, label, ckpt: Path, tmp_path: Path,  # noqa: ANN001
                                                     capsys: pytest.CaptureFixture) -> None:
    images, labels = _folder(tmp_path, fmt[0], label=label)
    out = tmp_path / "eval"
    err = refused(capsys, _evaluate(ckpt, images, labels, out, *fmt), match="no pixel would be evaluated")
    assert "don't care" in err or "black" in err
    assert not out.exists()


@pytest.mark.parametrize("fmt, blank", [
    (("binary", "--ignore", "7"), np.full(SHAPE, 7, np.uint8)),
    (("class-id", "--road", "3", "--ignore", "11"), np.full(SHAPE, 11, np.uint8)),
    (("kitti",), np.zeros(SHAPE + (3,), np.uint8)),
])
def test_a_frame_without_an_evaluated_pixel_is_listed_not_scored(fmt: tuple, blank: np.ndarray, ckpt: Path,
                                                                 tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture) -> None:
    images, labels = _folder(tmp_path, fmt[0], n=3, label=lambda i, road: blank if i == 1 else _label(fmt[0], road))
    out = tmp_path / "eval"
    assert main(_evaluate(ckpt, images, labels, out, *fmt)) == 0
    line = capsys.readouterr().out
    assert "(2 frames; 1 more without an evaluated pixel, not scored)" in line, line
    m = json.loads((out / "metrics.json").read_text())
    assert m["frames"] == 2 and m["unevaluated_frames"] == 1 and m["unevaluated"] == ["um_000001"]
    assert m["f_score"] < 1.0 and m["intervals"] is not None
    rows = {r["frame"]: r for r in csv.DictReader((out / "per_frame.csv").open())}
    assert rows["um_000001"]["f_score"] == "" and rows["um_000001"]["tn"] == "0"  # no score, not 1.0
    tp, fp, fn = (sum(int(r[k]) for r in rows.values()) for k in ("tp", "fp", "fn"))
    assert m["f_score"] == pytest.approx(2 * tp / (2 * tp + fp + fn))
    assert not (out / "overlays" / "um_000001.png").exists()


def _kitti_tree(root: Path, labels: list[np.ndarray]) -> Path:
    base = root / "data_road" / "training"
    for i, lab in enumerate(labels):
        img, _ = road_frame(SHAPE, 400 + i)
        write_image(base / "image_2" / f"um_{i:06d}.png", img)
        write_image(base / "gt_image_2" / f"um_road_{i:06d}.png", lab)
    return root


def test_a_kitti_tree_without_evaluated_pixels(ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """`evaluate --dataset kitti`: all-black ground truth is refused, nothing written; one black frame is listed."""
    black = np.zeros(SHAPE + (3,), np.uint8)
    root = _kitti_tree(tmp_path / "black", [black, black])
    out = tmp_path / "eval"
    refused(capsys, ["evaluate", "--checkpoint", str(ckpt), "--dataset", "kitti", "--root", str(root), "--subset",
                     "all", "--out", str(out), "--no-progress"], match="has an evaluated pixel")
    assert not out.exists()
    root = _kitti_tree(tmp_path / "one", [_label("kitti", road_frame(SHAPE, 400)[1]), black,
                                          _label("kitti", road_frame(SHAPE, 402)[1])])
    assert main(["evaluate", "--checkpoint", str(ckpt), "--dataset", "kitti", "--root", str(root), "--subset", "all",
                 "--out", str(out), "--no-progress"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["frames"] == 2 and m["unevaluated"] == ["um_000001"] and m["splits"] is None


def test_the_convention_of_frames_without_road() -> None:
    """Evaluated pixels, no road in label nor prediction: the frame scores 1.0 (nothing to get wrong) but adds
    nothing to the pooled scores, and a bootstrap resample of such frames only is no 1.0 in the interval."""
    scores = PooledScores()
    scores.add("empty", Counts(0, 0, 0, 500))     # evaluated, no road anywhere
    scores.add("road", Counts(50, 50, 0, 400))    # F = 2/3
    assert scores.rows[0]["f_score"] == 1.0
    s = scores.summary()
    assert s["frames"] == 2 and s["unevaluated_frames"] == 0
    assert s["f_score"] == pytest.approx(2 / 3) and s["intervals"]["f_score"] == pytest.approx([2 / 3, 2 / 3])
    scores.add("dont-care", Counts())             # no evaluated pixel: no score, not pooled
    assert scores.rows[-1]["f_score"] is None and scores.summary()["unevaluated"] == ["dont-care"]
    ci = bootstrap_intervals(np.array([[0, 0, 0], [0, 0, 0], [10, 0, 10]]))
    assert ci["recall"][1] == pytest.approx(0.5) and ci["iou"][1] == pytest.approx(0.5)
    with pytest.raises(DatasetError, match="marks road"):  # evaluated pixels, but no road in any label
        PooledScores([dict(scores.rows[0])]).summary()
    with pytest.raises(DatasetError, match="evaluated pixel"):
        PooledScores([dict(scores.rows[-1])]).summary()


# --- 2: labels with their own values ----------------------------------------------------------------------------


def test_sixteen_bit_labels_keep_their_values(tmp_path: Path) -> None:
    road = np.zeros(SHAPE, bool)
    road[40:] = True
    cases = {
        "binary": (parse_label_format("binary"), np.where(road, 1, 0).astype(np.uint16)),
        "binary-ignore": (parse_label_format("binary", ignore="4000"), np.where(road, 1, 0).astype(np.uint16)),
        "class-id": (parse_label_format("class-id", "1000", "65535"), np.where(road, 1000, 3).astype(np.uint16)),
        "class-id-3": (parse_label_format("class-id", "3"), np.where(road, 3, 1000).astype(np.uint16)),
        "palette": (parse_label_format("palette", "128,64,128"),
                    (np.where(road[..., None], ROAD_COLOUR, OTHER_COLOUR) * 257).astype(np.uint16)),
        "kitti": (parse_label_format("kitti"), _label("kitti", road).astype(np.uint16) * 257),
        "kitti-faint": (parse_label_format("kitti"), (_label("kitti", road) > 0).astype(np.uint16)),
    }
    for name, (fmt, img) in cases.items():
        path = tmp_path / f"{name}.png"
        assert cv2.imwrite(str(path), img[..., ::-1] if img.ndim == 3 else img)
        label = read_label(path, fmt)
        assert np.array_equal(label.road, road) and label.valid.all(), name
    rgba = np.dstack([_label("palette", road), np.full(SHAPE, 255, np.uint8)])  # an alpha channel is dropped
    assert cv2.imwrite(str(tmp_path / "rgba.png"), rgba[..., [2, 1, 0, 3]])
    assert np.array_equal(read_label(tmp_path / "rgba.png", parse_label_format("palette", "128,64,128")).road, road)
    odd = (np.where(road[..., None], ROAD_COLOUR, OTHER_COLOUR) * 250).astype(np.uint16)  # no widened 8-bit palette
    assert cv2.imwrite(str(tmp_path / "odd.png"), odd)
    with pytest.raises(CorruptFileError, match="multiple of 257"):
        read_label(tmp_path / "odd.png", parse_label_format("palette", "128,64,128"))
    assert parse_label_format("class-id", "65535").road == (65535,)
    with pytest.raises(InvalidOptionError, match="65535"):
        parse_label_format("class-id", "65536")


def test_evaluate_sixteen_bit_masks(ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """16-bit binary masks with road 1 and 16-bit class ids score as their 8-bit twins (were "no road": F 0)."""
    f = {}
    for kind, label, fmt in (
            ("binary", lambda i, road: road.astype(np.uint16), ("binary",)),
            ("class-id", lambda i, road: np.where(road, 700, 5).astype(np.uint16), ("class-id", "--road", "700")),
            ("eight", lambda i, road: _label("binary", road), ("binary",))):
        images, labels = _folder(tmp_path / kind, "binary", label=label)
        assert main(_evaluate(ckpt, images, labels, tmp_path / kind / "eval", *fmt, "--no-overlays")) == 0
        f[kind] = json.loads((tmp_path / kind / "eval" / "metrics.json").read_text())["f_score"]
    assert f["eight"] > 0.8 and f["binary"] == pytest.approx(f["eight"]) and f["class-id"] == pytest.approx(f["eight"])


# --- 3: road values the labels do not hold, values both road and don't care -------------------------------------


@pytest.mark.parametrize("args", [
    ("class-id", "3", "3"), ("class-id", "3,4", "4,11"), ("palette", "128,64,128", "128,64,128"),
    ("palette", "128,64,128", "130,60,128"), ("binary", None, "0"), ("binary", None, "7,0"),
])
def test_a_value_both_road_and_dont_care_is_refused(args: tuple) -> None:
    with pytest.raises(InvalidOptionError, match="road|don't care"):
        parse_label_format(*args)


def test_road_and_ignore_overlap_on_the_command_line(ckpt: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture) -> None:
    images, labels = _folder(tmp_path, "class-id")
    out = tmp_path / "eval"
    refused(capsys, _evaluate(ckpt, images, labels, out, "class-id", "--road", "3", "--ignore", "3"),
            match="both --road and --ignore")
    assert not out.exists()


@pytest.mark.parametrize("kind, fmt, match", [
    ("class-id", ("class-id", "--road", "7"), "--road 7 is in no label"),
    ("class-id", ("class-id", "--road", "3,7"), "--road 7 is in no label"),
    ("class-id", ("class-id", "--road", "300"), "8-bit"),
    ("palette", ("palette", "--road", "128,64,129;10,20,30", "--tolerance", "0"), "10,20,30 are in no label"),
    ("binary", ("binary",), "marks road"),
    ("kitti", ("kitti",), "marks road"),
])
def test_a_road_value_in_no_label_is_refused(kind: str, fmt: tuple, match: str, ckpt: Path, tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    no_road = {"binary": lambda i, road: np.zeros(SHAPE, np.uint8),
               "kitti": lambda i, road: _label("kitti", np.zeros(SHAPE, bool))}.get(kind)
    images, labels = _folder(tmp_path, kind, label=no_road)
    out = tmp_path / "eval"
    err = refused(capsys, _evaluate(ckpt, images, labels, out, *fmt), match=match)
    held = {"class-id": ["3 (", "1 ("], "palette": ["128,64,128 (", "70,70,70 ("], "binary": ["0 (100.0 %)"],
            "kitti": ["255,0,0 (100.0 %)"]}[kind]
    assert all(h in err for h in held), err  # the values the labels do hold
    assert not out.exists()


def test_labels_of_the_wrong_kind_are_still_refused(tmp_path: Path) -> None:
    images, labels = _folder(tmp_path, "palette")
    for fmt in (parse_label_format("class-id", "3"), parse_label_format("binary")):
        with pytest.raises(CorruptFileError, match="colour image"):
            check_labels(pair_labelled_frames(images, labels, fmt), fmt)
    images, labels = _folder(tmp_path / "grey", "class-id")
    fmt = parse_label_format("palette", "128,64,128")
    with pytest.raises(CorruptFileError, match="grey image"):
        check_labels(pair_labelled_frames(images, labels, fmt), fmt)


def test_scan_labels_is_reusable(tmp_path: Path) -> None:
    images, labels = _folder(tmp_path, "class-id", label=lambda i, road: np.where(road, 3, 11 if i == 2 else 1)
                             .astype(np.uint8))
    fmt = parse_label_format("class-id", "3,4", "11")
    frames = pair_labelled_frames(images, labels, fmt)
    scan = scan_labels(frames, fmt)  # refuses nothing by itself
    assert scan.frames == 3 and scan.missing_road == (4,) and scan.bits == (8,) and set(scan.values) == {1, 3, 11}
    assert scan.road[3] > 0 and scan.unevaluated == ()
    with pytest.raises(DatasetError, match="road 4 is in no label"):
        scan.check()
    assert check_labels(frames, fmt, each_road_value=False).road[4] == 0  # a public set's classes: one suffices
    with pytest.raises(DatasetError, match="road 4,7 are in no label"):
        check_labels(frames, parse_label_format("class-id", "4,7", "11"), each_road_value=False)


# --- 4: subset lists only from a run folder ---------------------------------------------------------------------


def test_subset_lists_come_from_a_run_folder_only(ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    labels = [_label("kitti", road_frame(SHAPE, 400 + i)[1]) for i in range(3)]
    root = _kitti_tree(tmp_path / "kitti", labels)

    def lists(folder: Path, test: str) -> None:
        folder.mkdir(parents=True)
        for subset, names in (("train", "um_000000"), ("val", "um_000001"), ("test", test)):
            (folder / f"{subset}.txt").write_text(names + "\n")

    models = tmp_path / "models"  # a model folder: models/splits belongs to no run of it
    (models / "fast").mkdir(parents=True)
    (models / "fast" / "model.ckpt").write_bytes(ckpt.read_bytes())
    lists(models / "splits", "um_000002")
    base = ["--dataset", "kitti", "--root", str(root), "--no-progress"]
    out = tmp_path / "eval"
    refused(capsys, ["evaluate", "--checkpoint", str(models / "fast" / "model.ckpt"), *base, "--out", str(out)],
            match="not in a training run's folder")
    assert not out.exists() and run_subset_lists(models / "fast" / "model.ckpt") is None
    loose = tmp_path / "loose" / "checkpoints" / "best.ckpt"  # checkpoints/ but no run record beside it
    loose.parent.mkdir(parents=True)
    loose.write_bytes(ckpt.read_bytes())
    lists(tmp_path / "loose" / "splits", "um_000002")
    assert run_subset_lists(loose) is None

    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "checkpoints" / "best.ckpt").write_bytes(ckpt.read_bytes())
    (run / "config.yaml").write_text("dataset: kitti\n")
    lists(run / "splits", "um_000002")
    assert run_subset_lists(run / "checkpoints" / "best.ckpt") == run / "splits"
    assert main(["evaluate", "--checkpoint", str(run / "checkpoints" / "best.ckpt"), *base, "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["splits"] == str(run / "splits") and m["frames"] == 1
    assert main(["evaluate", "--checkpoint", str(models / "fast" / "model.ckpt"), *base, "--splits",
                 str(models / "splits"), "--out", str(tmp_path / "e2")]) == 0
    assert json.loads((tmp_path / "e2" / "metrics.json").read_text())["splits"] == str(models / "splits")


# --- 5: one frame, no interval ----------------------------------------------------------------------------------


def test_one_scored_frame_has_no_interval(ckpt: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert bootstrap_intervals(np.zeros((0, 3))) is None and bootstrap_intervals(np.array([[5, 1, 1]])) is None
    assert bootstrap_intervals(np.array([[5, 1, 1], [5, 1, 2]])) is not None
    images, labels = _folder(tmp_path, "binary", n=1)
    out = tmp_path / "eval"
    assert main(_evaluate(ckpt, images, labels, out, "binary")) == 0
    line = capsys.readouterr().out
    assert "95 %" not in line and "no F interval: 1 frame scored, an interval needs 2" in line, line
    m = json.loads((out / "metrics.json").read_text())
    assert m["intervals"] is None and "needs 2 scored frames" in m["interval"]
    # two frames of which one is don't care everywhere: one scored frame, no interval either
    images, labels = _folder(tmp_path / "two", "binary", n=2,
                             label=lambda i, road: np.full(SHAPE, 9, np.uint8) if i else _label("binary", road))
    assert main(_evaluate(ckpt, images, labels, tmp_path / "two" / "eval", "binary", "--ignore", "9")) == 0
    m = json.loads((tmp_path / "two" / "eval" / "metrics.json").read_text())
    assert m["intervals"] is None and m["frames"] == 1 and m["unevaluated_frames"] == 1
    assert "no F interval" in evaluate_report(m, "x")
