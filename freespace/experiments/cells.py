"""Running the protocol's cells: one network, variant and seed each, in its run folder
``OUT/runs/<model>-<tag>-s<seed>/`` (:func:`~freespace.experiments.variants.run_name`).

A cell's training configuration is built from the variant (:func:`cell_config`) and checked, with every other
cell of a campaign, before any work: the same settings as the cell already started in its folder
(:meth:`~freespace.engine.config.TrainConfig.diff`; a larger epoch cap or patience extends it), the same
weights file and label tree as the campaign's other cells (:func:`check_inputs`), further test sets that are
other data than the training set (:func:`check_test_roots`). :func:`run_cell` then trains and tests it, writing
nothing outside its run folder, so cells can run concurrently on a cluster; a cell of a larger budget
(X-long) starts as its base variant's run continued.
"""

from __future__ import annotations

import json
import logging
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

from freespace.engine.config import TrainConfig
from freespace.errors import CorruptFileError, DatasetError, InvalidOptionError, param
from freespace.experiments.protocol import Protocol
from freespace.experiments.variants import (
    DEFAULT_TEST_SET,
    METRICS,
    VARIANTS,
    TestRoots,
    Variant,
    parse_test_roots,
    run_name,
    run_of,
)
from freespace.io.files import PathLike, write_json
from freespace.io.outdir import claim_folder

log = logging.getLogger(__name__)

__all__ = ["cell_config", "check_cell", "check_inputs", "check_test_roots", "check_autolabels_used", "run_cell",
           "evaluate_test_set", "read_metrics"]


def check_test_roots(dataset: str, roots: dict[str, Path], train_root: PathLike) -> None:
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


def cell_config(dataset: str | None, root: PathLike | None, out: Path, model: str, variant: str, seed: int,
                options: dict[str, Any], autolabels: PathLike | None = None,
                protocol: Protocol | None = None) -> TrainConfig:
    """The training configuration of one cell (``variant``: a table name of ``protocol``'s
    :attr:`~freespace.experiments.protocol.Protocol.vocabulary`, by default :data:`VARIANTS`; its budget scales
    the epoch cap and the patience; X-auto and X-mix read ``autolabels``; the ``virtual_*`` options go to the
    variants with virtual views only, so that the others' cells keep their settings whatever pose ranges are
    asked for). A variant the protocol declares trains on its own data
    (:meth:`~freespace.experiments.protocol.DataSource.training`: dataset, root, labels, splits_dir and, with
    an augment, cache_dir), not on ``dataset`` and ``root`` (then None)."""
    vocabulary = protocol.vocabulary if protocol is not None else VARIANTS
    spec = vocabulary[variant]
    options = {**options, "epochs": options["epochs"] * spec.budget, "patience": options["patience"] * spec.budget}
    if "virtual" not in spec.augment:
        options = {k: v for k, v in options.items() if not k.startswith("virtual_")}
    if spec.data is not None:
        sources = protocol.data if protocol is not None else {}  # (only a protocol declares variants with data)
        source = {k: v for k, v in sources[spec.data].training(spec.augment).items() if v is not None}
        dataset, root = source.pop("dataset"), source.pop("root")
        options.update(source)
    elif dataset is None or root is None:
        raise InvalidOptionError(f"{variant} trains on {param('dataset')} and {param('root')}: give both")
    elif spec.labels != "human":
        if autolabels is None:
            raise InvalidOptionError(f"{variant} trains on labels nobody drew: give {param('autolabels')} DIR, the "
                                     f"label tree of {root} that `freespace autolabel` wrote")
        from freespace.data.label_tree import check_label_tree

        check_label_tree(autolabels, dataset, root, options.get("split"), option="autolabels")  # named as given
        options.update(labels=str(autolabels), human_share=0.0)
    if spec.controls:  # a study control the variant reads (X-mix: mix_human_share), from the study's protocol
        options.update((protocol or Protocol()).control_values(variant))
    config = TrainConfig(dataset=dataset, root=str(root),
                         out=str(out / "runs" / run_name(model, variant, seed, vocabulary)), model=model,
                         augment=spec.augment, seed=seed, **{k: True for k in spec.samples}, **options)
    config.check()
    return config


def check_autolabels_used(autolabels: PathLike | None, variants: list[str] | tuple[str, ...]) -> None:
    """Refuse ``autolabels`` when none of the cells to run (``variants``) trains on it: the option would have no
    effect."""
    if autolabels is not None and not any(VARIANTS[v].labels != "human" for v in variants):
        takers = ", ".join(v.name for v in VARIANTS.values() if v.labels != "human")
        raise InvalidOptionError(f"{param('autolabels')} is the label tree of the variants {takers}, and none of the "
                                 f"cells run here is one; add one to {param('variants')}, or leave "
                                 f"{param('autolabels')} out")


def check_inputs(out: Path, configs: list[TrainConfig], variants: dict[str, Variant] | None = None) -> None:
    """Refuse, before any work, cells whose weights file or label tree (by content:
    :func:`~freespace.engine.record.content_hashes`, computed once) differ from what the protocol's other cells
    in ``OUT/runs`` were trained from: their scores would be averaged as one setting. With a protocol's declared
    ``variants``, a cell is compared with the cells of the variants of its own training data only."""
    from freespace.engine.record import content_hashes
    from freespace.engine.train import read_inputs

    def source(folder: str) -> str | None:  # the training data of a run folder's variant (None: reproduce's)
        cell = run_of(folder, variants)
        return cell[1].data if cell else None

    groups: dict[str | None, dict[str, dict[str, Any]]] = {}
    for config in configs:
        now = groups.setdefault(source(Path(config.out).name), {})
        for key, value in content_hashes(config).items():
            now.setdefault(key, value)
    if not any(groups.values()) or not (out / "runs").is_dir():
        return
    for run_dir in sorted(p.parent for p in (out / "runs").glob("*/inputs.json")):
        recorded = read_inputs(run_dir)
        group = source(run_dir.name)
        for key, value in groups.get(group, {}).items():
            old = recorded.get(key)
            if isinstance(old, dict) and old.get("sha256") != value["sha256"]:
                option = (f"the {key} of the protocol's data {group}" if group is not None else
                          param("autolabels") if key == "labels" else param(key))  # reproduce's name of the tree
                raise InvalidOptionError(
                    f"{run_dir} was trained from other contents of {option} than {value['path']} holds now "
                    f"(sha256 {str(old.get('sha256'))[:12]}… then, {value['sha256'][:12]}… now): the cells would "
                    f"average two settings; restore the files, or give another {param('out')}")


def check_cell(config: TrainConfig) -> bool:
    """Refuse ``config`` when the cell in ``config.out`` was started with other settings (``key old → new``, in
    config.yaml's spelling), but for a larger ``epochs`` or ``patience``; return whether one of those grew
    (:meth:`~freespace.engine.config.TrainConfig.diff`: the cell's config.yaml may be of any version; paths
    compare resolved; an ``image_size`` of :data:`~freespace.engine.option_values.FIRST_FRAME_SIZE` matches the size
    it was resolved to)."""
    run_dir = Path(config.out)
    saved_path = run_dir / "config.yaml"
    if not saved_path.is_file():
        return False
    changes, grown = config.diff(TrainConfig.load(saved_path))
    if changes:
        raise InvalidOptionError(f"{run_dir} was started with other settings ({'; '.join(changes)}); rerun with its "
                                 f"settings, or give another {param('out')} for the new ones")
    return bool(grown)


def run_cell(config: TrainConfig, *, test_root: TestRoots = None, progress: bool = True,
             variants: dict[str, Variant] | None = None) -> str:
    """Train and test one cell of the protocol (one network, variant and seed) in ``config.out`` — unless
    its ``metrics.json`` is there — and test it on every labelled frame of each further test set
    (:func:`parse_test_roots`; ``RUN/<name>/metrics.json``). Writes nothing outside the run folder.

    A cell started with other settings (its ``config.yaml``: every training option but where the files go
    and how the work is spread) is refused, finished or not, so a campaign never mixes regimes. A larger
    epoch cap or patience extends the cell instead: it resumes from its last checkpoint, exactly as a cell
    started with them would have gone on, and is tested again.

    ``variants``: the table names the run folders' tags stand for (a protocol's
    :attr:`~freespace.experiments.protocol.Protocol.vocabulary`; default :data:`VARIANTS`).

    Returns the status: ``"done"`` or ``"done (skipped)"``.
    """
    from freespace.engine.train import run_training

    run_dir = Path(config.out)
    _continue_base_run(config, variants)
    grown = check_cell(config)
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
    return next((v for v in VARIANTS.values()
                 if v.budget == 1 and (v.augment, v.labels) == (spec.augment, spec.labels)), None)


def _continue_base_run(config: TrainConfig, variants: dict[str, Variant] | None = None) -> None:
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
    cell = run_of(run_dir.name, variants)
    base_spec = _base_variant(cell[1]) if cell else None
    if cell is None or base_spec is None or (run_dir / "config.yaml").is_file():
        return
    model, spec, seed = cell
    base = run_dir.parent / run_name(model, base_spec.name, seed)
    if not (base / "config.yaml").is_file():
        return
    if not (base / "metrics.json").is_file() or not (base / "checkpoints" / "last.ckpt").is_file():
        missing = "is unfinished" if not (base / "metrics.json").is_file() else "has no checkpoints/last.ckpt"
        raise InvalidOptionError(f"{run_dir.name} continues {base.name}'s run, which {missing}; run {base_spec.name}'s "
                                 f"cell to its end on this machine first (or move {base} away to train "
                                 f"{run_dir.name} from scratch)")
    check_cell(replace(config, out=str(base), epochs=config.epochs // spec.budget,
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
    run = read_metrics(run_dir / "metrics.json")
    trained = {k: run.get(k) for k in ("best_epoch", "first_epoch", "epochs_run")
               if k != "first_epoch" or k in run} if isinstance(run, dict) else {}  # (older runs: no first_epoch)
    if path.is_file():
        done = read_metrics(path)
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


def read_metrics(path: Path) -> dict[str, Any] | str:
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

