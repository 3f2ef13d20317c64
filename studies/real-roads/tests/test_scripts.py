"""The real-roads study's scripts: the variants' table (evaluate.py) from run folders' real.json, and the
S+R-auto link dataset (mix.py)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

STUDY = Path(__file__).resolve().parents[1]


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"real_roads_{name}", STUDY / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _real_json(run: Path, f0: float, f1: float, polygon: float) -> None:
    run.mkdir(parents=True)
    frames = {"000000_10": {"kind": "mask", "precision": 0.9, "recall": 0.5, "f_score": f0, "iou": 0.5},
              "000001_10": {"kind": "mask", "precision": 0.9, "recall": 0.7, "f_score": f1, "iou": 0.6},
              "um_000000": {"kind": "polygon", "recall": polygon}}
    pooled = {"precision": 0.9, "recall": 0.6, "f_score": (f0 + f1) / 2, "iou": 0.55}
    (run / "real.json").write_text(json.dumps({"frames": frames, "pooled_masks": pooled, "left_out": []}))


def test_the_table_gives_means_intervals_and_paired_gains(tmp_path: Path) -> None:
    evaluate = _load("evaluate")
    for seed, (s, r) in enumerate([(0.40, 0.70), (0.50, 0.74), (0.45, 0.78)]):
        _real_json(tmp_path / f"unet-s-s{seed}", s, s, 0.5)
        _real_json(tmp_path / f"unet-r-auto-s{seed}", r, r, 0.99)
    _real_json(tmp_path / "unet-64x208-r-auto-s0", 0.7, 0.7, 0.9)  # another size: its own row
    _real_json(tmp_path / "unet-r-auto-fp-s1", 0.80, 0.80, 0.99)  # mirror and colour jitter: paired with R-auto
    _real_json(tmp_path / "notarun", 0.1, 0.1, 0.1)  # not a cell's name: ignored
    text = evaluate.table(tmp_path)
    rows = {tuple(c.strip() for c in line.split("|")[1:3]): line
            for line in text.splitlines() if line.startswith("| unet")}
    # R-auto's F over 3 seeds (70, 74, 78): 74.0 with the t-interval 74 ± 4.303·4/√3 = [64.1, 83.9]
    assert "| 3 | 74.0 [64.1, 83.9] | 74.0 [64.1, 83.9] | 74.0 [64.1, 83.9] |" in rows["unet", "R-auto"]
    assert "| 1 |" in rows["unet-64x208", "R-auto"]
    gain = next(line for line in text.splitlines() if "R-auto − S" in line)
    # paired differences 30, 24, 33 points: mean 29.0, t-interval 29 ± 4.303·4.583/√3 = [17.6, 40.4]
    assert "+29.0 [+17.6, +40.4]" in gain and "| 3 |" in gain
    assert "| 1 |" in rows["unet", "R-auto-fp"]
    fp = next(line for line in text.splitlines() if "R-auto-fp − R-auto" in line)
    assert "| 1 | +6.0 |" in fp  # seed 1 only: 80 − 74
    assert "notarun" not in text


def test_the_table_gives_the_rendered_f_where_runs_have_it(tmp_path: Path) -> None:
    evaluate = _load("evaluate")
    for seed, f in enumerate((0.50, 0.60)):
        _real_json(tmp_path / f"fastscnn-192x640-s-s{seed}", 0.4, 0.4, 0.5)
        (tmp_path / f"fastscnn-192x640-s-s{seed}" / "rendered.json").write_text(json.dumps({"f": f, "max_f": f}))
        _real_json(tmp_path / f"fastscnn-192x640-r-auto-s{seed}", 0.7, 0.7, 0.9)
        (tmp_path / f"fastscnn-192x640-r-auto-s{seed}" / "rendered.json").write_text(json.dumps({"f": f - 0.2}))
    _real_json(tmp_path / "fastscnn-192x640-r-auto-s2", 0.7, 0.7, 0.9)  # a seed not scored on the rendered frames
    _real_json(tmp_path / "unet-s-s0", 0.4, 0.4, 0.5)  # scored on the real frames only
    _real_json(tmp_path / "unet-r-auto-s0", 0.7, 0.7, 0.9)
    text = evaluate.table(tmp_path)
    r_auto = next(line for line in text.splitlines() if line.startswith("| fastscnn-192x640 | R-auto |"))
    # three seeds on the real frames, two of them on the rendered: the rendered F says so (30 and 40 points)
    assert "| 3 | 70.0 [70.0, 70.0] |" in r_auto and r_auto.endswith("| 35.0 [-28.5, 98.5] (n = 2) |")
    assert text.splitlines()[0].endswith("| polygon recall | F rendered |")
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")
            and line.split("|")[2].strip() == "S"}
    # 50 and 60: 55.0 ± 12.706·7.071/√2 = [-8.5, 118.5]
    assert rows["fastscnn-192x640"].endswith("| 55.0 [-8.5, 118.5] |")
    assert rows["unet"].endswith("| — |")
    gains = {line.split("|")[1].strip(): line for line in text.splitlines() if "R-auto − S" in line}
    assert gains["fastscnn-192x640"].endswith("| -20.0 [-20.0, -20.0] |")  # the same difference for both seeds
    assert gains["unet"].endswith("| — |")  # no rendered score: no gain


def test_rendered_scores_every_frame_of_a_tree_and_refuses_an_empty_one(tmp_path: Path, road_frame,
                                                                        tiny_road_checkpoint) -> None:
    """``evaluate.py --rendered``: a run's best checkpoint on a rendered tree's frames (F and MaxF from summed
    counts), written to RUN/rendered.json; a folder without frames is a one-line refusal."""
    import numpy as np

    from freespace.io.codecs import write_image

    evaluate = _load("evaluate")
    run = tmp_path / "fastscnn-s-s0"
    (run / "checkpoints").mkdir(parents=True)
    tiny_road_checkpoint(run / "checkpoints" / "best.ckpt", (32, 96), width=0.5)
    training = tmp_path / "tree" / "data_road" / "training"
    for folder in ("image_2", "gt_image_2"):
        (training / folder).mkdir(parents=True)
    for i in range(3):
        image, road = road_frame((75, 250), 900 + i)
        write_image(training / "image_2" / f"um_{i:06d}.png", image)
        label = np.zeros((*road.shape, 3), np.uint8)
        label[..., 0] = 255
        label[road.astype(bool), 2] = 255  # KITTI road colours: magenta road, red non-road
        write_image(training / "gt_image_2" / f"um_road_{i:06d}.png", label)
    result = evaluate.evaluate_rendered(run, tmp_path / "tree")
    assert result["images"] == 3 and 0.8 < result["f"] <= result["max_f"] <= 1  # the fixture finds the road
    assert json.loads((run / "rendered.json").read_text())["f"] == result["f"]
    with pytest.raises(SystemExit, match="no data_road/training/image_2 frames"):
        evaluate.evaluate_rendered(run, tmp_path / "empty")


def test_mix_links_both_sources_and_splits_them(tmp_path: Path) -> None:
    mix = _load("mix")
    syn = tmp_path / "syn" / "data_road" / "training"
    for folder, name in (("image_2", "um_000000.png"), ("gt_image_2", "um_road_000000.png")):
        (syn / folder).mkdir(parents=True)
        (syn / folder / name).write_bytes(b"png")
    drive = tmp_path / "raw" / "2011_09_26" / "2011_09_26_drive_0001_sync" / "image_02" / "data"
    drive.mkdir(parents=True)
    labels = tmp_path / "al" / "2011_09_26_drive_0001_sync"
    labels.mkdir(parents=True)
    for frame in ("0000000000", "0000000001", "0000000002"):
        (drive / f"{frame}.png").write_bytes(b"png")
        if frame != "0000000002":  # a frame without an autolabel is left out
            (labels / f"{frame}.png").write_bytes(b"label")
    splits = tmp_path / "splits"
    splits.mkdir()
    for part, frame in (("train", "0000000000"), ("val", "0000000001"), ("test", "0000000002")):
        (splits / f"{part}.txt").write_text(f"2011_09_26_drive_0001_sync/{frame}\n")
    out = tmp_path / "mix"
    lists = mix.build(tmp_path / "syn", tmp_path / "raw", tmp_path / "al", splits, out)
    assert lists == {"train": ["syn-um_000000", "2011_09_26_drive_0001_sync-0000000000"],
                     "val": ["2011_09_26_drive_0001_sync-0000000001"], "test": []}
    assert (out / "label" / "syn-um_000000.png").resolve() == (syn / "gt_image_2" / "um_road_000000.png").resolve()
    assert (out / "left" / "2011_09_26_drive_0001_sync-0000000000.png").read_bytes() == b"png"
    assert "label_encoding: kitti" in (out / "freespace.yaml").read_text()
    with pytest.raises(SystemExit, match="exists"):
        mix.build(tmp_path / "syn", tmp_path / "raw", tmp_path / "al", splits, out)


# --- hostile probe 4 (issue 59): no false success, nothing half made ---------------------------------------

def test_evaluate_with_no_real_frame_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                    tiny_road_checkpoint) -> None:
    """No real frame here (or every one trained on): a refusal, not F = 1 of no pixel."""
    from freespace.evaluation import real_frames

    evaluate = _load("evaluate")
    run = tmp_path / "fastscnn-s-s0"
    (run / "checkpoints").mkdir(parents=True)
    tiny_road_checkpoint(run / "checkpoints" / "best.ckpt", (32, 96), width=0.5)
    monkeypatch.setattr(real_frames, "available", lambda: [])
    with pytest.raises(SystemExit, match="no real frame"):
        evaluate.evaluate(run)
    assert not (run / "real.json").exists()


def test_publish_with_a_missing_example_leaves_no_model(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    publish = _load("publish")
    monkeypatch.setattr(publish, "ROOT", tmp_path)
    (tmp_path / "models").mkdir()
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    for name in ("checkpoints/best.ckpt", "real.json", "metrics.json"):
        (run / name).write_text("{}")
    raw = tmp_path / "raw" / "2011_09_26"
    for drive, frame in publish.EXAMPLES[:1]:  # the second example is missing
        (raw / drive / "image_02" / "data").mkdir(parents=True)
        (raw / drive / "image_02" / "data" / f"{frame}.png").write_bytes(b"png")
    with pytest.raises(SystemExit, match="not found.*nothing written"):
        publish.publish(run, "m", tmp_path / "raw")
    assert list((tmp_path / "models").iterdir()) == []


def _git_repo(folder: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
    env = {"GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t", "GIT_COMMITTER_EMAIL": "t@t",
           "HOME": str(folder), "PATH": "/usr/bin:/bin"}
    for cmd in (["init", "-q"], ["add", "."], ["commit", "-qm", "x"]):
        subprocess.run(["git", "-C", str(folder), *cmd], check=True, env=env)
    return folder / ".git"


def test_fetch_never_nests_a_drive_into_an_incomplete_one(tmp_path: Path) -> None:
    day = tmp_path / "raw" / "2011_09_26"
    d1 = day / "2011_09_26_drive_0001_sync" / "image_03" / "data"  # drive 0001 complete: skipped
    d1.mkdir(parents=True)
    (d1.parent.parent / "image_02" / "data").mkdir(parents=True)
    (d1.parent.parent / "image_02" / "data" / "0.png").write_bytes(b"png")
    for f in ("calib_cam_to_cam.txt", "calib_velo_to_cam.txt"):
        (day / f).write_text("x\n")
    d0 = day / "2011_09_26_drive_0000_sync"
    (d0 / "image_02").mkdir(parents=True)  # drive 0000 there but cut short: no velodyne_points
    udacity = _git_repo(tmp_path / "udacity", {"images/KITTI/2011_09_26/image_02/data/0.png": "png",
                                              "images/KITTI/2011_09_26/velodyne_points/data/0.bin": "bin"})
    env = {"SOFT": str(tmp_path / "nosoft"), "UDACITY": str(udacity), "RAW": str(tmp_path / "raw"),
           "PATH": "/usr/bin:/bin"}
    res = subprocess.run(["bash", str(STUDY / "fetch.sh")], capture_output=True, text=True, env=env)
    assert res.returncode == 2 and "exists but lacks velodyne_points/data" in res.stderr, res.stderr
    assert not (d0 / f"{d0.name}.part").exists() and "KITTI raw root" not in res.stdout
    (d0 / "image_02").rmdir()
    d0.rmdir()
    res = subprocess.run(["bash", str(STUDY / "fetch.sh")], capture_output=True, text=True, env=env)
    assert res.returncode == 0 and (d0 / "velodyne_points" / "data" / "0.bin").is_file(), res.stderr
    assert not list(day.glob("*.part"))


def test_collect_copies_a_record_whole_or_not_at_all(tmp_path: Path) -> None:
    import shutil

    study = tmp_path / "study"
    (study / "runs").mkdir(parents=True)
    for name in ("collect.sh", "evaluate.py"):
        shutil.copy(STUDY / name, study / name)
    work = tmp_path / "work" / "runs"
    for run, splits in (("unet-s-s0", True), ("unet-r-auto-s0", False)):
        _real_json(work / run, 0.5, 0.5, 0.5)
        (work / run / "config.yaml").write_text("model: unet\n")
        (work / run / "metrics.json").write_text("{}")
        if splits:
            (work / run / "splits").mkdir()
            (work / run / "splits" / "train.txt").write_text("a\n")
    res = subprocess.run(["bash", str(study / "collect.sh")], capture_output=True, text=True,
                         env={"WORK": str(tmp_path / "work"), "PYTHON": sys.executable, "PATH": "/usr/bin:/bin"})
    assert "skipped" in res.stderr and "unet-r-auto-s0" in res.stderr, res.stderr
    assert sorted(p.name for p in (study / "runs").iterdir()) == ["unet-s-s0"]
    assert (study / "runs" / "unet-s-s0" / "splits" / "train.txt").is_file()


class _RedIsRoad:
    """A stand-in teacher session: road logit +6 where the input's red channel is above ½, −6 where it is below."""

    def run(self, names, feeds):
        import numpy as np

        x = feeds["image"]
        road = np.where(x[:, 0] > 0.5, 6.0, -6.0).astype(np.float32)
        return [np.stack([-road, road], 1)]


def _one_train_one_val(tmp_path: Path) -> Path:
    """``tmp_path/splits``: drive 0001's frame 0 to train, frame 1 to validate, no test frame."""
    splits = tmp_path / "splits"
    splits.mkdir()
    for part, frame in (("train", "0000000000"), ("val", "0000000001"), ("test", "")):
        (splits / f"{part}.txt").write_text(f"2011_09_26_drive_0001_sync/{frame}\n" if frame else "")
    return splits


def test_student_labels_the_teacher_s_confident_road_beside_the_drives(tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2
    import numpy as np

    student = _load("student")
    drive = tmp_path / "raw" / "2011_09_26" / "2011_09_26_drive_0001_sync" / "image_02" / "data"
    drive.mkdir(parents=True)
    labels = tmp_path / "al" / "2011_09_26_drive_0001_sync"
    labels.mkdir(parents=True)
    for frame in ("0000000000", "0000000001"):
        (drive / f"{frame}.png").write_bytes(b"png")
        (labels / f"{frame}.png").write_bytes(b"label")
    splits = _one_train_one_val(tmp_path)
    frames = tmp_path / "other"
    frames.mkdir()
    image = np.zeros((36, 48, 3), np.uint8)
    image[18:] = (40, 40, 240)  # BGR: red below (road), dark above (not road)
    cv2.imwrite(str(frames / "a.png"), image)
    monkeypatch.setattr(student, "_sessions", lambda teachers: [(_RedIsRoad(), (16, 24))])
    out = tmp_path / "mix"
    report = student.build(tmp_path / "raw", tmp_path / "al", splits, frames, [tmp_path / "t"], out)
    assert report["counts"] == {"train": 2, "val": 1, "test": 0} and report["teacher_frames"] == 1
    assert (out / "splits" / "train.txt").read_text().split() == ["2011_09_26_drive_0001_sync-0000000000", "camvid-a"]
    label = cv2.imread(str(out / "label" / "camvid-a.png"))
    assert label.shape == (36, 48, 3)  # at the frame's size
    assert (label[24:] == student.ROAD_BGR).all() and (label[:12] == student.NON_ROAD_BGR).all()
    assert 0.4 < report["road_share"] < 0.6 and report["confident_share"] > 0.8
    with pytest.raises(SystemExit, match="exists"):
        student.build(tmp_path / "raw", tmp_path / "al", splits, frames, [tmp_path / "t"], out)
    twice = student.build(tmp_path / "raw", tmp_path / "al", splits, frames, [tmp_path / "t"], tmp_path / "mix2",
                          drive_copies=2)  # the drives' training frames listed twice, the rest once
    assert twice["counts"] == {"train": 3, "val": 1, "test": 0}
    assert (tmp_path / "mix2" / "splits" / "train.txt").read_text().split() == [
        "2011_09_26_drive_0001_sync-0000000000", "2011_09_26_drive_0001_sync-0000000000-c1", "camvid-a"]


def test_student_labels_several_frame_folders_each_with_its_prefix(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2
    import numpy as np

    student = _load("student")
    drive = tmp_path / "raw" / "2011_09_26" / "2011_09_26_drive_0001_sync" / "image_02" / "data"
    drive.mkdir(parents=True)
    (tmp_path / "al" / "2011_09_26_drive_0001_sync").mkdir(parents=True)
    for frame in ("0000000000", "0000000001"):
        (drive / f"{frame}.png").write_bytes(b"png")
        (tmp_path / "al" / "2011_09_26_drive_0001_sync" / f"{frame}.png").write_bytes(b"label")
    splits = _one_train_one_val(tmp_path)
    folders = [tmp_path / "city", tmp_path / "highway"]
    for folder, rows in zip(folders, (18, 9)):  # the city's road the lower half, the highway's the lower three quarters
        folder.mkdir()
        image = np.zeros((36, 48, 3), np.uint8)
        image[rows:] = (40, 40, 240)
        cv2.imwrite(str(folder / "f_000.png"), image)
    monkeypatch.setattr(student, "_sessions", lambda teachers: [(_RedIsRoad(), (16, 24))])
    report = student.build(tmp_path / "raw", tmp_path / "al", splits, folders, [tmp_path / "t"], tmp_path / "mix",
                           prefix=["camvid", "highway"])
    assert (tmp_path / "mix" / "splits" / "train.txt").read_text().split() == [
        "2011_09_26_drive_0001_sync-0000000000", "camvid-f_000", "highway-f_000"]
    assert report["teacher_frames"] == 2 and [s["prefix"] for s in report["sets"]] == ["camvid", "highway"]
    city, highway = report["sets"]
    assert 0.4 < city["road_share"] < 0.6 and 0.65 < highway["road_share"] < 0.85
    assert report["road_share"] == pytest.approx((city["road_share"] + highway["road_share"]) / 2)
    with pytest.raises(SystemExit, match="one --prefix"):
        student.build(tmp_path / "raw", tmp_path / "al", splits, folders, [tmp_path / "t"], tmp_path / "mix2")
    assert not (tmp_path / "mix2").exists()  # refused before anything is written
    assert report["opened"] is None
    opened = student.build(tmp_path / "raw", tmp_path / "al", splits, folders, [tmp_path / "t"], tmp_path / "mix3",
                           prefix=["camvid", "highway"], opening=(0.2, 1.0))
    assert opened["opened"] == [0.2, 1.0] and opened["confident_share"] < report["confident_share"]


def test_student_opens_the_confident_not_road_near_the_teacher_s_road() -> None:
    import numpy as np

    student = _load("student")
    prob = np.zeros((20, 8), np.float32)
    prob[10:] = 1  # the teachers' road: the lower half
    prob[:, 6:] = 0.3  # an unsure strip: don't care in the class map, and not opened
    classes = np.where(prob > 0.9, 1, np.where(prob < 0.1, 0, 255)).astype(np.uint8)
    out = student.opened(classes, prob, 0.9, (0.2, 1.0))  # within 4 rows of the road
    assert (out[6:10, :6] == 255).all() and (out[:6, :6] == 0).all()  # the band above the road opened, not beyond
    assert (out[10:] == classes[10:]).all() and (out[:, 6:] == classes[:, 6:]).all()
    beside = np.zeros((20, 8), np.float32)
    beside[10:, :3] = 1  # road on the left only: the not road right of it, in its top rows, opened
    c = np.where(beside > 0.9, 1, 0).astype(np.uint8)
    side = student.opened(c, beside, 0.9, (0.2, 0.5))  # rows from 15 (the road's lower half) stay
    assert (side[10:15, 3:7] == 255).all() and (side[15:, 3:] == 0).all() and (side[10:15, 7] == 0).all()


def test_student_fills_the_drives_don_t_care_with_the_drive_teacher_s_confident_labels(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2
    import numpy as np

    student = _load("student")
    drive = tmp_path / "raw" / "2011_09_26" / "2011_09_26_drive_0001_sync" / "image_02" / "data"
    labels = tmp_path / "al" / "2011_09_26_drive_0001_sync"
    drive.mkdir(parents=True)
    labels.mkdir(parents=True)
    image = np.zeros((36, 48, 3), np.uint8)
    image[18:] = (40, 40, 240)  # BGR: red below (road to the teacher), dark above
    label = np.zeros((36, 48, 3), np.uint8)  # don't care but for the autolabel's rows 30… (road) and 0…5 (not)
    label[30:] = student.ROAD_BGR
    label[:6] = student.NON_ROAD_BGR
    label[30:, :4] = student.NON_ROAD_BGR  # the autolabel wins where it labels, against the teacher
    for frame in ("0000000000", "0000000001"):
        cv2.imwrite(str(drive / f"{frame}.png"), image)
        cv2.imwrite(str(labels / f"{frame}.png"), label)
    splits = _one_train_one_val(tmp_path)
    frames = tmp_path / "other"
    frames.mkdir()
    cv2.imwrite(str(frames / "a.png"), image)
    seen = []
    monkeypatch.setattr(student, "_sessions", lambda teachers: seen.append(teachers) or [(_RedIsRoad(), (16, 24))])
    out = tmp_path / "mix"
    report = student.build(tmp_path / "raw", tmp_path / "al", splits, frames, [tmp_path / "t"], out, drive_copies=2,
                           drive_teachers=[tmp_path / "d"])
    assert seen[0] == [tmp_path / "d"] and report["drive_teachers"] == [str(tmp_path / "d")]
    name = "2011_09_26_drive_0001_sync-0000000000"
    for copy in (name, f"{name}-c1"):  # each copy is a file with the filled label, no longer a link
        path = out / "label" / f"{copy}.png"
        filled = cv2.imread(str(path))
        assert not path.is_symlink()
        assert (filled[20:30] == student.ROAD_BGR).all() and (filled[6:12] == student.NON_ROAD_BGR).all()
        assert (filled[30:, :4] == student.NON_ROAD_BGR).all() and (filled[:6] == student.NON_ROAD_BGR).all()
    val = out / "label" / "2011_09_26_drive_0001_sync-0000000001.png"
    assert val.is_symlink() and (cv2.imread(str(val)) == label).all()  # validation keeps its autolabel
    assert report["drives_filled"]["frames"] == 1
    assert report["drives_filled"]["labelled_before"] < 0.5 < report["drives_filled"]["labelled_after"]
    assert (cv2.imread(str(labels / "0000000000.png")) == label).all()  # the autolabel tree is untouched
    assert report["drives_filled"]["changed"] == 0.0
    first = student.build(tmp_path / "raw", tmp_path / "al", splits, frames, [tmp_path / "t"], tmp_path / "mix2",
                          drive_teachers=[tmp_path / "d"], drive_teacher_first=True)
    won = cv2.imread(str(tmp_path / "mix2" / "label" / f"{name}.png"))
    assert (won[30:, :4] == student.ROAD_BGR).all()  # the teacher's confident road wins over the autolabel
    assert (won[20:30] == student.ROAD_BGR).all() and (won[:6] == student.NON_ROAD_BGR).all()
    assert first["drives_filled"]["teacher_first"] and first["drives_filled"]["changed"] > 0


def test_labelcheck_scores_the_teacher_s_labels_against_human_road(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2
    import numpy as np

    labelcheck = _load("labelcheck")
    image = np.zeros((36, 48, 3), np.uint8)
    image[18:] = (40, 40, 240)  # BGR: red below (road to the stand-in teacher), dark above
    human = np.zeros((36, 48), np.uint8)
    human[24:] = 255  # the human road: the lower third; the teacher also takes rows 18-23
    k15 = tmp_path / "k15"
    for sub in ("image_2", "road_mask"):
        (k15 / sub).mkdir(parents=True)
    autolabels = tmp_path / "al"
    autolabels.mkdir()
    under = np.zeros((36, 48, 3), np.uint8)
    under[30:] = labelcheck.student.ROAD_BGR
    under[18:24] = labelcheck.student.NON_ROAD_BGR  # the autolabel is right where the teacher is wrong
    for frame in labelcheck.KITTI2015_FRAMES:
        cv2.imwrite(str(k15 / "image_2" / f"{frame}.png"), image)
        cv2.imwrite(str(k15 / "road_mask" / f"{frame}.png"), human)
        cv2.imwrite(str(autolabels / f"{frame}.png"), under)
    monkeypatch.setattr(labelcheck.student, "_sessions", lambda teachers: [(_RedIsRoad(), (12, 16))] * len(teachers))
    result = labelcheck.check_kitti2015([tmp_path / "t"], autolabels, k15)
    assert result["autolabel"] == {"labelled": 33.3, "road_as_road": 50.0, "road_as_not": 0.0, "precision": 100.0}
    # filled: every row labelled but the one where the teacher's upsampled probability crosses ½ (don't care)
    assert result["filled"] == {"labelled": 97.2, "road_as_road": 100.0, "road_as_not": 0.0, "precision": 100.0}
    # the teacher first: its road wins in rows 19-23 (false road: 5 of the 17 rows labelled road); in rows 17-18,
    # where its upsampled probability crosses ½, it is unsure and the autolabel stays
    assert result["teacher first"]["precision"] == pytest.approx(100 * 12 / 17, abs=0.1)
    cv2.imwrite(str(autolabels / "000001_10.png"), under[:10])
    with pytest.raises(SystemExit, match="frame's size"):
        labelcheck.check_kitti2015([tmp_path / "t"], autolabels, k15)

    camvid = tmp_path / "camvid"
    for sub in ("val", "valannot", "train", "duskannot"):
        (camvid / sub).mkdir(parents=True)
    classes = np.full((36, 48), 1, np.uint8)
    classes[24:] = labelcheck.CAMVID_ROAD
    classes[:6] = labelcheck.CAMVID_VOID  # left out of every count
    for images, masks in (("val", "valannot"), ("train", "duskannot")):
        cv2.imwrite(str(camvid / images / "a.png"), image)
        cv2.imwrite(str(camvid / masks / "a.png"), classes)
    result = labelcheck.check_camvid([tmp_path / "t"], [tmp_path / "r"], camvid, ("confident", "temporal"))
    assert sorted(result) == sorted(f"{part}, {name}{source}" for part in ("val", "dusk")
                                    for name in ("teachers", "raw teachers", "all") for source in ("", " / temporal"))
    assert result["val, all / temporal"] == result["val, all"]  # one frame: nothing to carry
    # rows 6-35 counted (0-5 void); rows 17-18 don't care, 19-35 road (12 of them the human road)
    assert result["val, all"] == {"labelled": pytest.approx(100 * 28 / 30, abs=0.1), "road_as_road": 100.0,
                                  "road_as_not": 0.0, "precision": pytest.approx(100 * 12 / 17, abs=0.1)}


def test_labelcheck_s_appearance_source_takes_release() -> None:
    """``labels_of`` passes ``release`` to the graph cut: a grey far road the teacher is sure is not road is
    relabelled road only with it (the green verge above stays not road)."""
    import numpy as np

    labelcheck = _load("labelcheck")
    rng = np.random.default_rng(0)
    image = np.empty((80, 120, 3), np.uint8)
    image[:40], image[40:] = (60, 140, 60), (110, 110, 110)
    image = np.clip(image.astype(int) + rng.integers(-8, 9, image.shape), 0, 255).astype(np.uint8)
    prob = np.zeros((80, 120), np.float32)
    prob[60:] = 0.97  # the teacher: road only in the near half of the grey road
    road = [(label == labelcheck.student.ROAD_BGR).all(2) for label in
            (labelcheck.labels_of("appearance", [image], [prob], release)[0] for release in ((0.0, 1.0), (0.3, 1.0)))]
    assert not road[0][40:60].any() and road[1][40:60].mean() > 0.95 and not road[1][:36].any()


def _rebuild(tmp_path: Path, frames: int, out: Path) -> subprocess.CompletedProcess:
    (tmp_path / "raw" / "2011_09_26").mkdir(parents=True, exist_ok=True)
    camvid = tmp_path / f"camvid{frames}"
    camvid.mkdir(exist_ok=True)
    for i in range(frames):
        (camvid / f"f{i:03d}.png").write_bytes(b"png")
    env = {"RAW": str(tmp_path / "raw"), "FRAMES": str(camvid), "OUT": str(out), "PYTHON": sys.executable,
           "PATH": "/usr/bin:/bin"}
    return subprocess.run(["bash", str(STUDY / "rebuild.sh")], capture_output=True, text=True, env=env)


def test_rebuild_refuses_an_output_in_the_repository_or_an_input_and_a_wrong_frame_folder(tmp_path: Path) -> None:
    res = _rebuild(tmp_path, 367, STUDY / "rebuilt" / "deeper")
    assert res.returncode == 2 and "lies inside" in res.stderr and "the repository" in res.stderr, res.stderr
    assert not (STUDY / "rebuilt").exists()
    res = _rebuild(tmp_path, 367, tmp_path / "raw" / "out")  # inside an input
    assert res.returncode == 2 and "lies inside" in res.stderr, res.stderr
    assert not (tmp_path / "raw" / "out").exists()
    res = _rebuild(tmp_path, 366, tmp_path / "out")
    assert res.returncode == 2 and "does not hold CamVid's 367 training images" in res.stderr, res.stderr
    assert not (tmp_path / "out").exists()


def test_rebuild_pins_what_the_model_card_names() -> None:
    """rebuild.sh's commits, teacher hashes and labels hash are the ones models/real-road-fast's card gives."""
    import re

    script = (STUDY / "rebuild.sh").read_text()
    card = (STUDY.parents[1] / "models" / "real-road-fast" / "README.md").read_text()
    commits = dict(re.findall(r"(FIRST|TEACHERS|DATASET|TRAINING)=([0-9a-f]{7})", script))
    assert f"git show {commits['FIRST']}:models/real-road-fast" in card
    assert (f"Teachers at commit {commits['TEACHERS']}, the look-checked tree and the student dataset at "
            f"{commits['DATASET']}, the training at {commits['TRAINING']}") in " ".join(card.split())
    hashes = re.findall(r"\b[0-9a-f]{64}\b", script)
    assert len(hashes) == 4
    for h in hashes[:3]:
        assert f"`{h[:16]}…`" in card
    assert hashes[3] in card


def test_errors_puts_the_false_road_on_its_class_and_the_missed_road_in_its_place() -> None:
    import numpy as np

    errors = _load("errors")
    raw = np.zeros((30, 40, 3), np.uint8)
    raw[:] = errors.CITYSCAPES["sky"]
    raw[10:] = errors.CITYSCAPES["road"]
    raw[10:, 30:] = errors.CITYSCAPES["sidewalk"]
    raw[20:25, 0:4] = (5, 3, 140)  # a car, its colour blended as a scaled frame's edges are
    classes, names = errors.class_names(raw)
    assert names[classes[22, 1]] == "car" and names[classes[0, 0]] == "sky"
    road = (classes == names.index("road"))
    valid = np.ones_like(road)
    pred = road.copy()
    pred[10:13] = False  # the far road (rows 10-16 are the top third of the road's rows 10-29) partly missed
    pred[15:29, :8] = False  # the road around the car missed
    pred[25:, 30:] = True  # the pavement taken for road
    counts = {"fp": {}, "road": {}, "missed": {}, "tp": {}}
    errors.tally(pred, road, valid, classes, names, 0.1, counts)  # beside: within 3 rows/columns of the car
    s = errors.summary(counts)
    assert s["false_road_by_class"] == {"sidewalk": 1.0} and s["false_road_pixels"] == 5 * 10
    where = errors.places(road, classes, names, 0.1)
    assert where[10, 20] == 1 and where[20, 20] == 2 and where[22, 6] == 0 and where[22, 8] == 2
    beside = s["missed_road_by_place"]["beside a vehicle"]
    assert beside["recall"] == 0.0  # every road pixel within 3 of the car is in the missed block
    assert 0 < s["missed_road_by_place"]["far"]["recall"] < 1 and s["missed_road_by_place"]["elsewhere"]["recall"] > 0.9
    assert sum(v["share"] for v in s["missed_road_by_place"].values()) == pytest.approx(1.0)
    assert s["recall"] == pytest.approx(counts["tp"]["all"] / road.sum())


def test_errors_reads_camvid_ids() -> None:
    import numpy as np

    errors = _load("errors")
    classes, names = errors.class_names(np.array([[3, 4], [8, 200]], np.uint8))
    assert [names[i] for i in classes.ravel()] == ["road", "pavement", "car", "void"]


def test_errors_refuses_a_missing_model_in_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    errors = _load("errors")
    for model, said in ((f"m={tmp_path / 'none.onnx'}", "no such file"), ("m", "NAME=PATH")):
        monkeypatch.setattr(sys, "argv", ["errors.py", "--real-dev", str(tmp_path), "--model", model,
                                          "--out", str(tmp_path / "e.json")])
        with pytest.raises(SystemExit) as exit_:
            errors.main()
        assert exit_.value.code == 2 and said in capsys.readouterr().err
    assert not (tmp_path / "e.json").exists()


def test_errors_sweeps_the_threshold_over_each_set_and_the_pool(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2
    import numpy as np

    import freespace.inference.predictor

    errors = _load("errors")
    label = np.full((8, 20), 2, np.uint8)
    label[:, 10:] = 3  # CamVid's road: the right half
    for images, labels, frames in (("val", "valannot", 2), ("train", "duskannot", 1)):
        for folder in (images, labels):
            (tmp_path / "camvid" / folder).mkdir(parents=True)
        for i in range(frames):
            cv2.imwrite(str(tmp_path / "camvid" / images / f"f{i}.png"), np.zeros((8, 20, 3), np.uint8))
            cv2.imwrite(str(tmp_path / "camvid" / labels / f"f{i}.png"), label)

    class Ramp:  # road probability (column + ½) / 20
        def __init__(self, **_: object) -> None:
            pass

        def predict(self, images: list[np.ndarray]) -> list[np.ndarray]:
            return [np.broadcast_to((np.arange(20) + 0.5) / 20, (8, 20)).astype(np.float32) for _ in images]

    monkeypatch.setattr(freespace.inference.predictor, "Predictor", Ramp)
    out = errors.sweep({"m": tmp_path / "m.onnx"}, tmp_path, threads=1)
    assert set(out) == {"camvid_val", "camvid_dusk", "camvid_pool"}  # KITTI's frames are not here
    curve = out["camvid_pool"]["m"]
    at = {t: i for i, t in enumerate(curve["th"])}
    assert curve["P"][at[0.5]] == curve["R"][at[0.5]] == curve["F"][at[0.5]] == 1.0
    assert curve["P"][at[0.05]] == pytest.approx(10 / 19) and curve["R"][at[0.05]] == 1.0  # columns 1-19
    assert curve["R"][at[0.95]] == pytest.approx(1 / 10) and out["camvid_val"]["m"] == curve
    seen = []
    monkeypatch.setattr(freespace.inference.predictor, "Predictor", lambda **kw: seen.append(kw) or Ramp())
    errors.sweep({"m": tmp_path / "m.ckpt"}, tmp_path, threads=1, tta=True)
    errors.sweep({"m": tmp_path / "m.ckpt"}, tmp_path, threads=1, crop_top=0.35)
    assert seen == [{"checkpoint": tmp_path / "m.ckpt", "tta": True, "crop_top": 0.0},  # as predict --tta runs it
                    {"checkpoint": tmp_path / "m.ckpt", "tta": False, "crop_top": 0.35}]  # and --crop-top 0.35


def _bench(tmp_path: Path, name: str, f: float, models: int = 1) -> Path:
    """A bench/real_bench.py output: every set at F ``f``; KITTI's other streets with 12 frames of growing road."""
    rows = [{"tp": 10 * i, "fp": i, "fn": 2 * i} for i in range(1, 13)]  # the 9 widest: i = 4…12
    sets = {k: {f"m{j}": {"f_score": f, "precision": f, "recall": f} for j in range(models)}
            for k in ("kitti2015", "kitti_dev", "camvid_val", "camvid_dusk", "camvid_pool")}
    for scores in sets["kitti_dev"].values():
        scores["per_frame"] = rows
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps({"machine": "test", "sets": sets}))
    return path


def _finished_run(tmp_path: Path) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    for f in ("config.yaml", "inputs.json", "metrics.csv", "metrics.json"):
        (run / f).write_text(f)
    (tmp_path / "report.json").write_text("{}")
    return run


def test_record_writes_a_cell_once_with_the_wide_frames_and_pairs_cells_with_their_control(tmp_path: Path) -> None:
    record = _load("record")
    run = _finished_run(tmp_path)
    for seed, (a, b) in enumerate([(0.80, 0.78), (0.84, 0.80), (0.82, 0.81)]):
        for name, f in (("cell", a), ("control", b)):
            record.record_cell(run, _bench(tmp_path, f"{name}{seed}", f), tmp_path / "report.json",
                               tmp_path / "look" / f"{name}-s{seed}")
    written = json.loads((tmp_path / "look" / "cell-s0" / "bench.json").read_text())
    wide = written["sets"]["kitti_dev_wide9"]  # rows 4…12: tp 720, fp 72, fn 144
    assert wide == {"frames": 9, "precision": 720 / 792, "recall": 720 / 864}
    assert "per_frame" not in written["sets"]["kitti_dev"] and list(written["sets"])[:3] == [
        "kitti2015", "kitti_dev", "kitti_dev_wide9"]
    assert (tmp_path / "look" / "cell-s0" / "student.json").read_text() == "{}"
    with pytest.raises(ValueError, match="exists"):
        record.record_cell(run, _bench(tmp_path, "again", 0.9), tmp_path / "report.json", tmp_path / "look" / "cell-s0")
    with pytest.raises(ValueError, match="one --model"):
        record.record_cell(run, _bench(tmp_path, "two", 0.9, models=2), tmp_path / "report.json", tmp_path / "x")
    assert not (tmp_path / "x").exists() and not (tmp_path / "x.part").exists()
    paired = record.pair(str(tmp_path / "look" / "cell"), str(tmp_path / "look" / "control"), [0, 1, 2])
    # differences 2, 4, 1 points: mean 2.33, t interval 2.33 ± 4.303 · 1.528 / √3 = [−1.46, +6.13]
    assert paired["kitti_dev"] == {"differences": [2.0, 4.0, 1.0], "mean": 2.33, "look": [80.0, 84.0, 82.0],
                                   "before": [78.0, 80.0, 81.0], "interval": [-1.46, 6.13]}
    assert paired["wide9_recall"]["differences"] == [0.0, 0.0, 0.0]


def test_record_refuses_a_missing_input_in_one_line_and_writes_nothing(tmp_path: Path) -> None:
    run = _finished_run(tmp_path)
    (run / "metrics.json").unlink()
    res = subprocess.run([sys.executable, str(STUDY / "record.py"), "cell", "--run", str(run), "--bench",
                          str(_bench(tmp_path, "b", 0.9)), "--report", str(tmp_path / "report.json"), "--out",
                          str(tmp_path / "rec")], capture_output=True, text=True)
    assert res.returncode == 2 and "metrics.json is not a file" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "rec").exists()
    res = subprocess.run([sys.executable, str(STUDY / "record.py"), "pair", "--cells", str(tmp_path / "none"),
                          "--control", str(tmp_path / "none"), "--seeds", "0", "--key", "k", "--paired",
                          str(tmp_path / "paired.json")], capture_output=True, text=True)
    assert res.returncode == 2 and "holds no bench.json" in res.stderr and not (tmp_path / "paired.json").exists()


def test_shifted_writes_both_cameras_beside_the_masks_and_refuses_its_input(tmp_path: Path) -> None:
    import cv2
    import numpy as np

    shifted = _load("shifted")
    grey = np.full((2, 3, 3), 128, np.uint8)  # BGR
    washed = shifted.shift(grey, "washed")[0, 0]  # RGB 0.35 + 0.5·0.502·(0.9, 1.0, 1.1) → BGR
    assert washed.tolist() == [round(255 * (0.35 + 0.5 * 128 / 255 * g)) for g in (1.1, 1.0, 0.9)]
    assert shifted.shift(np.full((1, 1, 3), 255, np.uint8), "dark")[0, 0].tolist() == [204, 242, 255]  # clipped red
    dev = tmp_path / "dev"
    for folder in ("images", "masks"):
        (dev / "kitti_dev" / folder).mkdir(parents=True)
    cv2.imwrite(str(dev / "kitti_dev" / "images" / "a.png"), grey)
    cv2.imwrite(str(dev / "kitti_dev" / "masks" / "a.png"), grey)
    assert shifted.write_shifted(dev, tmp_path / "out") == 1
    for name in ("washed", "dark"):
        assert cv2.imread(str(tmp_path / "out" / name / "kitti_dev" / "images" / "a.png")).tolist() == \
            shifted.shift(grey, name).tolist()
        assert (tmp_path / "out" / name / "kitti_dev" / "masks" / "a.png").read_bytes() == \
            (dev / "kitti_dev" / "masks" / "a.png").read_bytes()
    with pytest.raises(ValueError, match="exists"):
        shifted.write_shifted(dev, tmp_path / "out")
    for out, said in ((dev / "inside", "lies inside"), (tmp_path / "x", "holds no kitti_dev")):
        real_dev = dev if said == "lies inside" else tmp_path / "empty"
        res = subprocess.run([sys.executable, str(STUDY / "shifted.py"), "--real-dev", str(real_dev), "--out",
                              str(out)], capture_output=True, text=True)
        assert res.returncode == 2 and said in res.stderr and "Traceback" not in res.stderr and not out.exists()


def test_record_compares_unpaired_cells_on_shifted_copies_with_welch(tmp_path: Path) -> None:
    from scipy.stats import ttest_ind

    record = _load("record")
    a, b = [80.0, 84.0, 83.0], [78.0, 77.5, 80.0, 76.0]
    ci = ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
    assert record.welch(a, b) == pytest.approx((sum(a) / 3 - sum(b) / 4, ci.low, ci.high))
    models = {"c0": (0.80, 0.70), "c1": (0.84, 0.74), "k0": (0.78, 0.72), "k1": (0.76, 0.70)}
    sweeps = {}
    for i, shift in enumerate(("washed", "dark")):
        curves = {m: {"th": [0.4, 0.5], "F": [0.0, f[i]]} for m, f in models.items()}
        sweeps[shift] = tmp_path / f"{shift}.json"
        sweeps[shift].write_text(json.dumps({"sets": {"kitti_dev": curves}}))
    out = record.shifted(sweeps, ["c0", "c1"], ["k0", "k1"])
    assert out["mean_over_shifts"] == {"c0": 75.0, "c1": 79.0, "k0": 75.0, "k1": 73.0}
    assert out["cells_minus_control"] == 3.0 and out["f_at_0.5"]["dark"]["c1"] == 74.0
    with pytest.raises(ValueError, match="not scored"):
        record.shifted(sweeps, ["c0", "gone"], ["k0", "k1"])


def test_padded_pads_one_camera_s_frames_to_the_aspect_and_links_the_rest(tmp_path: Path) -> None:
    import cv2
    import numpy as np

    padded = _load("padded")
    image = np.full((4, 5, 3), 7, np.uint8)
    wide = padded.pad_to_aspect(image, 2.0)  # 8 wide: 1 column left, 2 right
    assert wide.shape == (4, 8, 3) and wide[:, 1:6].tolist() == image.tolist()
    assert not wide[:, :1].any() and not wide[:, 6:].any()
    assert padded.pad_to_aspect(image, 1.0) is image  # already wider
    root = tmp_path / "mix"
    for sub in ("left", "label"):
        (root / sub).mkdir(parents=True)
        for name in ("camvid-a.png", "drive-b.png"):
            cv2.imwrite(str(root / sub / name), image)
    (root / "splits").mkdir()
    (root / "splits" / "train.txt").write_text("camvid-a\ndrive-b\n")
    out = tmp_path / "pad"
    res = subprocess.run([sys.executable, str(STUDY / "padded.py"), "--root", str(root), "--out", str(out),
                          "--aspect", "2"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    for sub in ("left", "label"):
        assert cv2.imread(str(out / sub / "camvid-a.png")).tolist() == wide.tolist()
        assert (out / sub / "drive-b.png").resolve() == (root / sub / "drive-b.png").resolve()
    assert (out / "splits" / "train.txt").read_text() == "camvid-a\ndrive-b\n"
    for args, said in ((["--root", str(root), "--out", str(out)], "exists"),
                       (["--root", str(root), "--out", str(root / "x")], "lies inside"),
                       (["--root", str(tmp_path / "none"), "--out", str(tmp_path / "y")], "no left/"),
                       (["--root", str(root), "--out", str(tmp_path / "z"), "--aspect", "-1"], "must be positive"),
                       (["--root", str(root), "--out", str(tmp_path / "z"), "--cut-top", "0.7"], "must be in")):
        res = subprocess.run([sys.executable, str(STUDY / "padded.py"), *args], capture_output=True, text=True)
        assert res.returncode == 2 and said in res.stderr and "Traceback" not in res.stderr
    assert not (root / "x").exists() and not (tmp_path / "y").exists() and not (tmp_path / "z").exists()
    cut = tmp_path / "cut"
    res = subprocess.run([sys.executable, str(STUDY / "padded.py"), "--root", str(root), "--out", str(cut),
                          "--aspect", "0", "--cut-top", "0.5"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    for sub in ("left", "label"):
        for name in ("camvid-a.png", "drive-b.png"):  # every frame: its top 2 of 4 rows cut, no padding
            assert cv2.imread(str(cut / sub / name)).tolist() == image[2:].tolist()
    (root / "left" / "camvid-c.png").write_bytes(b"not a png")
    res = subprocess.run([sys.executable, str(STUDY / "padded.py"), "--root", str(root), "--out", str(tmp_path / "w")],
                         capture_output=True, text=True)
    assert res.returncode == 1 and "camvid-c.png is not an image" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "w").exists() and not (tmp_path / "w.partial").exists()
