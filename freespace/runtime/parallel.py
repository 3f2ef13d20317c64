"""Worker processes that never outlive the command that started them, and stop at once with it.

``ProcessPoolExecutor`` workers block on a queue whose write end they hold themselves, so a parent
killed with ``SIGKILL`` leaves them running. :func:`die_with_parent`, called in each worker's
initializer, ends a worker when its parent goes: on Linux through ``PR_SET_PDEATHSIG``, elsewhere through
a daemon thread that watches the parent process id.

When the parent stops on Ctrl-C or ``SIGTERM``, leaving a ``with ProcessPoolExecutor`` block would wait for
every job already submitted. :func:`worker_pool` instead cancels the jobs not started and kills the workers
at once, whatever they are doing (starting up included); its workers (:func:`init_worker`) ignore Ctrl-C,
which the terminal sends to the whole process group, so that only the parent reacts (one message, no worker
tracebacks). The standard library only.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any

__all__ = ["die_with_parent", "init_worker", "worker_pool"]

_PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int, poll_seconds: float = 1.0) -> None:
    """Arrange for this (worker) process to end when its parent process ends.

    Args:
        parent: the process id of the parent, taken in the parent (``os.getpid()`` there): a worker that
            starts after its parent died sees another parent and ends at once.
        poll_seconds: how often the fallback watcher checks the parent, in seconds.
    """
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_seconds)
        os._exit(1)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()


def init_worker(parent: int) -> None:
    """What every worker of :func:`worker_pool` does first: ignore Ctrl-C (the parent handles it and ends
    the workers), take ``SIGTERM`` again (a terminate that came while the worker started ends it now, silently)
    and :func:`die_with_parent`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C that came while the worker started is dropped
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _STARTUP_BLOCKED)
    die_with_parent(parent)


#: how long :func:`worker_pool` waits for the pool's manager thread after ending the workers, in seconds
_MANAGER_JOIN_SECONDS = 60.0

#: signals blocked while a worker starts (see :class:`_Pool`)
_STARTUP_BLOCKED = {signal.SIGINT, signal.SIGTERM}


class _Pool(ProcessPoolExecutor):
    """A pool whose ``submit`` (which starts the workers, ``spawn``) holds Ctrl-C and ``SIGTERM`` back until it
    returns (:func:`_signals_held`), so that the parent never stops between starting a worker and sending it its
    start-up data (the worker would print an ``EOFError``) and every worker it started is known and can be
    killed; and whose workers start with both signals blocked, a mask that passes on to them through ``exec``,
    until :func:`init_worker` (a Ctrl-C to the process group while a worker imports its modules would print
    that worker's traceback)."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Any:
        with _signals_held():
            return super().submit(fn, *args, **kwargs)


@contextmanager
def _signals_held() -> Iterator[None]:
    """Ctrl-C and ``SIGTERM`` held back while the block runs and delivered after it, to the handlers of before.

    Blocking them in this thread is not enough: the kernel then hands a signal to another thread that does
    not block it (OpenCV's, a reader's) and Python runs the handler in the main thread all the same, in the
    middle of the block. So the main thread also swaps its handlers for ones that only note the signal, and
    raises each noted signal again once the block is over and the handlers are back."""
    main = threading.current_thread() is threading.main_thread()  # handlers can be set there only
    noted: list[int] = []
    handlers = {s: signal.signal(s, lambda signum, frame: noted.append(signum)) for s in _STARTUP_BLOCKED} \
        if main else {}
    masked = hasattr(signal, "pthread_sigmask")
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _STARTUP_BLOCKED) if masked else None
    try:
        yield
    finally:
        if masked:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)  # type: ignore[arg-type]
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
        for sig in dict.fromkeys(noted):  # each once: a second Ctrl-C meanwhile is the same request
            signal.raise_signal(sig)


@contextmanager
def worker_pool(workers: int, initializer: Callable[..., None], initargs: tuple[Any, ...] = ()
                ) -> Iterator[ProcessPoolExecutor]:
    """A ``spawn`` process pool of ``workers`` processes whose workers end at once when the block raises.

    Args:
        initializer: run first in each worker; it must call :func:`init_worker` with the parent's
            process id (``os.getpid()`` here), e.g. as ``initargs``.

    When the block ends normally the pool is shut down after its jobs, as ``with ProcessPoolExecutor``
    does. When it raises (an error, Ctrl-C, ``SIGTERM``), the jobs not started are cancelled and the
    workers killed (``SIGKILL``) without waiting for the running ones, then the exception goes on. A kill
    stops a worker at once and silently whatever it does, even while it starts up with ``SIGTERM`` blocked
    (a worker with no handler of its own would end without clean-up on ``SIGTERM`` too; what it was writing
    is a temporary file, which the next run ignores).
    """
    # spawn, not fork: a forked child can deadlock on OpenCV's thread pool held by the parent
    pool = _Pool(max_workers=workers, initializer=initializer, initargs=initargs,
                 mp_context=multiprocessing.get_context("spawn"))
    try:
        yield pool
    except BaseException:
        processes = list((getattr(pool, "_processes", None) or {}).values())  # before shutdown forgets them,
        manager = getattr(pool, "_executor_manager_thread", None)  # as it forgets its manager thread
        pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            p.kill()
        for p in processes:
            p.join(timeout=5)
        # the pool's manager thread closes its wake-up pipe when it sees the workers gone; the interpreter's exit
        # hook writes to that pipe unless it is closed already, and when both happen at once the write fails
        # with a traceback on stderr (EBADF). So the manager must be gone before the exit (milliseconds on an
        # idle machine, possibly seconds on a loaded one)
        if manager is not None:
            manager.join(timeout=_MANAGER_JOIN_SECONDS)
        raise
    pool.shutdown(wait=True)
