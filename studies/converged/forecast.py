"""How many seeds the converged run's target needs, from the paired spread of the seeds finished so far.

``python forecast.py RES [--versus "HA-X - X-dup"] [--target 1.5]``: for each network and test set of
``RES/gains.csv`` (F-score points), the paired SD of the gain, recovered from its t-interval
(``sd = half_width·√n / t(0.975, n−1)``), and the fewest seeds whose interval at that SD has a half-width of at
most ``target`` points: the smallest ``k`` with ``t(0.975, k−1)·sd/√k ≤ target``. Printed as a Markdown table.
An SD from two or three seeds is itself uncertain (at n = 3 its 95 % interval spans 0.5–6.3 times the
estimate), so the forecast guides the order of the cells and decides nothing.
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

from scipy.stats import t

MAX_SEEDS = 100


def seeds_needed(sd: float, target: float) -> int | None:
    """Fewest seeds (≥ 2) whose 95 % paired t-interval at paired SD ``sd`` has half-width ≤ ``target``.

    ``sd`` and ``target`` in the same unit (F-score points); ``None`` when more than ``MAX_SEEDS`` are needed.
    """
    return next((k for k in range(2, MAX_SEEDS + 1) if t.ppf(0.975, k - 1) * sd / math.sqrt(k) <= target), None)


def forecast(gains_csv: Path, versus: str, target: float) -> list[dict[str, str]]:
    """One row per network and test set of ``gains_csv`` (F-score, ``versus``, n ≥ 2): n, mean, SD, half-width,
    seeds needed."""
    rows = []
    with gains_csv.open(newline="") as f:
        for g in csv.DictReader(f):
            n = int(g["n"])
            if g["versus"] != versus or g["metric"] != "f_score" or n < 2:
                continue
            half = (float(g["ci_high"]) - float(g["ci_low"])) / 2
            sd = half * math.sqrt(n) / t.ppf(0.975, n - 1)
            need = seeds_needed(sd, target)
            rows.append({"network": g["network"], "test set": g["test_set"], "n": str(n),
                         "mean": f"{float(g['mean']):+.2f}", "SD": f"{sd:.2f}", "half-width": f"{half:.2f}",
                         f"seeds for ≤ {target:g}": str(need) if need else f"> {MAX_SEEDS}"})
    return rows


def markdown(rows: list[dict[str, str]]) -> str:
    """``rows`` (the same keys in each) as a Markdown table, the keys as its header."""
    lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    return "\n".join(lines + ["| " + " | ".join(r.values()) + " |" for r in rows])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("res", type=Path, help="a reproduce folder (holds gains.csv)")
    parser.add_argument("--versus", default="HA-X - X-dup", help="the gain, as gains.csv names it")
    parser.add_argument("--target", type=float, default=1.5, help="half-width to reach, in F-score points")
    args = parser.parse_args()
    if not (args.res / "gains.csv").is_file():
        raise SystemExit(f"{args.res} holds no gains.csv: give a reproduce folder whose tables are built")
    rows = forecast(args.res / "gains.csv", args.versus, args.target)
    if not rows:
        raise SystemExit(f"no '{args.versus}' F-score gain with 2 or more seeds in {args.res / 'gains.csv'}")
    print(markdown(rows))


if __name__ == "__main__":
    main()
