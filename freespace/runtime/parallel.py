"""Worker processes that never outlive the command that started them, and stop at once with it.

``ProcessPoolExecutor`` workers block on a queue whose write end they hold themselves, so a parent
killed with ``SIGKILL`` leaves them running. :func:`die_with_parent`, called in each worker's
initializer, ends a worker when its parent goes: on Linux through ``PR_SET_PDEATHSIG``, elsewhere through
a daemon thread that watches the parent process id.

When the parent stops on Ctrl-C or ``SIGTERM``, leaving a ``with ProcessPoolExecutor`` block would wait for
every job already submitted. :func:`worker_pool` instead cancels the jobs not started and ends the workers
at once; its workers (:func:`init_worker`) ignore Ctrl-C, which the terminal sends to the whole process
group, so that only the parent reacts (one message, no worker tracebacks). The standard library only.
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
    """A pool whose workers start with Ctrl-C and ``SIGTERM`` blocked: ``submit`` starts them (``spawn``), and
    the blocked signal mask passes on to them through ``exec``, until :func:`init_worker`. Without it a Ctrl-C
    while a worker imports its modules prints that worker's traceback, and a ``SIGTERM`` that ends the parent
    between starting a worker and sending it its start-up data leaves that worker to print an ``EOFError``;
    blocked, the signal reaches the parent after ``submit``, when every worker it started is known and can be
    terminated."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Any:
        if not hasattr(signal, "pthread_sigmask"):
            return super().submit(fn, *args, **kwargs)
        old = signal.pthread_sigmask(signal.SIG_BLOCK, _STARTUP_BLOCKED)
        try:
            return super().submit(fn, *args, **kwargs)
        finally:  # a Ctrl-C or SIGTERM that came meanwhile is raised here, in the parent
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextmanager
def worker_pool(workers: int, initializer: Callable[..., None], initargs: tuple[Any, ...] = ()
                ) -> Iterator[ProcessPoolExecutor]:
    """A ``spawn`` process pool of ``workers`` processes whose workers end at once when the block raises.

    Args:
        initializer: run first in each worker; it must call :func:`init_worker` with the parent's
            process id (``os.getpid()`` here), e.g. as ``initargs``.

    When the block ends normally the pool is shut down after its jobs, as ``with ProcessPoolExecutor``
    does. When it raises (an error, Ctrl-C, ``SIGTERM``), the jobs not started are cancelled and the
    workers terminated without waiting for the running ones, then the exception goes on.
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
            p.terminate()
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
