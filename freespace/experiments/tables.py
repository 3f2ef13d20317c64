"""Collecting the protocol's run folders and tabulating them: ``OUT/index.json`` (every run, its status and
metrics), ``results.csv`` (per network × variant × test set: ``n`` seeds and each metric's mean and std over
them, %), ``gains.csv`` (per network, and averaged over the networks, the paired gains of a
:class:`~freespace.experiments.protocol.Protocol` in F-score and IoU points: mean, 95 % Student t-interval
over the seeds, n and whether the interval excludes 0; :func:`freespace.experiments.stats.paired_gain`) and
``results.md`` (both tables, the runs' convergence and the protocol's primary endpoint), rebuilt from the run
folders on disk by :func:`write_tables`.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from freespace.engine.config import read_config_yaml
from freespace.engine.option_values import augment_text
from freespace.errors import FreespaceError, InvalidOptionError
from freespace.experiments.cells import read_metrics
from freespace.experiments.figures import frames_figure, gain_figure
from freespace.experiments.protocol import Primary, Protocol
from freespace.experiments.stats import paired_gain
from freespace.experiments.variants import (
    ALL_NETWORKS,
    DEFAULT_TEST_SET,
    GAIN_METRICS,
    METRIC_NAMES,
    METRICS,
    RESERVED_TEST_SETS,
    VARIANTS,
    Variant,
    run_of,
)
from freespace.io.files import PathLike, atomic_write_text, write_csv, write_json
from freespace.io.outdir import claim_folder

log = logging.getLogger(__name__)

__all__ = ["write_tables", "collect", "OUT_ENTRIES"]

#: what ``reproduce`` writes into OUT (:mod:`freespace.io.outdir` entries)
OUT_ENTRIES = ("runs/", "index.json", "results.csv", "gains.csv", "results.md", "figures/")


def collect(out: Path, statuses: dict[str, str] | None = None,
            variants: dict[str, Variant] | None = None) -> tuple[list[dict[str, Any]], list[str]]:
    """Every run folder under ``OUT/runs`` (its config.yaml names the network, variant and seed), in
    network, variant (``variants``: a protocol's :attr:`~freespace.experiments.protocol.Protocol.vocabulary`,
    by default :data:`VARIANTS`) and seed order, with its test metrics (and those of further test sets,
    ``test_sets``) when finished; and the settings that differ between the runs (a table should compare
    like with like; the training data of a declared variant, its dataset, root, labels and subset lists, is
    compared among the variants of the same data only)."""
    from freespace.models import list_models

    vocabulary = variants or VARIANTS
    entries, settings = [], {}
    for run_dir in sorted((out / "runs").glob("*/config.yaml")):
        run_dir = run_dir.parent
        try:
            config = read_config_yaml(run_dir / "config.yaml")
        except FreespaceError as exc:
            log.warning("%s skipped: %s", run_dir, exc)
            continue
        cell = run_of(run_dir.name, vocabulary)
        spec = cell[1] if cell else None
        if spec is None or "model" not in config or spec.augment != config.get("augment", ()) or \
                (cell is not None and cell[0] != config["model"]):  # unet-r-auto-s0: no X-auto of a net unet-r
            log.warning("%s skipped: not a run folder of the protocol (<model>-<tag>-s<seed> with the variant's "
                        "augment; a protocol's own variants need its protocol file)", run_dir)
            continue
        entry: dict[str, Any] = {"run": str(run_dir.relative_to(out)), "model": config["model"],
                                 "variant": spec.name, "augment": augment_text(spec.augment),
                                 "seed": int(config.get("seed", 0)), "status": "unfinished"}
        if (run_dir / "metrics.json").is_file():
            metrics = read_metrics(run_dir / "metrics.json")
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
                if name in RESERVED_TEST_SETS:
                    continue
                extra = read_metrics(path)
                if isinstance(extra, str):
                    log.warning("%s skipped: %s", path, extra)
                    continue
                entry.setdefault("test_sets", {})[name] = {k: extra[k] for k in (*METRICS, "max_f", "ap")}
                settings.setdefault(f"the root of test set {name}", set()).add(json.dumps(extra.get("root")))
        of_data = f" of data {spec.data}" if spec.data is not None else ""  # each training data its own
        for key, value in _input_hashes(run_dir).items():  # runs of older versions recorded none
            settings.setdefault(f"the content of {key}{of_data}", set()).add(json.dumps(value))
        for key in ("dataset", "root", *(("labels", "splits_dir") if of_data else ()), "epochs", "patience",
                    "val_window", "min_delta", "lr", "batch_size", "max_frames", *_PER_NETWORK):
            value = config.get(key)
            if key in ("epochs", "patience") and isinstance(value, int):
                value //= spec.budget  # X-long's budget is part of the variant
            name = f"{key} of {config['model']}" if key in _PER_NETWORK else \
                f"{key}{of_data}" if key in ("dataset", "root", "labels", "splits_dir") else key
            settings.setdefault(name, set()).add(json.dumps(value))
        entries.append(entry)
    order = {m: i for i, m in enumerate(list_models())}
    names = list(vocabulary)
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


def _table(entries: list[dict[str, Any]], variants: dict[str, Variant] | None = None) -> list[dict[str, Any]]:
    """``results.csv`` rows: per network, variant (``variants`` order, by default :data:`VARIANTS`) and test
    set, ``n`` finished seeds and each metric's mean and std (ddof 1; 0 with one seed) in %."""
    rows = []
    for model in _models(entries):
        for test_set in _test_sets(entries):
            for name in variants or VARIANTS:
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


def _apart(a: str, b: str, test_set: str, variants: dict[str, Variant] | None) -> bool:
    """Whether the variants ``a`` and ``b`` are tested on other frames in ``test_set``: on ``test``, each
    variant's test split is its own training data's, so two declared variants of other data are not paired
    there (a further test set is the same frames for every variant)."""
    vocabulary = variants or VARIANTS
    return test_set == "test" and a in vocabulary and b in vocabulary and vocabulary[a].data != vocabulary[b].data


def _gains(entries: list[dict[str, Any]], gains: tuple[tuple[str, str], ...],
           variants: dict[str, Variant] | None = None) -> list[dict[str, Any]]:
    """``gains.csv`` rows: the paired ``gains`` (``(variant, versus)`` pairs, :attr:`Protocol.gains`) in points,
    over the seeds both variants finished; not on ``test`` between variants of other training data
    (:func:`_apart`)."""
    rows = []
    for model in _models(entries):
        for test_set in _test_sets(entries):
            for a, b in gains:
                if _apart(a, b, test_set, variants):
                    continue
                va, vb = _values(entries, model, a, test_set), _values(entries, model, b, test_set)
                seeds = sorted(set(va) & set(vb))
                if not seeds:
                    continue
                for k in GAIN_METRICS:
                    g = paired_gain([100 * va[s][k] for s in seeds], [100 * vb[s][k] for s in seeds])
                    rows.append(_gain_row(model, a, b, k, test_set, g))
    return rows + _averaged_gains(entries, gains, variants)


def _gain_row(network: str, a: str, b: str, metric: str, test_set: str, g: Any) -> dict[str, Any]:
    return {"network": network, "versus": f"{a} - {b}", "metric": metric, "test_set": test_set, "mean": g.mean,
            "ci_low": g.ci_low, "ci_high": g.ci_high, "n": g.n, "excludes_zero": g.excludes_zero}


def _averaged_gains(entries: list[dict[str, Any]], gains: tuple[tuple[str, str], ...],
                    variants: dict[str, Variant] | None = None) -> list[dict[str, Any]]:
    """Gains averaged over the networks (``network`` = :data:`ALL_NETWORKS`), with two or more networks:
    per seed, the mean over the networks of each variant's metric (the seeds every network finished in
    both variants), then the paired t-interval over those seeds. The primary endpoint is one of them."""
    models = _models(entries)
    if len(models) < 2:
        return []
    rows = []
    for test_set in _test_sets(entries):
        for a, b in gains:
            if _apart(a, b, test_set, variants):
                continue
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


def write_tables(out: PathLike, *, figures: int = 3, statuses: dict[str, str] | None = None,
                 protocol: Protocol | None = None) -> dict[str, Any]:
    """Rebuild ``index.json``, ``results.csv``, ``gains.csv``, ``results.md`` and (``figures`` > 0: test
    frames per figure) the figures from the run folders under ``OUT/runs``: the gains, primary endpoint and
    reference of ``protocol`` (None: the method's defaults, ``Protocol()``); ``statuses``: the status of runs
    by folder name (default ``"done"`` for a finished run).

    Returns ``{"table", "gains", "runs"}`` as :func:`~freespace.experiments.reproduce.reproduce`.

    Raises:
        InvalidOptionError: ``OUT/runs`` holds no run folder.
    """
    out = Path(out)
    protocol = Protocol() if protocol is None else protocol
    entries, differ = collect(out, statuses, protocol.vocabulary)
    if not entries:
        raise InvalidOptionError(f"{out / 'runs'} holds no run folders of `freespace reproduce`; nothing to collect")
    with claim_folder(out, "reproduce", entries=OUT_ENTRIES, shared=True):
        return _write_tables(out, entries, differ, figures, protocol)


def _write_tables(out: Path, entries: list[dict[str, Any]], differ: list[str], figures: int,
                  protocol: Protocol) -> dict[str, Any]:
    if differ:
        log.warning("the runs differ in %s", "; ".join(differ))
    vocabulary = protocol.vocabulary
    table, gains = _table(entries, vocabulary), _gains(entries, protocol.gains, vocabulary)
    write_json(out / "index.json", entries)
    fields = ["network", "variant", "test_set", "n"] + [f"{k}_{s}" for k in METRICS for s in ("mean", "std")]
    write_csv(out / "results.csv", fields, [{k: _cell(v) for k, v in r.items()} for r in table])
    write_csv(out / "gains.csv", ["network", "versus", "metric", "test_set", "mean", "ci_low", "ci_high", "n",
                                  "excludes_zero"], [{k: _cell(v) for k, v in r.items()} for r in gains])
    _write_markdown(out, entries, table, gains, differ, protocol)
    if figures > 0:
        for model in _models(entries):
            gain_figure(out, model, [g for g in gains if g["network"] == model])
            try:
                frames_figure(out, model, entries, figures, vocabulary)
            except FreespaceError as exc:  # a moved dataset, a damaged checkpoint: the tables stand without it
                log.warning("figures/%s.png skipped: %s", model, exc)
    return {"table": table, "gains": gains, "runs": entries}


def _write_markdown(out: Path, entries: list[dict[str, Any]], table: list[dict[str, Any]],
                    gains: list[dict[str, Any]], differ: list[str], protocol: Protocol) -> None:
    finished = sum("metrics" in e for e in entries)
    skipped = sum(e["status"].startswith("skipped") for e in entries)
    md = [f"Results of {finished} finished run{'s' if finished != 1 else ''} ({len(entries) - finished - skipped} "
          "unfinished" + (f", {skipped} skipped for unusable metrics.json" if skipped else "") + "): "
          + ("test set `test` = the test split of each variant's own training data (gains between variants of "
             "other data are not paired there), " if protocol.data else "test set `test` = the dataset's test split, ")
          + "any other = every labelled frame of the further test set of "
          "that name (`shifted` when it was given none); "
          "%, mean ± std over the `n` seeds finished (no std with one seed).", ""]
    if differ:
        md += [f"**Warning: the runs differ in {'; '.join(differ)}.**", ""]
    md += ["| Network | Variant | Test set | n | " + " | ".join(METRIC_NAMES.values()) + " |",
           "|---|---|---|---:|" + "---:|" * len(METRIC_NAMES)]
    for r in table:
        cells = [f"{r[k + '_mean']:.2f}" + (f" ± {r[k + '_std']:.2f}" if r["n"] > 1 else "") for k in METRIC_NAMES]
        md.append(f"| {r['network']} | {r['variant']} | {r['test_set']} | {r['n']} | " + " | ".join(cells) + " |")
    md += ["", "Paired gains in points (one difference per seed: the variants of a seed share the split and the "
           "initial weights), mean and 95 % Student t-interval over the `n` seeds (no interval with one seed)"
           + (f"; {protocol.reference}" if protocol.reference else "") + ".", "",
           "| Network | Gain | Metric | Test set | n | mean | 95 % t-interval | half-width | excludes 0 |",
           "|---|---|---|---|---:|---:|---:|---:|:---:|"]
    for g in gains:
        ci, half = ("—", "—") if math.isnan(g["ci_low"]) else \
            (f"[{g['ci_low']:+.2f}, {g['ci_high']:+.2f}]", f"{(g['ci_high'] - g['ci_low']) / 2:.2f}")
        md.append(f"| {g['network']} | {g['versus'].replace(' - ', ' − ')} | {METRIC_NAMES[g['metric']]} "
                  f"| {g['test_set']} | {g['n']} | {g['mean']:+.2f} | {ci} | {half} "
                  f"| {'yes' if g['excludes_zero'] else 'no'} |")
    md += _convergence_lines(entries, protocol.vocabulary) + _primary_lines(gains, protocol.primary)
    atomic_write_text(out / "results.md", "\n".join(md) + "\n")


def _convergence_lines(entries: list[dict[str, Any]], variants: dict[str, Variant] | None = None) -> list[str]:
    """results.md: per network and variant, the best and last epochs (1-based; mean, min–max) and how many
    runs early stopping ended against how many ran to the epoch cap."""
    lines = ["", "Convergence: best epoch (the checkpoint tested) and epochs run, mean (min–max) over the finished "
             "runs; stopped = early stopping fired (patience), cap = ran the most epochs allowed.", "",
             "| Network | Variant | n | best epoch | epochs run | stopped | cap |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for model in _models(entries):
        for name in variants or VARIANTS:
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


def _primary_lines(gains: list[dict[str, Any]], primary: Primary | None) -> list[str]:
    """results.md: the ``primary`` endpoint (:attr:`Protocol.primary`), when it was measured, against its
    margin."""
    if primary is None:
        return []
    versus = " - ".join(primary.versus)
    found = next((g for g in gains if g["network"] == ALL_NETWORKS and g["versus"] == versus
                  and g["metric"] == primary.metric and g["test_set"] == primary.test_set), None)
    if found is None or math.isnan(found["ci_low"]):
        return []
    m = primary.margin
    inside = -m <= found["ci_low"] and found["ci_high"] <= m
    verdict = (f"the interval lies inside ±{m:g}: equivalent within the margin" if inside else
               f"the interval leaves ±{m:g}: " + ("a difference" if found["excludes_zero"] else "not resolved"))
    return ["", f"**Primary endpoint** (named before the run): {versus.replace(' - ', ' − ')} "
            f"{METRIC_NAMES[primary.metric]} on `{primary.test_set}`, averaged over the networks: "
            f"{found['mean']:+.2f} points, 95 % t-interval [{found['ci_low']:+.2f}, {found['ci_high']:+.2f}] over "
            f"{found['n']} seeds; {verdict}."]
