"""Worker processes that never outlive the command that started them.

``ProcessPoolExecutor`` workers block on a queue whose write end they hold themselves, so a parent
killed with ``SIGKILL`` leaves them running. :func:`die_with_parent`, called in each worker's
initializer, ends a worker when its parent goes: on Linux through ``PR_SET_PDEATHSIG``, elsewhere through
a daemon thread that watches the parent process id. The standard library only.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time

__all__ = ["die_with_parent"]

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
