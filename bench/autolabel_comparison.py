"""Training on labels nobody drew (issue 22 §3): X (human labels), X-auto (autolabels only) and X-mix (human
labels on 20 % of the training drives, autolabels on the rest), from the tables of a `reproduce` folder.

It reads only the folder's `results.csv`, `gains.csv`, `index.json` and the runs' metrics (no training, no
checkpoints), so it rebuilds the BENCHMARKS.md section from the committed results of the converged run. With
`--auto2 DIR` (default `res-auto2` beside `--res`, when it exists) it adds X-auto trained on the autolabels of
the padded matcher (SGBM version 2), paired by seed with X and X-auto of `--res`:

    .venv/bin/python bench/autolabel_comparison.py [--res studies/converged/res-final] [--auto2 DIR] [--write]
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from statistics import median

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import write_section  # noqa: E402
from freespace.experiments.stats import paired_gain  # noqa: E402

VARIANTS = ("X", "X-auto", "X-mix")
GAINS = ("X-auto - X", "X-mix - X", "X-mix - X-auto")
TEST_SETS = ("test", "same-rigs", "shifted", "matched")


def read_csv(path: Path) -> list[dict[str, str]]:
    """The rows of a CSV file with a header, as dicts."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def tables(res: Path) -> tuple[str, str, str, list[str]]:
    """(F table, gains table, epochs and time table, networks) of the X / X-auto / X-mix runs in ``res``."""
    results = [r for r in read_csv(res / "results.csv") if r["variant"] in VARIANTS]
    nets = sorted({r["network"] for r in results if r["variant"] == "X-auto"})
    f_rows = ["| network | test set | " + " | ".join(f"{v} F (n)" for v in VARIANTS) + " |",
              "|---|---|" + "---:|" * len(VARIANTS)]
    by_key = {(r["network"], r["variant"], r["test_set"]): r for r in results}
    for net in nets:
        for test_set in TEST_SETS:
            cells = []
            for v in VARIANTS:
                r = by_key.get((net, v, test_set))
                cells.append(f"{float(r['f_score_mean']):.2f} ± {float(r['f_score_std']):.2f} ({r['n']})" if r else "—")
            f_rows.append(f"| {net} | {test_set} | " + " | ".join(cells) + " |")

    gains = [g for g in read_csv(res / "gains.csv")
             if g["network"] in nets and g["versus"] in GAINS and g["metric"] == "f_score"]
    g_rows = ["| network | gain | test set | n | mean | 95 % t-interval | excludes 0 |",
              "|---|---|---|---:|---:|---:|:---:|"]
    for net in nets:
        for versus in GAINS:
            for test_set in TEST_SETS:
                for g in gains:
                    if (g["network"], g["versus"], g["test_set"]) == (net, versus, test_set):
                        ci = (f"[{float(g['ci_low']):+.2f}, {float(g['ci_high']):+.2f}]" if g["ci_low"] else "—")
                        g_rows.append(f"| {net} | {versus.replace(' - ', ' − ')} | {test_set} | {g['n']} | "
                                      f"{float(g['mean']):+.2f} | {ci} | "
                                      f"{'yes' if g['excludes_zero'] == 'true' else 'no'} |")

    index = [e for e in json.loads((res / "index.json").read_text())
             if e["model"] in nets and e["variant"] in VARIANTS and e["status"] == "done"]
    e_rows = ["| network | variant | runs | best / stop epoch, per seed | stopped by patience | "
              "median training time per run (min) |", "|---|---|---:|---|---:|---:|"]
    for net in nets:
        for v in VARIANTS:
            runs = sorted((e for e in index if e["model"] == net and e["variant"] == v), key=lambda e: e["seed"])
            if not runs:
                continue
            epochs = ", ".join(f"s{e['seed']} {e['best_epoch']}/{e['epochs_run']}" for e in runs)
            minutes = [sum(float(row["seconds"]) for row in read_csv(res / e["run"] / "metrics.csv")) / 60
                       for e in runs]
            patience = sum(e["stopped_by"] == "patience" for e in runs)
            e_rows.append(f"| {net} | {v} | {len(runs)} | {epochs} | {patience} | {median(minutes):.0f} |")
    return "\n".join(f_rows), "\n".join(g_rows), "\n".join(e_rows), nets


def f_score(run: Path, test_set: str) -> float | None:
    """A finished run's F-score in points on ``test_set`` (``test``: the run's own split), None if not tested."""
    path = run / ("metrics.json" if test_set == "test" else f"{test_set}/metrics.json")
    return 100 * json.loads(path.read_text())["f_score"] if path.is_file() else None


def auto2_table(res: Path, auto2: Path) -> str:
    """X-auto on the padded matcher's autolabels (``auto2``) against X and X-auto (``res``), paired by seed."""
    rows = ["| network | gain | test set | n | mean | 95 % t-interval | excludes 0 |",
            "|---|---|---|---:|---:|---:|:---:|"]
    for net in sorted({p.name.split("-auto-s")[0] for p in auto2.glob("runs/*-auto-s*")}):
        for other, tag in (("X", "orig"), ("X-auto", "auto")):
            for test_set in TEST_SETS:
                pairs = []
                for run in sorted(auto2.glob(f"runs/{net}-auto-s*")):
                    a = f_score(run, test_set)
                    b = f_score(res / "runs" / run.name.replace("-auto-", f"-{tag}-"), test_set)
                    if a is not None and b is not None:
                        pairs.append((a, b))
                if not pairs:
                    continue
                g = paired_gain([a for a, _ in pairs], [b for _, b in pairs])
                ci = f"[{g.ci_low:+.2f}, {g.ci_high:+.2f}]" if np.isfinite(g.ci_low) else "—"
                rows.append(f"| {net} | X-auto (SGBM 2) − {other} | {test_set} | {g.n} | {g.mean:+.2f} | {ci} | "
                            f"{'yes' if g.excludes_zero else 'no'} |")
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--res", type=Path, default=Path("studies/converged/res-final"),
                        help="a reproduce folder with its tables (results.csv, gains.csv, index.json)")
    parser.add_argument("--auto2", type=Path, help="a reproduce folder of X-auto cells trained on the padded "
                        "matcher's autolabels (default: res-auto2 beside --res, if there)")
    parser.add_argument("--write", action="store_true", help="put the tables into BENCHMARKS.md")
    args = parser.parse_args()
    f_table, g_table, e_table, nets = tables(args.res)
    auto2 = args.auto2 or args.res.parent / "res-auto2"
    a_table = auto2_table(args.res, auto2) if (auto2 / "runs").is_dir() else ""
    print(f_table, g_table, e_table, a_table, sep="\n\n")
    a_section = "" if not a_table else f"""
X-auto trained on the autolabels of the padded matcher (SGBM version 2: 76.9 % of the training pixels
covered instead of 68.6 %, precision 98.6 %; `freespace autolabel --dataset synth --root syn
--disparity-source sgbm --out autolabels2` at ca4bddf or later, then `RES=res-auto2 AUTOLABELS=autolabels2
CELLS=... bash run.sh WORK`), paired by seed with X and with X-auto on the version-1 autolabels above:

{a_table}
"""
    if args.write:
        write_section("Training on labels nobody drew (issue 22)", f"""
{" and ".join(nets)} (EfficientNet-Lite0, ImageNet), trained as in the converged run (issue 23: SGD lr 0.01,
batch 2, early stopping with patience 20 on the 3-epoch mean validation F, cap 200) on the 60 training frames
of a seed with three label sets: **X** the human labels, **X-auto** the autolabels only (`freespace
autolabel` on SGBM disparities of the rendered pairs: no human label and no exact disparity), **X-mix** the
human labels on 20 % of the training drives and autolabels on the rest. Validation and test use the human
labels; don't care pixels are ignored by the loss. Gains are paired by seed (the variants of a seed share the
split and the initial weights), F-score points, 95 % Student t-intervals. The cells ran on 2-core Intel Xeon
(AVX-512) and AMD EPYC machines, two cells at a time with one thread each; the rendered data of every machine
pass `studies/converged/datacheck.py`.

    NETS="unet dupsampling" VARIANTS="X X-auto X-mix" PATIENCE=20 CAP=200 LR=0.01 MIN_DELTA=0.001 \\
        bash studies/converged/run.sh WORK          # or, for one cell:
    freespace reproduce --dataset synth --root syn --autolabels autolabels --models unet,dupsampling \\
        --variants X,X-auto,X-mix \\
        --test-root shifted=shifted --test-root matched=matched --test-root same-rigs=same-rigs --seeds 10 \\
        --epochs 200 --patience 20 --val-window 3 --min-delta 0.001 --lr 0.01 --batch-size 2 \\
        --image-size 192x256 --encoder-name efficientnet-lite0 --encoder-weights imagenet --out res-final
    .venv/bin/python bench/autolabel_comparison.py --write

F-score on the human labels, mean ± SD over the seeds (n runs):

{f_table}

Paired gains:

{g_table}

Convergence and cost (best: the epoch whose checkpoint was tested, the highest 3-epoch mean validation F;
stop: the last epoch, 20 after the last rise of that mean by more than 0.1 point; training time from the
runs' per-epoch seconds, which depend on the machine and on the cell beside it):

{e_table}
{a_section}""")


if __name__ == "__main__":
    main()
