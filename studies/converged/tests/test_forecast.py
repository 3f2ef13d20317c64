"""The converged run's seed forecast (studies/converged/forecast.py): the SD it recovers from gains.csv is
the paired SD, and the seeds it names are the fewest that reach the target."""

from __future__ import annotations

import csv
import importlib.util
import math
import statistics
from pathlib import Path

import pytest

from freespace.experiments.stats import paired_gain

SCRIPT = Path(__file__).resolve().parents[1] / "forecast.py"
spec = importlib.util.spec_from_file_location("forecast", SCRIPT)
forecast = importlib.util.module_from_spec(spec)
spec.loader.exec_module(forecast)


def _half_width(sd: float, k: int) -> float:
    from scipy.stats import t

    return t.ppf(0.975, k - 1) * sd / math.sqrt(k)


@pytest.mark.parametrize("sd", [0.3, 1.0, 2.1, 4.0])
def test_seeds_needed_is_the_fewest(sd: float) -> None:
    k = forecast.seeds_needed(sd, 1.5)
    assert k is not None and _half_width(sd, k) <= 1.5
    assert k == 2 or _half_width(sd, k - 1) > 1.5


def test_seeds_needed_beyond_the_limit() -> None:
    assert forecast.seeds_needed(100.0, 1.5) is None


def test_forecast_recovers_the_paired_sd(tmp_path: Path) -> None:
    a, b = [91.0, 93.5, 90.2, 92.8], [90.1, 91.0, 90.9, 91.3]
    g = paired_gain(a, b)
    rows = [{"network": "unet", "versus": "HA-X - X-dup", "metric": "f_score", "test_set": "same-rigs",
             "mean": g.mean, "ci_low": g.ci_low, "ci_high": g.ci_high, "n": g.n, "excludes_zero": g.excludes_zero},
            {"network": "unet", "versus": "HA-X - X", "metric": "f_score", "test_set": "same-rigs",
             "mean": 1.0, "ci_low": 0.0, "ci_high": 2.0, "n": 4, "excludes_zero": True},
            {"network": "segnet", "versus": "HA-X - X-dup", "metric": "f_score", "test_set": "same-rigs",
             "mean": 1.0, "ci_low": "", "ci_high": "", "n": 1, "excludes_zero": False}]
    with (tmp_path / "gains.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (row,) = forecast.forecast(tmp_path / "gains.csv", "HA-X - X-dup", 1.5)
    sd = statistics.stdev(x - y for x, y in zip(a, b))
    assert row["network"] == "unet" and row["n"] == "4"
    assert float(row["SD"]) == pytest.approx(sd, abs=0.006)
    assert row["seeds for ≤ 1.5"] == str(forecast.seeds_needed(sd, 1.5))
