"""Hostile cases of issue 44, classes C, D and F: a run's record says what it used, labels belong to their frames,
autolabel checks its inputs.

C. A run's record says what it used (silent wrong):
   * C6: config.yaml keeps every path resolved (labels, encoder_weights, splits_dir, cache_dir, through symbolic
     links); `train --config` from another folder, `--resume` with the same files by absolute paths and
     `reproduce` from another folder all work.
   * C7: a run records the content (SHA-256) of its weights file and label tree (inputs.json); a resumed run and
     the `reproduce` cells trained from files whose content changed in between are refused, and the tables warn.
   * C8: a YAML key given twice (config, freespace.yaml) and an option in its old and new spelling are refused;
     YAML merge keys still read, and no YAML tag makes an object.
   * C9: epochs are numbered from 1 in metrics.csv, metrics.json (`first_epoch: 1`) and index.json alike; the
     0-based files of older runs read right (the studies' published tables rebuild byte for byte: studies/*/tests).
D. Labels must belong to the frames (silent wrong):
   * D10: confidence maps, predictions and overlays given as a label tree are refused, naming what they look like.
   * D11: a label tree that autolabel made for another dataset root or split is refused (train --labels,
     reproduce --autolabels); a symbolic link to the right tree is taken.
   * D12: a training set without a labelled pixel is refused before training (a label tree, the dataset's own
     labels), and an epoch without one fails the run.
   * D13: reproduce --autolabels with no cell that reads it is refused.
F. Autolabel's inputs and messages:
   * F17: --cache-dir equal to, inside or holding --out, or inside the dataset, is refused before any file is
     written.
   * F18: --disparity-source none is not offered (and refused in Python).
   * F19: --disparity-source sgbm on a tree without right images is refused up front.
   * F20: --disparity-dir with a source that ignores it is refused (autolabel and generate); per-frame failures
     name flags.
   * F21: a swapped pair is reported as one (one image: the error or warning says so; a dataset: one line
     counting frames).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from freespace.cli import main
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.engine.config import TrainConfig, read_config_yaml
from freespace.errors import CorruptFileError, InvalidOptionError
from freespace.io.codecs import encode_image, load_yaml, read_image

SIZE = ["--image-size", "64x96"]


def _render(factory: pytest.TempPathFactory, name: str, seed: int) -> Path:
    root = factory.mktemp(name) / "syn"
    write_dataset(root, 16, seed=seed, config=SynthConfig(width=128, height=96, frames_per_scenario=2),
                  progress=False)
    return root


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _render(tmp_path_factory, "tiny", 2)


@pytest.fixture(scope="module")
def other(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Another dataset with the same frame names (other images)."""
    return _render(tmp_path_factory, "other", 5)


@pytest.fixture(scope="module")
def labels(tiny: Path) -> Path:
    out = tiny.parent / "lab"
    assert main(["-q", "autolabel", "--dataset", "synth", "--root", str(tiny), "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def other_labels(other: Path) -> Path:
    out = other.parent / "lab"
    assert main(["-q", "autolabel", "--dataset", "synth", "--root", str(other), "--out", str(out)]) == 0
    return out


def _err(capsys: pytest.CaptureFixture, args: list[str], *match: str, code: int = 2) -> str:
    capsys.readouterr()
    assert main(["-q", *args]) == code
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    for m in match:
        assert m in err, err
    assert "\x00" not in err and "Traceback" not in err
    return err


def _train(*args: str) -> list[str]:
    return ["train", "--dataset", "synth", "--model", "segnet", "--batch-size", "4", "--no-progress", *SIZE, *args]


def _copy_tree(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst, symlinks=True)
    manifest = dst / ".freespace"
    if manifest.exists():
        shutil.rmtree(manifest)
    return dst


# --- C6: paths resolved in the record ---------------------------------------------------------------------


def test_config_yaml_keeps_every_path_resolved(tiny: Path, labels: Path, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "w.pth").write_bytes(b"x")
    (tmp_path / "imagenet").write_bytes(b"a file named as weights")  # a name of weights stays a name
    link = tmp_path / "link"
    link.symlink_to(labels)
    monkeypatch.chdir(tmp_path)
    d = TrainConfig(dataset="synth", root=os.path.relpath(tiny), out="run", labels="link", encoder_weights="w.pth",
                    model="unet", splits_dir="s", cache_dir="~/c").to_dict()
    assert d["labels"] == str(labels.resolve())
    assert d["encoder_weights"] == str(tmp_path.resolve() / "w.pth")
    assert d["root"] == str(tiny.resolve()) and d["out"] == str(tmp_path.resolve() / "run")
    assert d["splits_dir"] == str(tmp_path.resolve() / "s") and not d["cache_dir"].startswith("~")
    for name in ("imagenet", "ssl", "swsl"):
        assert TrainConfig(dataset="synth", root="r", out="o", model="unet",
                           encoder_weights=name).to_dict()["encoder_weights"] == name
    assert TrainConfig(dataset="synth", root="r", out="o", model="unet",
                       encoder_weights="sub/x.pth").to_dict()["encoder_weights"] \
        == str(tmp_path.resolve() / "sub/x.pth")
    # a YAML file's ~/… is the home folder, as a shell's: the file is found, not looked for under "~"
    monkeypatch.setenv("HOME", str(tmp_path))
    (tmp_path / "home.yaml").write_text("labels: ~/link\nencoder_weights: ~/w.pth\n")
    config = TrainConfig(dataset="synth", root=str(tiny), out="run", model="unet",
                         **read_config_yaml(tmp_path / "home.yaml"))
    assert config.labels == str(tmp_path / "link") and Path(config.encoder_weights).is_file()


def test_a_run_works_from_another_folder_and_resumes_by_absolute_paths(tiny: Path, labels: Path, tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch,
                                                                       capsys: pytest.CaptureFixture) -> None:
    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir()
    there.mkdir()
    shutil.copytree(labels, here / "lab", symlinks=True)
    monkeypatch.chdir(here)
    assert main(_train("--root", os.path.relpath(tiny), "--labels", "lab", "--out", "run", "--epochs", "1")) == 0
    record = read_config_yaml(here / "run" / "config.yaml")
    assert record["labels"] == str((here / "lab").resolve()) and Path(record["root"]).is_absolute()
    monkeypatch.chdir(there)
    (there / "lab").mkdir()  # another folder of the same name here: the record must not read it
    config = TrainConfig(**{**read_config_yaml(here / "run" / "config.yaml"), "out": str(there / "run2")})
    config.check()
    assert config.to_dict()["labels"] == record["labels"]
    # the same run resumed from elsewhere, every file named by its absolute path
    assert main(_train("--root", str(tiny), "--labels", str(here / "lab"), "--out", str(here / "run"), "--epochs",
                       "2", "--resume")) == 0
    metrics = json.loads((here / "run" / "metrics.json").read_text())
    assert metrics["epochs_run"] == 2
    # C7: the label tree changed since: resuming again is refused, in one line, before any work
    label = here / "lab" / "um_000000.png"
    image = read_image(label)
    image[:8] = 0
    label.write_bytes(encode_image(image))
    before = (here / "run" / "checkpoints" / "last.ckpt").read_bytes()
    _err(capsys, _train("--root", str(tiny), "--labels", str(here / "lab"), "--out", str(here / "run"), "--epochs",
                        "3", "--resume"), "other contents of --labels", "sha256")
    assert (here / "run" / "checkpoints" / "last.ckpt").read_bytes() == before
    # C9: one numbering: metrics.csv, metrics.json
    rows = list(__import__("csv").DictReader((here / "run" / "metrics.csv").open()))
    assert [int(r["epoch"]) for r in rows] == [1, 2] and metrics["first_epoch"] == 1
    best = max(rows, key=lambda r: float(r["val_f_score"]))
    assert metrics["best_epoch"] == int(best["epoch"])


def _reproduce(root: str, out: str, cell: str, *extra: str) -> list[str]:
    return ["reproduce", "--dataset", "synth", "--root", root, "--models", "segnet", "--seeds", "2", "--epochs",
            "1", *SIZE, "--no-progress", "--out", out, "--only", cell, *extra]


def test_reproduce_from_another_folder_and_cells_of_changed_labels(tiny: Path, labels: Path, tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture) -> None:
    here, there = tmp_path / "here", tmp_path / "there"
    there.mkdir()
    lab = _copy_tree(labels, here / "lab")
    monkeypatch.chdir(here)
    assert main(_reproduce(os.path.relpath(tiny), "out", "segnet,X-auto,0", "--variants", "X,X-auto",
                           "--autolabels", "lab")) == 0
    run = here / "out" / "runs" / "segnet-auto-s0"
    inputs = json.loads((run / "inputs.json").read_text())
    assert inputs["labels"]["path"] == str(lab.resolve()) and inputs["labels"]["files"] == 16
    monkeypatch.chdir(there)
    capsys.readouterr()
    assert main(_reproduce(str(tiny), str(here / "out"), "segnet,X-auto,0", "--variants", "X,X-auto",
                           "--autolabels", str(lab))) == 0  # the same cell: skipped, not refused
    assert "skipped" in capsys.readouterr().out
    # C9: index.json and metrics.json give one best epoch
    assert main(["-q", "reproduce", "--tables", "--out", str(here / "out")]) == 0
    index = json.loads((here / "out" / "index.json").read_text())
    metrics = json.loads((run / "metrics.json").read_text())
    assert index[0]["best_epoch"] == metrics["best_epoch"] == 1
    # C7: a label file changed: another seed's cell would average two label trees
    label = lab / "um_000001.png"
    image = read_image(label)
    image[-4:] = 0
    label.write_bytes(encode_image(image))
    _err(capsys, _reproduce(str(tiny), str(here / "out"), "segnet,X-auto,1", "--variants", "X,X-auto",
                            "--autolabels", str(lab)), "segnet-auto-s0", "other contents of --autolabels", "sha256")
    assert not (here / "out" / "runs" / "segnet-auto-s1").exists()


def test_tables_warn_of_runs_from_other_contents(tiny: Path, tmp_path: Path) -> None:
    from freespace.experiments.cells import cell_config as _config
    from freespace.experiments.tables import collect as _collect

    for seed, digest in ((0, "a" * 64), (1, "b" * 64)):
        config = _config("synth", tiny, tmp_path, "unet", "X", seed, dict(epochs=1, patience=1, image_size=(64, 96)))
        Path(config.out).mkdir(parents=True)
        config.save(Path(config.out) / "config.yaml")
        (Path(config.out) / "inputs.json").write_text(json.dumps({"encoder_weights": {"path": "/w", "sha256": digest}}))
    assert any("the content of encoder_weights" in d for d in _collect(tmp_path)[1])


def test_weights_file_hash_and_a_changed_file_refused_for_reproduce_cells(tiny: Path, tmp_path: Path) -> None:
    from freespace.data.label_tree import changed_inputs
    from freespace.engine.record import content_hashes
    from freespace.experiments.cells import cell_config as _config
    from freespace.experiments.cells import check_inputs as _check_inputs

    weights = tmp_path / "w.pth"
    weights.write_bytes(b"first")
    config = _config("synth", tiny, tmp_path, "unet", "X", 0, dict(epochs=1, patience=1, image_size=(64, 96)))
    config = TrainConfig(**{**config.to_dict(), "encoder_weights": str(weights)})
    first = content_hashes(config)
    assert first["encoder_weights"] == {"path": str(weights.resolve()), "sha256": hashlib.sha256(b"first").hexdigest()}
    run = Path(config.out)
    run.mkdir(parents=True)
    (run / "inputs.json").write_text(json.dumps(first))
    _check_inputs(tmp_path, [config])  # the same content: taken
    weights.write_bytes(b"other")
    os.utime(weights, ns=(1, 1))
    now = content_hashes(config)
    assert now["encoder_weights"]["sha256"] == hashlib.sha256(b"other").hexdigest()  # not a stale cache
    assert changed_inputs(first, now) and not changed_inputs(first, first)
    with pytest.raises(InvalidOptionError, match="other contents of"):
        _check_inputs(tmp_path, [config])


# --- C8: YAML keys ----------------------------------------------------------------------------------------


def test_a_yaml_key_given_twice_or_in_two_spellings_is_refused(tiny: Path, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture) -> None:
    twice = tmp_path / "twice.yaml"
    twice.write_text(f"dataset: synth\nroot: {tiny}\nepochs: 1\nepochs: 5\n")
    err = _err(capsys, ["train", "--config", str(twice), "--out", str(tmp_path / "r")], "epochs", str(twice),
               "twice")
    assert "line 4" in err
    both = tmp_path / "both.yaml"
    both.write_text("disparity_mode: sgbm\ndisparity_source: auto\n")
    _err(capsys, ["train", "--config", str(both), "--dataset", "synth", "--root", str(tiny), "--out",
                  str(tmp_path / "r")], "disparity_mode", "disparity_source")
    both.write_text("disparity_source: auto\ndisparity: sgbm\n")  # whatever the order
    with pytest.raises(InvalidOptionError, match="disparity"):
        read_config_yaml(both)
    single = tmp_path / "single.yaml"
    single.write_text("epochs: 1\n")
    _err(capsys, ["train", "--config", str(single), "--config", str(both), "--out", str(tmp_path / "r")],
         "--config is given 2 times")
    nested = tmp_path / "nested.yaml"
    nested.write_text("a: {k: 1, k: 2}\n")
    with pytest.raises(CorruptFileError, match="k is given twice"):
        load_yaml(nested)
    merged = tmp_path / "merged.yaml"
    merged.write_text("a: &x {k: 1, j: 2}\nb:\n  <<: *x\n  k: 3\n")  # YAML's override of a merged key
    assert load_yaml(merged) == {"a": {"k": 1, "j": 2}, "b": {"k": 3, "j": 2}}
    code = tmp_path / "code.yaml"
    code.write_text("!!python/object/apply:os.system ['touch " + str(tmp_path / "ran") + "']\n")
    with pytest.raises(CorruptFileError):
        load_yaml(code)
    assert not (tmp_path / "ran").exists()
    assert not (tmp_path / "r").exists()


def test_freespace_yaml_with_a_key_twice_is_refused(tiny: Path, tmp_path: Path) -> None:
    from freespace.data.registry import get_dataset

    root = tmp_path / "g"
    (root / "left").mkdir(parents=True)
    shutil.copy(next((tiny / "data_road" / "training" / "image_2").glob("*.png")), root / "left" / "0001.png")
    (root / "freespace.yaml").write_text("left: left\nlabel_encoding: mask\nlabel_encoding: kitti\n")
    with pytest.raises(CorruptFileError, match="label_encoding is given twice"):
        get_dataset("generic", root)


# --- C9: old numbering ------------------------------------------------------------------------------------


def test_old_zero_based_metrics_read_right() -> None:
    from freespace.experiments.tables import _convergence

    assert _convergence({"best_epoch": 0, "epochs_run": 3}, {"epochs": 5})["best_epoch"] == 1  # older file
    assert _convergence({"best_epoch": 1, "first_epoch": 1, "epochs_run": 3}, {"epochs": 5})["best_epoch"] == 1


# --- D10–D12: label trees ---------------------------------------------------------------------------------


def test_confidence_maps_predictions_and_overlays_are_no_label_tree(tiny: Path, labels: Path, tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "run"
    _err(capsys, _train("--root", str(tiny), "--labels", str(labels / "confidence"), "--out", str(out)),
         "--labels", "grey image", f"give {labels}")
    predictions = tmp_path / "pred"
    predictions.mkdir()
    for name in (f.stem for f in labels.glob("*.png")):
        predictions.joinpath(f"{name}.png").write_bytes(encode_image(
            np.tile(np.linspace(0, 255, 128).astype(np.uint8), (96, 1))))
    _err(capsys, _train("--root", str(tiny), "--labels", str(predictions), "--out", str(out)), "prediction")
    overlays = tmp_path / "overlays"
    shutil.copytree(tiny / "data_road" / "training" / "image_2", overlays)  # photographs
    _err(capsys, _train("--root", str(tiny), "--labels", str(overlays), "--out", str(out)), "colour image")
    _err(capsys, _train("--root", str(tiny), "--labels", str(tiny), "--out", str(out)), "a dataset root")
    assert not out.exists()


def test_a_label_tree_of_another_dataset_is_refused(tiny: Path, labels: Path, other_labels: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "run"
    _err(capsys, _train("--root", str(tiny), "--labels", str(other_labels), "--out", str(out)), "another dataset",
         str(other_labels.parent / "syn"))
    _err(capsys, _reproduce(str(tiny), str(tmp_path / "rep"), "segnet,X-auto,0", "--variants", "X,X-auto",
                            "--autolabels", str(other_labels)), "--autolabels", "another dataset")
    split = _copy_tree(labels, tmp_path / "split")
    settings = json.loads((split / "settings.json").read_text())
    (split / "settings.json").write_text(json.dumps({**settings, "split": "testing"}))
    _err(capsys, _train("--root", str(tiny), "--labels", str(split), "--out", str(out)), "split testing")
    (split / "settings.json").write_text("{not json")
    _err(capsys, _train("--root", str(tiny), "--labels", str(split), "--out", str(out)), "settings.json")
    assert not out.exists() and not (tmp_path / "rep" / "runs").exists()
    link = tmp_path / "link"
    link.symlink_to(labels)
    TrainConfig(dataset="synth", root=str(tiny), out=str(out), model="segnet", labels=str(link)).check()


def test_labels_with_nothing_labelled_are_refused(tiny: Path, labels: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    black = _copy_tree(labels, tmp_path / "black")
    for path in black.glob("*.png"):
        path.write_bytes(encode_image(np.zeros(read_image(path).shape, np.uint8)))  # KITTI: all don't care
    out = tmp_path / "run"
    _err(capsys, _train("--root", str(tiny), "--labels", str(black), "--out", str(out)), "don't care")
    # only the training frames' labels are empty: found when the split is known, before training
    some = _copy_tree(labels, tmp_path / "some")
    (some / "settings.json").unlink()
    train = set()
    from freespace.data.registry import get_dataset
    from freespace.data.splits import make_splits
    frames = get_dataset("synth", tiny).labelled().frames
    train = set(make_splits([(f.name, f.scenario) for f in frames], seed=0)["train"])
    for path in some.glob("*.png"):
        if path.stem in train:
            path.write_bytes(encode_image(np.zeros(read_image(path).shape, np.uint8)))
    _err(capsys, _train("--root", str(tiny), "--labels", str(some), "--out", str(out)), "labelled pixel")
    assert not (out / "checkpoints").exists()


@pytest.fixture(scope="module")
def unlabelled(tiny: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``tiny`` whose own labels are all don't care (KITTI ground truth, black)."""
    root = _copy_tree(tiny, tmp_path_factory.mktemp("unlabelled") / "syn")
    for path in (root / "data_road" / "training" / "gt_image_2").glob("*.png"):
        path.write_bytes(encode_image(np.zeros(read_image(path).shape, np.uint8)))
    return root


def test_a_dataset_whose_labels_are_all_dont_care_is_refused(unlabelled: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture) -> None:
    _err(capsys, _train("--root", str(unlabelled), "--out", str(tmp_path / "run")), "labelled pixel",
         "dataset's labels")
    assert not (tmp_path / "run" / "checkpoints").exists()


def test_an_epoch_without_a_labelled_pixel_fails_the_run(unlabelled: Path, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture) -> None:
    import freespace.engine.data as data

    monkeypatch.setattr(data, "_check_labelled", lambda *a, **k: None)  # past the check up front
    _err(capsys, _train("--root", str(unlabelled), "--out", str(tmp_path / "run"), "--epochs", "2"),
         "epoch 1", "labelled pixel", code=1)
    assert not (tmp_path / "run" / "metrics.json").exists()


def test_autolabels_without_a_variant_that_reads_them_is_refused(tiny: Path, labels: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture) -> None:
    args = ["reproduce", "--dataset", "synth", "--root", str(tiny), "--models", "segnet", "--epochs", "1",
            "--out", str(tmp_path / "o"), "--autolabels", str(labels)]
    _err(capsys, [*args, "--variants", "X,HA-X"], "--autolabels", "X-auto")
    _err(capsys, [*args, "--only", "segnet,X,0"], "--autolabels", "--variants")
    assert not (tmp_path / "o").exists()


# --- F17–F21: autolabel -----------------------------------------------------------------------------------


def _autolabel(root: Path, out: Path, *extra: str) -> list[str]:
    return ["autolabel", "--dataset", "synth", "--root", str(root), "--out", str(out), *extra]


def test_cache_dir_apart_from_out_and_the_dataset(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "lab"
    sgbm = ["--disparity-source", "sgbm", "--max-disparity", "32"]
    _err(capsys, _autolabel(tiny, out, *sgbm, "--cache-dir", str(out)), "--cache-dir", "--out")
    _err(capsys, _autolabel(tiny, out, *sgbm, "--cache-dir", str(out / "cache")), "--cache-dir")
    _err(capsys, _autolabel(tiny, out, *sgbm, "--cache-dir", str(tmp_path)), "--cache-dir")  # holds --out
    images = tiny / "data_road" / "training" / "image_2"
    before = sorted(p.name for p in images.iterdir())
    _err(capsys, _autolabel(tiny, out, *sgbm, "--cache-dir", str(images)), "--cache-dir", "inside the input")
    assert sorted(p.name for p in images.iterdir()) == before and not out.exists()


def test_disparity_source_none_sgbm_without_right_images_and_an_ignored_disparity_dir(
        tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from freespace.data.registry import get_dataset
    from freespace.datagen.autolabel import autolabel_dataset

    out = tmp_path / "lab"
    capsys.readouterr()
    assert main(_autolabel(tiny, out, "--disparity-source", "none")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "invalid choice: 'none'" in err[0]
    with pytest.raises(InvalidOptionError, match="none"):
        autolabel_dataset(get_dataset("synth", tiny, disparity_source="none"), out)
    left_only = _copy_tree(tiny, tmp_path / "left_only")
    shutil.rmtree(left_only / "data_road_right")
    _err(capsys, _autolabel(left_only, out, "--disparity-source", "sgbm"), "right image")
    no_disparity = _copy_tree(tiny, tmp_path / "no_disparity")
    shutil.rmtree(no_disparity / "data_road" / "training" / "disparity")
    _err(capsys, _autolabel(no_disparity, out, "--disparity-source", "file"), "--disparity-source file",
         "no frame")
    disparities = tiny / "data_road" / "training" / "disparity"
    for command in ("autolabel", "generate"):
        _err(capsys, [command, "--dataset", "synth", "--root", str(tiny), "--out", str(out), "--disparity-dir",
                      str(disparities), "--disparity-source", "sgbm"], "--disparity-dir", "ignored")
    assert not out.exists()


def test_per_frame_failures_name_flags(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    root = _copy_tree(tiny, tmp_path / "syn")
    (root / "data_road" / "training" / "disparity" / "um_000000.png").unlink()
    (root / "data_road_right" / "training" / "image_3" / "um_000000.png").unlink()
    capsys.readouterr()
    assert main(["-q", *_autolabel(root, tmp_path / "lab", "--disparity-source", "file")]) == 1
    out = capsys.readouterr().out
    failed = [line for line in out.splitlines() if "failed um_000000" in line]
    assert failed and "--disparity-source file" in failed[0] and "disparity_source" not in failed[0], out


def test_a_swapped_pair_is_reported(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture,
                                    caplog: pytest.LogCaptureFixture) -> None:
    from freespace.data.registry import get_dataset

    wide = tmp_path / "wide"
    write_dataset(wide, 2, seed=3, config=SynthConfig(width=416, height=128, frames_per_scenario=2), progress=False)
    frame = get_dataset("synth", wide).frames[0]
    capsys.readouterr()
    with caplog.at_level(logging.WARNING):
        code = main(["autolabel", "--reference", str(frame.right), "--target", str(frame.left), "--out",
                     str(tmp_path / "L.png"), "--max-disparity", "64"])
    said = capsys.readouterr().err + caplog.text
    assert "swapped" in said and ("--reference" in said or "reference" in caplog.text), said
    assert code != 0 or "implausible" in said
    _err(capsys, ["autolabel", "--reference", str(frame.left), "--target", str(frame.left), "--out",
                  str(tmp_path / "S.png")], "same file")
    # a dataset of swapped pairs: one line for the run (and each failed frame says why)
    swapped = _copy_tree(wide, tmp_path / "swapped")
    left, right = swapped / "data_road" / "training" / "image_2", swapped / "data_road_right" / "training" / "image_3"
    for path in left.glob("*.png"):
        a, b = path.read_bytes(), (right / path.name).read_bytes()
        path.write_bytes(b)
        (right / path.name).write_bytes(a)
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        main(["autolabel", "--dataset", "synth", "--root", str(swapped), "--out", str(tmp_path / "lab"),
              "--disparity-source", "sgbm", "--max-disparity", "64"])
    out = capsys.readouterr().out
    assert "swapped" in out + caplog.text
    summary = json.loads((tmp_path / "lab" / "summary.json").read_text())
    assert all("swapped" in reason for reason in summary["failed"].values())


def test_evaluate_kitti_with_predictions_as_ground_truth_is_refused(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture) -> None:
    """--gt and --pred swapped: the confidence maps are no ground truth (read as "non-zero = road" they would
    score a network against its own output)."""
    from freespace.io.codecs import road_label_to_kitti, write_image
    from freespace.labels import RoadLabel

    rng = np.random.default_rng(0)
    gt, pred = tmp_path / "gt", tmp_path / "pred"
    road = np.zeros((20, 30), bool)
    road[10:] = True
    write_image(gt / "um_road_000000.png", road_label_to_kitti(RoadLabel(road, np.ones_like(road))))
    write_image(pred / "um_road_000000.png", rng.integers(0, 256, (20, 30), dtype=np.uint8))
    assert main(["-q", "evaluate-kitti", "--gt", str(gt), "--pred", str(pred), "--out", str(tmp_path / "a.json")]) == 0
    _err(capsys, ["evaluate-kitti", "--gt", str(pred), "--pred", str(gt), "--out", str(tmp_path / "b.json")],
         "--gt", "grey image")
    assert not (tmp_path / "b.json").exists()
