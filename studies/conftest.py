"""The studies' own tests (``pytest studies/``; a plain ``pytest`` collects ``tests/`` only, the product's): each
study's analysis scripts, and its published tables rebuilt from its run folders byte for byte."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

#: the tables ``freespace reproduce --tables`` writes from the run folders
TABLES = ("index.json", "results.csv", "gains.csv", "results.md")


@pytest.fixture
def rebuilt_tables(tmp_path: Path) -> Callable[[Path, Path], list[str]]:
    """``check(published, protocol)``: copy the run folders of the reproduce folder ``published`` (its ``runs/``)
    into a new folder, write the tables there from them with the study's ``protocol`` file (as ``freespace
    reproduce --tables --protocol FILE`` does, without figures) and return the tables that differ from the
    published ones."""
    from freespace.experiments import Protocol, write_tables

    def check(published: Path, protocol: Path) -> list[str]:
        out = tmp_path / published.name
        shutil.copytree(published / "runs", out / "runs", symlinks=True)
        write_tables(out, figures=0, protocol=Protocol.load(protocol))
        return [name for name in TABLES if (out / name).read_bytes() != (published / name).read_bytes()]

    return check
