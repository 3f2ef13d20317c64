"""Logging set-up shared by the command-line interface and scripts.

Library code logs through ``logging.getLogger(__name__)``; only :func:`setup_logging` (called once by
the CLI) installs a handler, so applications embedding ``freespace`` keep control of their logging.
"""

from __future__ import annotations

import logging
import sys
import warnings
from collections.abc import Iterable
from typing import Any, TypeVar

T = TypeVar("T")


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is at the time of each record (it may be replaced after set-up)."""

    @property  # type: ignore[override]
    def stream(self):  # noqa: D401
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:  # logging.StreamHandler.__init__ assigns it
        pass


class _Clean(logging.Formatter):
    """A record as one clean text: a parameter named with :func:`freespace.errors.param` shown by its name (never
    its NUL-delimited marker), and every control byte but newline and tab shown escaped (``\\x1b``), so that a
    file name cannot move the terminal's cursor, ring its bell or hide the rest of the line."""

    def format(self, record: logging.LogRecord) -> str:
        from freespace.errors import render

        text = render(super().format(record))
        return "".join(c if c.isprintable() or c in "\n\t" else ascii(c)[1:-1] for c in text)


def setup_logging(verbosity: int = 0) -> None:
    """Install a stderr handler on the ``freespace`` logger.

    Args:
        verbosity: 0 = warnings and info, 1+ = debug, -1 = warnings only.
    """
    level = logging.DEBUG if verbosity > 0 else logging.WARNING if verbosity < 0 else logging.INFO
    logger = logging.getLogger("freespace")
    logger.setLevel(level)
    if not any(getattr(h, "_freespace", False) for h in logger.handlers):
        handler = _StderrHandler()
        handler.setFormatter(_Clean("%(levelname)s %(name)s: %(message)s"))
        handler._freespace = True  # type: ignore[attr-defined]
        logger.addHandler(handler)
    logger.propagate = False


def progress_bar(iterable: Iterable[T] | None = None, *, enabled: bool = True, **kwargs: Any) -> Any:
    """A ``tqdm`` progress bar on a terminal; none off a terminal (a log file gets the stage's lines, not
    carriage-return frames). ``enabled=False`` (the command line's no-progress option) turns it off
    everywhere; ``kwargs`` go to ``tqdm`` (``total``, ``desc``, ``unit``, ...)."""
    from tqdm import tqdm

    return tqdm(iterable, disable=not (enabled and sys.stderr.isatty()), **kwargs)


def on_terminal() -> bool:
    """Whether stderr (where progress bars go) is a terminal."""
    return sys.stderr.isatty()


def quiet_lightning() -> None:
    """Route Lightning's loggers through ``freespace``'s handler and keep its start-up chatter (accelerator
    and device lines, tips) out of the output unless ``-v`` asked for debug messages. Lightning installs
    handlers bound to the ``sys.stderr`` of import time; a replaced stream would make them fail."""
    debug = logging.getLogger("freespace").isEnabledFor(logging.DEBUG)
    if not debug:  # Lightning's own deprecation inside its pytree helper, raised on every fit and test
        warnings.filterwarnings("ignore", message=r".*isinstance\(treespec, LeafSpec\)")
        # on every resume: the run's own checkpoints/ folder holds last.ckpt, as it should
        warnings.filterwarnings("ignore", message=r"Checkpoint directory .* exists and is not empty")
        # on resuming a checkpoint of an older version, whose early stopping had another name: its state is
        # replayed from the validation history (engine.train._EarlyStopping), nothing is missing
        warnings.filterwarnings("ignore", message=r"Be aware that when using `ckpt_path`, callbacks used to create")
    for name in ("lightning", "lightning.pytorch", "lightning.fabric"):
        logger = logging.getLogger(name)
        logger.handlers = [h for h in logger.handlers if not isinstance(h, logging.StreamHandler)]
        logger.addHandler(_StderrHandler())
        logger.handlers[-1].setFormatter(_Clean("%(levelname)s %(name)s: %(message)s"))
        logger.propagate = False
        logger.setLevel(logging.DEBUG if debug else logging.WARNING)
