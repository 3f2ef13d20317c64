"""The figures of ``reproduce``: ``figures/gains_<model>.png`` (each paired gain with its 95 % t-interval) and
``figures/<model>.png`` (a few test frames: each variant's predictions coloured TP green / FN red / FP blue),
both written atomically into ``OUT/figures/``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from freespace.engine.config import read_config_yaml
from freespace.experiments.variants import GAIN_METRICS, METRIC_NAMES, VARIANTS, Variant
from freespace.io.codecs import write_image
from freespace.io.files import atomic_write_bytes

__all__ = ["gain_figure", "frames_figure"]


def gain_figure(out: Path, model: str, gains: list[dict[str, Any]]) -> None:
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
        ax.set_xlabel(f"{METRIC_NAMES[k]} gain (points)")
        ax.grid(True, axis="x", alpha=0.3)
    axes[0][0].set_yticks(range(len(labels)), labels)
    axes[0][0].invert_yaxis()
    fig.suptitle(f"{model}: paired gains, mean and 95 % t-interval over seeds", fontsize=10)
    buf = _io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(out / "figures" / f"gains_{model}.png", buf.getvalue())


def frames_figure(out: Path, model: str, entries: list[dict[str, Any]], frames: int,
                  variants: dict[str, Variant] | None = None) -> None:
    """``figures/<model>.png``: test frames of seed 0 — image, then each finished variant's prediction
    (TP/FN/FP against the labels the runs were measured on: the dataset's, or the label tree of the runs'
    ``labels``; the prediction alone, magenta, where a frame has neither), X first: the test frames of the first
    of ``variants`` (by default :data:`VARIANTS`, whose first is X; a protocol's
    :attr:`~freespace.experiments.protocol.Protocol.vocabulary`)."""
    vocabulary = variants or VARIANTS
    first = next(iter(vocabulary))
    from freespace.data.label_tree import apply_label_tree
    from freespace.data.registry import get_dataset
    from freespace.data.splits import read_splits
    from freespace.evaluation.viz import caption, grid, overlay_errors, overlay_road
    from freespace.inference.predictor import Predictor

    runs = {e["variant"]: out / e["run"] for e in entries
            if e["model"] == model and e["seed"] == 0 and (out / e["run"] / "checkpoints" / "best.ckpt").is_file()
            and "metrics" in e}
    if first not in runs or len(runs) < 2 or frames < 1:
        return
    config = read_config_yaml(runs[first] / "config.yaml")
    ds = get_dataset(config["dataset"], config["root"], config.get("split"), disparity_source="none")
    names = read_splits(runs[first] / "splits")["test"][:frames]
    tree = config.get("labels")
    if tree and Path(tree).is_dir():  # the runs were measured on a label tree (e.g. autolabels of raw drives)
        labelled = [n for n in names if (Path(tree) / f"{n}.png").is_file()]
        ds = apply_label_tree(ds, tree, labelled)
    predictors = {v: Predictor(checkpoint=r / "checkpoints" / "best.ckpt") for v, r in runs.items()}
    rows = []
    for name in names:
        s = ds.load(ds.index(name), right=False, disparity=False)
        row = [caption(s.left, name)]
        for v, predictor in predictors.items():
            pred = predictor.predict([s.left])[0] >= 0.5
            shown = overlay_road(s.left, pred) if s.label is None else overlay_errors(s.left, pred, s.label.road,
                                                                                      s.label.valid)
            row.append(caption(shown, vocabulary[v].label(model)))
        rows.append(row)
    write_image(out / "figures" / f"{model}.png", grid(rows, width=min(480, rows[0][0].shape[1])))
