"""Training runs: the run folder, exact resume, the homography augmentation, bad options, NaN loss,
atomic checkpoints, DDP with two CPU processes."""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml

from freespace.cli import main
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.engine.config import TrainConfig
from freespace.errors import FreespaceError, InputFileError
from freespace.labels import IGNORE_INDEX


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("tiny")
    write_dataset(root, 16, seed=2, config=SynthConfig(width=128, height=96, frames_per_scenario=2), progress=False)
    return root


def _train(root: Path, out: Path, *extra: str) -> int:
    return main(["train", "--dataset", "synth", "--root", str(root), "--model", "segnet", "--batch-size", "4",
                 "--no-progress", "--out", str(out), *extra])


def _metrics(run: Path) -> dict:
    m = json.loads((run / "metrics.json").read_text())
    m.pop("seconds_per_frame")
    return m


def test_run_folder_and_exact_resume(tiny: Path, tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    assert _train(tiny, a, "--epochs", "3") == 0
    assert _train(tiny, b, "--epochs", "2") == 0
    assert _train(tiny, b, "--epochs", "3", "--resume") == 0
    assert _metrics(a) == _metrics(b)  # exactly
    assert (a / "metrics.csv").read_text().splitlines()[1:] != []
    rows_a = [r for r in csv.DictReader((a / "metrics.csv").open())]
    rows_b = [r for r in csv.DictReader((b / "metrics.csv").open())]
    assert [r["val_f_score"] for r in rows_a] == [r["val_f_score"] for r in rows_b] and len(rows_a) == 3
    config = yaml.safe_load((a / "config.yaml").read_text())
    assert config["model"] == "segnet" and config["image_size"] == [96, 128]
    m = json.loads((a / "metrics.json").read_text())
    assert {"accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap", "seconds_per_frame"} <= set(m)
    assert all(0 <= m[k] <= 1 for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap"))
    assert sum(m["frames"].values()) == 16 and min(m["frames"].values()) >= 1
    for name in ("best.ckpt", "last.ckpt"):
        ckpt = torch.load(a / "checkpoints" / name, weights_only=True)  # loads no code
        assert "state_dict" in ckpt and ckpt["hyper_parameters"]["model"] == "segnet"
    for split in ("train", "val", "test"):
        assert (a / "splits" / f"{split}.txt").is_file()


def test_last_checkpoint_is_the_last_epoch(tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """last.ckpt follows every epoch, not only those that improve the best: with a validation F that falls each
    epoch, best.ckpt stays at epoch 0 and last.ckpt moves to the final one, from which a resume goes on."""
    from freespace.engine.module import RoadModule

    reduce = RoadModule._reduce

    def falling(self: RoadModule) -> dict[str, float]:
        return {**reduce(self), "f_score": 0.9 - 0.1 * len(self.val_f_history)}

    monkeypatch.setattr(RoadModule, "_reduce", falling)
    run = tmp_path / "run"
    assert _train(tiny, run, "--epochs", "3", "--image-size", "64x96") == 0
    epochs = {name: torch.load(run / "checkpoints" / f"{name}.ckpt", weights_only=True)["epoch"]
              for name in ("best", "last")}
    assert epochs == {"best": 0, "last": 2}
    assert _train(tiny, run, "--epochs", "4", "--image-size", "64x96", "--resume") == 0
    assert torch.load(run / "checkpoints" / "last.ckpt", weights_only=True)["epoch"] == 3
    assert [int(r["epoch"]) for r in csv.DictReader((run / "metrics.csv").open())] == [1, 2, 3, 4]  # from 1


def test_resume_reads_a_config_yaml_of_older_spellings(tiny: Path, tmp_path: Path) -> None:
    """A run folder whose config.yaml is spelled as before the typed configuration (the key disparity_mode,
    a range as the user typed it) resumes: its recorded settings read as the same values."""
    run = tmp_path / "old"
    assert _train(tiny, run, "--epochs", "1", "--virtual-shift", "0.50,0.2,0.0") == 0
    text = (run / "config.yaml").read_text()
    assert "\ndisparity_source: auto\n" in text and "\nvirtual_shift: 0.5,0.2,0\n" in text
    (run / "config.yaml").write_text(text.replace("disparity_source:", "disparity_mode:")
                                     .replace("virtual_shift: 0.5,0.2,0", "virtual_shift: 0.50,0.2,0.0"))
    assert _train(tiny, run, "--epochs", "2", "--resume") == 0  # image size: the run's (resolved at its start)
    assert json.loads((run / "metrics.json").read_text())["epochs_run"] == 2


def test_homography_augmentation_adds_generated_views(tiny: Path, tmp_path: Path) -> None:
    run = tmp_path / "ha"
    assert _train(tiny, run, "--epochs", "1", "--augment", "homography") == 0
    m = json.loads((run / "metrics.json").read_text())
    train_names = (run / "splits" / "train.txt").read_text().split()
    assert m["frames"]["train"] == 2 * len(train_names)
    assert sorted(p.stem for p in (run / "generated").glob("*.png")) == sorted(train_names)


@pytest.mark.parametrize("args, message", [
    (["--model", "fcn"], "--model must be one of"), (["--augment", "flip"], "--augment"),
    (["--epochs", "0"], "--epochs"), (["--image-size", "12x5"], "--image-size"), (["--lr", "-1"], "--lr"),
    (["--strategy", "fsdp"], "--strategy"),
])
def test_bad_options_rejected_before_work(tiny: Path, tmp_path: Path, args: list[str], message: str,
                                          capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "bad"
    assert _train(tiny, out, *args) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_existing_run_and_resume_mistakes(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert _train(tiny, tmp_path / "none", "--resume") == 2
    assert "--resume needs" in capsys.readouterr().err
    run = tmp_path / "r"
    assert _train(tiny, run, "--epochs", "1") == 0
    assert _train(tiny, run, "--epochs", "1") == 2
    assert "already holds a run" in capsys.readouterr().err
    assert _train(tiny, run, "--epochs", "2", "--resume", "--lr", "0.01") == 2
    assert "other options" in capsys.readouterr().err


def test_nan_loss_stops_the_run(tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                capsys: pytest.CaptureFixture) -> None:
    from freespace.models.base import SegmentationModel

    def nan_loss(self, outputs, target, ignore_index=IGNORE_INDEX):
        return {"total": torch.nn.functional.cross_entropy(outputs, target, ignore_index=ignore_index) * float("nan")}

    monkeypatch.setattr(SegmentationModel, "loss", nan_loss)
    assert _train(tiny, tmp_path / "nan", "--epochs", "1") == 1
    err = capsys.readouterr().err
    assert "the loss became nan" in err and "lower --lr" in err


def test_checkpoints_are_written_atomically(tmp_path: Path) -> None:
    from freespace.engine.train import RunCheckpointIO

    io = RunCheckpointIO(tmp_path)
    path = tmp_path / "last.ckpt"
    io.save_checkpoint({"epoch": 1}, path)

    class Unpicklable:
        def __reduce__(self):
            raise RuntimeError("cannot be pickled")

    with pytest.raises(RuntimeError, match="cannot be pickled"):
        io.save_checkpoint({"bad": Unpicklable()}, path)  # the old file must survive
    assert torch.load(path, weights_only=True) == {"epoch": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["last.ckpt"]


def test_resumed_checkpoint_paths_stay_in_the_run_folder(tmp_path: Path) -> None:
    """A checkpoint callback state that names files elsewhere (a moved run, a crafted file) is confined."""
    from freespace.engine.train import RunCheckpointIO

    io = RunCheckpointIO(tmp_path / "run")
    elsewhere = "/elsewhere/checkpoints/"
    state = {"dirpath": elsewhere, "best_model_path": elsewhere + "best.ckpt", "last_model_path": "/etc/passwd",
             "kth_best_model_path": elsewhere + "best.ckpt", "best_k_models": {elsewhere + "best.ckpt": 0.5}}
    path = tmp_path / "last.ckpt"
    io.save_checkpoint({"state_dict": {}, "callbacks": {"ModelCheckpoint{}": state}}, path)
    loaded = io.load_checkpoint(path)["callbacks"]["ModelCheckpoint{}"]
    folder = os.path.realpath(tmp_path / "run" / "checkpoints")
    assert loaded["dirpath"] == folder and loaded["best_model_path"] == folder + "/best.ckpt"
    assert loaded["last_model_path"] == "" and loaded["best_k_models"] == {folder + "/best.ckpt": 0.5}


def test_config_round_trip(tmp_path: Path) -> None:
    c = TrainConfig(dataset="kitti", root=str(tmp_path), out=str(tmp_path / "o"), image_size=(64, 96))
    c.save(tmp_path / "c.yaml")
    assert TrainConfig.load(tmp_path / "c.yaml") == c
    (tmp_path / "bad.yaml").write_text("!!python/object/apply:os.system ['echo hi']\n")
    with pytest.raises(FreespaceError):
        TrainConfig.load(tmp_path / "bad.yaml")


def test_config_file_and_flags(tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                               capsys: pytest.CaptureFixture) -> None:
    import freespace.engine.train as train_module

    seen: list[TrainConfig] = []

    def fake_training(config: TrainConfig, resume: bool, progress: bool) -> dict[str, float]:
        seen.append(config)
        return dict.fromkeys(("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap"), 0.5)

    monkeypatch.setattr(train_module, "run_training", fake_training)
    run = TrainConfig(dataset="synth", root=str(tiny), out=str(tmp_path / "a"), model="segnet", epochs=7,
                      image_size=(64, 96), splits_dir=str(tmp_path / "lists"), disparity_source="sgbm",
                      tensorboard=False)
    run.save(tmp_path / "config.yaml")
    # a run's config.yaml, flags override it
    assert main(["train", "--config", str(tmp_path / "config.yaml"), "--epochs", "3",
                 "--out", str(tmp_path / "b")]) == 0
    assert seen[-1] == dataclasses.replace(run, epochs=3, out=str(tmp_path / "b"))
    # flags alone: every field has one (names of the CLI kept: --splits, --disparity-source)
    assert main(["train", "--dataset", "synth", "--root", str(tiny), "--out", str(tmp_path / "c"), "--model", "segnet",
                 "--epochs", "7", "--image-size", "64x96", "--splits", str(tmp_path / "lists"),
                 "--disparity-source", "sgbm"]) == 0
    assert seen[-1] == dataclasses.replace(run, out=str(tmp_path / "c"))
    # a config.yaml written before the renames still reads
    old = {**run.to_dict(), "splits": str(tmp_path / "lists"), "disparity": "sgbm"}
    del old["splits_dir"], old["disparity_source"]
    (tmp_path / "old.yaml").write_text(yaml.safe_dump(old))
    assert TrainConfig.load(tmp_path / "old.yaml") == run
    capsys.readouterr()
    for text, message in [("epoch: 3\n", "unknown option epoch;"), ("epochs: ten\n", "epochs must be an integer"),
                          ("image_size: 12x5\n", "bad.yaml: image_size must be HxW"),
                          ("- 3\n", "not a freespace training config")]:
        (tmp_path / "bad.yaml").write_text(text)
        assert main(["train", "--config", str(tmp_path / "bad.yaml"), "--dataset", "synth", "--root", str(tiny),
                     "--out", str(tmp_path / "d")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    assert main(["train", "--config", str(tmp_path / "none.yaml"), "--out", str(tmp_path / "d")]) == 2
    assert "config file not found" in capsys.readouterr().err
    assert len(seen) == 2 and not (tmp_path / "d").exists()


def test_missing_root_error(tmp_path: Path) -> None:
    with pytest.raises(InputFileError, match="dataset root not found"):
        TrainConfig(dataset="synth", root=str(tmp_path / "none"), out=str(tmp_path / "o")).check()


def test_evaluate_subset_names(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["evaluate", "--checkpoint", str(tmp_path / "x.ckpt"), "--dataset", "synth", "--root", str(tiny),
                 "--subset", "every", "--out", str(tmp_path / "e")]) == 2
    assert "--subset must be train, val, test or all" in capsys.readouterr().err
    # the on-disk split is --split; --disk-split is gone
    assert main(["evaluate", "--checkpoint", "x", "--dataset", "synth", "--root", str(tiny), "--disk-split",
                 "training", "--out", str(tmp_path / "e")]) == 2
    assert "unknown option --disk-split" in capsys.readouterr().err


def test_ddp_two_cpu_processes(tiny: Path, tmp_path: Path) -> None:
    run = tmp_path / "ddp"
    cmd = [sys.executable, "-m", "freespace.cli", "-v", "train", "--dataset", "synth", "--root", str(tiny), "--model",
           "segnet", "--batch-size", "4", "--no-progress", "--epochs", "2", "--devices", "2", "--strategy", "ddp",
           "--out", str(run)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert res.returncode == 0, res.stderr[-2000:]
    assert "Initializing distributed: GLOBAL_RANK: 0, MEMBER: 1/2" in res.stderr
    assert len(list(csv.DictReader((run / "metrics.csv").open()))) == 2
    # the test metrics were counted on two processes (disjoint halves of the test split) and summed: they
    # equal a single-process evaluation of the same checkpoint on the same frames
    from freespace.inference.evaluate import evaluate_checkpoint

    m = json.loads((run / "metrics.json").read_text())
    test_names = (run / "splits" / "test.txt").read_text().split()
    assert m["frames"]["test"] == len(test_names) >= 2
    single = evaluate_checkpoint(run / m["checkpoint"], "synth", tiny, tmp_path / "eval", progress=False)
    assert single["frames"] == len(test_names)
    for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap"):
        assert m[k] == pytest.approx(single[k], abs=1e-6), k


def test_evaluate_checkpoint(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    run = tmp_path / "run"
    assert _train(tiny, run, "--epochs", "1") == 0
    out = tmp_path / "eval"
    assert main(["evaluate", "--checkpoint", str(run / "checkpoints" / "best.ckpt"), "--dataset", "synth",
                 "--root", str(tiny), "--out", str(out), "--no-progress"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    trained = json.loads((run / "metrics.json").read_text())
    for k in ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap"):  # same frames, same size
        assert m[k] == pytest.approx(trained[k], abs=1e-6), k
    test_names = (run / "splits" / "test.txt").read_text().split()
    assert sorted(p.stem for p in (out / "overlays").glob("*.png")) == sorted(test_names)
    assert (out / "pr_curve.png").stat().st_size > 1000
    capsys.readouterr()
    assert main(["evaluate", "--checkpoint", str(tmp_path / "none.ckpt"), "--dataset", "synth", "--root", str(tiny),
                 "--out", str(tmp_path / "e2")]) == 2
    assert "checkpoint not found" in capsys.readouterr().err and not (tmp_path / "e2").exists()
    (tmp_path / "junk.ckpt").write_bytes(b"not a checkpoint")
    assert main(["evaluate", "--checkpoint", str(tmp_path / "junk.ckpt"), "--dataset", "synth", "--root", str(tiny),
                 "--out", str(tmp_path / "e2")]) == 2
    assert "not a freespace training checkpoint" in capsys.readouterr().err and not (tmp_path / "e2").exists()


def test_tensorboard_is_optional(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    try:
        import tensorboard  # noqa: F401
        pytest.skip("tensorboard is installed here")
    except ImportError:
        pass
    assert _train(tiny, tmp_path / "tb", "--tensorboard") == 2
    assert "pip install tensorboard" in capsys.readouterr().err


def test_the_module_trains_channels_last() -> None:
    from freespace.engine.module import RoadModule

    module = RoadModule("unet", {}, lr=0.01, momentum=0.9, weight_decay=0.0)
    module.on_fit_start()
    conv = next(m for m in module.net.modules() if isinstance(m, torch.nn.Conv2d))
    assert conv.weight.is_contiguous(memory_format=torch.channels_last)
    batch = module.on_after_batch_transfer({"image": torch.rand(2, 3, 32, 48), "label": torch.zeros(2, 32, 48)}, 0)
    assert batch["image"].is_contiguous(memory_format=torch.channels_last) and batch["label"].shape == (2, 32, 48)


def test_dropout_draws_depend_on_the_run_seed_and_the_epoch() -> None:
    from freespace.engine.module import epoch_seed

    seeds = {(s, e): epoch_seed(s, e) for s in range(3) for e in range(3)}
    assert len(set(seeds.values())) == 9
    assert epoch_seed(1, 2) == epoch_seed(1, 2)  # a resumed run draws the same


def test_the_monitored_validation_score(tmp_path: Path) -> None:
    """With --val-window N the best epoch is the one whose N-epoch mean F-score is highest."""
    from freespace.engine.train import CSV_FIELDS, _best_epoch, monitored
    from freespace.io.files import write_csv

    rows = [{"epoch": e, "val_f_score": f, "val_f_window": w}
            for e, (f, w) in enumerate([(0.70, 0.70), (0.90, 0.80), (0.72, 0.773), (0.85, 0.823), (0.86, 0.81)])]
    write_csv(tmp_path / "metrics.csv", CSV_FIELDS, rows)
    assert monitored(1) == "val_f_score" and monitored(3) == "val_f_window"
    assert _best_epoch(tmp_path, monitored(1)) == 2      # a lucky epoch (numbered from 1; the file from 0)
    assert _best_epoch(tmp_path, monitored(3)) == 4      # the best smoothed one


def test_min_delta_lets_early_stopping_fire(tiny: Path, tmp_path: Path) -> None:
    """An F-score that can never rise by half a point more ends the run after --patience epochs."""
    run = tmp_path / "run"
    assert _train(tiny, run, "--epochs", "6", "--patience", "1", "--min-delta", "0.5", "--image-size", "64x96") == 0
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["epochs_run"] == 2 and metrics["best_epoch"] == 1 and metrics["first_epoch"] == 1
    assert _train(tiny, tmp_path / "bad", "--min-delta", "1.5") == 2


def test_a_larger_patience_extends_a_stopped_run_exactly(tiny: Path, tmp_path: Path,
                                                        recwarn: pytest.WarningsRecorder) -> None:
    """Early stopping changes nothing a run computes before it stops: a run that stopped with patience 1 and is
    resumed with patience 3 ends as a run started with 3 (Lightning's checkpoint would restore the old one).
    The state of early stopping is replayed from the validation history, so a checkpoint whose state is under
    another name (an older version's) or wrong resumes exactly too, without Lightning's warning about it."""
    stopped, fresh = tmp_path / "stopped", tmp_path / "fresh"
    common = ("--epochs", "8", "--min-delta", "0.5", "--image-size", "64x96")
    assert _train(tiny, stopped, *common, "--patience", "1") == 0
    assert json.loads((stopped / "metrics.json").read_text())["epochs_run"] == 2
    last = stopped / "checkpoints" / "last.ckpt"
    ckpt = torch.load(last, weights_only=True)
    ckpt["callbacks"] = {k.lstrip("_"): {**v, "wait_count": 0, "best_score": torch.tensor(-torch.inf)}
                         if "EarlyStopping" in k else v for k, v in ckpt["callbacks"].items()}
    torch.save(ckpt, last)
    assert _train(tiny, fresh, *common, "--patience", "3") == 0
    assert _train(tiny, stopped, *common, "--patience", "3", "--resume") == 0
    assert not [w for w in recwarn if "callbacks used to create the checkpoint" in str(w.message)]
    assert _metrics(stopped) == _metrics(fresh) and _metrics(fresh)["epochs_run"] == 4
    rows = [[{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader((run / "metrics.csv").open())]
            for run in (stopped, fresh)]
    assert rows[0] == rows[1]
    assert _train(tiny, stopped, *common, "--patience", "2", "--resume") == 2  # patience may only grow


def test_deterministic_mode_warns_only_on_a_gpu(monkeypatch: pytest.MonkeyPatch) -> None:
    """On a CPU every operation has a deterministic kernel (an error otherwise); on a GPU the cross-entropy
    loss's forward (nll_loss2d) has none (seen on an H200, PyTorch 2.11), so deterministic mode there warns
    for it and stays deterministic for the others."""
    from freespace.engine.train import deterministic_mode

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert deterministic_mode() is True
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert deterministic_mode() == "warn"


def test_the_poly_schedule_decays_to_zero_and_resumes_exactly(tiny: Path, tmp_path: Path) -> None:
    """``--lr-schedule poly``: the rate after each epoch is ``lr (1 − steps / all steps)^0.9``, zero after the last;
    a run stopped early and resumed with more patience ends as a run started with it (the schedule's state comes
    back with the checkpoint), and more epochs are refused (the decay was laid over the first ones)."""
    stopped, fresh, constant = tmp_path / "stopped", tmp_path / "fresh", tmp_path / "constant"
    common = ("--epochs", "4", "--min-delta", "0.5", "--image-size", "64x96", "--lr", "0.01")
    assert _train(tiny, fresh, *common, "--patience", "4", "--lr-schedule", "poly") == 0
    lrs = [float(r["lr"]) for r in csv.DictReader((fresh / "metrics.csv").open())]
    assert lrs == pytest.approx([0.01 * (1 - k / 4) ** 0.9 for k in (1, 2, 3, 4)], abs=1e-12) and lrs[-1] == 0
    assert _train(tiny, constant, *common, "--patience", "4") == 0
    assert {float(r["lr"]) for r in csv.DictReader((constant / "metrics.csv").open())} == {0.01}
    assert _metrics(constant) != _metrics(fresh)
    assert _train(tiny, stopped, *common, "--patience", "1", "--lr-schedule", "poly") == 0
    assert json.loads((stopped / "metrics.json").read_text())["epochs_run"] == 2
    assert _train(tiny, stopped, *common, "--patience", "4", "--lr-schedule", "poly", "--resume") == 0
    assert _metrics(stopped) == _metrics(fresh)
    more = ("--epochs", "6", *common[2:], "--patience", "4", "--lr-schedule", "poly", "--resume")
    assert _train(tiny, stopped, *more) == 2  # refused: epochs 4 → 6 under a poly decay


def test_crop_top_trains_records_itself_and_is_checked(tiny: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """``--crop-top``: a run trains with it and its config.yaml says so; a resume with another value is refused,
    as is a value out of [0, 0.7), in one line and with no run folder."""
    run = tmp_path / "cut"
    common = ("--epochs", "1", "--image-size", "64x96")
    assert _train(tiny, run, *common, "--crop-top", "0.4") == 0
    assert yaml.safe_load((run / "config.yaml").read_text())["crop_top"] == 0.4
    assert _train(tiny, run, *common, "--epochs", "2", "--crop-top", "0.2", "--resume") == 2
    assert "crop_top 0.4 → 0.2" in capsys.readouterr().err
    assert _train(tiny, tmp_path / "bad", *common, "--crop-top", "0.7") == 2
    assert "Traceback" not in capsys.readouterr().err and not (tmp_path / "bad").exists()
