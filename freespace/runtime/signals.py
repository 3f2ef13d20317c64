"""How a command ends: ``SIGTERM`` raised as an exception so that clean-ups run, and the install a missing
module needs."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from freespace.errors import Terminated

__all__ = ["sigterm_raises", "missing_extra"]

#: the modules of the optional extras (pyproject.toml) by top-level name, and the extra that installs each
EXTRAS = {**dict.fromkeys(("torch", "torchvision", "segmentation_models_pytorch", "lightning", "albumentations",
                           "pydantic", "matplotlib", "scipy"), "train"), "onnx": "export", "onnxruntime": "export"}


def _raise_terminated(signum: int, frame: Any) -> None:
    """``SIGTERM`` handler: raise :class:`~freespace.errors.Terminated` once (so that clean-ups run, as on
    Ctrl-C); further ``SIGTERM`` signals are ignored while they do."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise Terminated()


@contextmanager
def sigterm_raises() -> Iterator[None]:
    """Inside, ``SIGTERM`` (SLURM's time limit, ``kill``) raises :class:`~freespace.errors.Terminated` in the
    main thread, so that ``finally`` blocks run; the handler before is restored on the way out. Outside the
    main thread (where no handler may be set) it does nothing."""
    main_thread = threading.current_thread() is threading.main_thread()  # signal handlers live there only
    previous = signal.signal(signal.SIGTERM, _raise_terminated) if main_thread else None
    try:
        yield
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous if previous is not None else signal.SIG_DFL)


def missing_extra(exc: ModuleNotFoundError, command: str | None) -> str | None:
    """The message for a ``command`` that needs a module of an optional extra this install lacks (``exc``): which
    extra to install, with the ``pip`` line; None when the module belongs to no extra."""
    extra = EXTRAS.get((exc.name or "").partition(".")[0])
    if extra is None:
        return None
    return (f"`freespace {command}` needs {exc.name}, which this install lacks; install the extra: pip install "
            f"'freespace[{extra}]'")
