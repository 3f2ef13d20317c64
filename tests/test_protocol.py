"""A study's protocol file (``reproduce --protocol``): its variants, gains, primary endpoint, test sets and
reference line reach the cells and the tables; without one the method's defaults hold; a bad file ends in one
line before any work."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from freespace.cli import main
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.experiments import GAINS, Primary, Protocol

METRICS = ("accuracy", "precision", "recall", "f_score", "iou", "max_f", "ap")

GOOD = """\
variants: [X, HA-X, X-long]
gains: [HA-X - X-long, HA-X - X]
primary: {versus: HA-X - X, metric: iou, test_set: fixed, margin: 2}
test_sets: {fixed: fixed-frames}
reference: "published: +1 to +2 points"
"""


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("proto")
    write_dataset(root, 8, seed=3, config=SynthConfig(width=128, height=96, frames_per_scenario=2), progress=False)
    return root


def test_a_protocol_file_reads_as_its_values(tmp_path: Path) -> None:
    (tmp_path / "p.yaml").write_text(GOOD)
    p = Protocol.load(tmp_path / "p.yaml")
    assert p == Protocol(variants=("X", "HA-X", "X-long"), gains=(("HA-X", "X-long"), ("HA-X", "X")),
                         primary=Primary(("HA-X", "X"), "iou", "fixed", 2.0),
                         test_sets={"fixed": Path("fixed-frames")}, reference="published: +1 to +2 points")
    (tmp_path / "empty.yaml").write_text("{}\n")
    assert Protocol.load(tmp_path / "empty.yaml") == Protocol()  # the method's defaults
    assert Protocol().gains == GAINS and Protocol().primary is None and Protocol().reference is None


@pytest.mark.parametrize("text, message", [
    ("- X\n", "is not a mapping"),
    ("variants: [X]\nprimry: {}\n", "unknown key 'primry'"),
    ("variants: [X, HA-Y]\n", "unknown variants ['HA-Y']"),
    ("variants: X\n", "variants must be a list"),
    ("gains: [HA-X-X]\n", "gain 'HA-X-X' is not 'VARIANT - VERSUS'"),
    ("gains: [HA-X - HA-X]\n", "is not 'VARIANT - VERSUS'"),
    ("gains: [HA-X - X, HA-X - X]\n", "names a gain twice"),
    ("gains: []\n", "gains must be a list"),
    ("gains: [HA-X - X]\nprimary: {versus: HA-X - X-dup, metric: f_score, test_set: a, margin: 1}\n",
     "primary's gain 'HA-X - X-dup' is not among the gains reported"),
    ("primary: {versus: HA-X - X, metric: accuracy, test_set: a, margin: 1}\n", "primary's metric must be one of"),
    ("primary: {versus: HA-X - X, metric: iou, test_set: a, margin: .nan}\n", "margin must be a positive number"),
    ("primary: {versus: HA-X - X, metric: iou, test_set: a, margin: true}\n", "margin must be a positive number"),
    ("primary: {versus: HA-X - X, metric: iou, test_set: A B, margin: 1}\n", "test_set must be test or"),
    ("primary: {versus: HA-X - X, metric: iou, margin: 1}\n", "primary must give margin, metric, test_set, versus"),
    ("test_sets: {test: t}\n", "'test' cannot name a test set"),
    ("test_sets: [a]\n", "test_sets must map names to folders"),
    ("reference: [1]\n", "reference must be one line"),
    ("variants: [X]\nvariants: [X]\n", "variants is given twice"),
])
def test_a_bad_protocol_file_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture, text: str,
                                         message: str) -> None:
    (tmp_path / "runs").mkdir()
    (tmp_path / "p.yaml").write_text(text)
    assert main(["reproduce", "--tables", "--out", str(tmp_path), "--protocol", str(tmp_path / "p.yaml")]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.yaml", "runs"]  # nothing written


def test_a_missing_protocol_file_names_the_flag(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["reproduce", "--tables", "--out", str(tmp_path), "--protocol", str(tmp_path / "none.yaml")]) == 2
    err = capsys.readouterr().err
    assert "--protocol" in err and "not found" in err and len(err.strip().splitlines()) == 1


def _fake_runs(out: Path, data: Path) -> None:
    """Finished run folders (config.yaml, metrics.json, fixed/metrics.json) of two networks × X, HA-X, X-long × 3
    seeds, as ``reproduce`` writes them, without training: HA-X 2 points above X-long, X-long 1 above X."""
    from freespace.experiments.cells import cell_config

    for model in ("unet", "segnet"):
        for seed in range(3):
            for variant, f in (("X", 0.80), ("HA-X", 0.83), ("X-long", 0.81)):
                config = cell_config("synth", data, out, model, variant, seed,
                                     dict(epochs=4, patience=2, image_size=(64, 96)))
                run = Path(config.out)
                (run / "fixed").mkdir(parents=True)
                config.save(run / "config.yaml")
                value = f + 0.001 * seed
                metrics = {k: value for k in METRICS}
                (run / "metrics.json").write_text(json.dumps({**metrics, "best_epoch": 1, "epochs_run": 3}))
                (run / "fixed" / "metrics.json").write_text(json.dumps({**metrics, "root": "/fixed"}))


def _tables(out: Path, protocol: Protocol) -> None:
    """The tables of the run folders in ``out`` (bypassing the folder's manifest: these runs were not trained)."""
    from freespace.experiments.tables import _write_tables, collect

    entries, differ = collect(out)
    _write_tables(out, entries, differ, 0, protocol)


def test_the_tables_follow_the_protocol(data: Path, tmp_path: Path) -> None:
    out = tmp_path / "res"
    _fake_runs(out, data)
    (tmp_path / "p.yaml").write_text(GOOD)
    _tables(out, Protocol.load(tmp_path / "p.yaml"))
    rows = list(csv.DictReader((out / "gains.csv").open()))
    assert list(dict.fromkeys(r["versus"] for r in rows)) == ["HA-X - X-long", "HA-X - X"]  # its gains, its order
    md = (out / "results.md").read_text()
    assert "(no interval with one seed); published: +1 to +2 points." in md
    assert "**Primary endpoint** (named before the run): HA-X − X IoU on `fixed`, averaged over the networks: " \
           "+3.00 points" in md and "leaves ±2: a difference" in md
    # without a protocol: every gain of the variants run, in the method's order; no reference, no primary endpoint
    _tables(out, Protocol())
    rows = list(csv.DictReader((out / "gains.csv").open()))
    assert list(dict.fromkeys(r["versus"] for r in rows)) == ["HA-X - X", "HA-X - X-long", "X-long - X"]
    md = (out / "results.md").read_text()
    assert "(no interval with one seed)." in md and "Primary endpoint" not in md and "published" not in md


def test_the_protocol_chooses_the_variants_and_test_sets(data: Path, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture) -> None:
    import freespace.experiments.reproduce as rep

    fixed = tmp_path / "fixed-frames"
    write_dataset(fixed, 2, seed=9, config=SynthConfig(width=128, height=96, frames_per_scenario=2), progress=False)
    (tmp_path / "p.yaml").write_text(GOOD)
    monkeypatch.chdir(tmp_path)  # the protocol's test set folders are taken from the working directory
    seen: list = []
    monkeypatch.setattr(rep, "run_cell", lambda config, **kw: seen.append((config, kw["test_root"])) or "done")
    monkeypatch.setattr(rep, "write_tables", lambda out, **kw: (Path(out, "results.md").write_text("")  # 0
                                                                or {"table": [], "gains": [], "runs": []}))
    args = ["reproduce", "--dataset", "synth", "--root", str(data), "--models", "segnet", "--seeds", "1",
            "--epochs", "1", "--image-size", "64x96", "--out", "res", "--protocol", "p.yaml"]
    assert main(args) == 0
    assert [Path(c.out).name for c, _ in seen] == ["segnet-orig-s0", "segnet-ha-s0", "segnet-long-s0"]
    assert {name: root.name for name, root in seen[0][1].items()} == {"fixed": "fixed-frames"}
    seen.clear()
    assert main(args + ["--variants", "X,X-dup", "--test-root", f"more={fixed}"]) == 0  # flags add to / override
    assert [Path(c.out).name for c, _ in seen] == ["segnet-orig-s0", "segnet-dup-s0"]
    assert sorted(seen[0][1]) == ["fixed", "more"]
    capsys.readouterr()
    assert main(args + ["--test-root", f"fixed={fixed}"]) == 2  # the same name twice
    err = capsys.readouterr().err
    assert "the protocol names the test set 'fixed' already" in err and len(err.strip().splitlines()) == 1
