"""Fixtures shared by the test files: one tiny trained run for the whole session."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

from helpers import TRAINED_ARGS, TRAINED_FRAMES, TRAINED_SEED, TRAINED_SIZE


@pytest.fixture(autouse=True, scope="session")
def ctrl_c_raises() -> Iterator[None]:
    """SIGINT raises :class:`KeyboardInterrupt`, as in a terminal, even when the suite was started in the background
    (``nohup``, ``&`` in a script), where it inherits SIGINT ignored and Python installs no handler for it: the
    tests that send Ctrl-C to a command then test the command, not how pytest was started. Restored after."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def _state(*roots: Path) -> dict[str, tuple[int, int]]:
    """``{path: (size, mtime_ns)}`` of every file and folder under ``roots`` (a folder's size is -1)."""
    state = {}
    for root in roots:
        for p in (root, *root.rglob("*")):
            st = p.lstat()
            state[str(p)] = (st.st_size if p.is_file() else -1, st.st_mtime_ns)
    return state


@pytest.fixture(scope="session")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Path]]:
    """A tiny synth dataset and a SegNet trained on it for one epoch through the command line.

    ``data``: the dataset root (``helpers.TRAINED_FRAMES`` frames of ``TRAINED_SIZE``, seed
    ``TRAINED_SEED``); ``run``: the ``train --out`` folder (settings ``helpers.TRAINED_ARGS``); ``ckpt``: its
    ``checkpoints/best.ckpt``. One run for the whole session: tests read it and never write into these
    folders (copy them first); the session fails at teardown if anything under them changed.
    """
    from freespace.cli import main
    from freespace.data.synthetic import SynthConfig, write_dataset

    base = tmp_path_factory.mktemp("trained")
    data, run = base / "data", base / "run"
    write_dataset(data, TRAINED_FRAMES, seed=TRAINED_SEED, progress=False,
                  config=SynthConfig(width=TRAINED_SIZE[0], height=TRAINED_SIZE[1], frames_per_scenario=2))
    assert main(["train", "--dataset", "synth", "--root", str(data), *TRAINED_ARGS, "--out", str(run)]) == 0
    before = _state(data, run)
    yield {"data": data, "run": run, "ckpt": run / "checkpoints" / "best.ckpt"}
    after = _state(data, run)
    changed = sorted(p for p in before.keys() | after.keys() if before.get(p) != after.get(p))
    assert not changed, f"tests wrote into the shared trained run (copy it first): {changed[:10]}"
