"""freespace.runtime.parallel: worker pools that end with the command."""

from __future__ import annotations

import os
import signal
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


def test_a_signal_during_submit_waits_until_it_is_over() -> None:
    """A SIGTERM that the kernel hands to another thread while ``submit`` starts a worker (the main thread
    blocks it) still runs its handler in the main thread; held back, it runs after ``submit``, never between
    starting a worker and sending it its start-up data (the worker then printed ``EOFError: Ran out of input``)."""

    class Stop(Exception):
        pass

    def stop(signum: int, frame: object) -> None:
        raise Stop

    go = threading.Event()
    sender = threading.Thread(target=lambda: go.wait(10) and os.kill(os.getpid(), signal.SIGTERM))
    sender.start()  # before the block: this thread does not block SIGTERM, so the kernel may deliver it here
    previous = signal.signal(signal.SIGTERM, stop)
    steps: list[int] = []
    try:
        with pytest.raises(Stop):
            with parallel._signals_held():
                go.set()
                sender.join()
                for i in range(200):  # bytecode boundaries, where Python runs a handler
                    time.sleep(0.001)
                    steps.append(i)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert len(steps) == 200, f"the handler ran inside the block, after {len(steps)} steps"


def _start_slowly(parent: int) -> None:
    time.sleep(60)  # a worker still importing its modules on a loaded machine: SIGTERM is blocked until init_worker
    parallel.init_worker(parent)


def test_workers_still_starting_are_killed_at_once() -> None:
    """A worker that has not reached :func:`~freespace.runtime.parallel.init_worker` (signals still blocked) ends
    at once with the block, not when it gets there."""
    started = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        with parallel.worker_pool(1, _start_slowly, (os.getpid(),)) as pool:
            pool.submit(_sleep, 0.0)
            workers = list(pool._processes.values())  # type: ignore[attr-defined]
            time.sleep(0.5)
            raise KeyboardInterrupt
    assert workers and not any(p.is_alive() for p in workers)
    assert time.perf_counter() - started < 10, "the pool waited for a starting worker"
