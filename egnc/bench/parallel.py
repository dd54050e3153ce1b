"""Run many `Call`s, each in its own child process: several at once here, or on a Dask cluster.

Both pools take `(key, Call)` pairs from an iterator, lazily (a call is only built when a slot is
free for it, so a large grid never holds all its graphs at once), and yield `(key, Outcome)` as
the calls finish, in completion order; the caller puts the results back in its own order.

- `LocalPool(workers)`: at most `workers` children of this process at a time, each killed at its
  own time limit (`egnc.bench.child`). `LocalPool(1)` is the serial run.
- `DaskPool(address)`: every call is a task `run_in_child(target, args, time_limit_s)` on a
  `dask.distributed` cluster (the optional `dask` extra), so each worker forks its own child and
  enforces the limit there. The workers need egnc (the same version) importable; the graphs
  travel with the tasks, so the datasets only need to be readable here. At most twice as many
  tasks as the cluster has worker threads are submitted at a time.
"""

from __future__ import annotations

import contextlib
import time
import typing
from collections.abc import Hashable, Iterable, Iterator
from multiprocessing.connection import Connection, wait
from typing import Protocol

from egnc.bench.child import Call, Child, Outcome, run_in_child
from egnc.errors import EgncError

__all__ = ["DaskPool", "LocalPool", "Pool", "open_pool"]

DASK_INSTALL_HINT = "pip install 'egnc[dask]'"
"""How to get dask.distributed; quoted in the error raised without it."""


class Pool(Protocol):
    """Something that runs calls in child processes and yields their outcomes as they finish."""

    def run(self, calls: Iterable[tuple[Hashable, Call]]) -> Iterator[tuple[Hashable, Outcome]]: ...


class LocalPool:
    """At most `workers` child processes of this process at a time."""

    def __init__(self, workers: int = 1):
        if workers < 1:
            raise EgncError(f"workers must be at least 1, got {workers}")
        self.workers = workers

    def run(self, calls: Iterable[tuple[Hashable, Call]]) -> Iterator[tuple[Hashable, Outcome]]:
        """Start calls while fewer than `workers` run; yield each outcome when its child answers or
        times out. Children still running when the caller stops (or on an error) are killed."""
        pending = iter(calls)
        running: dict[Connection, tuple[Hashable, Child]] = {}
        try:
            while True:
                while len(running) < self.workers and (item := next(pending, None)) is not None:
                    key, call = item
                    child = Child(call)
                    running[child.connection] = (key, child)
                if not running:
                    return
                earliest = min(child.deadline for _, child in running.values())
                answered = wait(list(running), timeout=max(0.0, earliest - time.perf_counter()))
                now = time.perf_counter()
                for connection, (key, child) in list(running.items()):
                    if connection in answered or child.deadline <= now:
                        del running[connection]
                        yield key, child.finish()
        finally:
            for _, child in running.values():
                child.kill()


class DaskPool:
    """Tasks on a running `dask.distributed` cluster (the `dask` extra)."""

    def __init__(self, address: str):
        try:
            from distributed import Client
        except ImportError:
            raise EgncError(f"a Dask cluster needs dask.distributed, not installed: {DASK_INSTALL_HINT}") from None
        try:
            # Waits for the scheduler as long as Dask's `distributed.comm.timeouts.connect` (30 s by default).
            self.client = Client(address, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as error:
            raise EgncError(f"cannot connect to the Dask scheduler at {address}: {error}") from None

    def close(self) -> None:
        """Disconnect from the scheduler (the cluster keeps running)."""
        self.client.close()

    def run(self, calls: Iterable[tuple[Hashable, Call]]) -> Iterator[tuple[Hashable, Outcome]]:
        """Submit calls, at most twice the cluster's thread count at a time; yield each outcome as
        its task finishes. A task the cluster itself lost (e.g. a worker died) is an "error" outcome."""
        from distributed import as_completed

        pending = iter(calls)
        submitted: dict[Hashable, tuple[Hashable, typing.Any]] = {}  # future key -> (call key, future)
        finished = as_completed(loop=self.client.loop)
        window = max(2, 2 * sum(self.client.nthreads().values()))

        def submit_next() -> None:
            item = next(pending, None)
            if item is not None:
                key, call = item
                future = self.client.submit(run_in_child, call.target, call.args, call.time_limit_s, pure=False)
                submitted[future.key] = (key, future)
                finished.add(future)

        for _ in range(window):
            submit_next()
        try:
            for future in finished:
                try:
                    outcome = future.result()
                except Exception as error:  # whatever the cluster raised becomes the run's status
                    outcome = Outcome(f"error: dask: {type(error).__name__}: {' '.join(str(error).split())}")
                yield submitted.pop(future.key)[0], outcome
                submit_next()
        finally:
            for _, future in submitted.values():  # the caller stopped early: nothing left running
                future.cancel()


@contextlib.contextmanager
def open_pool(workers: int = 1, dask_scheduler: str | None = None) -> Iterator[Pool]:
    """A `DaskPool` connected to `dask_scheduler` when given (disconnected on exit), else a `LocalPool`."""
    if dask_scheduler is None:
        yield LocalPool(workers)
        return
    pool = DaskPool(dask_scheduler)
    try:
        yield pool
    finally:
        pool.close()
