"""freespace.runtime.parallel: worker pools that end with the command."""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import process

import pytest

from freespace.runtime import parallel


def _sleep(seconds: float) -> None:
    time.sleep(seconds)


def test_pool_manager_is_gone_when_the_block_raises(monkeypatch: pytest.MonkeyPatch) -> None:
    """After a raise inside ``worker_pool`` (Ctrl-C, SIGTERM) the pool's manager thread has ended before the
    exception goes on, even when it is slow (a loaded machine): the interpreter's exit hook then finds its
    wake-up pipe closed and writes nothing. A manager still closing that pipe at exit races the hook's write,
    which fails with ``OSError: Bad file descriptor`` and a traceback after "terminated" (seen once in the
    hostile tests on a loaded machine: the pool waited for a manager that ``shutdown`` had already forgotten)."""
    slow = 2.0
    internals = process._ExecutorManagerThread.join_executor_internals

    def slow_internals(self: process._ExecutorManagerThread) -> None:
        time.sleep(slow)
        internals(self)

    monkeypatch.setattr(process._ExecutorManagerThread, "join_executor_internals", slow_internals)
    started = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        with parallel.worker_pool(1, parallel.init_worker, (os.getpid(),)) as pool:
            pool.submit(_sleep, 30.0)
            time.sleep(0.5)
            raise KeyboardInterrupt
    managers = [t for t in threading.enumerate() if isinstance(t, process._ExecutorManagerThread)]
    assert not managers, "the pool's manager thread outlived worker_pool"
    assert time.perf_counter() - started < slow + 20, "the running job was waited for"
