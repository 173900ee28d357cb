"""One executor interface over a local process pool, a serial loop, or a Dask cluster.

Work is a function applied to independent tasks (chunks of frames). Workers read their inputs
and write their outputs themselves; only the small value each task returns travels back. At
most ``max_in_flight`` tasks are submitted at once, so memory stays bounded whatever the
number of tasks (the task iterable is consumed lazily).

A task that raises, or whose worker process dies, does not stop the others: with
``errors="return"`` it comes back as a :class:`TaskError` in place of its result.

* :class:`LocalExecutor` starts its workers with the ``spawn`` method (no state inherited from
  the caller, safe when the caller has threads) and replaces a pool broken by a dead worker
  (out-of-memory killer, ``kill -9``): the tasks that were in flight are re-run one at a time,
  so the task that kills its worker is identified and reported, and the others finish. Workers
  exit by themselves when the process that started them dies.
* :class:`DaskExecutor` relies on Dask's own rescheduling of the tasks of lost workers; a task
  that keeps killing workers ends as ``KilledWorker``.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
import time
import warnings
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, Literal, get_args

from ..errors import CalibrationWarning, ColoradarError, DataWarning, MissingDependencyError, SettingsError

__all__ = ["DaskExecutor", "Executor", "LocalExecutor", "SerialExecutor", "TaskError",
           "WorkerStartupError", "make_executor"]

TaskErrors = Literal["raise", "return"]
"""What a failing task does: raise in the caller, or come back as a :class:`TaskError`."""
_ERRORS: tuple[TaskErrors, ...] = get_args(TaskErrors)


@dataclass(frozen=True)
class TaskError:
    """A task that raised or whose worker died, yielded in place of its result.

    Attributes
    ----------
    error
        Name of the exception type (``"FormatError"``, ``"WorkerDied"``, ``"KilledWorker"``).
    message
        Its message.
    """

    error: str
    message: str

    @classmethod
    def from_exception(cls, exc: BaseException) -> TaskError:
        return cls(type(exc).__name__, str(exc))


def _check_errors(errors: TaskErrors) -> None:
    if errors not in _ERRORS:
        raise SettingsError(f"errors must be one of {_ERRORS}, got {errors!r}")


class Executor:
    """Runs ``fn(task)`` for every task; yields ``(task, result)`` as tasks complete."""

    #: Number of parallel workers (for chunking decisions and reports).
    workers: int = 1
    description: str = "executor"

    def imap_unordered(self, fn: Callable[[Any], Any], tasks: Iterable[Any], *,
                       errors: TaskErrors = "raise") -> Iterator[tuple[Any, Any]]:
        """Apply ``fn`` to every task, yielding ``(task, result)`` in completion order.

        Parameters
        ----------
        fn
            A module-level function (it is pickled by reference for process and cluster
            workers).
        tasks
            Any iterable; consumed lazily, at most ``max_in_flight`` ahead of the results.
        errors
            ``"raise"``: an exception of a task is raised here; ``"return"``: it is yielded as
            a :class:`TaskError` result and the other tasks go on.
        """
        raise NotImplementedError

    def close(self) -> None:
        """Release the workers."""

    def terminate(self) -> None:
        """Stop at once (Ctrl-C): tasks in flight are abandoned, not waited for. Every output
        file is written atomically, so an abandoned task leaves nothing a rerun cannot redo."""
        self.close()

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SerialExecutor(Executor):
    """Runs tasks one after the other in this process (debugging, tiny jobs)."""

    description = "serial (this process)"

    def imap_unordered(self, fn: Callable[[Any], Any], tasks: Iterable[Any], *,
                       errors: TaskErrors = "raise") -> Iterator[tuple[Any, Any]]:
        _check_errors(errors)
        for task in tasks:
            try:
                # The task reopens data the caller opened and warned about already (as pool
                # workers do, see _init_worker): the same warning twice would read as two faults.
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", DataWarning)
                    warnings.simplefilter("ignore", CalibrationWarning)
                    result = fn(task)
            except Exception as exc:
                if errors == "raise":
                    raise
                result = TaskError.from_exception(exc)
            yield task, result


def _watch_parent(parent_pid: int) -> None:
    # A pool worker blocks on its task queue forever once its parent is gone (killed with
    # SIGKILL, say); without this it would outlive the job and keep writing.
    while True:
        time.sleep(0.5)
        if os.getppid() != parent_pid:
            os._exit(1)


def _init_worker(parent_pid: int, started: Any = None) -> None:
    # Reaching this line means the worker has imported the caller's main module (what the
    # spawn start method does first) and coloradar: the pool can run tasks.
    if started is not None:
        started.set()
    # Ctrl-C is the parent's to handle: it ends the workers (every file they write is atomic,
    # so a frame cut short is redone by a rerun) and writes its report.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True,
                     name="coloradar-parent-watch").start()
    # The parent opened the same data and has shown these once already.
    warnings.simplefilter("ignore", DataWarning)
    warnings.simplefilter("ignore", CalibrationWarning)


class WorkerDied(ColoradarError):
    """The worker process running a task died (killed, out of memory, crashed)."""


class WorkerStartupError(ColoradarError, RuntimeError):
    """The workers of a local pool died while starting, before any of them could run a task:
    nearly always a script without an ``if __name__ == "__main__":`` guard, whose top-level
    call to the batch functions runs again in every ``spawn``-ed worker."""


def _startup_message(workers: int) -> str:
    main = sys.modules.get("__main__")
    script = getattr(main, "__file__", None)
    where = f" ({script})" if script else ""
    return (f"the {workers} local worker process(es) died while starting, before running any "
            "task. With the 'spawn' start method every worker first imports the main "
            f"module{where}, so a script that calls process_dataset(), process_run() or "
            "process() at its top level runs that call again in each worker, which fails. Put "
            'the call under `if __name__ == "__main__":` (see docs/batch.md), or pass jobs=1; '
            "the workers' own error is printed above")


class LocalExecutor(Executor):
    """A local process pool (``concurrent.futures.ProcessPoolExecutor``, ``spawn`` start).

    Parameters
    ----------
    jobs
        Worker processes (None: all cores).
    max_in_flight
        Tasks submitted but not finished at any time (None: 2 × jobs).
    """

    def __init__(self, jobs: int | None = None, max_in_flight: int | None = None):
        if jobs is not None and jobs < 1:
            raise ColoradarError(f"the number of jobs must be at least 1, got {jobs}")
        self.workers = jobs or os.cpu_count() or 1
        self.max_in_flight = max(max_in_flight or 2 * self.workers, 1)
        self.description = f"local process pool, {self.workers} workers"
        self.restarts = 0
        ctx = multiprocessing.get_context("spawn")
        # Set by the first worker that gets through start-up: a pool that breaks before any
        # worker did is a start-up failure (the caller's script), not a task that killed it.
        self._started = ctx.Event()
        self._pool = self._new_pool()

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(max_workers=self.workers,
                                   mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_init_worker,
                                   initargs=(os.getpid(), self._started))

    def _restart(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = self._new_pool()
        self.restarts += 1

    def imap_unordered(self, fn: Callable[[Any], Any], tasks: Iterable[Any], *,
                       errors: TaskErrors = "raise") -> Iterator[tuple[Any, Any]]:
        _check_errors(errors)
        it = iter(tasks)
        none = object()
        exhausted = False
        pending: dict[Future, Any] = {}
        # Tasks in flight when a worker died: re-run alone, so that the one that kills its
        # worker is known (it fails) and the others complete.
        suspects: deque = deque()
        alone: Any = none
        while True:
            broken = False
            if suspects:
                if not pending:
                    alone = suspects.popleft()
                    broken = not self._submit(pending, fn, alone)
                    if broken:
                        suspects.appendleft(alone)
                        alone = none
            else:
                alone = none
                while not exhausted and len(pending) < self.max_in_flight:
                    task = next(it, none)
                    if task is none:
                        exhausted = True
                    elif not self._submit(pending, fn, task):
                        suspects.append(task)   # never ran; the pool broke meanwhile
                        broken = True
                        break
            if not pending and not broken:
                return
            if broken:
                done = set(pending)
                wait(done)
            else:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                # After a worker death every other task in flight fails too: settle them now.
                if any(isinstance(f.exception(), BrokenProcessPool) for f in done):
                    broken = True
                    done = set(pending)
                    wait(done)
            if broken and not self._started.is_set():
                # No worker ever got through start-up: re-running tasks cannot help, and
                # blaming each task ("worker died, out of memory") would mislead.
                self._pool.shutdown(wait=True, cancel_futures=True)
                raise WorkerStartupError(_startup_message(self.workers))
            for fut in done:
                task = pending.pop(fut)
                exc = fut.exception()
                if isinstance(exc, BrokenProcessPool):
                    if task is not alone:
                        suspects.append(task)
                        continue
                    exc = WorkerDied("the worker process running this task died (killed, out "
                                     "of memory or crashed), also when re-run alone")
                if exc is None:
                    yield task, fut.result()
                elif errors == "raise":
                    raise exc
                else:
                    yield task, TaskError.from_exception(exc)
            if broken:
                self._restart()

    def _submit(self, pending: dict, fn, task) -> bool:
        try:
            pending[self._pool.submit(fn, task)] = task
        except BrokenProcessPool:
            return False
        return True

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)

    def terminate(self) -> None:
        # ProcessPoolExecutor has no public way to stop running tasks (before Python 3.14):
        # end its workers (they ignore SIGINT), then shut it down without waiting.
        procs = list((getattr(self._pool, "_processes", None) or {}).values())
        for proc in procs:
            proc.terminate()
        self._pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.join(timeout=1.0)


def _malloc_trim_threshold() -> str | None:
    return os.environ.get("MALLOC_TRIM_THRESHOLD_")


class DaskExecutor(Executor):
    """Runs tasks on a Dask distributed cluster (optional extra ``coloradar[dask]``).

    The workers must be able to import ``coloradar`` and to read and write the same paths as
    this process (a shared file system).

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
        Tasks submitted but not finished at any time (None: 2 × worker threads, followed as
        workers join or leave).
    wait_for_workers
        Seconds to wait for a first worker when the cluster has none yet.
    """

    def __init__(self, address: str | None = None, scheduler_file: str | None = None,
                 client: Any = None, max_in_flight: int | None = None,
                 wait_for_workers: float = 120.0):
        try:
            from distributed import Client
        except ImportError:
            raise MissingDependencyError("running on a Dask cluster needs the dask extra: "
                                         "pip install 'coloradar[dask]'") from None
        self._own = client is None
        if client is None:
            if address is None and scheduler_file is None:
                raise ColoradarError("DaskExecutor needs a scheduler address or scheduler file")
            if scheduler_file is not None and not os.path.isfile(scheduler_file):
                raise ColoradarError(f"{scheduler_file}: scheduler file not found (start the "
                                     "scheduler with dask scheduler --scheduler-file FILE)")
            try:
                client = Client(address=address, scheduler_file=scheduler_file, timeout="30s")
            except OSError as exc:
                raise ColoradarError(f"cannot reach the Dask scheduler "
                                     f"{address or scheduler_file}: {exc}") from None
        self.client = client
        self._fixed_in_flight = max_in_flight
        if not self._threads():
            try:
                client.wait_for_workers(1, timeout=wait_for_workers)
            except Exception:
                if self._own:
                    client.close()
                raise ColoradarError(f"no Dask worker joined the scheduler "
                                     f"{client.scheduler.address} within {wait_for_workers:g} s "
                                     "(start some with dask worker)") from None
        self.workers = max(self._threads(), 1)
        self.description = f"dask cluster {client.scheduler.address}, {self.workers} worker threads"
        try:
            trims = {v for v in client.run(_malloc_trim_threshold).values() if v is not None}
        except Exception:  # an old or restricted cluster: no advice then
            trims = set()
        if trims:
            warnings.warn(
                f"the Dask workers run with MALLOC_TRIM_THRESHOLD_={min(trims)} (the dask "
                "nanny's default), which makes radar processing about 3x slower (every large "
                "temporary array becomes a fresh mmap); start the workers with dask worker "
                "--no-nanny, or see docs/batch.md", UserWarning, stacklevel=2)

    def _threads(self) -> int:
        return int(sum(self.client.nthreads().values()))

    @property
    def max_in_flight(self) -> int:
        return self._fixed_in_flight or 2 * self.workers

    def imap_unordered(self, fn: Callable[[Any], Any], tasks: Iterable[Any], *,
                       errors: TaskErrors = "raise") -> Iterator[tuple[Any, Any]]:
        from distributed import as_completed

        _check_errors(errors)
        it = iter(tasks)
        owner: dict[str, Any] = {}
        ac = as_completed()
        sentinel = object()

        def top_up() -> None:
            while len(owner) < self.max_in_flight:
                task = next(it, sentinel)
                if task is sentinel:
                    return
                fut = self.client.submit(fn, task, pure=False)
                owner[fut.key] = task
                ac.add(fut)

        top_up()
        for n, fut in enumerate(ac, 1):
            task = owner.pop(fut.key)
            try:
                result = fut.result()
            except Exception as exc:
                if errors == "raise":
                    raise
                result = TaskError.from_exception(exc)
            finally:
                fut.release()
            yield task, result
            if n % 16 == 0:  # follow workers joining or leaving (adaptive clusters)
                self.workers = max(self._threads(), 1)
            top_up()

    def close(self) -> None:
        if self._own:
            self.client.close()


def make_executor(jobs: int | None = None, scheduler: str | None = None,
                  scheduler_file: str | None = None) -> Executor:
    """The executor a command line asks for: Dask when given a scheduler, else a local pool
    (``jobs == 1``: serial in this process; None: one worker per core)."""
    if scheduler or scheduler_file:
        return DaskExecutor(address=scheduler, scheduler_file=scheduler_file)
    if jobs is not None and jobs < 1:
        raise ColoradarError(f"the number of jobs must be at least 1, got {jobs}")
    if jobs == 1:
        return SerialExecutor()
    return LocalExecutor(jobs)
