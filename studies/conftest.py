"""The studies' own tests (``pytest studies/``; a plain ``pytest`` collects ``tests/`` only, the product's): each
study's analysis scripts, and its published tables rebuilt from its run folders byte for byte.

The studies' tests import the package and what lies in ``studies/`` only (never ``tests/`` or ``bench/``:
``tests/test_folders.py``); a study's test loads its own study's scripts by path. What they share is here:
the fixtures ``road_frame`` and ``tiny_road_checkpoint`` (:mod:`freespace.testing`'s, as the product's tests have
them)."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
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


@pytest.fixture
def road_frame() -> Callable[[tuple[int, int], int], tuple[np.ndarray, np.ndarray]]:
    """:func:`freespace.testing.road_frame`, for a study's test."""
    from freespace.testing import road_frame

    return road_frame


@pytest.fixture
def tiny_road_checkpoint() -> Callable[..., Path]:
    """:func:`freespace.testing.tiny_road_checkpoint`, for a study's test."""
    from freespace.testing import tiny_road_checkpoint

    return tiny_road_checkpoint
