"""The decomposition of HA-X − X at two sets of seeds (studies/converged/decomposition.py, issue 47)."""

from __future__ import annotations

import csv
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

from freespace.experiments.stats import paired_gain

SCRIPT = Path(__file__).resolve().parents[1] / "decomposition.py"
spec = importlib.util.spec_from_file_location("decomposition", SCRIPT)
decomposition = importlib.util.module_from_spec(spec)
spec.loader.exec_module(decomposition)


def _entry(model: str, variant: str, seed: int, f: float, status: str = "done") -> dict:
    return {"run": f"runs/{model}-{variant}-s{seed}", "model": model, "variant": variant, "seed": seed,
            "status": status, "metrics": {"f_score": 0.5},
            "test_sets": {"same-rigs": {"f_score": f / 100}, "shifted": {"f_score": (f - 3) / 100}}}


def _index() -> list[dict]:
    """Two networks; ``a`` has X-long for seeds 0–3, ``b`` for seeds 0–1 and 3 (seed 2 still running)."""
    entries = []
    for model, base in (("a", 90.0), ("b", 80.0)):
        for s in range(4):
            entries += [_entry(model, "X", s, base + s), _entry(model, "X-dup", s, base + s + 0.2),
                        _entry(model, "HA-X", s, base + s + 1.0 + 0.1 * s)]
            entries.append(_entry(model, "X-long", s, base + s + 0.5 * (s + 1),
                                  "running" if (model, s) == ("b", 2) else "done"))
    return entries


def _row(rows: list[dict], test_set: str, gain: str, network: str) -> dict:
    return next(r for r in rows if (r["test set"], r["gain"], r["network"]) == (test_set, gain, network))


def test_each_network_pairs_its_finished_seeds_and_the_mean_only_shared_ones() -> None:
    scores = decomposition.f_scores(_index())
    rows = decomposition.decomposition(scores, ["a", "b"], [[0, 1], [0, 1, 2, 3]])
    assert len(rows) == 2 * len(decomposition.GAINS) * 3
    a = _row(rows, "same-rigs", "X-long − X", "a")
    g = paired_gain([0.5, 1.0, 1.5, 2.0], [0.0] * 4)
    assert a["seeds 0–3"] == f"{g.mean:+.2f} [{g.ci_low:+.2f}, {g.ci_high:+.2f}] (n = 4)"
    assert a["seeds 0–1"].endswith("(n = 2)")
    b = _row(rows, "same-rigs", "X-long − X", "b")
    assert b["seeds 0–3"].endswith("(n = 3)")  # b's seed 2 has not finished X-long
    mean = _row(rows, "same-rigs", "X-long − X", "mean of 2")
    g = paired_gain([0.5, 1.0, 2.0], [0.0] * 3)  # seeds 0, 1, 3: both networks equal, so the mean is either
    assert mean["seeds 0–3"] == f"{g.mean:+.2f} [{g.ci_low:+.2f}, {g.ci_high:+.2f}] (n = 3)"
    # the gains that need no X-long keep every seed, and shifted is its own test set
    assert _row(rows, "shifted", "HA-X − X-dup", "mean of 2")["seeds 0–3"].endswith("(n = 4)")
    only = decomposition.decomposition(scores, ["a"], [[2]])
    assert _row(only, "same-rigs", "HA-X − X", "a")["seeds 2–2"] == "+1.20 (n = 1)"
    assert _row(only, "same-rigs", "HA-X − X", "mean of 1 (subgroup)")["seeds 2–2"] == "+1.20 (n = 1)"
    assert _row(decomposition.decomposition(scores, ["b"], [[2]]), "same-rigs", "X-long − X", "b")["seeds 2–2"] == ""


def test_the_script_prints_and_writes_the_table_and_refuses_mistakes(tmp_path: Path) -> None:
    res = tmp_path / "res"
    res.mkdir()
    (res / "index.json").write_text(json.dumps(_index()))
    out = tmp_path / "d.csv"
    run = subprocess.run([sys.executable, str(SCRIPT), str(res), "--networks", "a,b", "--seeds", "0-1",
                          "--seeds", "0,3", "--csv", str(out)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "| same-rigs | HA-X − X-long | mean of 2 |" in run.stdout
    with out.open(newline="") as f:
        table = list(csv.DictReader(f))
    assert list(table[0]) == ["test set", "gain", "network", "seeds 0–1", "seeds 0,3"]
    for args, message in ((["--networks", "a,zz"], "no finished run of zz"), (["--seeds", "x-y"], "seeds 'x-y'"),
                          (["--csv", str(res / "index.json")], "is the input")):
        run = subprocess.run([sys.executable, str(SCRIPT), str(res), *args], capture_output=True, text=True)
        assert run.returncode != 0 and message in run.stderr and "Traceback" not in run.stderr
    run = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path)], capture_output=True, text=True)
    assert run.returncode != 0 and "holds no index.json" in run.stderr


def _run_folders(res: Path, index: list[dict]) -> None:
    """A run folder for every entry: ``metrics.json`` with its training frames, ``config.yaml`` with batch 2."""
    for e in index:
        run = res / e["run"]
        run.mkdir(parents=True)
        frames = 120 if e["variant"] in ("HA-X", "X-dup") else 60
        (run / "metrics.json").write_text(json.dumps({"frames": {"train": frames, "val": 20, "test": 20}}))
        (run / "config.yaml").write_text("batch_size: 2\n")


def test_the_steps_taken_are_epochs_times_batches_and_the_ratios_pair_seeds(tmp_path: Path) -> None:
    index = _index()
    for e in index:  # epochs: X 10 + seed, X-long 20 + seed, X-dup 8 + seed, HA-X 9 + seed
        e["epochs_run"] = {"X": 10, "X-long": 20, "X-dup": 8, "HA-X": 9}[e["variant"]] + e["seed"]
    _run_folders(tmp_path, index)
    steps = decomposition.steps_taken(tmp_path, index)
    assert steps["a", "X"][3] == (13, 390) and steps["a", "HA-X"][0] == (9, 540)
    assert 2 not in steps["b", "X-long"]  # still running
    rows = {r["variant or ratio"]: r for r in decomposition.steps_table(steps, ["a", "b"], [[0, 1, 2, 3]])}
    assert rows["X-dup"]["seeds 0–3"] == "9.5 epochs, 570 steps (n = 8)"
    assert rows["X-long"]["seeds 0–3"].endswith("(n = 7)")
    # HA-X / X-long seed by seed: 2 (9 + s) / (20 + s); the ratio falls with the seed
    r = sorted(2 * (9 + s) / (20 + s) for s in (0, 1, 2, 3, 0, 1, 3))
    assert rows["HA-X / X-long"]["seeds 0–3"] == f"{r[0]:.2f}–{r[-1]:.2f}, median {r[3]:.2f} (n = 7)"
    d = sorted((9 + s) / (8 + s) for s in (0, 1, 2, 3) * 2)  # both 60 steps an epoch
    assert rows["HA-X / X-dup"]["seeds 0–3"] == f"{d[0]:.2f}–{d[-1]:.2f}, median {(d[3] + d[4]) / 2:.2f} (n = 8)"


def test_the_script_prints_the_steps_and_says_what_a_run_folder_lacks(tmp_path: Path) -> None:
    res = tmp_path / "res"
    index = _index()
    for e in index:
        e["epochs_run"] = 10
    _run_folders(res, index)
    (res / "index.json").write_text(json.dumps(index))
    run = subprocess.run([sys.executable, str(SCRIPT), str(res), "--networks", "a,b", "--steps"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "| HA-X / X-long | 2.00–2.00, median 2.00 (n = 7) | 2.00–2.00, median 2.00 (n = 7) |" in run.stdout
    (res / "runs/a-X-s0/config.yaml").unlink()
    run = subprocess.run([sys.executable, str(SCRIPT), str(res), "--networks", "a,b", "--steps"],
                         capture_output=True, text=True)
    assert run.returncode != 0 and "lacks its metrics.json or config.yaml" in run.stderr
    assert "Traceback" not in run.stderr
