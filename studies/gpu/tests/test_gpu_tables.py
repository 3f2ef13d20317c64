"""The GPU cells' tables (res-paper/) rebuild from their run folders byte for byte with the study's protocol."""

from __future__ import annotations

from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def test_the_published_tables_rebuild_identically(rebuilt_tables) -> None:
    assert rebuilt_tables(HERE / "res-paper", HERE / "protocol.yaml") == []
