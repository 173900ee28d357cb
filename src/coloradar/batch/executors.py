"""One executor interface over a local process pool, a serial loop, or a Dask cluster.

Work is a function applied to independent tasks (chunks of frames). Workers read their inputs
and write their outputs themselves; only the small value each task returns travels back. At
most ``max_in_flight`` tasks are submitted at once, so memory stays bounded whatever the
number of tasks.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from ..errors import ColoradarError

__all__ = ["DaskExecutor", "Executor", "LocalExecutor", "SerialExecutor", "make_executor"]


class Executor:
    """Runs ``fn(task)`` for every task; yields ``(task, result)`` as tasks complete."""

    #: Number of parallel workers (for chunking decisions and reports).
    workers: int = 1
    description: str = "executor"

    def imap_unordered(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        raise NotImplementedError

    def close(self) -> None:
        """Release the workers."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SerialExecutor(Executor):
    """Runs tasks one after the other in this process (debugging, tiny jobs)."""

    description = "serial (this process)"

    def imap_unordered(self, fn, tasks):
        for task in tasks:
            yield task, fn(task)


class LocalExecutor(Executor):
    """A local process pool (``concurrent.futures.ProcessPoolExecutor``).

    Parameters
    ----------
    jobs
        Worker processes (None: all cores).
    max_in_flight
        Tasks submitted but not finished at any time (None: 2 × jobs).
    """

    def __init__(self, jobs: int | None = None, max_in_flight: int | None = None):
        self.workers = jobs or os.cpu_count() or 1
        self.max_in_flight = max_in_flight or 2 * self.workers
        self.description = f"local process pool, {self.workers} workers"
        self._pool = ProcessPoolExecutor(max_workers=self.workers)

    def imap_unordered(self, fn, tasks):
        it = iter(tasks)
        pending: dict = {}
        for task in it:
            pending[self._pool.submit(fn, task)] = task
            if len(pending) >= self.max_in_flight:
                break
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                task = pending.pop(fut)
                yield task, fut.result()
                nxt = next(it, None)
                if nxt is not None:
                    pending[self._pool.submit(fn, nxt)] = nxt

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


class DaskExecutor(Executor):
    """Runs tasks on a Dask distributed cluster (optional extra ``coloradar[dask]``).

    Parameters
    ----------
    address
        Scheduler address (``tcp://host:8786``), or None with ``scheduler_file``, or a
        ``distributed.Client`` / ``LocalCluster`` via ``client``.
    scheduler_file
        A scheduler file written by ``dask scheduler --scheduler-file``.
    client
        An existing ``distributed.Client`` (not closed by this executor).
    max_in_flight
        Tasks submitted but not finished at any time (None: 2 × workers).
    """

    def __init__(self, address: str | None = None, scheduler_file: str | None = None,
                 client: Any = None, max_in_flight: int | None = None):
        try:
            from distributed import Client
        except ImportError:
            raise ColoradarError("running on a Dask cluster needs the dask extra: "
                                 "pip install 'coloradar[dask]'") from None
        self._own = client is None
        if client is None:
            if address is None and scheduler_file is None:
                raise ColoradarError("DaskExecutor needs a scheduler address or scheduler file")
            client = Client(address=address, scheduler_file=scheduler_file)
        self.client = client
        nthreads = client.nthreads() if hasattr(client, "nthreads") else {}
        self.workers = max(sum(nthreads.values()), 1) if nthreads else 1
        self.max_in_flight = max_in_flight or 2 * self.workers
        self.description = f"dask cluster {client.scheduler.address}, {self.workers} worker threads"

    def imap_unordered(self, fn, tasks):
        from distributed import as_completed

        it = iter(tasks)
        owner: dict[str, Any] = {}
        ac = as_completed()
        for task in it:
            fut = self.client.submit(fn, task, pure=False)
            owner[fut.key] = task
            ac.add(fut)
            if len(owner) >= self.max_in_flight:
                break
        for fut in ac:
            task = owner.pop(fut.key)
            result = fut.result()
            fut.release()
            yield task, result
            nxt = next(it, None)
            if nxt is not None:
                f = self.client.submit(fn, nxt, pure=False)
                owner[f.key] = nxt
                ac.add(f)

    def close(self) -> None:
        if self._own:
            self.client.close()


def make_executor(jobs: int | None = None, scheduler: str | None = None,
                  scheduler_file: str | None = None) -> Executor:
    """The executor a command line asks for: Dask when given a scheduler, else a local pool
    (``jobs == 1``: serial in this process)."""
    if scheduler or scheduler_file:
        return DaskExecutor(address=scheduler, scheduler_file=scheduler_file)
    if jobs == 1:
        return SerialExecutor()
    return LocalExecutor(jobs)
