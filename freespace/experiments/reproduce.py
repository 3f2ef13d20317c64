"""`freespace reproduce`: the paper's protocol on one dataset, with a control and paired statistics.

Every chosen network is trained on the original training set (X), on the set augmented with the
DS-Generator views (HA-X) and on the control X-dup (X with every frame that has a DS-Generator view once
more, unchanged: as many optimiser steps per epoch as HA-X under the same early stopping, without the
views' content) — or any variants of :data:`VARIANTS` (HV-X: road-plane virtual views, HAV-X: both) —
with the same seeds and budget, and tested on the test split (``test_set = test``) and, with
``test_root``, on every labelled frame of further datasets (``test_set = shifted`` for a bare folder, e.g.
other rigs, or the name given as ``NAME=DIR``, e.g. a large fixed set rendered with the training rigs).
For one network and seed all variants share the split and the initial weights; HA-X and X-dup also share
the data order and the conventional augmentation's draws (same number of samples).

``OUT`` receives ``runs/<model>-<tag>-s<seed>/`` (training run folders; ``<name>/metrics.json`` in each
for each further test set) and, built from the run folders on disk (:func:`write_tables`):

* ``results.csv``: one row per network × variant × test set: ``n`` seeds and each metric's mean and std
  over them (%);
* ``gains.csv``: per network (and averaged over the networks) the paired gains of :data:`GAINS` (one
  difference per seed: HA-X − X, HA-X − X-dup, the controls' X-dup − X, X-long − X, HA-X − X-long and
  X-dup − X-long, the virtual views' HV-X − X, ...) in F-score and IoU points: mean, 95 % Student
  t-interval over the seeds, n and whether the interval excludes 0
  (:func:`freespace.experiments.stats.paired_gain`);
* ``results.md`` (both tables), ``figures/gains_<model>.png`` (the gains with their intervals),
  ``figures/<model>.png`` (a few test frames: each variant's predictions coloured TP green / FN red /
  FP blue) and ``index.json`` (every run, its status and metrics).

Finished runs are skipped when the command is run again; interrupted ones resume. One cell
(:func:`run_cell`; :func:`reproduce` with ``only="NETWORK,VARIANT,SEED"``) writes only its run folder, so cells
can run concurrently on a cluster and :func:`write_tables` collects them.

Names: a *variant* is an arm of the protocol, named as in the tables (``"HA-X"``, :attr:`Variant.name`; its
run folders carry its short :attr:`Variant.tag`, ``ha``); its ``augment`` is the training configuration's
(:attr:`freespace.engine.config.TrainConfig.augment`, e.g. ``("homography",)``), which several variants may
share (X and X-long). index.json holds both: ``variant`` (the name) and ``augment`` (spelled as in
config.yaml, ``"homography"``).
"""

from __future__ import annotations

import json
import logging
import math
import re
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from freespace.engine.config import FIRST_FRAME_SIZE, TrainConfig, augment_text, read_config_yaml
from freespace.errors import CorruptFileError, DatasetError, FreespaceError, InvalidOptionError, param
from freespace.experiments.stats import paired_gain
from freespace.io.codecs import write_image
from freespace.io.files import PathLike, atomic_write_bytes, atomic_write_text, check_writable, write_csv, write_json
from freespace.io.outdir import claim_folder

log = logging.getLogger(__name__)

__all__ = ["reproduce", "run_cell", "write_tables", "parse_models", "parse_variants", "parse_cell",
           "parse_test_roots", "evaluate_test_set", "Variant", "VARIANTS", "DEFAULT_VARIANTS", "METRICS", "GAINS",
           "TestRoots"]

@dataclass(frozen=True)
class Variant:
    """A variant (one arm) of the protocol: its ``name`` in the tables (``X`` stands for the network), its
    training ``augment`` (a :attr:`~freespace.engine.config.TrainConfig.augment` value: ``()`` none), the
    ``tag`` of its run folders (``runs/<model>-<tag>-s<seed>``), ``budget``, the factor on the epoch cap
    and on the early-stopping patience (X-long: 2, as many optimiser steps as HA-X), and where the training
    labels come from: ``human`` (the dataset's), ``auto`` (the ``autolabels`` tree) or ``mix`` (the
    dataset's on :data:`MIX_HUMAN_SHARE` of the training drives, the tree's on the rest)."""

    name: str
    augment: tuple[str, ...]
    tag: str
    budget: int = 1
    labels: str = "human"

    def label(self, model: str) -> str:
        """The table row of ``model``: ``X`` replaced by the network's name (``HA-X`` → ``HA-unet``)."""
        return self.name.replace("X", model)


#: the arms, by table name
VARIANTS: dict[str, Variant] = {v.name: v for v in (
    Variant("X", (), "orig"),                              # conventional augmentation only
    Variant("HA-X", ("homography",), "ha"),                # + the DS-Generator views (the paper)
    Variant("HV-X", ("virtual",), "hv"),                   # + road-plane virtual views (no right image)
    Variant("HAV-X", ("homography", "virtual"), "hav"),    # + both
    Variant("X-dup", ("duplicate",), "dup"),               # control: HA-X's step count, the frames' own images
    Variant("X-long", (), "long", budget=2),               # control: HA-X's step count, each frame once per epoch
    Variant("X-auto", (), "auto", labels="auto"),          # labels nobody drew (freespace autolabel)
    Variant("X-mix", (), "mix", labels="mix"),             # people's labels on a fifth of the drives, autolabels after
)}
#: the share of the training drives that keep the dataset's labels in X-mix
MIX_HUMAN_SHARE = 0.2
DEFAULT_VARIANTS = ("X", "HA-X", "X-dup")
#: the paired gains reported (variant, versus), when both were run (X-dup − X-long: the second draw of the
#: conventional augmentation at equal optimiser steps)
GAINS = (("HA-X", "X"), ("HA-X", "X-dup"), ("HA-X", "X-long"), ("X-dup", "X"), ("X-long", "X"), ("X-dup", "X-long"),
         ("HV-X", "X"), ("HAV-X", "X"), ("X-auto", "X"), ("X-mix", "X"), ("X-mix", "X-auto"))
#: the primary endpoint, named before the converged run: HA-X − X-dup in F-score points on ``same-rigs``,
#: averaged over the networks (one mean per seed), with an equivalence margin of ±1 point
PRIMARY = {"versus": "HA-X - X-dup", "metric": "f_score", "test_set": "same-rigs", "margin": 1.0}
#: the ``network`` of the gains averaged over networks
ALL_NETWORKS = "all"
#: the paper's six networks: what ``models="all"`` trains (networks registered later, e.g. ``fastscnn``, by name)
PAPER_NETWORKS = ("deeplabv3plus", "denseaspp", "dupsampling", "gscnn", "segnet", "unet")
GAIN_METRICS = ("f_score", "iou")
#: the name of a further test set (``test_root``) given without one
DEFAULT_TEST_SET = "shifted"
#: names a further test set cannot take: the test split's, and the run folder's own entries
_RESERVED_TEST_SETS = {"train", "val", "test", "metrics", "config", "splits", "generated", "checkpoints",
                       "tensorboard"}
_TEST_SET_NAME = re.compile(r"[a-z][a-z0-9_-]*")
METRICS = ("accuracy", "precision", "recall", "f_score", "iou")
PAPER_GAINS = "HA gain in the paper: F-score +1.5 to +5.0, IoU +2.8 to +7.3 points"
_BY_TAG = {v.tag: v for v in VARIANTS.values()}
_RUN_NAME = re.compile(r"(?P<model>.+)-(?P<tag>[a-z]+)-s(?P<seed>\d+)")
#: further test sets: a folder (named ``shifted``), ``NAME=DIR`` strings, or ``{name: folder}``
TestRoots = PathLike | list[PathLike] | tuple[PathLike, ...] | dict[str, PathLike] | None


#: what ``reproduce`` writes into OUT (:mod:`freespace.io.outdir` entries)
OUT_ENTRIES = ("runs/", "index.json", "results.csv", "gains.csv", "results.md", "figures/")


def _name(model: str, variant: str, seed: int) -> str:
    """The run folder of a cell: ``<model>-<tag>-s<seed>`` (``variant``: a table name)."""
    return f"{model}-{VARIANTS[variant].tag}-s{seed}"


def parse_models(text: str | list[str] | tuple[str, ...] | None) -> list[str]:
    """``"unet,segnet"`` (``models``) → the networks, in the given order; ``"all"`` or None → the paper's six
    (:data:`PAPER_NETWORKS`).

    Raises:
        InvalidOptionError: an unknown network, or none.
    """
    from freespace.models import list_models

    if text is None or text == "all":
        return list(PAPER_NETWORKS)
    names = list(dict.fromkeys(n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()))
    unknown = [n for n in names if n not in list_models()]
    if unknown or not names:
        raise InvalidOptionError(f"unknown models {unknown}; choose from {', '.join(list_models())} or all")
    return names


def parse_variants(text: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """``"HA-X,X-dup"`` → the variants' table names, in the given order; ``X`` always comes first."""
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    bad = [n for n in names if n not in VARIANTS]
    if bad or not names:
        raise InvalidOptionError(f"unknown variants {bad}; choose from {', '.join(VARIANTS)} (comma-separated)")
    return tuple(["X"] + [n for n in dict.fromkeys(names) if n != "X"])  # the gains are measured against X


#: more seeds than this is a typo, not an experiment (each seed trains every network and variant)
MAX_SEEDS = 1000


def parse_cell(text: str, seeds: int) -> tuple[str, str, int]:
    """``"unet,HA-X,2"`` (``only``) → ``("unet", "HA-X", 2)``: network, variant, seed.

    Raises:
        InvalidOptionError: not three comma-separated fields, an unknown network or variant, or a seed
        outside ``0 … seeds − 1``.
    """
    from freespace.models import list_models

    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 3:
        raise InvalidOptionError(f"{param('only')} must be NETWORK,VARIANT,SEED (e.g. unet,HA-X,0), got {text!r}")
    model, name, seed_text = parts
    if model not in list_models():
        raise InvalidOptionError(f"{param('only')}: unknown network {model!r}; choose from {', '.join(list_models())}")
    if name not in VARIANTS:
        raise InvalidOptionError(f"{param('only')}: unknown variant {name!r}; choose from {', '.join(VARIANTS)}")
    if not seed_text.isdigit() or not 0 <= int(seed_text) < seeds:
        raise InvalidOptionError(f"{param('only')}: the seed must be an integer in 0…{seeds - 1} ({param('seeds')} "
                                 f"{seeds}), "
                                 f"got {seed_text!r}")
    return model, name, int(seed_text)


def parse_test_roots(test_root: TestRoots) -> dict[str, Path]:
    """``test_root`` values → ``{name: folder}``: ``DIR`` is named ``shifted``, ``NAME=DIR`` ``NAME``
    (lower-case letters, digits, ``-`` and ``_``; not ``test``, the test split's). A dict is taken as it is.

    Raises:
        InvalidOptionError: a bad or repeated name.
    """
    if test_root is None:
        return {}
    if isinstance(test_root, dict):
        pairs = list(test_root.items())
    else:
        pairs = []
        for text in [test_root] if isinstance(test_root, (str, Path)) else test_root:
            name, sep, folder = str(text).partition("=")
            named = sep and _TEST_SET_NAME.fullmatch(name)  # else a folder, whatever its characters
            if sep and not named and re.fullmatch(r"\w[\w-]*", name) and not Path(text).exists():
                raise InvalidOptionError(f"{param('test_root')} {text}: test set names are lower-case letters, digits, "
                                         f"- and _ "
                                         f"(e.g. {name.lower()}={folder}); {text} is no folder either")
            pairs.append((name, folder) if named else (DEFAULT_TEST_SET, str(text)))
    roots: dict[str, Path] = {}
    for name, folder in pairs:
        if not _TEST_SET_NAME.fullmatch(name) or name in _RESERVED_TEST_SETS:
            raise InvalidOptionError(f"{param('test_root')}: {name!r} cannot name a test set; use lower-case letters, "
                                     f"digits, "
                                     f"- and _, and none of {', '.join(sorted(_RESERVED_TEST_SETS))} (NAME=DIR)")
        if name in roots:
            raise InvalidOptionError(f"{param('test_root')}: two test sets are named {name!r}; give the others "
                                     f"NAME=DIR")
        roots[name] = Path(folder)
    return roots


def _check_test_roots(dataset: str, roots: dict[str, Path], train_root: PathLike) -> None:
    """Refuse a further test set (``roots``) that is not a ``dataset`` tree with labelled frames, or that holds
    frames of the training data ``train_root`` (the same images, by resolved path: the same folder, or one inside
    it), before any work."""
    from freespace.data.base import check_dataset_root
    from freespace.data.registry import get_dataset, get_dataset_class

    training: set[Path] | None = None
    for name, root in roots.items():
        check_dataset_root(root, get_dataset_class(dataset).name)
        frames = get_dataset(dataset, root, disparity_source="none").labelled().frames
        if not frames:
            raise DatasetError(f"{param('test_root')} {root} has no labelled frames to test on")
        if training is None:
            training = {f.left.resolve() for f in get_dataset(dataset, train_root, disparity_source="none").frames}
        shared = [f.name for f in frames if f.left.resolve() in training]
        if shared:
            raise InvalidOptionError(f"{param('test_root')} {name}={root} holds {len(shared)} of {param('root')}'s own "
                                     f"frames (e.g. "
                                     f"{shared[0]}); a further test set must be other data than the training set")


def _config(dataset: str, root: PathLike, out: Path, model: str, variant: str, seed: int,
            options: dict[str, Any], autolabels: PathLike | None = None) -> TrainConfig:
    """The training configuration of one cell (``variant``: a table name; its budget scales the epoch cap
    and the patience; X-auto and X-mix read ``autolabels``; the ``virtual_*`` options go to the variants with
    virtual views only, so that the others' cells keep their settings whatever pose ranges are asked for)."""
    spec = VARIANTS[variant]
    options = {**options, "epochs": options["epochs"] * spec.budget, "patience": options["patience"] * spec.budget}
    if "virtual" not in spec.augment:
        options = {k: v for k, v in options.items() if not k.startswith("virtual_")}
    if spec.labels != "human":
        if autolabels is None:
            raise InvalidOptionError(f"{variant} trains on labels nobody drew: give {param('autolabels')} DIR, the "
                                     f"label tree of {root} that `freespace autolabel` wrote")
        from freespace.engine.config import check_label_tree

        check_label_tree(autolabels, dataset, root, options.get("split"), option="autolabels")  # named as given
        options.update(labels=str(autolabels), human_share=MIX_HUMAN_SHARE if spec.labels == "mix" else 0.0)
    config = TrainConfig(dataset=dataset, root=str(root), out=str(out / "runs" / _name(model, variant, seed)),
                         model=model, augment=spec.augment, seed=seed, **options)
    config.check()
    return config


def _check_autolabels_used(autolabels: PathLike | None, variants: list[str] | tuple[str, ...]) -> None:
    """Refuse ``autolabels`` when none of the cells to run (``variants``) trains on it: the option would have no
    effect."""
    if autolabels is not None and not any(VARIANTS[v].labels != "human" for v in variants):
        takers = ", ".join(v.name for v in VARIANTS.values() if v.labels != "human")
        raise InvalidOptionError(f"{param('autolabels')} is the label tree of the variants {takers}, and none of the "
                                 f"cells run here is one; add one to {param('variants')}, or leave "
                                 f"{param('autolabels')} out")


def _check_inputs(out: Path, configs: list[TrainConfig]) -> None:
    """Refuse, before any work, cells whose weights file or label tree (by content:
    :func:`~freespace.engine.config.content_hashes`, computed once) differ from what the protocol's other cells
    in ``OUT/runs`` were trained from: their scores would be averaged as one setting."""
    from freespace.engine.config import content_hashes
    from freespace.engine.train import read_inputs

    now: dict[str, dict[str, Any]] = {}
    for config in configs:
        for key, value in content_hashes(config).items():
            now.setdefault(key, value)
    if not now or not (out / "runs").is_dir():
        return
    for run_dir in sorted(p.parent for p in (out / "runs").glob("*/inputs.json")):
        recorded = read_inputs(run_dir)
        for key, value in now.items():
            old = recorded.get(key)
            if isinstance(old, dict) and old.get("sha256") != value["sha256"]:
                option = "autolabels" if key == "labels" else key  # reproduce's name of the label tree
                raise InvalidOptionError(
                    f"{run_dir} was trained from other contents of {param(option)} than {value['path']} holds now "
                    f"(sha256 {str(old.get('sha256'))[:12]}… then, {value['sha256'][:12]}… now): the cells would "
                    f"average two settings; restore the files, or give another {param('out')}")


def _check_cell(config: TrainConfig) -> bool:
    """Refuse ``config`` when the cell in ``config.out`` was started with other settings (``key old → new``, in
    config.yaml's spelling), but for a larger ``epochs`` or ``patience``
    (:data:`~freespace.engine.train.GROWABLE`); return whether one of those grew. The cell's
    config.yaml may be of any version (its spellings and renamed keys read as the values they were); ``root``
    compares resolved; an ``image_size`` of :data:`~freespace.engine.config.FIRST_FRAME_SIZE` matches the
    size it was resolved to."""
    from freespace.engine.train import GROWABLE, WHERE_AND_HOW

    run_dir = Path(config.out)
    saved_path = run_dir / "config.yaml"
    if not saved_path.is_file():
        return False
    recorded = TrainConfig.load(saved_path)
    if config.image_size == FIRST_FRAME_SIZE:
        config = replace(config, image_size=recorded.image_size)
    saved, new = recorded.to_dict(), config.to_dict()
    for d in (saved, new):
        d["root"] = str(Path(d["root"]).expanduser().resolve())
    grown = [k for k in GROWABLE if new[k] > saved[k]]
    changes = [f"{k} {saved.get(k)!r} → {v!r}" for k, v in new.items()
               if k not in (*WHERE_AND_HOW, *grown) and saved.get(k) != v]
    if changes:
        raise InvalidOptionError(f"{run_dir} was started with other settings ({'; '.join(changes)}); rerun with its "
                                 f"settings, or give another {param('out')} for the new ones")
    return bool(grown)


def run_cell(config: TrainConfig, *, test_root: TestRoots = None, progress: bool = True) -> str:
    """Train and test one cell of the protocol (one network, variant and seed) in ``config.out`` — unless
    its ``metrics.json`` is there — and test it on every labelled frame of each further test set
    (:func:`parse_test_roots`; ``RUN/<name>/metrics.json``). Writes nothing outside the run folder.

    A cell started with other settings (its ``config.yaml``: every training option but where the files go
    and how the work is spread) is refused, finished or not, so a campaign never mixes regimes. A larger
    epoch cap or patience extends the cell instead: it resumes from its last checkpoint, exactly as a cell
    started with them would have gone on, and is tested again.

    Returns the status: ``"done"`` or ``"done (skipped)"``.
    """
    from freespace.engine.train import run_training

    run_dir = Path(config.out)
    _continue_base_run(config)
    grown = _check_cell(config)
    finished = (run_dir / "metrics.json").is_file()
    tests = parse_test_roots(test_root)
    if finished and not grown:
        status = "done (skipped)"
    else:
        if finished:  # extended: its test scores were the old end's (under the lock: no other run is in it)
            with claim_folder(run_dir, "train", entries=[f"{name}/" for name in tests]):
                for name in tests:
                    (run_dir / name / "metrics.json").unlink(missing_ok=True)
        resume = (run_dir / "checkpoints" / "last.ckpt").is_file()
        log.info("training %s (%s)", run_dir.name, "extending" if finished and resume else
                 "resuming" if resume else "new")
        run_training(config, resume=resume, progress=progress)
        status = "done"
    for name, root in tests.items():
        evaluate_test_set(run_dir, config.dataset, root, name)
    return status


def _base_variant(spec: Variant) -> Variant | None:
    """The variant whose run ``spec``'s continues: the one with the same training (augment, labels) and a budget
    of 1 (X for X-long), or None (``spec`` has a budget of 1, or no such variant)."""
    if spec.budget == 1:
        return None
    return next((v for v in VARIANTS.values() if v.budget == 1 and (v.augment, v.labels) == (spec.augment, spec.labels)),
                None)


def _continue_base_run(config: TrainConfig) -> None:
    """Start a new cell of a variant with a larger budget (X-long) as its base variant's run (X's, same network
    and seed) continued: X's config, splits, per-epoch CSV and checkpoints are copied into the new run folder,
    which :func:`run_cell` then extends from X's ``last.ckpt`` with the larger cap and patience. Its epochs up to
    X's stop are then X's, byte for byte, whatever machine or software runs the extension (a run trained anew
    equals X's only where both ran on the same machine, software and data bytes).

    Does nothing when the cell's folder already holds a run, when the variant has no base, or when X's folder
    is missing (X not run here: the cell trains from scratch, as before). Otherwise X's folder must hold a
    finished run with its ``last.ckpt`` (an unfinished one, or one whose checkpoints were not kept, e.g. copied
    from another machine, is refused in one line), started with the cell's settings but for the budget (else
    one line: which setting differs)."""
    from freespace.engine.train import RUN_ENTRIES

    run_dir = Path(config.out)
    named = _RUN_NAME.fullmatch(run_dir.name)
    spec = _BY_TAG.get(named["tag"]) if named else None
    base_spec = _base_variant(spec) if spec else None
    if base_spec is None or (run_dir / "config.yaml").is_file():
        return
    base = run_dir.parent / _name(named["model"], base_spec.name, int(named["seed"]))
    if not (base / "config.yaml").is_file():
        return
    if not (base / "metrics.json").is_file() or not (base / "checkpoints" / "last.ckpt").is_file():
        missing = "is unfinished" if not (base / "metrics.json").is_file() else "has no checkpoints/last.ckpt"
        raise InvalidOptionError(f"{run_dir.name} continues {base.name}'s run, which {missing}; run {base_spec.name}'s "
                                 f"cell to its end on this machine first (or move {base} away to train "
                                 f"{run_dir.name} from scratch)")
    _check_cell(replace(config, out=str(base), epochs=config.epochs // spec.budget,
                        patience=config.patience // spec.budget))  # X started with the cell's settings
    with claim_folder(base, "train", entries=RUN_ENTRIES):  # X's lock: nothing writes X while it is copied
        with claim_folder(run_dir, "train", entries=RUN_ENTRIES):
            log.info("%s starts as %s's run continued", run_dir.name, base.name)
            for name in ("splits", "checkpoints"):
                (run_dir / name).mkdir(exist_ok=True)
                for path in sorted((base / name).glob("*.txt" if name == "splits" else "*.ckpt")):
                    shutil.copy2(path, run_dir / name / path.name)
            for name in ("metrics.csv", "config.yaml"):  # config last: a folder with it holds a run
                shutil.copy2(base / name, run_dir / name)


def evaluate_test_set(run_dir: PathLike, dataset: str, test_root: PathLike,
                      name: str = DEFAULT_TEST_SET) -> dict[str, Any]:
    """Test a finished run's checkpoint on every labelled frame of ``test_root`` (a ``dataset`` tree):
    ``RUN/<name>/metrics.json`` (accuracy, precision, recall, f_score, iou at p ≥ 0.5, max_f, ap as
    fractions; frames; the resolved root; the run's ``best_epoch`` and ``epochs_run``). Skipped when that file
    exists for the same root and the same end of training (an extended run is tested again)."""
    from freespace.data.registry import get_dataset
    from freespace.inference.evaluate import evaluate_frames
    from freespace.inference.predictor import Predictor

    run_dir = Path(run_dir)
    path = run_dir / name / "metrics.json"
    root = str(Path(test_root).resolve())
    run = _read_metrics(run_dir / "metrics.json")
    trained = {k: run.get(k) for k in ("best_epoch", "first_epoch", "epochs_run")
               if k != "first_epoch" or k in run} if isinstance(run, dict) else {}  # (older runs: no first_epoch)
    if path.is_file():
        done = _read_metrics(path)
        if isinstance(done, dict) and done.get("root") == root and done.get("trained", trained) == trained:
            return done  # (a file of an older version records no end of training)
    checkpoint = run_dir / str(run.get("checkpoint") if isinstance(run, dict) else "")
    if isinstance(run, str) or not checkpoint.is_file() or not checkpoint.resolve().is_relative_to(run_dir.resolve()):
        raise CorruptFileError(f"{run_dir / 'metrics.json'} names no checkpoint of the run "
                               f"({run if isinstance(run, str) else 'checkpoint: ' + repr(checkpoint.name)}); "
                               f"remove it to train the run again")
    predictor = Predictor(checkpoint=checkpoint)
    ds = get_dataset(dataset, test_root, disparity_source="none")
    names = [f.name for f in ds.labelled().frames]
    if not names:
        raise DatasetError(f"{param('test_root')} {test_root} has no labelled frames to test on")
    with claim_folder(run_dir, "train", entries=[f"{name}/"]):  # the run folder's own entry, under its lock
        scores = evaluate_frames(predictor, ds, names)[0].evaluate()
        metrics = {**{k: scores[k] for k in (*METRICS, "max_f", "ap")}, "frames": len(names), "dataset": dataset,
                   "root": root, "checkpoint": checkpoint.relative_to(run_dir).as_posix(), "trained": trained}
        write_json(path, metrics)
    log.info("%s on the %s set (%d frames): F %.4f  IoU %.4f", run_dir.name, name, len(names),
             metrics["f_score"], metrics["iou"])
    return metrics


def reproduce(dataset: str, root: PathLike, out: PathLike, *, models: str | list[str] | None = None, seeds: int = 3,
              epochs: int = 50, image_size: tuple[int, int] | str = FIRST_FRAME_SIZE, patience: int = 10,
              val_window: int = 1,
              min_delta: float = 0.0,
              lr: float = 0.001, batch_size: int = 4, workers: int = 0, max_frames: int | None = None, figures: int = 3,
              progress: bool = True, variants: str | tuple[str, ...] | None = None, test_root: TestRoots = None,
              only: str | None = None, preset: str = "light", encoder_name: str | None = None,
              encoder_weights: str | None = None, autolabels: PathLike | None = None,
              **virtual: Any) -> dict[str, Any]:
    """Run the protocol (see the module docstring) and return ``{"table": results rows, "gains": gain rows,
    "runs": index}``.

    ``models``: networks (:func:`parse_models`; None = all). ``variants``: table names from :data:`VARIANTS`
    (None = :data:`DEFAULT_VARIANTS`; ``X`` is always run: gains are against it); a variant's ``budget``
    multiplies ``epochs`` and ``patience`` (X-long).
    ``test_root``: further test sets (:func:`parse_test_roots`). ``autolabels``: the label tree of ``root``
    that X-auto and X-mix train on (made by ``freespace autolabel``).
    ``image_size``: (H, W), or :data:`~freespace.engine.config.FIRST_FRAME_SIZE`.
    ``preset``: every network's size (``"light"`` for a CPU, ``"paper"``: the paper's backbones).
    ``encoder_name``, ``encoder_weights``: every run's encoder and its initial weights (``"imagenet"`` or a
    state-dict file; see :mod:`freespace.models.weights`), for the networks that take them.
    ``virtual``: ``virtual_shift``, ``virtual_rotate`` and ``virtual_prob`` of the variants with virtual views
    (HV-X, HAV-X; as :class:`~freespace.engine.config.TrainConfig` takes them, e.g. ``virtual_shift="0,-3:1,0"``).
    ``only``: ``"NETWORK,VARIANT,SEED"`` runs that one cell and writes only its run folder; ``models`` and
    ``variants``, when given, must include it (a cluster job's command line stays consistent). The returned
    table and gains are then empty (collect the cells with :func:`write_tables`).
    """
    if not 1 <= seeds <= MAX_SEEDS:
        raise InvalidOptionError(f"{param('seeds')} must be in 1…{MAX_SEEDS}, got {seeds}")
    options = dict(epochs=epochs, batch_size=batch_size, patience=patience, val_window=val_window,
                   min_delta=min_delta, lr=lr, image_size=image_size, workers=workers, max_frames=max_frames,
                   preset=preset, encoder_name=encoder_name, encoder_weights=encoder_weights)
    unknown = sorted(set(virtual) - {"virtual_shift", "virtual_rotate", "virtual_prob"})
    if unknown:
        raise TypeError(f"reproduce() got unexpected keyword arguments {', '.join(unknown)}")
    options.update(virtual)
    out = check_writable(out, folder=True)
    roots = parse_test_roots(test_root)
    chosen_models = parse_models(models)
    chosen = parse_variants(variants if variants is not None else DEFAULT_VARIANTS)
    if only is not None:
        model, variant, seed = parse_cell(only, seeds)
        if (models is not None and model not in chosen_models) or (variants is not None and variant not in chosen):
            what = (f"network {model!r} is not among {param('models')}" if model not in chosen_models
                    else f"variant {variant!r} is not among {param('variants')}")
            raise InvalidOptionError(f"{param('only')} {only}: its {what}; include it there, or leave the option out")
    _check_autolabels_used(autolabels, [variant] if only is not None else chosen)
    if only is not None:
        config = _config(dataset, root, out, model, variant, seed, options, autolabels)
        _check_inputs(out, [config])
        _check_test_roots(dataset, roots, root)
        with claim_folder(out, "reproduce", entries=OUT_ENTRIES, shared=True):
            status = run_cell(config, test_root=roots, progress=progress)
        entry = {"run": str(Path(config.out).relative_to(out)), "model": model, "variant": variant,
                 "augment": augment_text(VARIANTS[variant].augment), "seed": seed, "status": status}
        return {"table": [], "gains": [], "runs": [entry]}
    configs = [_config(dataset, root, out, model, variant, seed, options, autolabels)  # all checked before any work
               for model in chosen_models for variant in chosen for seed in range(seeds)]
    for config in configs:
        _check_cell(config)
    _check_inputs(out, configs)
    _check_test_roots(dataset, roots, root)
    statuses: dict[str, str] = {}
    with claim_folder(out, "reproduce", entries=OUT_ENTRIES, shared=True):
        for config in configs:
            statuses[Path(config.out).name] = run_cell(config, test_root=roots, progress=progress)
            write_tables(out, figures=0, statuses=statuses)  # the tables so far, after every run
        return write_tables(out, figures=figures, statuses=statuses)


# --- collecting the run folders ------------------------------------------------------------------------

def _collect(out: Path, statuses: dict[str, str] | None = None) -> tuple[list[dict[str, Any]], list[str]]:
    """Every run folder under ``OUT/runs`` (its config.yaml names the network, variant and seed), in
    network, :data:`VARIANTS` and seed order, with its test metrics (and those of further test sets,
    ``test_sets``) when finished; and the settings that differ between the runs (a table should compare
    like with like)."""
    from freespace.models import list_models

    entries, settings = [], {}
    for run_dir in sorted((out / "runs").glob("*/config.yaml")):
        run_dir = run_dir.parent
        try:
            config = read_config_yaml(run_dir / "config.yaml")
        except FreespaceError as exc:
            log.warning("%s skipped: %s", run_dir, exc)
            continue
        named = _RUN_NAME.fullmatch(run_dir.name)
        spec = _BY_TAG.get(named["tag"]) if named else None
        if spec is None or "model" not in config or spec.augment != config.get("augment", ()):
            log.warning("%s skipped: not a run folder of the protocol (<model>-<tag>-s<seed> with the variant's "
                        "augment)", run_dir)
            continue
        entry: dict[str, Any] = {"run": str(run_dir.relative_to(out)), "model": config["model"],
                                 "variant": spec.name, "augment": augment_text(spec.augment),
                                 "seed": int(config.get("seed", 0)), "status": "unfinished"}
        if (run_dir / "metrics.json").is_file():
            metrics = _read_metrics(run_dir / "metrics.json")
            if isinstance(metrics, str):
                log.warning("%s skipped: %s", run_dir / "metrics.json", metrics)
                entry["status"] = f"skipped: {metrics}"
                entries.append(entry)
                continue
            entry["status"] = (statuses or {}).get(run_dir.name, "done")
            entry["metrics"] = {k: metrics[k] for k in (*METRICS, "max_f", "ap")}
            entry.update(_convergence(metrics, config))
            if isinstance(metrics.get("record"), dict):  # the commit, data root and torch that finished the run
                entry["record"] = metrics["record"]
            for path in sorted(run_dir.glob("*/metrics.json")):  # further test sets: RUN/<name>/metrics.json
                name = path.parent.name
                if name in _RESERVED_TEST_SETS:
                    continue
                extra = _read_metrics(path)
                if isinstance(extra, str):
                    log.warning("%s skipped: %s", path, extra)
                    continue
                entry.setdefault("test_sets", {})[name] = {k: extra[k] for k in (*METRICS, "max_f", "ap")}
                settings.setdefault(f"the root of test set {name}", set()).add(json.dumps(extra.get("root")))
        for key, value in _input_hashes(run_dir).items():  # runs of older versions recorded none
            settings.setdefault(f"the content of {key}", set()).add(json.dumps(value))
        for key in ("dataset", "root", "epochs", "patience", "val_window", "min_delta", "lr", "batch_size",
                    "max_frames", *_PER_NETWORK):
            value = config.get(key)
            if key in ("epochs", "patience") and isinstance(value, int):
                value //= spec.budget  # X-long's budget is part of the variant
            name = f"{key} of {config['model']}" if key in _PER_NETWORK else key
            settings.setdefault(name, set()).add(json.dumps(value))
        entries.append(entry)
    order = {m: i for i, m in enumerate(list_models())}
    names = list(VARIANTS)
    entries.sort(key=lambda e: (order.get(e["model"], len(order)), e["model"], names.index(e["variant"]), e["seed"]))
    differ = [f"{k}: {', '.join(sorted(v))}" for k, v in settings.items() if len(v) > 1]
    return entries, differ


def _input_hashes(run_dir: Path) -> dict[str, str]:
    """The content hashes a run recorded (``inputs.json``: ``encoder_weights``, ``labels``), by input."""
    from freespace.engine.train import read_inputs

    return {k: str(v.get("sha256")) for k, v in read_inputs(run_dir).items() if isinstance(v, dict)}


#: settings that may differ between networks (each at its own size and encoder), not within one
_PER_NETWORK = ("image_size", "preset", "encoder_name", "encoder_weights")


def _convergence(metrics: dict[str, Any], config: dict[str, Any]) -> dict[str, Any]:
    """``best_epoch`` and ``epochs_run`` of a finished run (1-based, as counted by a person) and how it
    stopped: ``"patience"`` (early stopping fired) or ``"cap"`` (it ran the most epochs, ``config``'s).
    metrics.json counts from 1 when it says ``first_epoch: 1``; one of an older version, without it, from 0."""
    best, run, cap = metrics.get("best_epoch"), metrics.get("epochs_run"), config.get("epochs")
    shift = 1 - metrics.get("first_epoch", 0) if metrics.get("first_epoch") in (None, 0, 1) else None
    best = best if isinstance(best, int) and not isinstance(best, bool) and shift is not None else None
    found: dict[str, Any] = {"best_epoch": best + shift if best is not None else None,
                             "epochs_run": run if isinstance(run, int) else None}
    found["stopped_by"] = None if found["epochs_run"] is None or not isinstance(cap, int) else \
        "cap" if found["epochs_run"] >= cap else "patience"
    return found


def _read_metrics(path: Path) -> dict[str, Any] | str:
    """A run's (or a further test set's) ``metrics.json``, its scores checked: fractions in [0, 1]; or, for a
    file that cannot be used (damaged, scores missing, NaN or out of range), the reason as one line."""
    try:
        metrics = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        return f"not readable as JSON ({type(exc).__name__})"
    if not isinstance(metrics, dict):
        return "not a mapping of metrics"
    missing = [k for k in (*METRICS, "max_f", "ap") if k not in metrics]
    if missing:
        return f"no {', '.join(missing)}"
    bad = [k for k in (*METRICS, "max_f", "ap") if isinstance(metrics[k], bool)
           or not isinstance(metrics[k], (int, float)) or not 0 <= metrics[k] <= 1]  # NaN fails 0 <= NaN
    if bad:
        return f"{bad[0]} is {metrics[bad[0]]!r}, not a fraction in [0, 1]"
    return {**metrics, **{k: float(metrics[k]) for k in (*METRICS, "max_f", "ap")}}


def _values(entries: list[dict[str, Any]], model: str, variant: str, test_set: str) -> dict[int, dict[str, float]]:
    found = ((e["seed"], e.get("metrics") if test_set == "test" else e.get("test_sets", {}).get(test_set))
             for e in entries if e["model"] == model and e["variant"] == variant)
    return {seed: m for seed, m in found if m is not None}


def _test_sets(entries: list[dict[str, Any]]) -> list[str]:
    """``test``, then ``shifted``, then the other further test sets by name."""
    names = sorted({n for e in entries for n in e.get("test_sets", {})}, key=lambda n: (n != DEFAULT_TEST_SET, n))
    return ["test", *names]


def _models(entries: list[dict[str, Any]]) -> list[str]:
    return list(dict.fromkeys(e["model"] for e in entries))


def _table(entries: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``results.csv`` rows: per network, variant (:data:`VARIANTS` order) and test set, ``n`` finished
    seeds and each metric's mean and std (ddof 1; 0 with one seed) in %."""
    rows = []
    for model in _models(entries):
        for test_set in _test_sets(entries):
            for name in VARIANTS:
                runs = list(_values(entries, model, name, test_set).values())
                if not runs:
                    continue
                row: dict[str, Any] = {"network": model, "variant": name, "test_set": test_set, "n": len(runs)}
                for k in METRICS:
                    vals = 100 * np.array([r[k] for r in runs])
                    row[f"{k}_mean"] = float(vals.mean())
                    row[f"{k}_std"] = float(vals.std(ddof=1)) if len(vals) > 1 else 0.0
                rows.append(row)
    return rows


def _gains(entries: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``gains.csv`` rows: the paired gains of :data:`GAINS` in points, over the seeds both variants finished."""
    rows = []
    for model in _models(entries):
        for test_set in _test_sets(entries):
            for a, b in GAINS:
                va, vb = _values(entries, model, a, test_set), _values(entries, model, b, test_set)
                seeds = sorted(set(va) & set(vb))
                if not seeds:
                    continue
                for k in GAIN_METRICS:
                    g = paired_gain([100 * va[s][k] for s in seeds], [100 * vb[s][k] for s in seeds])
                    rows.append(_gain_row(model, a, b, k, test_set, g))
    return rows + _averaged_gains(entries)


def _gain_row(network: str, a: str, b: str, metric: str, test_set: str, g: Any) -> dict[str, Any]:
    return {"network": network, "versus": f"{a} - {b}", "metric": metric, "test_set": test_set, "mean": g.mean,
            "ci_low": g.ci_low, "ci_high": g.ci_high, "n": g.n, "excludes_zero": g.excludes_zero}


def _averaged_gains(entries: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Gains averaged over the networks (``network`` = :data:`ALL_NETWORKS`), with two or more networks:
    per seed, the mean over the networks of each variant's metric (the seeds every network finished in
    both variants), then the paired t-interval over those seeds. The primary endpoint is one of them."""
    models = _models(entries)
    if len(models) < 2:
        return []
    rows = []
    for test_set in _test_sets(entries):
        for a, b in GAINS:
            va = {m: _values(entries, m, a, test_set) for m in models}
            vb = {m: _values(entries, m, b, test_set) for m in models}
            seeds = sorted(set.intersection(*(set(va[m]) & set(vb[m]) for m in models)))
            if not seeds:
                continue
            for k in GAIN_METRICS:
                g = paired_gain([100 * float(np.mean([va[m][s][k] for m in models])) for s in seeds],
                                [100 * float(np.mean([vb[m][s][k] for m in models])) for s in seeds])
                rows.append(_gain_row(ALL_NETWORKS, a, b, k, test_set, g))
    return rows


def _cell(v: Any) -> Any:
    """A CSV cell: floats with 4 decimals, NaN (an interval of one seed) empty."""
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.4f}"
    return v


def write_tables(out: PathLike, *, figures: int = 3, statuses: dict[str, str] | None = None) -> dict[str, Any]:
    """Rebuild ``index.json``, ``results.csv``, ``gains.csv``, ``results.md`` and (``figures`` > 0: test
    frames per figure) the figures from the run folders under ``OUT/runs``.

    Returns ``{"table", "gains", "runs"}`` as :func:`reproduce`.

    Raises:
        InvalidOptionError: ``OUT/runs`` holds no run folder.
    """
    out = Path(out)
    entries, differ = _collect(out, statuses)
    if not entries:
        raise InvalidOptionError(f"{out / 'runs'} holds no run folders of `freespace reproduce`; nothing to collect")
    with claim_folder(out, "reproduce", entries=OUT_ENTRIES, shared=True):
        return _write_tables(out, entries, differ, figures)


def _write_tables(out: Path, entries: list[dict[str, Any]], differ: list[str], figures: int) -> dict[str, Any]:
    if differ:
        log.warning("the runs differ in %s", "; ".join(differ))
    table, gains = _table(entries), _gains(entries)
    write_json(out / "index.json", entries)
    fields = ["network", "variant", "test_set", "n"] + [f"{k}_{s}" for k in METRICS for s in ("mean", "std")]
    write_csv(out / "results.csv", fields, [{k: _cell(v) for k, v in r.items()} for r in table])
    write_csv(out / "gains.csv", ["network", "versus", "metric", "test_set", "mean", "ci_low", "ci_high", "n",
                                  "excludes_zero"], [{k: _cell(v) for k, v in r.items()} for r in gains])
    _write_markdown(out, entries, table, gains, differ)
    if figures > 0:
        for model in _models(entries):
            _gain_figure(out, model, [g for g in gains if g["network"] == model])
            try:
                _figure(out, model, entries, figures)
            except FreespaceError as exc:  # a moved dataset, a damaged checkpoint: the tables stand without it
                log.warning("figures/%s.png skipped: %s", model, exc)
    return {"table": table, "gains": gains, "runs": entries}


_NAMES = {"accuracy": "Accuracy", "precision": "Precision", "recall": "Recall", "f_score": "F-score", "iou": "IoU"}


def _write_markdown(out: Path, entries: list[dict[str, Any]], table: list[dict[str, Any]],
                    gains: list[dict[str, Any]], differ: list[str]) -> None:
    finished = sum("metrics" in e for e in entries)
    skipped = sum(e["status"].startswith("skipped") for e in entries)
    md = [f"Results of {finished} finished run{'s' if finished != 1 else ''} ({len(entries) - finished - skipped} "
          "unfinished" + (f", {skipped} skipped for unusable metrics.json" if skipped else "") + "): "
          "test set `test` = the dataset's test split, any other = every labelled frame of the further test set of "
          "that name (`shifted` when it was given none); "
          "%, mean ± std over the `n` seeds finished (no std with one seed).", ""]
    if differ:
        md += [f"**Warning: the runs differ in {'; '.join(differ)}.**", ""]
    md += ["| Network | Variant | Test set | n | " + " | ".join(_NAMES.values()) + " |",
           "|---|---|---|---:|" + "---:|" * len(_NAMES)]
    for r in table:
        cells = [f"{r[k + '_mean']:.2f}" + (f" ± {r[k + '_std']:.2f}" if r["n"] > 1 else "") for k in _NAMES]
        md.append(f"| {r['network']} | {r['variant']} | {r['test_set']} | {r['n']} | " + " | ".join(cells) + " |")
    md += ["", f"Paired gains in points (one difference per seed: the variants of a seed share the split and the "
           f"initial weights), mean and 95 % Student t-interval over the `n` seeds (no interval with one seed); "
           f"{PAPER_GAINS} (HA-X − X).", "",
           "| Network | Gain | Metric | Test set | n | mean | 95 % t-interval | half-width | excludes 0 |",
           "|---|---|---|---|---:|---:|---:|---:|:---:|"]
    for g in gains:
        ci, half = ("—", "—") if math.isnan(g["ci_low"]) else \
            (f"[{g['ci_low']:+.2f}, {g['ci_high']:+.2f}]", f"{(g['ci_high'] - g['ci_low']) / 2:.2f}")
        md.append(f"| {g['network']} | {g['versus'].replace(' - ', ' − ')} | {_NAMES[g['metric']]} | {g['test_set']} "
                  f"| {g['n']} | {g['mean']:+.2f} | {ci} | {half} | {'yes' if g['excludes_zero'] else 'no'} |")
    md += _convergence_lines(entries) + _primary_lines(gains)
    atomic_write_text(out / "results.md", "\n".join(md) + "\n")


def _convergence_lines(entries: list[dict[str, Any]]) -> list[str]:
    """results.md: per network and variant, the best and last epochs (1-based; mean, min–max) and how many
    runs early stopping ended against how many ran to the epoch cap."""
    lines = ["", "Convergence: best epoch (the checkpoint tested) and epochs run, mean (min–max) over the finished "
             "runs; stopped = early stopping fired (patience), cap = ran the most epochs allowed.", "",
             "| Network | Variant | n | best epoch | epochs run | stopped | cap |", "|---|---|---:|---:|---:|---:|---:|"]
    for model in _models(entries):
        for name in VARIANTS:
            done = [e for e in entries if e["model"] == model and e["variant"] == name and "metrics" in e]
            if not done:
                continue

            def spread(key: str) -> str:
                vals = [e[key] for e in done if e.get(key) is not None]
                return f"{np.mean(vals):.1f} ({min(vals)}–{max(vals)})" if vals else "—"

            lines.append(f"| {model} | {name} | {len(done)} | {spread('best_epoch')} | {spread('epochs_run')} | "
                         f"{sum(e.get('stopped_by') == 'patience' for e in done)} | "
                         f"{sum(e.get('stopped_by') == 'cap' for e in done)} |")
    return lines


def _primary_lines(gains: list[dict[str, Any]]) -> list[str]:
    """results.md: the primary endpoint (:data:`PRIMARY`), when it was measured, against its margin."""
    found = next((g for g in gains if g["network"] == ALL_NETWORKS and g["versus"] == PRIMARY["versus"]
                  and g["metric"] == PRIMARY["metric"] and g["test_set"] == PRIMARY["test_set"]), None)
    if found is None or math.isnan(found["ci_low"]):
        return []
    m = PRIMARY["margin"]
    inside = -m <= found["ci_low"] and found["ci_high"] <= m
    verdict = (f"the interval lies inside ±{m:g}: equivalent within the margin" if inside else
               f"the interval leaves ±{m:g}: " + ("a difference" if found["excludes_zero"] else "not resolved"))
    return ["", f"**Primary endpoint** (named before the run): {PRIMARY['versus'].replace(' - ', ' − ')} F-score on "
            f"`{PRIMARY['test_set']}`, averaged over the networks: {found['mean']:+.2f} points, 95 % t-interval "
            f"[{found['ci_low']:+.2f}, {found['ci_high']:+.2f}] over {found['n']} seeds; {verdict}."]


def _gain_figure(out: Path, model: str, gains: list[dict[str, Any]]) -> None:
    """``figures/gains_<model>.png``: each paired gain (points) with its 95 % t-interval, F-score and IoU side
    by side, one row per comparison and test set; written atomically."""
    if not gains:
        return
    import io as _io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = list(dict.fromkeys(f"{g['versus'].replace(' - ', ' − ')} ({g['test_set']})" for g in gains))
    fig, axes = plt.subplots(1, len(GAIN_METRICS), figsize=(4 * len(GAIN_METRICS), 0.5 * len(labels) + 1.2),
                             dpi=100, sharey=True, squeeze=False)
    for ax, k in zip(axes[0], GAIN_METRICS):
        for g in (g for g in gains if g["metric"] == k):
            y = labels.index(f"{g['versus'].replace(' - ', ' − ')} ({g['test_set']})")
            colour = "tab:green" if g["excludes_zero"] and g["mean"] > 0 else \
                "tab:red" if g["excludes_zero"] else "tab:grey"
            if not math.isnan(g["ci_low"]):
                ax.plot([g["ci_low"], g["ci_high"]], [y, y], color=colour, linewidth=2)
            ax.plot([g["mean"]], [y], "o", color=colour)
            ax.annotate(f"n={g['n']}", (g["mean"], y), textcoords="offset points", xytext=(0, 5), ha="center",
                        fontsize=7)
        ax.axvline(0, color="black", linewidth=0.8)
        ax.set_xlabel(f"{_NAMES[k]} gain (points)")
        ax.grid(True, axis="x", alpha=0.3)
    axes[0][0].set_yticks(range(len(labels)), labels)
    axes[0][0].invert_yaxis()
    fig.suptitle(f"{model}: paired gains, mean and 95 % t-interval over seeds", fontsize=10)
    buf = _io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(out / "figures" / f"gains_{model}.png", buf.getvalue())


def _figure(out: Path, model: str, entries: list[dict[str, Any]], frames: int) -> None:
    """``figures/<model>.png``: test frames of seed 0 — image, then each finished variant's prediction
    (TP/FN/FP), X first."""
    from freespace.data.registry import get_dataset
    from freespace.data.splits import read_splits
    from freespace.evaluation.viz import caption, grid, overlay_errors
    from freespace.inference.predictor import Predictor

    runs = {e["variant"]: out / e["run"] for e in entries
            if e["model"] == model and e["seed"] == 0 and (out / e["run"] / "checkpoints" / "best.ckpt").is_file()
            and "metrics" in e}
    if "X" not in runs or len(runs) < 2 or frames < 1:
        return
    config = read_config_yaml(runs["X"] / "config.yaml")
    ds = get_dataset(config["dataset"], config["root"], config.get("split"), disparity_source="none")
    names = read_splits(runs["X"] / "splits")["test"][:frames]
    predictors = {v: Predictor(checkpoint=r / "checkpoints" / "best.ckpt") for v, r in runs.items()}
    rows = []
    for name in names:
        s = ds.load(ds.index(name), right=False, disparity=False)
        row = [caption(s.left, name)]
        for v, predictor in predictors.items():
            pred = predictor.predict([s.left])[0] >= 0.5
            row.append(caption(overlay_errors(s.left, pred, s.label.road, s.label.valid), VARIANTS[v].label(model)))
        rows.append(row)
    write_image(out / "figures" / f"{model}.png", grid(rows, width=min(480, rows[0][0].shape[1])))
