"""HA-X − X split into the steps and the views (issue 47): the decomposition at two sets of seeds, side by side.

``python decomposition.py RES [--networks deeplabv3plus,dupsampling,unet] [--seeds 0-4 --seeds 0-9] [--csv OUT]``:
``RES`` is the converged run's reproduce folder (its ``index.json``). For each test set (``same-rigs``,
``shifted``), each gain of :data:`GAINS` and each set of seeds, the paired gain in F-score points with its 95 %
t-interval, per network and averaged over the networks (one mean of the networks' differences per seed, then
the interval over the seeds). A seed enters a set only where every variant of the gain has finished for that
network (for the average: for every network), so ``n`` says how many pairs stand behind each figure.

The average over the three pretrained networks (the default ``--networks``) is a subgroup: the networks were
chosen for the seeds 5–9 of X and X-long after the five-network results were seen (issue 47), so its intervals
are labelled so and are not the primary endpoint (that is ``gains.csv``'s five-network ``same-rigs`` row).
Printed as a Markdown table; ``--csv`` also writes it. ``--steps`` adds the optimiser steps each variant took
before stopping (the budget is equal, the steps taken are not: issue 47's item 5): per set of seeds the median
epochs and steps of each variant over the networks' finished cells, and seed by seed the ratios of HA-X's steps to
X-long's and to X-dup's (their range and median).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

from freespace.experiments.stats import paired_gain
from freespace.io.codecs import load_yaml
from freespace.io.files import write_csv

sys.path.insert(0, str(Path(__file__).resolve().parent))
from forecast import markdown  # noqa: E402  (the table printer of the script beside this one)

TEST_SETS = ("same-rigs", "shifted")
# (a, b): the gain a − b; X-long − X is the extra steps alone, HA-X − X-long the views with the second
# augmentation draw at the same budget of steps, X-dup − X-long a frame twice in an epoch against a second epoch
GAINS = (("X-long", "X"), ("HA-X", "X-long"), ("X-dup", "X-long"), ("HA-X", "X"), ("HA-X", "X-dup"))
PRETRAINED = ("deeplabv3plus", "dupsampling", "unet")

Scores = dict[tuple[str, str, str], dict[int, float]]  # (network, variant, test set) -> {seed: F in points}


def f_scores(index: list[dict]) -> Scores:
    """The F-score (points) of every finished run of a reproduce ``index.json`` (a list of its entries), by
    network, variant and test set (the run's own ``test`` split included)."""
    out: Scores = {}
    for e in index:
        if e.get("status") != "done":
            continue
        for name, m in ({"test": e["metrics"]} | e.get("test_sets", {})).items():
            out.setdefault((e["model"], e["variant"], name), {})[int(e["seed"])] = 100.0 * float(m["f_score"])
    return out


def steps_taken(res: Path, index: list[dict]) -> dict[tuple[str, str], dict[int, tuple[int, int]]]:
    """(network, variant) → {seed: (epochs run, optimiser steps)} of every finished run of a reproduce folder
    ``res`` and its ``index.json`` entries ``index``. Steps = epochs × ⌈training frames / batch⌉ (the training
    loader keeps a last short batch), the frames from the run's ``metrics.json``, the batch from its
    ``config.yaml``; an X-long continued from X counts X's epochs too (it is one run)."""
    out: dict[tuple[str, str], dict[int, tuple[int, int]]] = {}
    for e in index:
        if e.get("status") != "done":
            continue
        run = res / e["run"]
        frames = json.loads((run / "metrics.json").read_text())["frames"]["train"]
        batch = int(load_yaml(run / "config.yaml")["batch_size"])
        epochs = int(e["epochs_run"])
        out.setdefault((e["model"], e["variant"]), {})[int(e["seed"])] = (epochs, epochs * math.ceil(frames / batch))
    return out


def steps_table(steps: dict[tuple[str, str], dict[int, tuple[int, int]]], networks: list[str],
                seed_sets: list[list[int]]) -> list[dict[str, str]]:
    """Rows ``variant`` (the median epochs and steps over the networks' cells of each seed set) and ``HA-X /
    X-long``, ``HA-X / X-dup`` (the steps' ratio of each network and seed where both finished: range, median)."""
    labels = _labels(seed_sets)
    rows = []
    for variant in ("X", "X-long", "X-dup", "HA-X"):
        row = {"variant or ratio": variant}
        for label, seeds in zip(labels, seed_sets):
            cells = [steps[n, variant][s] for n in networks for s in seeds if s in steps.get((n, variant), {})]
            row[label] = (f"{statistics.median(c[0] for c in cells):g} epochs, "
                          f"{statistics.median(c[1] for c in cells):g} steps (n = {len(cells)})" if cells else "")
        rows.append(row)
    for other in ("X-long", "X-dup"):
        row = {"variant or ratio": f"HA-X / {other}"}
        for label, seeds in zip(labels, seed_sets):
            r = [steps[n, "HA-X"][s][1] / steps[n, other][s][1] for n in networks for s in seeds
                 if s in steps.get((n, "HA-X"), {}) and s in steps.get((n, other), {})]
            row[label] = f"{min(r):.2f}–{max(r):.2f}, median {statistics.median(r):.2f} (n = {len(r)})" if r else ""
        rows.append(row)
    return rows


def seed_range(text: str) -> list[int]:
    """``"0-4"`` → ``[0, 1, 2, 3, 4]``; ``"0,2,5"`` → ``[0, 2, 5]``."""
    try:
        if "-" in text:
            lo, hi = (int(v) for v in text.split("-"))
            return list(range(lo, hi + 1))
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"seeds {text!r}: give a range such as 0-4 or a list such as 0,2,5")


def _cell(diffs: list[float]) -> str:
    if not diffs:
        return ""
    g = paired_gain(diffs, [0.0] * len(diffs))
    return (f"{g.mean:+.2f} [{g.ci_low:+.2f}, {g.ci_high:+.2f}] (n = {g.n})" if g.n >= 2
            else f"{g.mean:+.2f} (n = {g.n})")


def _labels(seed_sets: list[list[int]]) -> list[str]:
    return [f"seeds {s[0]}–{s[-1]}" if s == list(range(s[0], s[-1] + 1)) else "seeds " + ",".join(map(str, s))
            for s in seed_sets]


def decomposition(scores: Scores, networks: list[str], seed_sets: list[list[int]]) -> list[dict[str, str]]:
    """One row per test set, gain and network (and ``mean of N`` over ``networks``, ``(subgroup)`` when the run
    has more networks), one column per seed set.

    A network's cell pairs the seeds of the set where both variants finished; the mean's cell the seeds where
    both finished for every network, each seed's value the mean of the networks' differences."""
    labels = _labels(seed_sets)
    # the mean over fewer networks than the run has is a subgroup (the three pretrained ones were chosen after
    # the five-network results were seen); over all of them it is the run's own average
    mean = f"mean of {len(networks)}" + (" (subgroup)" if set(networks) < {k[0] for k in scores} else "")
    rows = []
    for test_set in TEST_SETS:
        for a, b in GAINS:
            diff = {n: {s: scores[n, a, test_set][s] - scores[n, b, test_set][s]
                        for s in set(scores.get((n, a, test_set), {})) & set(scores.get((n, b, test_set), {}))}
                    for n in networks}
            for name in [*networks, mean]:
                row = {"test set": test_set, "gain": f"{a} − {b}", "network": name}
                for label, seeds in zip(labels, seed_sets):
                    if name in diff:
                        row[label] = _cell([diff[name][s] for s in seeds if s in diff[name]])
                    else:
                        row[label] = _cell([sum(diff[n][s] for n in networks) / len(networks) for s in seeds
                                            if all(s in diff[n] for n in networks)])
                rows.append(row)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("res", type=Path, help="the converged run's reproduce folder (holds index.json)")
    parser.add_argument("--networks", default=",".join(PRETRAINED), help="comma-separated networks")
    parser.add_argument("--seeds", type=seed_range, action="append",
                        help="a set of seeds (0-4, or 0,2,5); repeat for columns (default: 0-4 and 0-9)")
    parser.add_argument("--csv", type=Path, help="also write the table here")
    parser.add_argument("--steps", action="store_true", help="also print the optimiser steps taken per variant")
    args = parser.parse_args()
    index = args.res / "index.json"
    if not index.is_file():
        raise SystemExit(f"{args.res} holds no index.json: give a reproduce folder whose tables are built")
    if args.csv and args.csv.resolve() == index.resolve():
        raise SystemExit(f"--csv {args.csv} is the input: give another file")
    try:
        entries = json.loads(index.read_text())
        scores = f_scores(entries)
    except (ValueError, KeyError, TypeError) as e:
        raise SystemExit(f"{index} is not a reproduce index ({e}): rebuild it with reproduce --tables")
    networks = [n for n in args.networks.split(",") if n]
    missing = [n for n in networks if not any(k[0] == n for k in scores)]
    if missing:
        raise SystemExit(f"no finished run of {', '.join(missing)} in {index}: check --networks")
    seed_sets = args.seeds or [list(range(5)), list(range(10))]
    rows = decomposition(scores, networks, seed_sets)
    print(markdown(rows))
    if args.steps:
        try:
            steps = steps_taken(args.res, entries)
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise SystemExit(f"a run folder of {args.res} lacks its metrics.json or config.yaml ({e}): "
                             "give the reproduce folder with its runs/")
        print("\nSteps taken before stopping\n\n" + markdown(steps_table(steps, networks, seed_sets)))
    if args.csv:
        write_csv(args.csv, list(rows[0]), rows)


if __name__ == "__main__":
    main()
