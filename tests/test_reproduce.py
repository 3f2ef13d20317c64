"""`freespace reproduce`: X, HA-X and the X-dup control with shared splits and initial weights; the tables
(mean ± std per network × variant × test set), paired gains with t-intervals, a shifted test set, figures,
index; reruns skip; one cell at a time (--only) and the tables from the run folders (--tables)."""

from __future__ import annotations

import csv
import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from freespace.cli import main
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.errors import InvalidOptionError
from freespace.experiments.stats import paired_gain
from freespace.io.codecs import read_image

METRICS = ("accuracy", "precision", "recall", "f_score", "iou")


def _render(factory: pytest.TempPathFactory, name: str, num: int, seed: int, **rigs) -> Path:
    """``num`` rendered 128×96 frames, 2 a drive, in a new temporary folder."""
    root = factory.mktemp(name)
    write_dataset(root, num, seed=seed, config=SynthConfig(width=128, height=96, frames_per_scenario=2, **rigs),
                  progress=False)
    return root


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _render(tmp_path_factory, "rep", 16, 3)


@pytest.fixture(scope="module")
def shifted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Other rigs: wider roll, other heights, pitches and baselines (the README's recipe, smaller)."""
    return _render(tmp_path_factory, "shifted", 4, 11, max_roll_deg=6, camera_heights=(1.0, 2.6), pitches_deg=(-5, 5),
                   baselines=(0.2, 2.0))


@pytest.fixture(scope="module")
def same_rigs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A further test set named on the command line: other drives of the training rigs."""
    return _render(tmp_path_factory, "same", 4, 12)


@pytest.fixture(scope="module")
def experiment(data: Path, shifted: Path, same_rigs: Path, tmp_path_factory: pytest.TempPathFactory):
    """One protocol run (segnet, X / HA-X / X-dup, 2 seeds, 1 epoch, with a shifted test set and one named
    `same`), with the
    initial weights of every run as the engine made them (seen when the optimiser is made)."""
    import freespace.engine.module as module

    out = tmp_path_factory.mktemp("exp") / "exp"
    args = ["reproduce", "--dataset", "synth", "--root", str(data), "--models", "segnet", "--seeds", "2",
            "--variants", "X,HA-X,X-dup", "--test-root", str(shifted), "--test-root", f"same={same_rigs}",
            "--epochs", "1", "--batch-size", "4",
            "--image-size", "64x96",
            "--no-progress", "--out", str(out)]
    weights = []
    configure = module.RoadModule.configure_optimizers

    def recording(self):  # at the start of fit, before the first step: the initial weights
        weights.append({k: v.detach().clone() for k, v in self.state_dict().items()})
        return configure(self)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(module.RoadModule, "configure_optimizers", recording)
        assert main(args) == 0
    return out, args, weights


def _of(entry: dict, test_set: str) -> dict:
    """An index entry's metrics on one test set."""
    return entry["metrics"] if test_set == "test" else entry["test_sets"][test_set]


def _same(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_duplicate_matches_homography_training_list(data: Path, tmp_path: Path) -> None:
    """X-dup trains on exactly HA-X's frames and labels (the frames with a generated view, unchanged)."""
    from freespace.engine.config import TrainConfig
    from freespace.engine.data import prepare_data

    lists = {}
    for augment in ("none", "homography", "duplicate"):
        config = TrainConfig(dataset="synth", root=str(data), out=str(tmp_path / augment), model="segnet",
                             augment=augment, seed=1)
        config.check()
        lists[augment] = prepare_data(config, tmp_path / augment)
    x, ha, dup = (lists[a]["train"] for a in ("none", "homography", "duplicate"))
    n = len(x)
    assert n >= 8 and len(ha) == len(dup) == 2 * n  # every training frame has a view here (exact disparities)
    assert [(it.index, it.name) for it in ha] == [(it.index, it.name) for it in dup]  # same frames → same labels
    assert [it.image for it in dup] == [None] * 2 * n and all(it.image for it in ha[n:])  # own images vs views
    assert [(it.index, it.name) for it in dup[:n]] == [(it.index, it.name) for it in x]
    assert lists["none"]["frames"] == lists["homography"]["frames"] == lists["duplicate"]["frames"] == n
    for k in ("val", "test"):  # one split per seed
        assert lists["none"][k] == lists["homography"][k] == lists["duplicate"][k]


@pytest.mark.slow  # with its fixture: six short runs, about 1½ minutes on an idle 2-core machine
def test_reproduce(experiment, shifted: Path, same_rigs: Path, capsys: pytest.CaptureFixture) -> None:
    out, args, weights = experiment
    # runs in order X s0, X s1, HA-X s0, HA-X s1, X-dup s0, X-dup s1: one seed → one set of initial weights
    assert len(weights) == 6
    assert _same(weights[0], weights[2]) and _same(weights[0], weights[4])
    assert _same(weights[1], weights[3]) and _same(weights[1], weights[5]) and not _same(weights[0], weights[1])
    for seed in (0, 1):  # ... and one split
        tests = {(out / f"runs/segnet-{t}-s{seed}/splits/test.txt").read_text() for t in ("orig", "ha", "dup")}
        assert len(tests) == 1
    index = json.loads((out / "index.json").read_text())
    assert [(r["variant"], r["seed"]) for r in index] == [(v, s) for v in ("X", "HA-X", "X-dup") for s in (0, 1)]
    frames = {r["variant"]: json.loads((out / r["run"] / "metrics.json").read_text())["frames"] for r in index}
    assert frames["HA-X"]["train"] == frames["X-dup"]["train"] == 2 * frames["X"]["train"] > 0
    for entry in index:  # the index holds each run's own test metrics, from one set of counts
        m = json.loads((out / entry["run"] / "metrics.json").read_text())
        assert entry["status"] == "done" and entry["metrics"] == {k: m[k] for k in entry["metrics"]}
        assert m["iou"] == pytest.approx(m["f_score"] / (2 - m["f_score"]), abs=1e-12)  # IoU = F/(2−F)
        assert 0.2 < m["f_score"] <= 1 and 0 < m["precision"] <= 1 and 0 < m["recall"] <= 1
        for name, root in (("shifted", shifted), ("same", same_rigs)):
            s = json.loads((out / entry["run"] / name / "metrics.json").read_text())
            assert s["frames"] == 4 and s["root"] == str(root.resolve())
            assert entry["test_sets"][name]["f_score"] == s["f_score"]
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert list(rows[0])[:5] == ["network", "variant", "test_set", "n", "accuracy_mean"]
    assert [(r["network"], r["variant"], r["test_set"], r["n"]) for r in rows] == \
        [("segnet", v, t, "2") for t in ("test", "shifted", "same") for v in ("X", "HA-X", "X-dup")]
    for row in rows:  # mean ± std (in %) over the seeds of the index
        for k in METRICS:
            values = 100 * np.array([_of(e, row["test_set"])[k] for e in index if e["variant"] == row["variant"]])
            assert float(row[f"{k}_mean"]) == pytest.approx(values.mean(), abs=1e-4)
            assert float(row[f"{k}_std"]) == pytest.approx(values.std(ddof=1), abs=1e-4)
    gains = list(csv.DictReader((out / "gains.csv").open()))
    assert list(gains[0]) == ["network", "versus", "metric", "test_set", "mean", "ci_low", "ci_high", "n",
                              "excludes_zero"]
    assert {(g["versus"], g["test_set"]) for g in gains} == \
        {(v, t) for v in ("HA-X - X", "HA-X - X-dup", "X-dup - X") for t in ("test", "shifted", "same")}
    for g in gains:  # the paired t-interval of the per-seed differences, in points
        a, b = g["versus"].split(" - ")
        va = [100 * _of(e, g["test_set"])[g["metric"]] for e in index if e["variant"] == a]
        vb = [100 * _of(e, g["test_set"])[g["metric"]] for e in index if e["variant"] == b]
        ref = paired_gain(va, vb)
        assert g["n"] == "2" and float(g["mean"]) == pytest.approx(ref.mean, abs=1e-4)
        assert float(g["ci_low"]) == pytest.approx(ref.ci_low, abs=1e-4) and float(g["ci_low"]) <= float(g["mean"])
        assert float(g["ci_high"]) == pytest.approx(ref.ci_high, abs=1e-4)
        assert g["excludes_zero"] == str(ref.excludes_zero).lower()
    md = (out / "results.md").read_text()
    r = rows[1]
    assert f"| segnet | HA-X | test | 2 | {float(r['accuracy_mean']):.2f} ± {float(r['accuracy_std']):.2f} |" in md
    assert "t-interval" in md and "| segnet | HA-X − X-dup | F-score | shifted | 2 |" in md
    g = next(g for g in gains if (g["versus"], g["metric"], g["test_set"]) == ("HA-X - X-dup", "f_score", "shifted"))
    lo, hi = float(g["ci_low"]), float(g["ci_high"])  # the half-width column: what "± 1.5 points" is read from
    assert f"| {float(g['mean']):+.2f} | [{lo:+.2f}, {hi:+.2f}] | {(hi - lo) / 2:.2f} |" in md
    # three test frames of seed 0: image, X, HA-X, X-dup side by side at the data's size (96×128)
    assert read_image(out / "figures" / "segnet.png").shape == (3 * 96, 4 * 128, 3)
    assert read_image(out / "figures" / "gains_segnet.png").shape[2] == 3
    capsys.readouterr()
    assert main(args) == 0  # finished runs (and their shifted tests) are skipped
    assert "| segnet | HA-X | test | 2 |" in capsys.readouterr().out
    assert all(r["status"] == "done (skipped)" for r in json.loads((out / "index.json").read_text()))
    assert list(csv.DictReader((out / "gains.csv").open())) == gains


@pytest.mark.slow
def test_reproduce_cells_and_tables(experiment, data: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """--only runs one cell into its run folder only (the same result as in the whole run); --tables
    collects whatever cells are finished."""
    out, _, _ = experiment
    cells = tmp_path / "cells"
    base = ["reproduce", "--dataset", "synth", "--root", str(data), "--seeds", "2", "--epochs", "1",
            "--image-size", "64x96", "--batch-size", "4", "--no-progress", "--out", str(cells)]
    assert main(base + ["--only", "segnet,X,1"]) == 0
    assert "runs/segnet-orig-s1: done" in capsys.readouterr().out
    assert sorted(p.name for p in cells.iterdir()) == [".freespace", "runs"]  # no table: only the manifest
    ours = json.loads((cells / "runs/segnet-orig-s1/metrics.json").read_text())
    theirs = json.loads((out / "runs/segnet-orig-s1/metrics.json").read_text())
    assert {k: ours[k] for k in METRICS} == {k: theirs[k] for k in METRICS}  # deterministic on a CPU
    shutil.copytree(out / "runs/segnet-ha-s1", cells / "runs/segnet-ha-s1")  # another cell, finished elsewhere
    assert main(["reproduce", "--tables", "--out", str(cells)]) == 0
    assert "| segnet | HA-X − X | F-score | test | 1 |" in capsys.readouterr().out
    rows = list(csv.DictReader((cells / "results.csv").open()))
    assert [(r["variant"], r["test_set"], r["n"]) for r in rows] == [("X", "test", "1"), ("HA-X", "test", "1"),
                                                                     ("HA-X", "shifted", "1"), ("HA-X", "same", "1")]
    assert rows[0]["f_score_std"] == "0.0000"
    gains = list(csv.DictReader((cells / "gains.csv").open()))
    assert [(g["versus"], g["metric"], g["n"], g["ci_low"], g["excludes_zero"]) for g in gains] == \
        [("HA-X - X", "f_score", "1", "", "false"), ("HA-X - X", "iou", "1", "", "false")]  # no interval of one
    index = json.loads((cells / "index.json").read_text())
    assert [(e["run"], e["status"]) for e in index] == [("runs/segnet-orig-s1", "done"), ("runs/segnet-ha-s1", "done")]
    assert not (cells / "figures" / "segnet.png").exists()  # the figure shows seed 0
    shutil.copytree(out / "runs/segnet-dup-s1", cells / "runs/segnet-dup-s1")  # tested on another `same` folder:
    moved = cells / "runs/segnet-dup-s1/same/metrics.json"                     # not mixed silently
    moved.write_text(json.dumps({**json.loads(moved.read_text()), "root": "/elsewhere"}))
    assert main(["reproduce", "--tables", "--out", str(cells)]) == 0
    assert "**Warning: the runs differ in the root of test set same: " in (cells / "results.md").read_text()
    (cells / "runs/segnet-orig-s1/bogus").mkdir()  # a crafted file where a test set's metrics would be: skipped
    (cells / "runs/segnet-orig-s1/bogus/metrics.json").write_text('{"f_score": "x"}')
    assert main(["reproduce", "--tables", "--out", str(cells)]) == 0
    assert "bogus" not in (cells / "results.csv").read_text()


def test_a_larger_cap_or_patience_extends_a_finished_cell(data: Path, same_rigs: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture) -> None:
    """A finished cell run again with a larger --epochs resumes from its last checkpoint, ends as a cell started
    with it, and is tested again on each test set; a smaller patience is refused."""
    def cell(out: Path, epochs: str, patience: str = "10") -> list[str]:
        return ["reproduce", "--dataset", "synth", "--root", str(data), "--seeds", "1", "--epochs", epochs,
                "--patience", patience, "--image-size", "64x96", "--batch-size", "4", "--no-progress",
                "--test-root", f"same={same_rigs}", "--out", str(out), "--only", "segnet,X,0"]

    extended, fresh = tmp_path / "extended", tmp_path / "fresh"
    assert main(cell(extended, "1")) == 0
    run = extended / "runs/segnet-orig-s0"
    assert json.loads((run / "same/metrics.json").read_text())["trained"] == \
        {"best_epoch": 1, "first_epoch": 1, "epochs_run": 1}
    assert main(cell(extended, "2")) == 0
    assert main(cell(fresh, "2")) == 0
    ours, theirs = (json.loads((r / "runs/segnet-orig-s0/metrics.json").read_text()) for r in (extended, fresh))
    assert {k: ours[k] for k in (*METRICS, "epochs_run")} == {k: theirs[k] for k in (*METRICS, "epochs_run")}
    assert ours["epochs_run"] == 2
    same = [json.loads((r / "runs/segnet-orig-s0/same/metrics.json").read_text()) for r in (extended, fresh)]
    assert same[0]["trained"]["epochs_run"] == 2
    assert {k: same[0][k] for k in METRICS} == {k: same[1][k] for k in METRICS}
    capsys.readouterr()
    assert main(cell(extended, "2", patience="5")) == 2
    assert "patience 10 → 5" in capsys.readouterr().err


@pytest.mark.parametrize("extra, message", [
    (["--models", "fcn"], "unknown models"),
    (["--seeds", "0"], "--seeds must be an integer in [1, 1000]"),
    (["--only", "fcn,X,0"], "--only: unknown network 'fcn'"),
    (["--only", "unet,HB-X,0"], "--only: unknown variant 'HB-X'"),
    (["--only", "unet,X,3"], "--only: the seed must be an integer in 0…2"),
    (["--only", "unet,X"], "--only must be NETWORK,VARIANT,SEED"),
    (["--test-root", "/nonexistent/shifted"], "/nonexistent/shifted"),
    (["--test-root", "test=/tmp"], "'test' cannot name a test set"),
    (["--test-root", "/tmp", "--test-root", "shifted=/tmp"], "two test sets are named 'shifted'"),
    (["--tables", "--only", "unet,X,0"], "--tables collects the finished cells"),
    (["--only", "unet,X-auto,0"], "give --autolabels DIR"),
    (["--variants", "X,X-mix"], "give --autolabels DIR"),
])
def test_reproduce_mistakes(data: Path, tmp_path: Path, capsys: pytest.CaptureFixture, extra: list[str],
                            message: str) -> None:
    assert main(["reproduce", "--dataset", "synth", "--root", str(data), "--out", str(tmp_path / "o")] + extra) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()  # rejected before any work


def test_reproduce_tables_mistakes(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["reproduce", "--tables", "--out", str(tmp_path)]) == 2
    assert "holds no run folders" in capsys.readouterr().err
    assert main(["reproduce", "--out", str(tmp_path)]) == 2
    assert "needs --dataset and --root" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# --- the converged protocol (issue 23): X-long, convergence, the averaged gains and the primary endpoint ---

def _fake_run(out: Path, data: Path, model: str, variant: str, seed: int, f: float, best: int, run: int,
              size: tuple[int, int] = (64, 96)) -> None:
    """A finished run folder as ``reproduce`` writes it (config.yaml, metrics.json), without training."""
    from freespace.experiments.cells import cell_config as _config

    config = _config("synth", data, out, model, variant, seed, dict(epochs=10, patience=3, val_window=1,
                                                                    batch_size=4, image_size=size))
    Path(config.out).mkdir(parents=True)
    config.save(Path(config.out) / "config.yaml")
    metrics = {k: f for k in (*METRICS, "max_f", "ap")}
    (Path(config.out) / "metrics.json").write_text(json.dumps({**metrics, "best_epoch": best, "epochs_run": run}))


def test_x_long_budget_and_convergence_in_the_index(data: Path, tmp_path: Path) -> None:
    from freespace.experiments.cells import cell_config as _config
    from freespace.experiments.tables import _convergence_lines
    from freespace.experiments.tables import collect as _collect

    long = _config("synth", data, tmp_path, "unet", "X-long", 0, dict(epochs=10, patience=3, lr=0.01))
    assert (long.augment, long.epochs, long.patience, long.lr, Path(long.out).name) == \
        ((), 20, 6, 0.01, "unet-long-s0")
    _fake_run(tmp_path, data, "unet", "X", 0, 0.8, best=4, run=8)      # early stopping fired after epoch 8
    _fake_run(tmp_path, data, "unet", "X-long", 0, 0.82, best=19, run=20)  # ran to its cap of 20
    _fake_run(tmp_path, data, "segnet", "X", 0, 0.7, best=2, run=5, size=(96, 128))
    entries, differ = _collect(tmp_path)
    assert differ == []  # X-long's doubled budget is its variant's; each network may have its own size
    _fake_run(tmp_path, data, "segnet", "X", 1, 0.7, best=2, run=5, size=(64, 96))
    assert _collect(tmp_path)[1] == ['image_size of segnet: [64, 96], [96, 128]']  # within a network: warned
    entries = [e for e in _collect(tmp_path)[0] if e["model"] == "unet"]
    assert [(e["variant"], e["augment"], e["best_epoch"], e["epochs_run"], e["stopped_by"]) for e in entries] == \
        [("X", "none", 5, 8, "patience"), ("X-long", "none", 20, 20, "cap")]
    lines = "\n".join(_convergence_lines(entries))
    assert "| unet | X | 1 | 5.0 (5–5) | 8.0 (8–8) | 1 | 0 |" in lines
    assert "| unet | X-long | 1 | 20.0 (20–20) | 20.0 (20–20) | 0 | 1 |" in lines


def test_virtual_pose_ranges_reach_only_the_virtual_variants(data: Path, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture) -> None:
    """``reproduce --virtual-shift`` (e.g. HV-X covering a shifted test set's camera heights) sets the pose ranges
    of HV-X and HAV-X; X's cells keep the defaults, so a campaign's finished X cells are not refused as changed."""
    from freespace.engine.config import TrainConfig
    from freespace.experiments.cells import cell_config as _config

    options = dict(epochs=2, patience=1, virtual_shift="0,-3.1:1.25,0", virtual_rotate="12,6,0")
    hv, x = (_config("synth", data, tmp_path, "unet", v, 0, options) for v in ("HV-X", "X"))
    assert hv.to_dict()["virtual_shift"] == "0,-3.1:1.25,0" and hv.virtual_rotate == ((-12, 12), (-6, 6), (0, 0))
    defaults = TrainConfig(dataset="synth", root=str(data), out="o")
    assert (x.virtual_shift, x.virtual_rotate) == (defaults.virtual_shift, defaults.virtual_rotate)
    assert main(["reproduce", "--dataset", "synth", "--root", str(data), "--out", str(tmp_path / "r"), "--models",
                 "unet", "--variants", "HV-X", "--virtual-shift", "0,-3:0.9,9:8", "--epochs", "1"]) == 2
    assert "--virtual-shift must be three ranges" in capsys.readouterr().err


def test_preset_reaches_the_cells(data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``reproduce --preset paper`` (the paper's backbones, for a GPU) reaches every cell's configuration, and a
    cell started with another preset is refused, not mixed in."""
    import freespace.experiments.reproduce as rep
    from freespace.experiments.cells import check_cell

    seen = []
    monkeypatch.setattr(rep, "run_cell", lambda config, **_: seen.append(config) or "done")
    args = ["reproduce", "--dataset", "synth", "--root", str(data), "--out", str(tmp_path / "r"), "--only",
            "segnet,HA-X,0", "--epochs", "1"]
    assert main(args + ["--preset", "paper"]) == 0
    assert [(c.preset, c.model_options()) for c in seen] == [("paper", {"preset": "paper"})]
    seen[0].save(Path(seen[0].out, "config.yaml"))  # as a started cell holds it
    with pytest.raises(InvalidOptionError, match="preset 'paper' → 'light'"):
        check_cell(replace(seen[0], preset="light"))


def test_gains_averaged_over_networks_and_the_primary_endpoint() -> None:
    from freespace.experiments.protocol import Primary
    from freespace.experiments.tables import _gains, _primary_lines
    from freespace.experiments.variants import ALL_NETWORKS, GAINS

    rng = np.random.default_rng(0)
    entries = []
    for model in ("unet", "segnet"):
        for seed in range(6):
            base = 0.8 + 0.02 * rng.standard_normal()
            dup = 0.02 + 0.002 * rng.standard_normal()
            for variant, shift in (("X", 0.0), ("HA-X", 0.02), ("X-dup", dup), ("X-long", 0.015)):
                m = {k: base + shift for k in METRICS}
                entries.append({"model": model, "variant": variant, "seed": seed, "metrics": m,
                                "test_sets": {"fixed": m}})
    gains = _gains(entries, GAINS)
    avg = [g for g in gains if g["network"] == ALL_NETWORKS and g["versus"] == "HA-X - X-dup"
           and g["metric"] == "f_score" and g["test_set"] == "fixed"]
    assert len(avg) == 1 and avg[0]["n"] == 6
    per_seed = [100 * np.mean([next(e["metrics"]["f_score"] for e in entries if e["model"] == m and e["seed"] == s
                                    and e["variant"] == v) for m in ("unet", "segnet")]) for s in range(6)
                for v in ("HA-X", "X-dup")]
    expected = paired_gain(per_seed[0::2], per_seed[1::2])
    assert avg[0]["mean"] == pytest.approx(expected.mean) and avg[0]["ci_low"] == pytest.approx(expected.ci_low)
    primary = Primary(("HA-X", "X-dup"), "f_score", "fixed", 1.0)
    line = "\n".join(_primary_lines(gains, primary))
    assert "Primary endpoint" in line and "inside ±1" in line  # the two differ by noise of 0.2 points
    assert "`fixed`" in line and f"{avg[0]['mean']:+.2f} points" in line
    assert _primary_lines(gains, None) == []  # a protocol without one: no line
    assert _primary_lines(gains, Primary(("HA-X", "X-dup"), "f_score", "other", 1.0)) == []  # not measured
    ha_x = [g for g in gains if g["network"] == ALL_NETWORKS and g["versus"] == "HA-X - X" and g["metric"] == "f_score"
            and g["test_set"] == "test"]
    assert ha_x[0]["mean"] == pytest.approx(2.0) and ha_x[0]["excludes_zero"]
    # the second augmentation draw at equal steps (X-dup − X-long), per network and averaged over them
    dup_long = {g["network"]: g for g in gains if g["versus"] == "X-dup - X-long" and g["metric"] == "f_score"
                and g["test_set"] == "test"}
    assert sorted(dup_long) == [ALL_NETWORKS, "segnet", "unet"] and dup_long["unet"]["n"] == 6
    assert dup_long["unet"]["mean"] == pytest.approx(
        100 * np.mean([e["metrics"]["f_score"] for e in entries if e["model"] == "unet" and e["variant"] == "X-dup"])
        - 100 * np.mean([e["metrics"]["f_score"] for e in entries
                         if e["model"] == "unet" and e["variant"] == "X-long"]))


def test_the_frames_figure_measures_on_the_runs_label_tree(tmp_path: Path) -> None:
    """Runs trained on frames that have no labels of their own (KITTI raw drives) were measured on a label tree
    (``labels``): the figure shows each prediction's errors against it, and the prediction alone where the tree
    is gone (once this crashed on the frames' missing labels)."""
    import cv2
    import yaml

    from freespace.experiments.figures import frames_figure
    from freespace.testing import road_frame, tiny_road_checkpoint

    root, tree, out = tmp_path / "frames", tmp_path / "labels", tmp_path / "out"
    (root / "left").mkdir(parents=True)
    tree.mkdir()
    (root / "freespace.yaml").write_text("left: left\n")  # images only: no label of its own
    for i in range(2):
        image, road = road_frame((48, 96), seed=i)
        cv2.imwrite(str(root / "left" / f"f{i}.png"), image[..., ::-1])
        label = np.zeros((48, 96, 3), np.uint8)
        label[..., 2] = 255
        label[road] = (255, 0, 255)  # KITTI colours, BGR: road magenta, not road red
        cv2.imwrite(str(tree / f"f{i}.png"), label)
    checkpoint = tiny_road_checkpoint(tmp_path / "tiny.ckpt", (48, 96), 0.25)
    entries = []
    for variant in ("X", "HA-X"):
        run = out / "runs" / f"fastscnn-{variant.lower()}-s0"
        (run / "checkpoints").mkdir(parents=True)
        (run / "splits").mkdir()
        shutil.copy(checkpoint, run / "checkpoints" / "best.ckpt")
        for part, names in (("train", ""), ("val", ""), ("test", "f0\nf1\n")):
            (run / "splits" / f"{part}.txt").write_text(names)
        (run / "config.yaml").write_text(yaml.safe_dump({"dataset": "generic", "root": str(root),
                                                         "labels": str(tree)}))
        entries.append({"model": "fastscnn", "seed": 0, "variant": variant, "run": str(run.relative_to(out)),
                        "metrics": {}})
    frames_figure(out, "fastscnn", entries, 2)
    measured = read_image(out / "figures" / "fastscnn.png")
    shutil.rmtree(tree)
    frames_figure(out, "fastscnn", entries, 2)
    alone = read_image(out / "figures" / "fastscnn.png")
    assert measured.shape == alone.shape and not np.array_equal(measured, alone)
