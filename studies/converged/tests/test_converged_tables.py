"""The converged run's tables (res-final/, res-auto2/, res-scratch/) rebuild from their run folders byte for
byte with the study's protocol (res-pilot-lr01/ kept its tables only)."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("res", ["res-final", "res-auto2", "res-scratch"])
def test_the_published_tables_rebuild_identically(res: str, rebuilt_tables) -> None:
    assert rebuilt_tables(HERE / res, HERE / "protocol.yaml") == []


def test_without_the_protocol_the_primary_endpoint_and_the_paper_are_left_out(tmp_path: Path, rebuilt_tables) -> None:
    """The library holds no study's constants: the converged run's primary endpoint and the paper's gains (lines
    of results.md) come from its protocol file only; its gains are among the method's own, in the same order."""
    (tmp_path / "generic.yaml").write_text("{}\n")
    assert rebuilt_tables(HERE / "res-final", tmp_path / "generic.yaml") == ["results.md"]


def _epochs(run: Path) -> list[dict[str, str]]:
    """A run's ``metrics.csv`` rows without the seconds (the only column that differs between machines' runs)."""
    with (run / "metrics.csv").open(newline="") as f:
        return [{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(f)]


def test_every_x_long_is_x_s_run_continued() -> None:
    """Issue 47: X-long is X with twice the cap and patience, extending X's own run, so its per-epoch record
    equals X's in every column but the seconds up to X's stop, for every network and seed that has both."""
    runs = HERE / "res-final" / "runs"
    pairs = sorted(p for p in runs.glob("*-long-s*") if (runs / p.name.replace("-long-", "-orig-")).is_dir())
    assert len(pairs) == 40  # the five networks' seeds 0–4, the three pretrained ones' 5–9
    for long in pairs:
        x, x_long = _epochs(runs / long.name.replace("-long-", "-orig-")), _epochs(long)
        assert len(x_long) > len(x), long.name  # twice the patience: at least 20 epochs past X's stop
        assert x_long[: len(x)] == x, long.name
