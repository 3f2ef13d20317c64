"""How a command ends: ``SIGTERM`` raised as an exception so that clean-ups run, the signals held back while
output is moved into place (all or nothing), and the install a missing module needs."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from freespace.errors import Terminated

__all__ = ["sigterm_raises", "signals_held", "HELD_SIGNALS", "missing_extra"]

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


#: the signals that end a command and that :func:`signals_held` holds back (SIGKILL and SIGSTOP cannot be)
HELD_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold back ``SIGINT``, ``SIGTERM`` and ``SIGHUP`` (:data:`HELD_SIGNALS`) for the block, so that it runs whole:
    one that arrives inside is recorded and raised again when the block ends, once the handlers before are back
    (Ctrl-C's :class:`KeyboardInterrupt`, :func:`sigterm_raises`' :class:`~freespace.errors.Terminated`, or the
    default action: the process ends then). For moves into place: output appears all or, when the block raises,
    as the block left it; never cut short by a signal half-way.

    The handlers are replaced rather than the signals blocked (``pthread_sigmask``): a signal the main thread blocks
    is delivered to another thread (ONNX Runtime's, torch's), and Python still runs its handler in the main thread,
    in the middle of the block. A signal ignored before stays ignored. Outside the main thread it does nothing:
    handlers run in the main thread only, so a signal does not cut into this one. ``SIGKILL`` cannot be held back:
    what it leaves (a stage, a temporary file) is removed by the next run (:mod:`freespace.io.outdir`)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous: dict[int, Any] = {}
    try:
        for signum in HELD_SIGNALS:
            if signal.getsignal(signum) != signal.SIG_IGN:
                previous[signum] = signal.signal(signum, lambda number, frame: caught.append(number))
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler if handler is not None else signal.SIG_DFL)
        for signum in dict.fromkeys(caught):  # each once, in the order they came
            signal.raise_signal(signum)


def missing_extra(exc: ModuleNotFoundError, command: str | None) -> str | None:
    """The message for a ``command`` that needs a module of an optional extra this install lacks (``exc``): which
    extra to install, with the ``pip`` line; None when the module belongs to no extra."""
    extra = EXTRAS.get((exc.name or "").partition(".")[0])
    if extra is None:
        return None
    return (f"`freespace {command}` needs {exc.name}, which this install lacks; install the extra: pip install "
            f"'freespace[{extra}]'")
