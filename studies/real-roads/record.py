"""Record issue 70's fast cells and pair them with their controls (what sessions 40–46 did with scripts kept
outside the repository).

- ``cell``: a training run and its bench into a record folder (``runs-70/look/<name>/``): the run's
  ``config.yaml``, ``inputs.json``, ``metrics.csv``, ``metrics.json``, the dataset step's ``report.json`` as
  ``student.json``, and ``bench.json``: ``bench/real_bench.py``'s pooled figures of the one model it scored (its
  per-frame rows left out), with ``kitti_dev_wide9``: precision and recall pooled over the 9 KITTI frames of other
  streets with the most human road (the issue's wide frames).
- ``pair``: cells ``<cells>-s<seed>`` against ``<control>-s<seed>`` (record folders), seed by seed: each figure's
  differences in points, their mean and 95 % t interval (:func:`freespace.experiments.stats.paired_gain`), into
  ``paired.json`` under ``--key`` (other keys kept).
- ``shifted``: cells against a control that is not paired with them, on ``shifted.py``'s copies of KITTI's frames
  of other streets (``errors.py --sweep`` outputs): each model's F, its mean over the copies, and the difference of
  the two groups' means with a Welch t interval.

    python studies/real-roads/record.py cell --run RUN --bench BENCH.json --report REPORT.json --out DIR
    python studies/real-roads/record.py pair --cells DIR/poly288 --control DIR/lookall288 --seeds 0 1 2 \\
        --key lookall_poly_288x960 --paired DIR/paired.json
    python studies/real-roads/record.py shifted --sweep washed=W.json --sweep dark=D.json --cells A B C \
        --control X Y Z --out shifted.json
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np

from freespace.experiments.stats import paired_gain
from freespace.io.files import atomic_write_text

#: the bench's sets in the order a record gives them
ORDER = ("kitti2015", "kitti_dev", "kitti_dev_wide9", "camvid_val", "camvid_dusk", "camvid_pool", "polygons")
#: the issue's wide frames: the KITTI frames of other streets with the most human road
WIDE = 9
RUN_FILES = ("config.yaml", "inputs.json", "metrics.csv", "metrics.json")


def wide_frames(per_frame: list[dict], frames: int = WIDE) -> dict[str, float]:
    """Precision and recall (fractions) pooled over the ``frames`` rows of ``per_frame`` (the bench's rows, each with
    pixel counts ``tp``, ``fp``, ``fn``) with the most human road (``tp + fn``)."""
    rows = sorted(per_frame, key=lambda r: r["tp"] + r["fn"], reverse=True)[:frames]
    tp, fp, fn = (sum(r[c] for r in rows) for c in ("tp", "fp", "fn"))
    return {"frames": len(rows), "precision": tp / max(tp + fp, 1), "recall": tp / max(tp + fn, 1)}


def bench_summary(bench: dict, name: str) -> dict:
    """A record's ``bench.json`` from ``bench/real_bench.py``'s output: each set's figures of its one model."""
    sets = {}
    for key, per_model in bench["sets"].items():
        models = [m for m in per_model if not m.startswith("mean")]
        if len(models) != 1:
            raise ValueError(f"the bench scored {len(models)} models on {key}: record a bench of one --model")
        scores = per_model[models[0]]
        sets[key] = {k: v for k, v in scores.items() if k != "per_frame"}
        if key == "kitti_dev":
            sets["kitti_dev_wide9"] = wide_frames(scores["per_frame"])
    return {"model": name, "machine": bench.get("machine"), "sets": {k: sets[k] for k in ORDER if k in sets}}


def record_cell(run: Path, bench: Path, report: Path, out: Path) -> dict:
    """Write ``out`` (a new folder) from a run folder, its bench and its dataset's report; the summary written."""
    missing = [p for p in (*(run / f for f in RUN_FILES), bench, report) if not p.is_file()]
    if missing:
        raise ValueError(f"{missing[0]} is not a file: give a finished run, its bench's --out and the dataset's "
                         f"report.json")
    if out.exists():
        raise ValueError(f"{out} exists: a record is written once; choose another --out")
    summary = bench_summary(json.loads(bench.read_text()), out.name)
    part = out.with_name(out.name + ".part")
    shutil.rmtree(part, ignore_errors=True)
    part.mkdir(parents=True)
    for f in RUN_FILES:
        shutil.copy(run / f, part / f)
    shutil.copy(report, part / "student.json")
    (part / "bench.json").write_text(json.dumps(summary, indent=1) + "\n")
    part.rename(out)
    return summary


def figures(record: Path) -> dict[str, float]:
    """A record's figures in points: F of each set, KITTI other streets' precision and recall, the wide frames'."""
    sets = json.loads((record / "bench.json").read_text())["sets"]
    out = {k: sets[k]["f_score"] for k in ("kitti2015", "kitti_dev", "camvid_val", "camvid_dusk", "camvid_pool")}
    out |= {"kitti_dev_precision": sets["kitti_dev"]["precision"], "kitti_dev_recall": sets["kitti_dev"]["recall"],
            "wide9_recall": sets["kitti_dev_wide9"]["recall"], "wide9_precision": sets["kitti_dev_wide9"]["precision"]}
    return {k: 100 * v for k, v in out.items()}


def pair(cells: str, control: str, seeds: list[int]) -> dict:
    """Each figure of the records ``<cells>-s<seed>`` minus ``<control>-s<seed>``: differences, mean and 95 % t
    interval in points (2 decimals), with the two sides' figures (``look``: the cells', ``before``: the control's)."""
    got = {side: [figures(Path(f"{prefix}-s{s}")) for s in seeds] for side, prefix in (("a", cells), ("b", control))}
    out: dict = {"seeds": seeds}
    for k in got["a"][0]:
        a, b = [g[k] for g in got["a"]], [g[k] for g in got["b"]]
        gain = paired_gain(a, b)
        out[k] = {"differences": [round(x - y, 2) for x, y in zip(a, b)], "mean": round(gain.mean, 2),
                  "look": [round(x, 2) for x in a], "before": [round(x, 2) for x in b]}
        if len(seeds) > 1:
            out[k]["interval"] = [round(gain.ci_low, 2), round(gain.ci_high, 2)]
    return out


def welch(a: list[float], b: list[float], level: float = 0.95) -> tuple[float, float, float]:
    """``mean(a) − mean(b)`` with its Welch t interval (scipy's, unequal variances): two groups of cells that are
    not paired by seed (each of at least two values)."""
    from scipy.stats import ttest_ind

    ci = ttest_ind(a, b, equal_var=False).confidence_interval(level)
    return float(np.mean(a) - np.mean(b)), float(ci.low), float(ci.high)


def shifted(sweeps: dict[str, Path], cells: list[str], control: list[str]) -> dict:
    """KITTI's other streets' F at p ≥ 0.5 (points) of each model on each shifted copy (``{shift: errors.py --sweep
    output}``), each model's mean over the shifts, and the cells' mean minus the control's with :func:`welch`'s
    interval."""
    f = {}
    for name, path in sweeps.items():
        curves = json.loads(path.read_text())["sets"]["kitti_dev"]
        f[name] = {m: 100 * c["F"][c["th"].index(0.5)] for m, c in curves.items()}
    missing = [m for m in cells + control for name in f if m not in f[name]]
    if missing:
        raise ValueError(f"{missing[0]} was not scored in every sweep: sweep each model on each shifted copy")
    mean = {m: float(np.mean([f[name][m] for name in f])) for m in cells + control}
    diff, low, high = welch([mean[m] for m in cells], [mean[m] for m in control])
    return {"f_at_0.5": {name: {m: round(f[name][m], 2) for m in cells + control} for name in f},
            "mean_over_shifts": {m: round(v, 2) for m, v in mean.items()},
            "cells_minus_control": round(diff, 2), "interval": [round(low, 2), round(high, 2)]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    c = sub.add_parser("cell", help="a run and its bench into a record folder")
    for name in ("run", "bench", "report", "out"):
        c.add_argument(f"--{name}", type=Path, required=True)
    p = sub.add_parser("pair", help="cells against their control, seed by seed, into paired.json")
    p.add_argument("--cells", required=True, help="the cells' record folders without -s<seed>")
    p.add_argument("--control", required=True, help="the control's record folders without -s<seed>")
    p.add_argument("--seeds", type=int, nargs="+", required=True)
    p.add_argument("--key", required=True)
    p.add_argument("--paired", type=Path, required=True, help="paired.json (its other keys kept)")
    h = sub.add_parser("shifted", help="cells against a control on shifted copies (Welch), into a JSON file")
    h.add_argument("--sweep", action="append", required=True, metavar="SHIFT=FILE",
                   help="errors.py --sweep's output on one shifted copy; repeatable")
    h.add_argument("--cells", nargs="+", required=True, help="the cells' model names in the sweeps")
    h.add_argument("--control", nargs="+", required=True, help="the control's model names in the sweeps")
    h.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    if args.what == "shifted":
        sweeps = {k: Path(v) for k, v in (s.split("=", 1) for s in args.sweep if "=" in s)}
        if len(sweeps) != len(args.sweep) or not all(p.is_file() for p in sweeps.values()):
            ap.error("--sweep takes SHIFT=FILE, FILE an errors.py --sweep output")
        try:
            result = shifted(sweeps, args.cells, args.control)
        except ValueError as exc:
            ap.error(str(exc))
        atomic_write_text(args.out, json.dumps(result, indent=1) + "\n")
        print(result["mean_over_shifts"], result["cells_minus_control"], result["interval"])
        return
    if args.what == "cell":
        try:
            summary = record_cell(args.run, args.bench, args.report, args.out)
        except ValueError as exc:
            ap.error(str(exc))
        print({k: round(100 * v.get("f_score", v["recall"]), 2) for k, v in summary["sets"].items()})
        return
    missing = [f"{prefix}-s{s}" for prefix in (args.cells, args.control) for s in args.seeds
               if not Path(f"{prefix}-s{s}", "bench.json").is_file()]
    if missing:
        ap.error(f"{missing[0]} holds no bench.json: record the cell first (record.py cell)")
    table = json.loads(args.paired.read_text()) if args.paired.is_file() else {}
    table[args.key] = pair(args.cells, args.control, args.seeds)
    atomic_write_text(args.paired, json.dumps(table, indent=1) + "\n")
    for k, v in table[args.key].items():
        print(k, v)


if __name__ == "__main__":
    main()
