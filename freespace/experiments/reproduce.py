"""`freespace reproduce`: the paper's protocol on one dataset.

Every chosen network is trained on the original training set (X) and on the set augmented with the
DS-Generator views (HA-X), with the same seeds, splits, budget and early stopping, and tested on the test
split. ``OUT`` receives ``runs/<model>-<variant>-s<seed>/`` (training run folders), ``results.md`` and
``results.csv`` (one row per network and variant: accuracy, precision, recall, F-score, IoU as mean ± std
over seeds in %, and the HA gain), ``figures/<model>.png`` (a few test frames: original vs HA
predictions coloured TP green / FN red / FP blue) and ``index.json`` (every run, its status and metrics).
Finished runs are skipped when the command is run again; interrupted ones resume.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

from freespace.engine.config import TrainConfig
from freespace.errors import InvalidOptionError
from freespace.io import PathLike, atomic_write_text, write_csv, write_image, write_json

log = logging.getLogger(__name__)

__all__ = ["reproduce", "VARIANTS", "METRICS"]

VARIANTS = ("none", "homography")
METRICS = ("accuracy", "precision", "recall", "f_score", "iou")
PAPER_GAINS = "the paper: F-score +1.5 to +5.0, IoU +2.8 to +7.3 points"


def _name(model: str, variant: str, seed: int) -> str:
    return f"{model}-{'ha' if variant == 'homography' else 'orig'}-s{seed}"


#: more seeds than this is a typo, not an experiment (each seed trains every network and variant)
MAX_SEEDS = 1000


def reproduce(dataset: str, root: PathLike, out: PathLike, *, models: list[str], seeds: int = 3, epochs: int = 50,
              image_size: tuple[int, int] | None = None, patience: int = 10, batch_size: int = 4, workers: int = 0,
              max_frames: int | None = None, figures: int = 3, progress: bool = True) -> dict[str, Any]:
    """Run the protocol (see the module docstring) and return ``{"table": rows, "runs": index}``."""
    from freespace.engine.train import run_training
    from freespace.models import list_models

    unknown = [m for m in models if m not in list_models()]
    if unknown or not models:
        raise InvalidOptionError(f"unknown models {unknown}; choose from {', '.join(list_models())} or all")
    if not 1 <= seeds <= MAX_SEEDS:
        raise InvalidOptionError(f"--seeds must be in 1…{MAX_SEEDS}, got {seeds}")
    out = Path(out)
    index: list[dict[str, Any]] = []
    results: dict[tuple[str, str], list[dict[str, float]]] = {}
    for model in models:
        for variant in VARIANTS:
            for seed in range(seeds):
                run_dir = out / "runs" / _name(model, variant, seed)
                config = TrainConfig(dataset=dataset, root=str(root), out=str(run_dir), model=model, augment=variant,
                                     epochs=epochs, batch_size=batch_size, patience=patience, image_size=image_size,
                                     seed=seed, workers=workers, max_frames=max_frames)
                config.check()
                entry = {"run": str(run_dir.relative_to(out)), "model": model, "variant": variant, "seed": seed}
                if (run_dir / "metrics.json").is_file():
                    metrics = json.loads((run_dir / "metrics.json").read_text())
                    entry["status"] = "done (skipped)"
                else:
                    resume = (run_dir / "checkpoints" / "last.ckpt").is_file()
                    log.info("training %s (%s)", run_dir.name, "resuming" if resume else "new")
                    metrics = run_training(config, resume=resume, progress=progress)
                    entry["status"] = "done"
                entry["metrics"] = {k: metrics[k] for k in (*METRICS, "max_f", "ap")}
                index.append(entry)
                results.setdefault((model, variant), []).append(entry["metrics"])
                write_json(out / "index.json", index)
                _write_tables(out, _table(models, results), dataset, seeds)  # the table so far, after every run
    table = _table(models, results)
    for model in models:
        _figure(out, model, dataset, root, figures)
    return {"table": table, "runs": index}


def _table(models: list[str], results: dict[tuple[str, str], list[dict[str, float]]]) -> list[dict[str, Any]]:
    """Rows X and HA-X per network (mean ± std over the finished seeds); the gain once both exist."""
    rows = []
    for model in models:
        means = {}
        for variant in VARIANTS:
            runs = results.get((model, variant))
            if not runs:
                continue
            row: dict[str, Any] = {"network": ("HA-" if variant == "homography" else "") + model, "seeds": len(runs)}
            for k in METRICS:
                vals = 100 * np.array([r[k] for r in runs])
                row[k] = float(vals.mean())
                row[f"{k}_std"] = float(vals.std(ddof=1)) if len(vals) > 1 else 0.0
            means[variant] = row
            rows.append(row)
        if len(means) == 2:
            rows[-1]["gain_f_score"] = means["homography"]["f_score"] - means["none"]["f_score"]
            rows[-1]["gain_iou"] = means["homography"]["iou"] - means["none"]["iou"]
    return rows


def _write_tables(out: Path, rows: list[dict[str, Any]], dataset: str, seeds: int) -> None:
    names = {"accuracy": "Accuracy", "precision": "Precision", "recall": "Recall", "f_score": "F-score", "iou": "IoU"}
    md = [f"Results on `{dataset}` (test split, %, mean ± std over up to {seeds} seed{'s' if seeds > 1 else ''}, "
          f"column `n` = seeds finished); "
          f"HA gain = HA-X − X in points ({PAPER_GAINS}).", "",
          "| Network | n | " + " | ".join(names.values()) + " | HA gain F | HA gain IoU |",
          "|---|---:|" + "---:|" * (len(names) + 2)]
    for r in rows:
        cells = [f"{r[k]:.2f} ± {r[k + '_std']:.2f}" for k in names]
        gains = [f"{r['gain_f_score']:+.2f}", f"{r['gain_iou']:+.2f}"] if "gain_f_score" in r else ["", ""]
        md.append(f"| {r['network']} | {r['seeds']} | " + " | ".join(cells + gains) + " |")
    atomic_write_text(out / "results.md", "\n".join(md) + "\n")
    fields = ["network", "seeds"] + [x for k in METRICS for x in (k, f"{k}_std")] + ["gain_f_score", "gain_iou"]
    write_csv(out / "results.csv", fields,
              [{k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows])


def _figure(out: Path, model: str, dataset: str, root: PathLike, frames: int) -> None:
    """``figures/<model>.png``: test frames of seed 0 — image, X prediction, HA-X prediction (TP/FN/FP)."""
    from freespace.data.registry import get_dataset
    from freespace.data.splits import read_splits
    from freespace.predictor import Predictor
    from freespace.viz import caption, grid, overlay_errors

    runs = {v: out / "runs" / _name(model, v, 0) for v in VARIANTS}
    ckpts = {v: r / "checkpoints" / "best.ckpt" for v, r in runs.items()}
    if not all(c.is_file() for c in ckpts.values()) or frames < 1:
        return
    ds = get_dataset(dataset, root, disparity_mode="none")
    names = read_splits(runs["none"] / "splits")["test"][:frames]
    predictors = {v: Predictor(checkpoint=c) for v, c in ckpts.items()}
    rows = []
    for name in names:
        s = ds.load(ds.index(name), right=False, disparity=False)
        row = [caption(s.left, name)]
        for v, label in (("none", model), ("homography", f"HA-{model}")):
            pred = predictors[v].predict([s.left])[0] >= 0.5
            row.append(caption(overlay_errors(s.left, pred, s.label.road, s.label.valid), label))
        rows.append(row)
    write_image(out / "figures" / f"{model}.png", grid(rows, width=min(480, rows[0][0].shape[1])))

