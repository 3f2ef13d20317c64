"""``freespace generate --dataset D --root R --labels TREE`` (issue 45): the DS-Generator fitted to the road
labels of a label tree (``freespace autolabel``'s output) — for KITTI raw, which has no labels of its own,
or instead of a dataset's own labels — with the tree recorded (its content hash), so that a resumed or
repeated run with another tree is refused, or made again with ``--overwrite``.

Real data: the eight shared KITTI raw pairs, autolabelled once per module (~15-30 s on two cores);
skipped when the shared samples are absent.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.data.label_tree import label_tree_sha256
from freespace.io.codecs import read_image, road_label_to_kitti, write_disparity, write_image
from freespace.labels import RoadLabel

from helpers import shared_path, synthetic_pair

FRAMES = 8  # the shared drive's pairs


@pytest.fixture(scope="module")
def raw(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = shared_path("kitti_raw")
    base = tmp_path_factory.mktemp("raw-labels")
    tree = base / "tree"
    assert main(["autolabel", "--dataset", "kitti-raw", "--root", str(root), "--out", str(tree)]) == 0
    return {"root": root, "tree": tree, "base": base}


def _generate(raw: dict[str, Path], out: Path, *extra: str) -> int:
    return main(["generate", "--dataset", "kitti-raw", "--root", str(raw["root"]), "--out", str(out), *extra])


def _views(out: Path) -> list[str]:
    return sorted(p.relative_to(out).with_suffix("").as_posix() for p in out.glob("*_sync/*.png"))


def test_kitti_raw_with_a_label_tree_writes_every_view(raw: dict[str, Path], tmp_path: Path, capsys) -> None:
    out = tmp_path / "gen"
    assert _generate(raw, out, "--labels", str(raw["tree"])) == 0
    assert f"{FRAMES} generated, 0 already done, 0 failed of {FRAMES} frames" in capsys.readouterr().out
    views = _views(out)
    assert len(views) == FRAMES and all(v.startswith("2011_09_26_drive_0001_sync/") for v in views)
    left = read_image(raw["root"] / "2011_09_26/2011_09_26_drive_0001_sync/image_02/data/0000000000.png")
    view = read_image(out / "2011_09_26_drive_0001_sync/0000000000.png")
    assert view.shape == left.shape and not np.array_equal(view, left)
    # the tree is recorded by content; the same tree again: every frame already done
    digest, count = label_tree_sha256(raw["tree"])
    record = json.loads((out / "labels.json").read_text())["labels"]
    assert record["sha256"] == digest and record["files"] == count == FRAMES
    assert record["path"] == str(raw["tree"].resolve())
    assert _generate(raw, out, "--labels", str(raw["tree"])) == 0
    assert f"0 generated, {FRAMES} already done" in capsys.readouterr().out


def test_kitti_raw_without_labels_is_refused_naming_labels(raw: dict[str, Path], tmp_path: Path, capsys) -> None:
    out = tmp_path / "gen"
    assert _generate(raw, out) == 2
    err = capsys.readouterr().err.strip()
    assert "has no road labels" in err and "--labels TREE" in err and "freespace autolabel" in err
    assert err.count("\n") == 0 and not out.exists()


def test_another_tree_is_refused_then_made_again(raw: dict[str, Path], tmp_path: Path, capsys) -> None:
    """A tree with one frame fewer and one label changed: a frame without a label is skipped (one warning
    line); the folder made with the first tree is refused in one line, and with --overwrite made again from
    the second one, the first tree's frame that the second lacks gone too."""
    out, other = tmp_path / "gen", tmp_path / "tree2"
    shutil.copytree(raw["tree"], other)
    (other / "2011_09_26_drive_0001_sync/0000000105.png").unlink()
    changed = other / "2011_09_26_drive_0001_sync/0000000000.png"
    label = read_image(changed)
    label[: label.shape[0] * 3 // 4] = 0  # don't care above the last quarter: another road to fit
    write_image(changed, label)
    assert _generate(raw, out, "--labels", str(raw["tree"])) == 0
    before = read_image(out / "2011_09_26_drive_0001_sync/0000000000.png")
    capsys.readouterr()
    assert _generate(raw, out, "--labels", str(other)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "1 of 8 frames have no label in" in err[0] and "0000000105" in err[0]
    assert "holds frames fitted to the label tree" in err[1] and "--overwrite" in err[1]
    assert _generate(raw, out, "--labels", str(other), "--overwrite") == 0
    assert "7 generated, 0 already done, 0 failed of 7 frames" in capsys.readouterr().out
    assert len(_views(out)) == 7 and not (out / "2011_09_26_drive_0001_sync/0000000105.png").exists()
    assert not (out / "reports/2011_09_26_drive_0001_sync/0000000105.json").exists()
    assert json.loads((out / "labels.json").read_text())["labels"]["sha256"] == label_tree_sha256(other)[0]
    assert not np.array_equal(read_image(out / "2011_09_26_drive_0001_sync/0000000000.png"), before)


def test_label_tree_mistakes_are_one_line_and_write_nothing(raw: dict[str, Path], tmp_path: Path, capsys) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    for labels, out, message in ((tmp_path / "nowhere", tmp_path / "o1", "not found"),
                                 (empty, tmp_path / "o2", "holds no <frame>.png"),
                                 (raw["root"], tmp_path / "o3", "not a label tree"),
                                 (raw["tree"], raw["tree"] / "inside", "inside the input --labels")):
        assert _generate(raw, out, "--labels", str(labels)) == 2, labels
        err = capsys.readouterr().err.strip()
        assert message in err and err.count("\n") == 0 and "--labels" in err, err
        assert not out.exists()
    # a tree of other frames (their names are not this drive's)
    stray = tmp_path / "stray"
    write_image(stray / "2011_09_26_drive_0002_sync/0000000000.png", read_image(
        raw["tree"] / "2011_09_26_drive_0001_sync/0000000000.png"))
    assert _generate(raw, tmp_path / "o4", "--labels", str(stray)) == 2
    err = capsys.readouterr().err.strip()
    assert "labels none of the 8 frames" in err and err.count("\n") == 0 and not (tmp_path / "o4").exists()
    # a run refused by generate after the record was written leaves nothing
    assert _generate(raw, tmp_path / "o5", "--labels", str(raw["tree"]), "--disparity-source", "lidar") == 2
    assert "Velodyne" in capsys.readouterr().err and not (tmp_path / "o5").exists()
    # --labels belongs to the dataset mode
    assert main(["generate", "--reference", "a.png", "--labels", str(raw["tree"]),
                 "--out", str(tmp_path / "g.png")]) == 2
    assert "--labels is for --dataset" in capsys.readouterr().err


def test_generate_with_labels_never_imports_torch(raw: dict[str, Path], tmp_path: Path) -> None:
    code = "import sys, freespace.cli; rc = freespace.cli.main(sys.argv[1:]); print(rc, 'torch' in sys.modules)"
    res = subprocess.run([sys.executable, "-c", code, "generate", "--dataset", "kitti-raw", "--root", str(raw["root"]),
                          "--labels", str(raw["tree"]), "--out", str(tmp_path / "gen")], capture_output=True, text=True)
    assert res.stdout.strip().splitlines()[-1] == "0 False", res.stderr


# --- a dataset with labels of its own ----------------------------------------------------------------------


def _kitti(root: Path, n: int = 3) -> list[str]:
    """A KITTI road tree of ``n`` rendered pairs with their exact disparities and road labels."""
    names = []
    for i in range(n):
        name = f"um_{i:06d}"
        left, right, label, disp = synthetic_pair(roll_deg=0.5 * i, seed=i)
        write_image(root / "data_road/training/image_2" / f"{name}.png", left)
        write_image(root / "data_road/training/gt_image_2" / f"um_road_{i:06d}.png", road_label_to_kitti(label))
        write_image(root / "data_road_right/training/image_3" / f"{name}.png", right)
        write_disparity(root / "data_road/training/disparity" / f"{name}.png", disp)
        names.append(name)
    return names


def test_a_tree_replaces_a_datasets_own_labels(tmp_path: Path, capsys) -> None:
    """KITTI road with a tree whose label of the first frame marks no road: that frame fails (its own label
    has road, so the tree's was used); a folder made with the own labels is refused with a tree, and a folder
    made with a tree is refused without one."""
    root, tree = tmp_path / "kitti", tmp_path / "tree"
    names = _kitti(root)
    for i, name in enumerate(names):
        own = read_image(root / "data_road/training/gt_image_2" / f"um_road_{i:06d}.png")
        write_image(tree / f"{name}.png", own)
    shape = read_image(tree / f"{names[0]}.png").shape[:2]
    no_road = RoadLabel(road=np.zeros(shape, bool), valid=np.ones(shape, bool))
    write_image(tree / f"{names[0]}.png", road_label_to_kitti(no_road))
    base = ["generate", "--dataset", "kitti", "--root", str(root)]
    own, labelled = tmp_path / "own", tmp_path / "labelled"
    assert main([*base, "--out", str(own)]) == 0
    assert main([*base, "--labels", str(tree), "--out", str(labelled)]) == 1
    printed = capsys.readouterr().out
    assert "2 generated, 0 already done, 1 failed of 3 frames" in printed and f"failed {names[0]}: " in printed
    assert "road" in printed.splitlines()[-1]
    assert main([*base, "--labels", str(tree), "--out", str(own)]) == 2
    assert "holds frames fitted to the dataset's own labels" in capsys.readouterr().err
    assert main([*base, "--out", str(labelled)]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds frames fitted to the label tree" in err and "not to the dataset's own labels" in err
    assert main([*base, "--out", str(labelled), "--overwrite"]) == 0
    assert not (labelled / "labels.json").exists() and len(list(labelled.glob("um_*.png"))) == 3
