"""The converged run's tables (res-final/, res-auto2/, res-scratch/) rebuild from their run folders byte for
byte with the study's protocol (res-pilot-lr01/ kept its tables only)."""

from __future__ import annotations

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
