"""The training configuration: typed values parsed once, config.yaml of older versions read as the same
settings, errors naming parameters (the command line their flags), no flag in the library."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from freespace.cli import CONFIG_FLAGS, REPRODUCE_OPTIONS, _flags, build_parser, main
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.engine.config import TrainConfig, read_config_yaml
from freespace.engine.option_values import FIRST_FRAME_SIZE
from freespace.engine.options import options
from freespace.errors import InvalidOptionError, param

ROOT = Path(__file__).resolve().parent.parent

# a cell's config.yaml as `freespace reproduce` wrote it before this version (the converged run's unet-ha-s0),
# its folders put in the test's place
CAMPAIGN_YAML = """\
dataset: synth
root: {root}
out: {out}
model: unet
preset: light
encoder_name: efficientnet-lite0
encoder_weights: imagenet
split: null
augment: homography
epochs: 100
batch_size: 2
lr: 0.01
momentum: 0.9
weight_decay: 0.0
patience: 10
val_window: 3
min_delta: 0.001
image_size:
- 192
- 256
seed: 0
devices: 1
num_nodes: 1
strategy: auto
workers: 0
splits_dir: null
max_frames: null
labels: null
human_share: 0.0
disparity_mode: auto
cache_dir: null
tensorboard: false
virtual_shift: 0.5,0.2,0
virtual_rotate: 3,3,3
virtual_prob: 0.5
"""

# what the version before wrote for `train --augment virtual,homography --virtual-shift 0.50,0.2,0.0
# --virtual-rotate 1,2.5,0 --image-size auto --disparity-source sgbm ...` (ranges kept as typed; size unresolved)
OLDER_YAML = """\
dataset: synth
root: {root}
out: {out}
model: segnet
preset: light
encoder_name: null
encoder_weights: null
split: null
augment: homography,virtual
epochs: 20
batch_size: 4
lr: 0.01
momentum: 0.9
weight_decay: 0.0
patience: 10
val_window: 1
min_delta: 0.0
image_size: null
seed: 2
devices: 1
num_nodes: 1
strategy: auto
workers: 0
splits_dir: {root}/lists
max_frames: 12
labels: {root}/auto
human_share: 0.2
disparity_mode: sgbm
cache_dir: null
tensorboard: false
virtual_shift: 0.50,0.2,0.0
virtual_rotate: 1,2.5,0
virtual_prob: 0.5
"""


def _folders(tmp_path: Path) -> dict[str, str]:
    return {"root": os.path.realpath(tmp_path / "syn"), "out": os.path.realpath(tmp_path / "res" / "runs" / "cell")}


def test_a_config_yaml_of_the_running_campaign_is_the_same_cell(tmp_path: Path) -> None:
    """The recorded-settings check of reproduce passes for a cell written before this version, and the cell
    is written back in the same spellings (the disparity source's key renamed, the old key read too; the options
    added since written at their defaults)."""
    from freespace.experiments.cells import check_cell as _check_cell

    where = _folders(tmp_path)
    run = Path(where["out"])
    run.mkdir(parents=True)
    (run / "config.yaml").write_text(CAMPAIGN_YAML.format(**where))
    cell = TrainConfig(dataset="synth", root=where["root"], out=where["out"], model="unet",
                       encoder_name="efficientnet-lite0", encoder_weights="imagenet", augment="homography", epochs=100,
                       batch_size=2, lr=0.01, val_window=3, min_delta=0.001, seed=0)  # image size: the first frame's
    assert cell.image_size == FIRST_FRAME_SIZE
    assert _check_cell(cell) is False  # the same cell, nothing grown
    assert TrainConfig.load(run / "config.yaml") == dataclasses.replace(cell, image_size=(192, 256))
    assert _check_cell(dataclasses.replace(cell, patience=20)) is True  # extended
    for change, message in (({"lr": 0.001}, "(lr 0.01 → 0.001)"),
                            ({"augment": "homography,virtual"}, "(augment 'homography' → 'homography,virtual')"),
                            ({"epochs": 50, "patience": 20}, "(epochs 100 → 50)")):
        with pytest.raises(InvalidOptionError, match=re.escape(message)):
            _check_cell(dataclasses.replace(cell, **change))
    TrainConfig.load(run / "config.yaml").save(tmp_path / "again.yaml")
    assert (tmp_path / "again.yaml").read_text() == \
        CAMPAIGN_YAML.format(**where).replace("disparity_mode:", "disparity_source:").replace(
            "augment: homography\n", "augment: homography\nflip: false\nphotometric: false\n"
            "photometric_strength: mild\nzoom: 0.0\ncrop_top: 0.0\n").replace(
            "dataset: synth", "dataset: kitti").replace(
            "human_share: 0.0\n", "human_share: 0.0\nimages: null\nlabel_format: null\nlabels_like: null\n"
            "road: null\nignore: null\ntolerance: null\nval_images: null\nval_labels: null\nval_share: 0.2\n"
            "init: null\nfreeze: auto\nteacher: null\nteacher_weight: 1.0\nteacher_pixels: all\n").replace(
            "- 256\nseed: 0\n", "- 256\nresize: stretch\nseed: 0\n").replace(
            "\nmomentum:", "\nlr_schedule: constant\nmomentum:")
    # the options added since; the layout's own name for an alias


def test_diff_lets_only_the_cap_and_patience_grow(tmp_path: Path) -> None:
    """``TrainConfig.diff``: the one comparison of a run's recorded settings (resume, reproduce's cells)."""
    (tmp_path / "data").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "data")
    saved = TrainConfig(dataset="synth", root=str(tmp_path / "data"), out=str(tmp_path / "run"), image_size=(64, 96),
                        epochs=10, patience=3)
    same = dataclasses.replace(saved, root=str(tmp_path / "link"), image_size=FIRST_FRAME_SIZE, workers=2, devices=2,
                               out=str(tmp_path / "elsewhere"))  # the same folder spelled otherwise; where and how
    assert same.diff(saved) == ([], [])
    assert dataclasses.replace(saved, patience=5).diff(saved) == ([], ["patience"])
    assert dataclasses.replace(saved, epochs=20, patience=5).diff(saved) == ([], ["epochs", "patience"])
    assert dataclasses.replace(saved, epochs=5).diff(saved) == (["epochs 10 → 5"], [])  # a smaller cap: changed
    changed, grown = dataclasses.replace(saved, epochs=20, lr=0.01, image_size=(32, 48)).diff(saved)
    assert changed == ["lr 0.001 → 0.01", "image_size [64, 96] → [32, 48]"] and grown == ["epochs"]
    assert saved.diff(dataclasses.replace(saved, image_size=FIRST_FRAME_SIZE)) == (["image_size None → [64, 96]"], [])
    poly = dataclasses.replace(saved, lr_schedule="poly")  # its decay was laid over its first epochs
    assert dataclasses.replace(poly, epochs=20, patience=5).diff(poly) == (["epochs 10 → 20"], ["patience"])


def test_older_spellings_read_as_the_same_values(tmp_path: Path) -> None:
    where = _folders(tmp_path)
    (tmp_path / "old.yaml").write_text(OLDER_YAML.format(**where))
    old = TrainConfig.load(tmp_path / "old.yaml")
    assert old == TrainConfig(dataset="synth", root=where["root"], out=where["out"], model="segnet",
                              augment=("homography", "virtual"), epochs=20, lr=0.01, seed=2,
                              splits_dir=f"{where['root']}/lists", max_frames=12, labels=f"{where['root']}/auto",
                              human_share=0.2, disparity_source="sgbm", virtual_shift=(0.5, 0.2, 0.0),
                              virtual_rotate=(1.0, 2.5, 0.0))
    assert old.image_size == FIRST_FRAME_SIZE and old.virtual_shift == ((-0.5, 0.5), (-0.2, 0.2), (0.0, 0.0))
    old.save(tmp_path / "new.yaml")
    written, before = yaml.safe_load((tmp_path / "new.yaml").read_text()), yaml.safe_load(OLDER_YAML.format(**where))
    assert written == {**{k if k != "disparity_mode" else "disparity_source": v for k, v in before.items()},
                       "virtual_shift": "0.5,0.2,0", "flip": False, "photometric": False,
                       "photometric_strength": "mild", "zoom": 0.0, "dataset": "kitti", "images": None,
                       "label_format": None, "labels_like": None, "road": None, "ignore": None, "tolerance": None,
                       "val_images": None, "val_labels": None, "val_share": 0.2, "init": None, "freeze": "auto",
                       "teacher": None, "teacher_weight": 1.0, "teacher_pixels": "all", "resize": "stretch",
                       "lr_schedule": "constant", "crop_top": 0.0}
    # one spelling per value (the layout's own name for the alias synth); the options added since, at their defaults
    assert TrainConfig.load(tmp_path / "new.yaml") == old
    assert read_config_yaml(tmp_path / "old.yaml")["augment"] == ("homography", "virtual")


def test_values_are_parsed_once_into_types(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import freespace.data.base

    c = TrainConfig(dataset="synth", root=str(tmp_path / "data"), out=str(tmp_path / "run"),
                    augment="virtual, homography", virtual_shift="0.5,-3:0.25,0", image_size="64x96")
    assert (c.augment, c.virtual_shift, c.virtual_rotate, c.image_size) == \
        (("homography", "virtual"), ((-0.5, 0.5), (-3.0, 0.25), (0.0, 0.0)), ((-3.0, 3.0),) * 3, (64, 96))
    assert c.to_dict()["virtual_shift"] == "0.5,-3:0.25,0"  # a symmetric range keeps its old spelling
    assert TrainConfig(dataset="synth", root=str(tmp_path), out="o", augment="none").augment == ()
    for auto in (None, "auto", FIRST_FRAME_SIZE):
        assert TrainConfig(dataset="synth", root=str(tmp_path), out="o", image_size=auto).image_size == FIRST_FRAME_SIZE
    assert dataclasses.replace(c, epochs=3) == TrainConfig(**{**c.to_dict(), "epochs": 3})  # the spellings parse back
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.augment = ("duplicate",)  # type: ignore[misc]
    # the checks against the machine run once per configuration
    seen = []
    monkeypatch.setattr(freespace.data.base, "check_dataset_root", lambda root, layout: seen.append(root))
    c.check()
    c.check()
    assert seen == [str(tmp_path / "data")]
    dataclasses.replace(c, epochs=3).check()
    assert len(seen) == 2


@pytest.mark.parametrize("values, message", [
    ({"epochs": 0}, "epochs must be in [1, 100000], got 0"),
    ({"epochs": True}, "epochs must be an integer, got True"),
    ({"lr": 20.0}, "lr must be in (0, 10), got 20.0"),
    ({"lr": float("inf")}, "lr must be a finite number, got inf"),
    ({"min_delta": 1.0}, "min_delta must be in [0, 1), got 1.0"),
    ({"seed": -1}, "seed must be in [0, 4294967295], got -1"),
    ({"max_frames": 2}, "max_frames must be in [3, 100000000], got 2"),
    ({"max_frames": "3"}, "max_frames must be an integer or null, got '3'"),
    ({"augment": "homography,duplicate"}, "augment must be one of none, homography, virtual, homography,virtual, "
                                          "duplicate, got 'homography,duplicate'"),
    ({"augment": "virtual,duplicate"}, "augment must be one of"),
    ({"virtual_shift": "0.5,-1,0"}, "virtual_shift must be three ranges, each a half-range h ≥ 0 (±h) or LO:HI with "
                                    "LO ≤ HI, got '0.5,-1,0'"),
    ({"virtual_rotate": "3,3:-3,3"}, "virtual_rotate must be three ranges"),
    ({"image_size": "12x5"}, "image_size must be HxW with both in 32…"),
    ({"strategy": "fsdp"}, "strategy must be one of auto, ddp, got 'fsdp'"),
    ({"disparity_source": "laser"}, "disparity_source must be one of"),
    ({"human_share": 0.5}, "human_share keeps the dataset's labels on a share of the training drives"),
])
def test_a_bad_value_names_its_parameter(values: dict, message: str) -> None:
    with pytest.raises(InvalidOptionError) as caught:
        TrainConfig(dataset="synth", root=".", out="o", **values)
    assert str(caught.value).startswith(message) and "--" not in str(caught.value)


def test_a_yaml_file_is_read_strictly(tmp_path: Path) -> None:
    for text, message in [("epochs: 3.0\n", "epochs must be an integer, got 3.0"),
                          ("lr: '0.1'\n", "lr must be a number, got '0.1'"),
                          ("augment: [homography]\n", "augment must be one of"),
                          ("tensorboard: 1\n", "tensorboard must be true or false, got 1"),
                          ("model: fcn\n", "model must be one of")]:
        (tmp_path / "c.yaml").write_text(text)
        with pytest.raises(InvalidOptionError, match=re.escape(f"{tmp_path / 'c.yaml'}: {message}")):
            read_config_yaml(tmp_path / "c.yaml")
    (tmp_path / "c.yaml").write_text("image_size: [64, 96]\nmax_frames: null\nlr: 1\n")
    assert read_config_yaml(tmp_path / "c.yaml") == {"image_size": (64, 96), "max_frames": None, "lr": 1.0}


def test_the_command_line_names_the_flags(tmp_path: Path, capsys: pytest.CaptureFixture,
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Every field's option has the field's name as its dest, so that an error naming the parameter names
    the flag; the flags are the field names with dashes but for CONFIG_FLAGS."""
    for command, names in (("train", None), ("reproduce", REPRODUCE_OPTIONS)):
        flags = _flags(build_parser({command}), [command])
        for o in options(names):
            assert flags[o.name] == CONFIG_FLAGS.get(o.name, "--" + o.name.replace("_", "-"))
    assert _flags(build_parser({"train"}), ["train"])["splits_dir"] == "--splits"
    root = tmp_path / "syn"
    write_dataset(root, 4, seed=0, config=SynthConfig(width=96, height=64, frames_per_scenario=2), progress=False)
    for option, value, message in [("--virtual-prob", "2", "--virtual-prob must be in [0, 1], got 2.0"),
                                   ("--virtual-rotate", "1,2", "--virtual-rotate must be three ranges"),
                                   ("--human-share", "0.5", "--human-share keeps the dataset's labels on a share of "
                                                            "the training drives and takes the label tree of --labels "
                                                            "on the others; give --labels too")]:
        assert main(["train", "--dataset", "synth", "--root", str(root), "--out", str(tmp_path / "run"), option,
                     value]) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
    # the help speaks in flags too
    help_text = " ".join(o.help for o in options(["augment", "human_share"]))
    assert param("virtual_shift") in help_text and "--" not in help_text
    monkeypatch.setenv("COLUMNS", "1000")  # argparse's help: one line per option
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    out = capsys.readouterr().out
    assert "from --virtual-shift/--virtual-rotate" in out and "with --labels: the share" in out and "\x00" not in out


def test_options_spell_defaults_as_config_yaml_does() -> None:
    found = {o.name: (o.kind, o.default, o.required) for o in options()}
    assert found["augment"] == (str, "none", False) and found["virtual_shift"] == (str, "0.5,0.2,0", False)
    found = {k: (getattr(kind, "kind", kind), *rest) for k, (kind, *rest) in found.items()}  # numbers: Bounded
    assert found["image_size"] == (str, None, False) and found["epochs"] == (int, 50, False)
    assert found["lr"] == (float, 0.001, False) and found["tensorboard"] == (bool, False, False)
    assert found["max_frames"] == (int, None, False) and found["out"] == (str, None, True)
    assert found["root"] == (str, None, False)  # a dataset's, or none: a labelled folder (images) instead
    assert {o.name: o.default for o in options(["augment"], {"augment": ("homography", "virtual")})} == \
        {"augment": "homography,virtual"}


def test_the_library_speaks_in_parameters() -> None:
    """No command-line flag in the training engine, the protocol or the torch dataset: messages name
    parameters (freespace.errors.param), the command line writes their flags."""
    files = [*sorted((ROOT / "freespace" / "engine").glob("*.py")), *sorted((ROOT / "freespace" / "experiments")
                                                                             .glob("*.py")),
             ROOT / "freespace" / "data" / "torch_dataset.py"]
    found = [f"{p.relative_to(ROOT)}:{i}: {line.strip()}" for p in files
             for i, line in enumerate(p.read_text().splitlines(), 1) if re.search(r"--[a-z]", line)]
    assert found == []


def test_generate_and_the_geometry_do_not_import_pydantic() -> None:
    """pydantic validates the training configuration only: `freespace generate` and the geometry stay light."""
    code = ("import sys, freespace.geometry, freespace.datagen.generate, freespace.cli; "
            "freespace.cli.build_parser({'generate'}); print('pydantic' in sys.modules, 'torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split() == ["False", "False"]


def test_train_config_checks_each_yaml_value_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`train --config`: each value of the file is parsed and checked once (when the file is read), not again
    for the options' defaults nor when the TrainConfig is made; a flag given as well still is checked, and wins."""
    import freespace.engine.config_yaml as config_yaml
    import freespace.engine.train as train_module

    calls: list[str] = []
    typed = config_yaml.typed_value
    monkeypatch.setattr(config_yaml, "typed_value",
                        lambda cls, name, value: (calls.append(name), typed(cls, name, value))[1])
    seen: list[TrainConfig] = []
    monkeypatch.setattr(train_module, "run_training", lambda config, **_: (
        seen.append(config),
        dict.fromkeys(("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap"), 0.5))[1])
    made = TrainConfig(dataset="synth", root=str(tmp_path), out=str(tmp_path / "a"), epochs=7, image_size=(64, 96),
                       augment=("homography", "virtual"), virtual_shift=((-1.0, 1.0), (-3.0, 0.9), (0.0, 0.0)))
    made.save(tmp_path / "c.yaml")
    in_file = set(yaml.safe_load((tmp_path / "c.yaml").read_text()))
    options()  # the fields' own defaults are typed once per process: not the file's values
    calls.clear()
    assert main(["train", "--config", str(tmp_path / "c.yaml"), "--epochs", "3", "--no-progress"]) == 0
    counts = {name: calls.count(name) for name in in_file}
    assert seen == [dataclasses.replace(made, epochs=3)]
    assert counts == {**dict.fromkeys(in_file, 1), "epochs": 2}, counts
    calls.clear()
    assert TrainConfig.load(tmp_path / "c.yaml") == made and sorted(calls) == sorted(in_file)
    with pytest.raises(InvalidOptionError, match="epochs must be in"):  # a flag is no file's value: checked
        TrainConfig.from_checked(read_config_yaml(tmp_path / "c.yaml"), epochs=0)


def test_the_first_frame_size_is_resolved_in_one_place(tmp_path: Path) -> None:
    """TrainConfig.with_size: a config asking for the first frame's size takes the one given (read only then);
    one that names its size keeps it."""
    reads: list[int] = []

    def first_frame() -> tuple[int, int]:
        reads.append(1)
        return (64, 96)

    asks = TrainConfig(dataset="synth", root=str(tmp_path), out="o")
    assert asks.image_size == FIRST_FRAME_SIZE
    assert asks.with_size(first_frame) == dataclasses.replace(asks, image_size=(64, 96)) and reads == [1]
    assert asks.with_size([48, 80]).image_size == (48, 80)
    named = TrainConfig(dataset="synth", root=str(tmp_path), out="o", image_size="32x64")
    assert named.with_size(first_frame) is named and named.with_size((48, 80)) is named and reads == [1]
    with pytest.raises(InvalidOptionError, match="image_size must be HxW"):
        asks.with_size((8, 8))
