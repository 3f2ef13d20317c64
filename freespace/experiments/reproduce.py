"""`freespace reproduce`: the paper's protocol on one dataset, with a control and paired statistics.

Every chosen network is trained on the original training set (X), on the set augmented with the
DS-Generator views (HA-X) and on the control X-dup (X with every frame that has a DS-Generator view once
more, unchanged: as many optimiser steps per epoch as HA-X under the same early stopping, without the
views' content) — or any variants of :data:`~freespace.experiments.variants.VARIANTS` (HV-X: road-plane virtual
views, HAV-X: both) — with the same seeds and budget, and tested on the test split (``test_set = test``) and, with
``test_root``, on every labelled frame of further datasets (``test_set = shifted`` for a bare folder, e.g.
other rigs, or the name given as ``NAME=DIR``, e.g. a large fixed set rendered with the training rigs).
A study's protocol file may instead declare its own variants, each training on its own data
(:attr:`~freespace.experiments.protocol.Protocol.declared`; then no ``dataset`` and ``root`` are given).
For one network and seed all variants share the split and the initial weights; HA-X and X-dup also share
the data order and the conventional augmentation's draws (same number of samples).

``OUT`` receives ``runs/<model>-<tag>-s<seed>/`` (training run folders; ``<name>/metrics.json`` in each
for each further test set) and, built from the run folders on disk
(:func:`~freespace.experiments.tables.write_tables`):

* ``results.csv``: one row per network × variant × test set: ``n`` seeds and each metric's mean and std
  over them (%);
* ``gains.csv``: per network (and averaged over the networks) the paired gains of the protocol (one
  difference per seed: HA-X − X, HA-X − X-dup, the controls' X-dup − X, X-long − X, HA-X − X-long and
  X-dup − X-long, the virtual views' HV-X − X, ...) in F-score and IoU points: mean, 95 % Student
  t-interval over the seeds, n and whether the interval excludes 0
  (:func:`freespace.experiments.stats.paired_gain`);
* ``results.md`` (both tables), ``figures/gains_<model>.png`` (the gains with their intervals),
  ``figures/<model>.png`` (a few test frames: each variant's predictions coloured TP green / FN red /
  FP blue) and ``index.json`` (every run, its status and metrics).

Finished runs are skipped when the command is run again; interrupted ones resume. One cell
(:func:`~freespace.experiments.cells.run_cell`; :func:`reproduce` with ``only="NETWORK,VARIANT,SEED"``) writes
only its run folder, so cells can run concurrently on a cluster and
:func:`~freespace.experiments.tables.write_tables` collects them.

The rooms: :mod:`~freespace.experiments.protocol` (the variants, gains and a study's
:class:`~freespace.experiments.protocol.Protocol`),
:mod:`~freespace.experiments.cells` (running one cell), :mod:`~freespace.experiments.tables` (collecting and
tabulating), :mod:`~freespace.experiments.figures`; this module runs a whole campaign through them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from freespace.engine.config import TrainConfig
from freespace.engine.option_values import FIRST_FRAME_SIZE, augment_text
from freespace.errors import InvalidOptionError, param
from freespace.experiments.cells import (
    cell_config,
    check_autolabels_used,
    check_cell,
    check_inputs,
    check_test_roots,
    run_cell,
)
from freespace.experiments.protocol import Protocol
from freespace.experiments.tables import OUT_ENTRIES, write_tables
from freespace.experiments.variants import (
    MAX_SEEDS,
    TestRoots,
    parse_cell,
    parse_models,
    parse_test_roots,
    parse_variants,
    run_of,
)
from freespace.io.files import PathLike, check_writable
from freespace.io.outdir import claim_folder

__all__ = ["reproduce", "run_reproduce"]


def reproduce(dataset: str | None, root: PathLike | None, out: PathLike, *, models: str | list[str] | None = None,
              seeds: int = 3,
              epochs: int = 50, image_size: tuple[int, int] | str = FIRST_FRAME_SIZE, patience: int = 10,
              val_window: int = 1,
              min_delta: float = 0.0,
              lr: float = 0.001, batch_size: int = 4, workers: int = 0, max_frames: int | None = None, figures: int = 3,
              progress: bool = True, variants: str | tuple[str, ...] | None = None, test_root: TestRoots = None,
              only: str | None = None, preset: str = "light", encoder_name: str | None = None,
              encoder_weights: str | None = None, autolabels: PathLike | None = None,
              protocol: Protocol | None = None, **virtual: Any) -> dict[str, Any]:
    """Run the protocol (see the module docstring) and return ``{"table": results rows, "gains": gain rows,
    "runs": index}``.

    ``protocol``: the study's :class:`~freespace.experiments.protocol.Protocol` (its variants, gains, primary
    endpoint, test sets and reference; None: the method's defaults, ``Protocol()``). A protocol with ``data``
    gives each of its declared variants its training data: ``dataset`` and ``root`` are then None (and
    ``autolabels`` too), ``variants`` and ``only`` name its variants, and a further test set is read in the
    layout of each cell's data.
    ``models``: networks (:func:`~freespace.experiments.variants.parse_models`; None = all). ``variants``: table
    names from :data:`~freespace.experiments.variants.VARIANTS` (None = the protocol's; ``X`` is always run:
    gains are against it); a variant's ``budget`` multiplies ``epochs`` and ``patience`` (X-long).
    ``test_root``: further test sets (:func:`~freespace.experiments.variants.parse_test_roots`), added to the
    protocol's. ``autolabels``: the label tree of ``root``
    that X-auto and X-mix train on (made by ``freespace autolabel``).
    ``image_size``: (H, W), or :data:`~freespace.engine.option_values.FIRST_FRAME_SIZE`.
    ``preset``: every network's size (``"light"`` for a CPU, ``"paper"``: the paper's backbones).
    ``encoder_name``, ``encoder_weights``: every run's encoder and its initial weights (``"imagenet"`` or a
    state-dict file; see :mod:`freespace.models.weights`), for the networks that take them.
    ``virtual``: ``virtual_shift``, ``virtual_rotate`` and ``virtual_prob`` of the variants with virtual views
    (HV-X, HAV-X; as :class:`~freespace.engine.config.TrainConfig` takes them, e.g. ``virtual_shift="0,-3:1,0"``).
    ``only``: ``"NETWORK,VARIANT,SEED"`` runs that one cell and writes only its run folder; ``models`` and
    ``variants``, when given, must include it (a cluster job's command line stays consistent). The returned
    table and gains are then empty (collect the cells with :func:`~freespace.experiments.tables.write_tables`).
    """
    options = _train_options(seeds, dict(
        epochs=epochs, batch_size=batch_size, patience=patience, val_window=val_window, min_delta=min_delta, lr=lr,
        image_size=image_size, workers=workers, max_frames=max_frames, preset=preset, encoder_name=encoder_name,
        encoder_weights=encoder_weights), virtual)
    out = check_writable(out, folder=True)
    protocol = Protocol() if protocol is None else protocol
    vocabulary = protocol.vocabulary
    _check_data_source(protocol, dataset, root, autolabels)
    roots = _test_roots(protocol, test_root)
    chosen_models = parse_models(models)
    chosen = parse_variants(variants if variants is not None else protocol.variants, vocabulary)
    cell = None if only is None else _only_cell(only, seeds, protocol, models, chosen_models, variants, chosen)
    if not protocol.data:
        check_autolabels_used(autolabels, [cell[1]] if cell is not None else chosen)
    if cell is not None:
        config = cell_config(dataset, root, out, *cell, options, autolabels, protocol)
        return _run_one(out, config, cell, roots, protocol, progress)
    configs = [cell_config(dataset, root, out, model, variant, seed, options, autolabels, protocol)  # all checked
               for model in chosen_models for variant in chosen for seed in range(seeds)]   # before any work
    for config in configs:
        check_cell(config)
    check_inputs(out, configs, vocabulary)
    _check_test_roots(configs, roots)
    _check_data(configs, protocol)
    statuses: dict[str, str] = {}
    with claim_folder(out, "reproduce", entries=OUT_ENTRIES, shared=True):
        for config in configs:
            statuses[Path(config.out).name] = run_cell(config, test_root=roots, progress=progress, variants=vocabulary)
            write_tables(out, figures=0, statuses=statuses, protocol=protocol)  # the tables so far, after every run
        return write_tables(out, figures=figures, statuses=statuses, protocol=protocol)


def _train_options(seeds: int, options: dict[str, Any], virtual: dict[str, Any]) -> dict[str, Any]:
    """Every cell's training ``options`` with the ``virtual`` ones (``virtual_shift``, ``virtual_rotate``,
    ``virtual_prob``), after checking ``seeds`` (1…:data:`~freespace.experiments.variants.MAX_SEEDS`) and that
    ``virtual`` holds nothing else.

    Raises:
        InvalidOptionError: ``seeds`` out of bounds. TypeError: another keyword in ``virtual``.
    """
    if not 1 <= seeds <= MAX_SEEDS:
        raise InvalidOptionError(f"{param('seeds')} must be in 1…{MAX_SEEDS}, got {seeds}")
    unknown = sorted(set(virtual) - {"virtual_shift", "virtual_rotate", "virtual_prob"})
    if unknown:
        raise TypeError(f"reproduce() got unexpected keyword arguments {', '.join(unknown)}")
    return {**options, **virtual}


def _check_data_source(protocol: Protocol, dataset: str | None, root: PathLike | None,
                       autolabels: PathLike | None) -> None:
    """The training data comes from the ``protocol``'s data or from ``dataset`` and ``root``, never both.

    Raises:
        InvalidOptionError: both, or neither.
    """
    if protocol.data and (dataset is not None or root is not None or autolabels is not None):
        given = [param(k) for k, v in (("dataset", dataset), ("root", root), ("autolabels", autolabels))
                 if v is not None]
        raise InvalidOptionError(f"{param('protocol')} gives each variant its training data (its data); leave "
                                 f"{' and '.join(given)} out")
    if not protocol.data and (dataset is None or root is None):
        raise InvalidOptionError(f"reproduce needs {param('dataset')} and {param('root')} (or a {param('protocol')} "
                                 f"with data)")


def _only_cell(only: str, seeds: int, protocol: Protocol, models: str | list[str] | None, chosen_models: list[str],
               variants: str | tuple[str, ...] | None, chosen: tuple[str, ...] | list[str]) -> tuple[str, str, int]:
    """The cell ``only`` names, ``(network, variant, seed)``; ``models`` and ``variants``, when given, must
    include it.

    Raises:
        InvalidOptionError: a cell outside ``models`` or ``variants`` (or not of their form).
    """
    model, variant, seed = parse_cell(only, seeds, protocol.vocabulary)
    if (models is not None and model not in chosen_models) or (variants is not None and variant not in chosen):
        what = (f"network {model!r} is not among {param('models')}" if model not in chosen_models
                else f"variant {variant!r} is not among {param('variants')}")
        raise InvalidOptionError(f"{param('only')} {only}: its {what}; include it there, or leave the option out")
    return model, variant, seed


def _run_one(out: Path, config: TrainConfig, cell: tuple[str, str, int], roots: dict[str, Path],
             protocol: Protocol, progress: bool) -> dict[str, Any]:
    """Check and run the one cell ``cell`` (``config``: its training run) in ``out``; :func:`reproduce`'s
    result with that cell's entry alone in ``runs``."""
    check_inputs(out, [config], protocol.vocabulary)
    _check_test_roots([config], roots)
    _check_data([config], protocol)
    with claim_folder(out, "reproduce", entries=OUT_ENTRIES, shared=True):
        status = run_cell(config, test_root=roots, progress=progress, variants=protocol.vocabulary)
    model, variant, seed = cell
    entry = {"run": str(Path(config.out).relative_to(out)), "model": model, "variant": variant,
             "augment": augment_text(protocol.vocabulary[variant].augment), "seed": seed, "status": status}
    return {"table": [], "gains": [], "runs": [entry]}


def run_reproduce(out: PathLike, *, protocol: PathLike | None = None, tables: bool = False,
                  dataset: str | None = None, root: PathLike | None = None, models: str | None = None,
                  variants: str | None = None, test_root: TestRoots = None, only: str | None = None,
                  **options: Any) -> dict[str, Any]:
    """``freespace reproduce``: the ``protocol`` file read (None: the method's defaults), ``models`` and
    ``variants`` checked in every mode; then with ``tables`` the tables rebuilt from the cells in ``out``
    (:func:`~freespace.experiments.tables.write_tables`), else :func:`reproduce` with ``options`` (its other
    keyword arguments).

    Returns:
        :func:`reproduce`'s (or :func:`~freespace.experiments.tables.write_tables`') result.

    Raises:
        InvalidOptionError: ``tables`` with a cell, networks, variants or test sets to run; no ``dataset`` and
            ``root`` (without ``tables`` or a protocol with data).
    """
    loaded = Protocol.load(protocol) if protocol is not None else None
    if models is not None:  # names checked in every mode
        parse_models(models)
    if variants is not None:
        parse_variants(variants, loaded.vocabulary if loaded is not None else None)
    if tables:
        unused = [param(name) for name, value in (("only", only), ("models", models), ("variants", variants),
                                                  ("test_root", test_root)) if value]
        if unused:
            raise InvalidOptionError(f"{param('tables')} collects the finished cells in {param('out')}, whatever they "
                                     f"are; it takes no {', '.join(unused)}")
        return write_tables(out, protocol=loaded)
    if (dataset is None or root is None) and not (loaded is not None and loaded.data):
        raise InvalidOptionError(f"reproduce needs {param('dataset')} and {param('root')} (only {param('tables')}, "
                                 f"and a {param('protocol')} with data, do without)")
    return reproduce(dataset, root, out, models=models, variants=variants, test_root=test_root, only=only,
                     protocol=loaded, **options)


#: the options that decide what a cell trains on (:func:`~freespace.engine.data.plan_data`)
_DATA_OPTIONS = ("dataset", "root", "split", "labels", "human_share", "max_frames", "splits_dir", "seed", "augment")


def _check_data(configs: list[TrainConfig], protocol: Protocol) -> None:
    """Each cell's training data decided and checked (:func:`~freespace.engine.data.plan_data`: labelled frames,
    splits, label tree, right images) before the first cell trains, once per distinct data, so that a cell that
    cannot train is refused now, naming its run and variant, and not after the cells before it have trained.
    Without the protocol's data, a cell's label tree is ``autolabels``, and its message says so.

    Raises:
        FreespaceError: the first cell that cannot train, its run and variant before the reason.
    """
    from freespace.engine.data import plan_data
    from freespace.errors import FreespaceError

    seen: set[tuple[Any, ...]] = set()
    for config in configs:
        key = tuple(str(getattr(config, k)) for k in _DATA_OPTIONS)
        if key in seen:
            continue
        seen.add(key)
        try:
            plan_data(config, Path(config.out), warn=False)
        except FreespaceError as exc:
            name = Path(config.out).name
            cell = run_of(name, protocol.vocabulary)
            what = f"run {name} (variant {cell[1].name})" if cell else f"run {name}"
            text = exc.args[0] if protocol.data else exc.args[0].replace(param("labels"), param("autolabels"))
            raise type(exc)(f"{what}: {text}") from None


def _check_test_roots(configs: list[TrainConfig], roots: dict[str, Path]) -> None:
    """:func:`~freespace.experiments.cells.check_test_roots` for each training data of ``configs`` (one
    dataset and root; several when a protocol's variants train on their own data)."""
    if roots:
        for dataset, root in dict.fromkeys((c.dataset, c.root) for c in configs):
            check_test_roots(dataset, roots, root)


def _test_roots(protocol: Protocol, test_root: TestRoots) -> dict[str, Path]:
    """The further test sets: the protocol's, then ``test_root``'s (:func:`parse_test_roots`).

    Raises:
        InvalidOptionError: a name given twice (by the protocol and ``test_root``, or twice in ``test_root``).
    """
    given = parse_test_roots(test_root)
    twice = sorted(set(given) & set(protocol.test_sets))
    if twice:
        raise InvalidOptionError(f"{param('test_root')}: the protocol names the test set {twice[0]!r} already "
                                 f"({protocol.test_sets[twice[0]]}); leave it out of {param('test_root')}")
    return {**protocol.test_sets, **given}
