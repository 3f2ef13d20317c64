"""The effect of ImageNet pretraining on X, beside HA's gains (issue 23 §3): the converged run's control.

``python pretraining.py RES SCRATCH [--csv OUT.csv]``: ``RES`` is the converged run's reproduce folder (X with
the Lite0 encoders' ImageNet weights, and HA-X, X-dup, X-long), ``SCRATCH`` the control's (X with the same
encoders from random weights: ``RES=res-scratch WEIGHTS= run.sh``). For each network in both and each test set,
the paired gain X(ImageNet) − X(scratch) in F-score points over the seeds both ran (the two runs of a seed
share its split, data order and decoder initialisation; only the encoder's starting weights differ), with its
95 % t-interval, and beside it HA-X − X-dup and HA-X − X from ``RES/gains.csv`` (their own seeds). Printed as a
Markdown table; ``--csv`` also writes it.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import Any

from freespace.experiments.stats import paired_gain
from freespace.io.files import write_csv

sys.path.insert(0, str(Path(__file__).resolve().parent))
from forecast import markdown  # noqa: E402  (the table printer of the script beside this one)

TEST_SETS = ("test", "same-rigs", "shifted")
BESIDE = ("HA-X - X-dup", "HA-X - X")


def _x_f_scores(res: Path) -> dict[tuple[str, str], dict[int, float]]:
    """``{(network, test set): {seed: F-score in points}}`` of the finished X runs in ``res/index.json``
    (``test`` is the run's own test split)."""
    out: dict[tuple[str, str], dict[int, float]] = {}
    for e in json.loads((res / "index.json").read_text()):
        if e.get("variant") != "X" or e.get("status") != "done":
            continue
        scores = {"test": e["metrics"]} | e.get("test_sets", {})
        for name, m in scores.items():
            out.setdefault((e["model"], name), {})[int(e["seed"])] = 100.0 * float(m["f_score"])
    return out


def _interval(mean: float, low: float, high: float, n: int) -> str:
    return f"{mean:+.2f} [{low:+.2f}, {high:+.2f}] (n = {n})" if n >= 2 else f"{mean:+.2f} (n = {n})"


def pretraining_table(res: Path, scratch: Path) -> list[dict[str, Any]]:
    """One row per network (in both folders) and test set (:data:`TEST_SETS`): mean F of X with ImageNet
    weights and from scratch over the shared seeds, the paired gain with its interval, and :data:`BESIDE`'s
    gains from ``res/gains.csv``."""
    pre, scr = _x_f_scores(res), _x_f_scores(scratch)
    with (res / "gains.csv").open(newline="") as f:
        gains = {(g["network"], g["versus"], g["test_set"]): g for g in csv.DictReader(f)
                 if g["metric"] == "f_score"}
    rows = []
    for model in sorted({m for m, _ in pre} & {m for m, _ in scr}):
        for test_set in TEST_SETS:
            seeds = sorted(set(pre.get((model, test_set), {})) & set(scr.get((model, test_set), {})))
            if not seeds:
                continue
            a, b = [pre[model, test_set][s] for s in seeds], [scr[model, test_set][s] for s in seeds]
            g = paired_gain(a, b)
            row = {"network": model, "test set": test_set, "seeds": ",".join(map(str, seeds)),
                   "X ImageNet": f"{sum(a) / len(a):.2f}", "X scratch": f"{sum(b) / len(b):.2f}",
                   "ImageNet − scratch": _interval(g.mean, g.ci_low, g.ci_high, g.n)}
            for versus in BESIDE:
                h = gains.get((model, versus, test_set))
                row[versus.replace(" - ", " − ")] = (_interval(float(h["mean"]), float(h["ci_low"] or "nan"),
                                                               float(h["ci_high"] or "nan"), int(h["n"]))
                                                     if h else "")
            rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("res", type=Path, help="the converged run's reproduce folder (X with ImageNet weights)")
    parser.add_argument("scratch", type=Path, help="the control's reproduce folder (X from scratch)")
    parser.add_argument("--csv", type=Path, help="also write the table here")
    args = parser.parse_args()
    for folder, name in ((args.res, "index.json"), (args.res, "gains.csv"), (args.scratch, "index.json")):
        if not (folder / name).is_file():
            raise SystemExit(f"{folder} holds no {name}: give a reproduce folder whose tables are built")
    inputs = {(f / n).resolve() for f in (args.res, args.scratch) for n in ("index.json", "gains.csv")}
    if args.csv and args.csv.resolve() in inputs:
        raise SystemExit(f"--csv {args.csv} is one of the inputs: give another file")
    rows = pretraining_table(args.res, args.scratch)
    if not rows:
        raise SystemExit(f"no network has finished X runs of the same seed in {args.res} and {args.scratch}")
    print(markdown(rows))
    if args.csv:
        write_csv(args.csv, list(rows[0]), rows)


if __name__ == "__main__":
    main()
