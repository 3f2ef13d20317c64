"""Training on a dataset with no labels of its own (KITTI raw) from a label tree: every split is labelled by
the tree, the time-block split is kept, and what cannot work (human_share, no tree) is refused in one line.

Uses the eight real pairs of ``../shared/data/kitti_raw`` (skipped when absent) and a label tree drawn here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.io.codecs import road_label_to_kitti, write_image
from freespace.labels import RoadLabel

from helpers import shared_path

DRIVE = "2011_09_26_drive_0001_sync"


def _label_tree(folder: Path, frames: list[str]) -> Path:
    """A KITTI-colour label per frame (``<drive>/<frame>.png``): the lower centre road, a don't-care band, the rest
    non-road; and a grey confidence map beside it under ``confidence/``, as `freespace autolabel` writes."""
    h, w = 375, 1242
    v, u = np.mgrid[0:h, 0:w]
    road = (v > 250) & (np.abs(u - w / 2) < (v - 200) * 2.5)
    valid = ~((v > 230) & (v <= 250))
    confidence = np.clip(v * 255 // h, 0, 255).astype(np.uint8)  # autolabel's grey confidence/ maps: no labels
    for name in frames:
        write_image(folder / f"{name}.png", road_label_to_kitti(RoadLabel(road=road, valid=valid)))
        write_image(folder / "confidence" / f"{name}.png", confidence)
    return folder


def _frames() -> list[str]:
    root = shared_path("kitti_raw")
    return sorted(f"{DRIVE}/{p.stem}" for p in (root / "2011_09_26" / DRIVE / "image_02" / "data").glob("*.png"))


def test_kitti_raw_trains_on_a_label_tree_in_every_split(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = shared_path("kitti_raw")
    labels = _label_tree(tmp_path / "labels", _frames())
    assert main(["datasets", "split", "--dataset", "kitti-raw", "--root", str(root), "--by", "time",
                 "--fractions", "0.5,0.25,0.25", "--out", str(tmp_path / "splits")]) == 0
    capsys.readouterr()
    run = tmp_path / "run"
    code = main(["train", "--dataset", "kitti-raw", "--root", str(root), "--labels", str(labels), "--splits",
                 str(tmp_path / "splits"), "--model", "segnet", "--epochs", "1", "--batch-size", "2",
                 "--image-size", "64x192", "--no-progress", "--out", str(run)])
    assert code == 0, capsys.readouterr().err
    assert "has no labels of its own: validation and test use" in capsys.readouterr().err
    splits = {k: (run / "splits" / f"{k}.txt").read_text().split() for k in ("train", "val", "test")}
    # the time blocks: frames 0, 15, 30, 45 train, 60, 75 val, 90, 105 test (never interleaved)
    assert [n[-3:] for n in splits["train"]] == ["000", "015", "030", "045"]
    assert [n[-3:] for n in splits["test"]] == ["090", "105"]
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["frames"] == {"train": 4, "val": 2, "test": 2} and metrics["f_score"] > 0  # scored on the tree


def test_an_autolabelled_drive_trains_with_ds_generator_views_of_its_real_pairs(tmp_path: Path,
                                                                                capsys: pytest.CaptureFixture) -> None:
    """The chain of the real-roads study's HA-R-auto: `autolabel` of the drive (SGBM), the time-block split,
    `train --labels --augment homography`: every training frame gets its DS-Generator view, the road model fitted
    to the autolabel's road (once the views failed with "missing road label": the drive has no labels of its
    own, and the generator looked at the frames' own labels only)."""
    root, labels, cache = shared_path("kitti_raw"), tmp_path / "labels", tmp_path / "cache"
    assert main(["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--cache-dir", str(cache), "--out",
                 str(labels)]) == 0
    assert main(["datasets", "split", "--dataset", "kitti-raw", "--root", str(root), "--by", "time",
                 "--fractions", "0.5,0.25,0.25", "--out", str(tmp_path / "splits")]) == 0
    capsys.readouterr()
    run = tmp_path / "run"
    code = main(["train", "--dataset", "kitti-raw", "--root", str(root), "--labels", str(labels), "--splits",
                 str(tmp_path / "splits"), "--augment", "homography", "--cache-dir", str(cache), "--model", "segnet",
                 "--epochs", "1", "--batch-size", "2", "--image-size", "64x192", "--no-progress", "--out", str(run)])
    assert code == 0, capsys.readouterr().err
    assert "gave no generated view" not in capsys.readouterr().err
    train = (run / "splits" / "train.txt").read_text().split()
    assert sorted(p.relative_to(run / "generated").with_suffix("").as_posix()
                  for p in (run / "generated").glob(f"{DRIVE}/*.png")) == sorted(train) and len(train) == 4


def test_a_label_less_dataset_without_a_tree_or_with_human_share_is_refused(tmp_path: Path,
                                                                             capsys: pytest.CaptureFixture) -> None:
    root = shared_path("kitti_raw")
    base = ["train", "--dataset", "kitti-raw", "--root", str(root), "--model", "segnet", "--epochs", "1",
            "--image-size", "64x192", "--no-progress"]
    assert main(base + ["--out", str(tmp_path / "a")]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "0 labelled frames" in err[0]
    labels = _label_tree(tmp_path / "labels", _frames())
    assert main(base + ["--labels", str(labels), "--human-share", "0.5", "--out", str(tmp_path / "b")]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--human-share needs frames labelled by people" in err[0]
