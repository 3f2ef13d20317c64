"""A protocol that declares its own variants, each with its own training data (``data:``): each cell trains on
its variant's dataset, root, labels, split lists and augment, in a run folder tagged from the variant's name;
the existing checks hold per cell; the tables pair only what was tested on the same frames; a bad file, a bad
path or a clash ends in one line before any work."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest

from freespace.cli import main
from freespace.data.synthetic import SynthConfig, write_dataset
from freespace.engine.config import TrainConfig
from freespace.errors import InvalidOptionError
from freespace.experiments import VARIANTS, Protocol, parse_variants
from freespace.experiments.variants import parse_cell, run_name, run_of

#: two training sources: ``first`` (a rendered set as it is) and ``second`` (another rendered set, with its own
#: label tree and split lists, both given relative to the protocol file's folder; its root through ${FS_SECOND})
PROTOCOL = """\
data:
  first: {dataset: synth, root: "${FS_FIRST}"}
  second: {dataset: synth, root: "${FS_SECOND}", labels: labels, splits: lists, cache_dir: cache}
variants:
  A: {data: first}
  A-dup: {data: first, augment: duplicate}
  B+A: {data: second}
gains: [B+A - A, A-dup - A]
"""


def _render(root: Path, seed: int) -> Path:
    write_dataset(root, 8, seed=seed, config=SynthConfig(width=64, height=48, frames_per_scenario=2), progress=False)
    return root


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A study folder: ``p.yaml`` (:data:`PROTOCOL`), ``labels/`` (the second set's labels as a label tree) and
    ``lists/`` (its split lists, frames named otherwise than the paper's split would); the rendered sets lie
    elsewhere (``FS_FIRST``, ``FS_SECOND``)."""
    base = tmp_path_factory.mktemp("sets")
    _render(base / "first", 3)
    second = _render(base / "second", 4)
    folder = tmp_path_factory.mktemp("study")
    (folder / "p.yaml").write_text(PROTOCOL)
    (folder / "labels").mkdir()
    for gt in sorted((second / "data_road/training/gt_image_2").glob("*.png")):
        category, _, number = gt.stem.split("_")
        shutil.copy(gt, folder / "labels" / f"{category}_{number}.png")
    names = sorted(p.stem for p in (folder / "labels").glob("*.png"))
    (folder / "lists").mkdir()
    for part, chosen in (("train", names[:4]), ("val", names[4:6]), ("test", names[6:])):
        (folder / "lists" / f"{part}.txt").write_text("".join(f"{n}\n" for n in chosen))
    return folder


@pytest.fixture
def env(study: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    sets = next(study.parent.glob("sets*"))
    monkeypatch.setenv("FS_FIRST", str(sets / "first"))
    monkeypatch.setenv("FS_SECOND", str(sets / "second"))
    return sets


def _args(study: Path, out: Path, *extra: str) -> list[str]:
    return ["reproduce", "--protocol", str(study / "p.yaml"), "--models", "segnet", "--seeds", "1", "--epochs", "1",
            "--image-size", "32x64", "--batch-size", "4", "--no-progress", "--out", str(out), *extra]


def test_each_cell_trains_on_its_variants_data(study: Path, env: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "res"
    assert main(_args(study, out)) == 0
    runs = {p.name: TrainConfig.load(p / "config.yaml") for p in sorted((out / "runs").iterdir())}
    assert sorted(runs) == ["segnet-a-dup-s0", "segnet-a-s0", "segnet-b_a-s0"]  # tags: lower case, + as _
    a, dup, b = runs["segnet-a-s0"], runs["segnet-a-dup-s0"], runs["segnet-b_a-s0"]
    first, second = (str((env / n).resolve()) for n in ("first", "second"))
    assert (a.dataset, a.root, a.labels, a.splits_dir, a.cache_dir, a.augment) == \
        ("kitti", first, None, None, None, ())  # the protocol's synth: an alias of kitti
    assert (dup.root, dup.augment, dup.cache_dir) == (first, ("duplicate",), None)  # first gives no cache
    assert (b.root, b.augment, b.cache_dir) == (second, (), None)  # a cache only for a variant with an augment
    assert (b.labels, b.splits_dir) == (str(study / "labels"), str(study / "lists"))  # from the protocol's folder
    assert (out / "runs/segnet-b_a-s0/splits/test.txt").read_text() == (study / "lists/test.txt").read_text()
    assert json.loads((out / "runs/segnet-b_a-s0/inputs.json").read_text())["labels"]["path"] == str(study / "labels")
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [(r["variant"], r["test_set"]) for r in rows] == [("A", "test"), ("A-dup", "test"), ("B+A", "test")]
    gains = list(csv.DictReader((out / "gains.csv").open()))
    assert {g["versus"] for g in gains} == {"A-dup - A"}  # B+A - A: other test frames on `test`, not paired
    md = (out / "results.md").read_text()
    assert "the test split of each variant's own training data" in md and "Warning" not in md
    index = json.loads((out / "index.json").read_text())
    assert [(e["run"], e["variant"], e["augment"]) for e in index] == [
        ("runs/segnet-a-s0", "A", "none"), ("runs/segnet-a-dup-s0", "A-dup", "duplicate"),
        ("runs/segnet-b_a-s0", "B+A", "none")]
    assert (out / "figures/segnet.png").is_file()  # A's test frames, each variant's prediction
    capsys.readouterr()
    # one cell again: finished, with the same settings: skipped (the checks of every cell still apply)
    assert main(_args(study, out, "--only", "segnet,B+A,0")) == 0
    assert "runs/segnet-b_a-s0: done (skipped)" in capsys.readouterr().out
    # the tables from the run folders alone, with the protocol's names
    assert main(["reproduce", "--tables", "--out", str(out), "--protocol", str(study / "p.yaml")]) == 0
    assert "| segnet | A-dup − A | F-score | test | 1 |" in capsys.readouterr().out
    # without the file, the folders are none of the built-in variants' (segnet-a-dup-s0 is no X-dup of "segnet-a")
    assert main(["reproduce", "--tables", "--out", str(out)]) == 2
    assert "holds no run folders" in capsys.readouterr().err
    # the data moved under a finished cell: refused in one line, naming the setting
    shutil.copytree(env / "first", tmp_path / "moved")
    monkeypatch.setenv("FS_FIRST", str(tmp_path / "moved"))
    assert main(_args(study, out, "--only", "segnet,A,0")) == 2
    err = capsys.readouterr().err
    assert "segnet-a-s0 was started with other settings (root " in err and len(err.strip().splitlines()) == 1


def test_variants_and_only_name_the_declared_variants(study: Path, env: Path, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    import freespace.experiments.reproduce as rep

    seen: list[TrainConfig] = []
    monkeypatch.setattr(rep, "run_cell", lambda config, **kw: seen.append(config) or "done")
    monkeypatch.setattr(rep, "write_tables", lambda out, **kw: (Path(out, "results.md").write_text("")  # 0
                                                                or {"table": [], "gains": [], "runs": []}))
    assert main(_args(study, tmp_path / "o", "--variants", "B+A,A")) == 0  # no X: the declared ones, as given
    assert [Path(c.out).name for c in seen] == ["segnet-b_a-s0", "segnet-a-s0"]
    seen.clear()
    assert main(_args(study, tmp_path / "o", "--only", "segnet,A-dup,0")) == 0
    assert [(Path(c.out).name, c.augment) for c in seen] == [("segnet-a-dup-s0", ("duplicate",))]


def test_the_protocol_reads_its_data_and_variants(study: Path) -> None:
    p = Protocol.load(study / "p.yaml")
    assert p.variants == ("A", "A-dup", "B+A") and list(p.vocabulary) == ["A", "A-dup", "B+A"]
    assert [(v.tag, v.augment, v.data) for v in p.declared.values()] == \
        [("a", (), "first"), ("a-dup", ("duplicate",), "first"), ("b_a", (), "second")]
    assert p.gains == (("B+A", "A"), ("A-dup", "A")) and p.data["second"].base == study
    assert p.declared["B+A"].label("unet") == "B+A" and VARIANTS["HA-X"].label("unet") == "HA-unet"
    assert parse_variants("A-dup", p.vocabulary) == ("A-dup",)  # nothing added in front
    # a name as a run folder spells it (lower case) is the declared variant; the cell too
    assert parse_variants("a-dup,b+a", p.vocabulary) == ("A-dup", "B+A")
    assert parse_cell("unet,a-dup,1", 2, p.declared) == ("unet", "A-dup", 1)
    with pytest.raises(InvalidOptionError, match="unknown variant 'c-dup'"):
        parse_cell("unet,c-dup,1", 2, p.declared)
    with pytest.raises(InvalidOptionError, match="unknown variants"):
        parse_variants("X", p.vocabulary)
    # a run folder's tag may hold -: the longest tag that leaves a network wins
    assert run_name("unet", "A-dup", 2, p.vocabulary) == "unet-a-dup-s2"
    assert run_of("unet-a-dup-s2", p.vocabulary)[:1] == ("unet",) and run_of("unet-a-dup-s2", p.vocabulary)[1].name \
        == "A-dup"
    assert run_of("unet-orig-s0", p.vocabulary) is None and run_of("unet-orig-s0")[1].name == "X"
    assert run_of("unet-a-s", p.vocabulary) is None and run_of("a-s0", p.vocabulary) is None


def test_a_declared_variant_may_mirror_and_jitter_its_samples(study: Path, env: Path, tmp_path: Path) -> None:
    """``flip: true`` and ``photometric: true`` in a declared variant: its cells train with those switches on; the
    others keep them off."""
    from freespace.experiments.cells import cell_config

    (tmp_path / "p.yaml").write_text(PROTOCOL.replace("A-dup: {data: first, augment: duplicate}", "A-fp: {data: "
                                                      "first, flip: true, photometric: true}").replace("A-dup", "A-fp"))
    p = Protocol.load(tmp_path / "p.yaml")
    assert [v.samples for v in p.declared.values()] == [(), ("flip", "photometric"), ()]
    options = {"epochs": 1, "patience": 1, "image_size": (32, 64)}
    fp, a = (cell_config(None, None, tmp_path / "o", "segnet", v, 0, options, protocol=p) for v in ("A-fp", "A"))
    assert (fp.flip, fp.photometric, Path(fp.out).name) == (True, True, "segnet-a-fp-s0")
    assert (a.flip, a.photometric) == (False, False)


#: (protocol text, what the one line says); each refused when the file is read, before any work
BAD = [
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A: {data: b}}\ngains: [A - A]\n", "variant A: unknown data 'b'"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A: {augment: homography}}\ngains: []\n",
     "variant A: names no data"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A: {data: a}, HA-X: {data: a}}\ngains: [A - HA-X]\n",
     "variant HA-X is (or spells) the built-in variant HA-X"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A: {data: a}, x-dup: {data: a}}\ngains: [A - x-dup]\n",
     "variant x-dup is (or spells) the built-in variant X-dup"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {S+R: {data: a}, s_r: {data: a}}\ngains: [S+R - s_r]\n",
     "variants S+R and s_r would share the run folders' tag 's_r'"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {Long: {data: a}, A: {data: a}}\ngains: [Long - A]\n",
     "variants X-long and Long would share the run folders' tag 'long'"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A/B: {data: a}}\ngains: []\n", "variant name 'A/B'"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A: {data: a, augment: warp}}\ngains: []\n",
     "variant A: augment must be one of"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A: {data: a, labels: l}}\ngains: []\n",
     "variant A must be a mapping of data, augment, flip and photometric"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A: {data: a, flip: 'yes'}}\ngains: []\n",
     "variant A: flip must be true or false, got 'yes'"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: [X, HA-X]\n", "give variants as a mapping"),
    ("variants: {A: {data: a}}\ngains: [A - A]\n", "variants given as a mapping declare their own training data"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A: {data: a}, B: {data: a}}\n", "names its gains"),
    ("data: {a: {dataset: synth, root: r}}\nvariants: {A: {data: a}, B: {data: a}}\ngains: [A - X]\n",
     "gain 'A - X' is not 'VARIANT - VERSUS' of two variants among A, B"),
    ("data: {a: {dataset: synth}}\nvariants: {A: {data: a}}\ngains: []\n", "data a must give dataset and root"),
    ("data: {a: {dataset: synth, root: r, split: s}}\nvariants: {A: {data: a}}\ngains: []\n",
     "data a must give dataset and root"),
    ("data: {a: {dataset: kitty, root: r}}\nvariants: {A: {data: a}}\ngains: []\n", "data a: unknown dataset 'kitty'"),
    ("data: {a: {dataset: synth, root: $RAW/x}}\nvariants: {A: {data: a}}\ngains: []\n",
     "write an environment variable as ${NAME}"),
    ("data: {a: {dataset: synth, root: 3}}\nvariants: {A: {data: a}}\ngains: []\n", "data a: root must be text"),
    ("data: {A: {dataset: synth, root: r}}\nvariants: {A: {data: A}}\ngains: []\n", "data name 'A'"),
    ("data: {a: {dataset: synth, root: r}, b: {dataset: synth, root: r}}\nvariants: {A: {data: a}, B: {data: a}}\n"
     "gains: [A - B]\n", "data b is the data of no variant"),
    ("data: []\nvariants: {A: {data: a}}\ngains: []\n", "data must map names to training sources"),
]


@pytest.mark.parametrize("text, message", BAD)
def test_a_bad_data_protocol_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture, text: str,
                                         message: str) -> None:
    (tmp_path / "p.yaml").write_text(text)
    assert main(["reproduce", "--out", str(tmp_path / "o"), "--protocol", str(tmp_path / "p.yaml")]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert "p.yaml" in err  # names the file
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.yaml"]  # nothing written


@pytest.mark.parametrize("change, extra, message", [
    ({"FS_FIRST": "/nonexistent/first"}, [], "data first: root ${FS_FIRST}: no folder /nonexistent/first"),
    ({"FS_FIRST": None}, [], "data first: root ${FS_FIRST}: the environment variable FS_FIRST is not set"),
    ({"FS_FIRST": ""}, [], "the environment variable FS_FIRST is not set"),
    ({}, ["--dataset", "synth"], "gives each variant its training data (its data); leave --dataset out"),
    ({}, ["--root", "/tmp"], "leave --root out"),
    ({}, ["--autolabels", "/tmp"], "leave --autolabels out"),
    ({}, ["--only", "segnet,X,0"], "--only: unknown variant 'X'; choose from A, A-dup, B+A"),
    ({}, ["--variants", "A,HA-X"], "unknown variants ['HA-X']"),
    ({}, ["--only", "segnet,A,0", "--variants", "B+A"], "its variant 'A' is not among --variants"),
])
def test_bad_data_or_options_are_one_line(study: Path, env: Path, tmp_path: Path, capsys: pytest.CaptureFixture,
                                          monkeypatch: pytest.MonkeyPatch, change: dict, extra: list[str],
                                          message: str) -> None:
    for name, value in change.items():
        if value is None:
            monkeypatch.delenv(name)
        else:
            monkeypatch.setenv(name, value)
    assert main(_args(study, tmp_path / "o", *extra)) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "o").exists()  # refused before any work


@pytest.mark.parametrize("damage, message", [
    (lambda s: shutil.rmtree(s / "labels"), "data second: labels labels: no folder"),
    (lambda s: (s / "lists/test.txt").unlink(), "data second: splits lists: subset list not found"),
    (lambda s: (s / "lists/val.txt").write_text((s / "lists/train.txt").read_text()), "listed in more than one split"),
    (lambda s: (s / "cache").write_text("x"), "data second: cache_dir cache: "),
])
def test_a_bad_path_of_the_data_is_one_line(study: Path, env: Path, tmp_path: Path, capsys: pytest.CaptureFixture,
                                            damage, message: str) -> None:
    copy = tmp_path / "study"
    shutil.copytree(study, copy)
    damage(copy)
    # the cache is given to variants with an augment only: make B+A one
    (copy / "p.yaml").write_text(PROTOCOL.replace("B+A: {data: second}", "B+A: {data: second, augment: duplicate}"))
    assert main(_args(copy, tmp_path / "o")) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "o").exists()


def test_the_inputs_check_compares_the_cells_of_one_data(study: Path, env: Path, tmp_path: Path) -> None:
    """Each training data's label tree is compared with the cells of the same data only."""
    from freespace.experiments.cells import cell_config, check_inputs

    p = Protocol.load(study / "p.yaml")
    options = dict(epochs=1, patience=1, image_size=(32, 64))
    config = cell_config(None, None, tmp_path, "segnet", "B+A", 0, options, protocol=p)
    other = tmp_path / "runs" / run_name("segnet", "A", 0, p.vocabulary)  # a cell of other data, other labels
    other.mkdir(parents=True)
    (other / "inputs.json").write_text(json.dumps({"labels": {"path": "/elsewhere", "sha256": "0" * 64}}))
    check_inputs(tmp_path, [config], p.vocabulary)  # not compared
    same = tmp_path / "runs" / run_name("segnet", "B+A", 1, p.vocabulary)
    same.mkdir()
    (same / "inputs.json").write_text(json.dumps({"labels": {"path": str(study / "labels"), "sha256": "0" * 64}}))
    with pytest.raises(InvalidOptionError, match="other contents of the labels of the protocol's data second"):
        check_inputs(tmp_path, [config], p.vocabulary)
