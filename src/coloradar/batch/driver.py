"""Process the ADC frames of one run or a whole dataset through one executor.

The driver plans (opens every run, picks its frames) and dispatches chunks of frames to an
executor — a local process pool, this process, or a Dask cluster, one code path. Everything
about a run's output folder — whether it may be written, its manifest, lock, valid and stale
frames, partial files, timestamps files — it asks of :mod:`.output_folder`, in three calls:
:meth:`~.output_folder.JobOutputs.open` checks every folder before anything is written (nothing
inside a run; a manifest that agrees with the settings, or ``overwrite``), locks and prepares
each, and says which frames are complete and where new ones go; as a radar of a run finishes,
:meth:`~.output_folder.ProcessedRun.finish_radar` rewrites its ``timestamps.txt`` (and
``heatmap_cfg.txt``) from the frames complete on disk; at the end, or when interrupted,
:meth:`~.output_folder.JobOutputs.close` writes ``process_report.json`` (what was done and what
failed) and releases the locks.

Resuming: frames whose product files are all complete are skipped; the rest are processed, so a
killed job rerun with the same command finishes the work and gives the same bytes as an
uninterrupted one. ``overwrite`` deletes the requested products' frame files first and redoes
every frame.

What to do travels as one :class:`ProcessingJob` (the keyword options of :func:`process`,
:func:`process_dataset` and :func:`process_targets` are its fields).
"""

from __future__ import annotations

import dataclasses
import fnmatch
import math
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..calib import RADARS, Calibration, format_heatmap_cfg
from ..dataset import FrameStream, find_runs, open_sequence
from ..dataset.dataset import is_run_folder
from ..dsp import ProcessingSettings, RadarProcessor
from ..errors import ColoradarError, MissingDataError
from ..formats import heatmap_nbytes
from ..progress import Progress
from .chunks import FrameChunk, FrameFailure, process_chunk
from .executors import Executor, TaskError, WorkerStartupError, make_executor
from .manifest import calibration_fingerprint, input_versions, settings_record
from .output_folder import (
    PRODUCTS,
    FolderPlan,
    JobOutputs,
    OutputRequest,
    RadarProducts,
    check_folders,
)
from .report import REPORT, BatchReport, RadarOutcome, RunOutcome

__all__ = ["DEFAULT_CHUNK_SIZE", "ProcessingJob", "RunTarget", "check_products", "process",
           "process_dataset", "process_targets"]

DEFAULT_CHUNK_SIZE = 16
"""Frames per task: long enough (≈ 0.5–1 s) that scheduling costs nothing, short enough that
a killed job loses little and the progress line moves."""

CalibLike = Calibration | str | os.PathLike | None


@dataclass(frozen=True)
class RunTarget:
    """A run to process and the folder its products go to."""

    path: Path
    out: Path


@dataclass(frozen=True)
class ProcessingJob:
    """What to process, how, and where the work runs: the options of :func:`process_targets`.

    Attributes
    ----------
    calib
        Calibration object or calib folder/zip; None finds it beside each run.
    radars
        ``"all"`` (every radar with ADC frames), a radar name, or a list of names.
    products
        ``"heatmaps"`` and/or ``"pointclouds"``.
    frames
        Positions in each ADC stream (a slice); None = all.
    overwrite
        Delete the requested products' frame files and redo every frame; otherwise resume
        (complete frames are kept) when the manifest's settings agree, and refuse when not.
    settings
        Processing settings.
    executor
        Where chunks run; None: ``make_executor(jobs)`` (closed at the end).
    jobs
        Local worker processes when no executor is given (1: this process; None: all cores).
    chunk_size
        Frames per task.
    progress
        Progress line on stderr.
    strict
        Raise on a run that cannot be processed (single-run use) instead of recording it.
    desc
        Label of the progress line.
    """

    calib: CalibLike = None
    radars: str | Sequence[str] = "all"
    products: Sequence[str] = PRODUCTS
    frames: slice | None = None
    overwrite: bool = False
    settings: ProcessingSettings | None = None
    executor: Executor | None = None
    jobs: int | None = 1
    chunk_size: int = DEFAULT_CHUNK_SIZE
    progress: bool = True
    strict: bool = False
    desc: str = "process"

    @classmethod
    def of(cls, job: ProcessingJob | None = None, **options: Any) -> ProcessingJob:
        """``job`` (default: all defaults) with the keyword ``options`` replacing its fields."""
        return dataclasses.replace(job or cls(), **options)


@dataclass
class _RadarJob:
    products: RadarProducts
    stream: FrameStream
    positions: list[int]
    outcome: RadarOutcome
    todo: list[int] = field(default_factory=list)
    chunks_left: int = 0
    unsure: list[tuple[int, TaskError]] = field(default_factory=list)

    @property
    def radar(self) -> str:
        return self.products.radar


@dataclass
class _RunJob:
    target: RunTarget
    name: str
    outcome: RunOutcome
    radars: list[_RadarJob] = field(default_factory=list)
    plan: FolderPlan | None = None  # its output folder, once opened

    @property
    def output(self) -> FolderPlan:
        assert self.plan is not None, "the output folder is opened before any work"
        return self.plan


def check_products(products: Sequence[str]) -> tuple[str, ...]:
    """The products asked for, deduplicated; a ColoradarError for unknown ones."""
    prods = tuple(dict.fromkeys(products))
    bad = [p for p in prods if p not in PRODUCTS]
    if bad or not prods:
        raise ColoradarError(f"unknown product(s) {', '.join(bad) or '(none)'}; expected one or "
                             f"both of {', '.join(PRODUCTS)}")
    return prods


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def _check_radars(radars: str | Sequence[str]) -> None:
    if radars != "all":
        for r in [radars] if isinstance(radars, str) else radars:
            if r not in RADARS:
                raise MissingDataError(f"unknown radar {r!r}; expected one of "
                                       f"{', '.join(RADARS)} or all")


def _chosen_radars(seq, radars: str | Sequence[str], strict: bool,
                   outcome: RunOutcome) -> list[str]:
    have = [r for r in RADARS if f"{r}/adc" in seq.available()]
    present = ", ".join(seq.available()) or "nothing"
    if radars == "all":
        if not have:
            msg = f"no radar ADC frames in this run (present: {present})"
            if strict:
                raise MissingDataError(f"{seq.location}: {msg}")
            outcome.note = msg
        return have
    wanted = [radars] if isinstance(radars, str) else list(radars)
    missing = [r for r in wanted if r not in have]
    if missing:
        msg = f"no {' or '.join(missing)} ADC frames in this run (present: {present})"
        if strict:
            raise MissingDataError(f"{seq.location}: {msg}")
        outcome.note = msg
    return [r for r in wanted if r in have]


def _plan_run(t: RunTarget, opts: ProcessingJob) -> _RunJob:
    seq = open_sequence(t.path, calib=opts.calib)
    job = _RunJob(t, seq.name, RunOutcome(seq.name, str(t.path), str(t.out)))
    rec = settings_record(opts.settings)
    for radar in _chosen_radars(seq, opts.radars, opts.strict, job.outcome):
        rc = seq.calib.radar(radar)
        try:
            stream = seq.radar(radar).adc
        except ColoradarError as exc:
            if opts.strict:
                raise
            job.outcome.radars[radar] = RadarOutcome(error=str(exc))
            continue
        positions = list(range(len(stream)))
        if opts.frames is not None:
            positions = positions[opts.frames]
        hcfg = RadarProcessor(rc, opts.settings).heatmap_config()
        made = RadarProducts(radar, rec, calibration_fingerprint(rc), heatmap_nbytes(hcfg.shape),
                             format_heatmap_cfg(hcfg), input_versions(stream))
        outcome = RadarOutcome(frames=len(positions))
        if opts.frames is None:
            # A frame file whose time is not a number cannot be placed in the output's
            # timeline: it is not processed, and said as a failed frame (position -1: it is
            # not in the stream), so that the job does not end as if all were well.
            outcome.frames += len(stream.untimed)
            outcome.failures += [FrameFailure(-1, fid, path, "FormatError",
                                              "its timestamp is not a finite number")
                                 for fid, path in stream.untimed]
        job.radars.append(_RadarJob(made, stream, positions, outcome))
        job.outcome.radars[radar] = job.radars[-1].outcome
    return job


def _plan(targets: Sequence[RunTarget], opts: ProcessingJob,
          report: BatchReport) -> tuple[list[_RunJob], list[OutputRequest]]:
    """Open every run and pick its radars and frames; a run that cannot be opened is recorded
    in ``report`` (or raised with ``strict``). Returns the runs opened and what every target
    asks of its output folder (nothing to write for a run that could not be opened)."""
    planned: list[_RunJob] = []
    requests: list[OutputRequest] = []
    for t in targets:
        try:
            job = _plan_run(t, opts)
        except ColoradarError as exc:
            if opts.strict:
                # An output folder that may not be written is said first, as if checked before
                # any run was opened (JobOutputs.open checks them all, after the runs).
                check_folders([(u.path, u.out) for u in targets])
                raise
            name = t.path.name.removesuffix(".zip")
            report.runs[name] = RunOutcome(name, str(t.path), str(t.out), error=str(exc))
            requests.append(OutputRequest(t.path, t.out, name))
            continue
        report.runs[job.name] = job.outcome
        planned.append(job)
        requests.append(OutputRequest(t.path, t.out, job.name,
                                      [rj.products for rj in job.radars]))
    return planned, requests


def _set_todo(job: _RunJob, complete: dict[str, set[int]], chunk_size: int) -> None:
    """The frames still to do, given each radar's complete frame numbers."""
    for rj in job.radars:
        ids = rj.stream.frame_ids
        rj.todo = [k for k in rj.positions if int(ids[k]) not in complete[rj.radar]]
        rj.outcome.skipped = len(rj.positions) - len(rj.todo)
        rj.chunks_left = math.ceil(len(rj.todo) / chunk_size)


def _finish_radar(job: _RunJob, rj: _RadarJob, prods: tuple[str, ...]) -> None:
    """A radar's chunks are all back: write its timestamps, settle lost chunks from the disk."""
    ids = np.asarray(rj.stream.frame_ids)
    complete = job.output.folder.finish_radar(rj.products, prods, ids,
                                              np.asarray(rj.stream.timestamps))
    for k, err in rj.unsure:
        if int(ids[k]) in complete:  # written before its worker died
            rj.outcome.done += 1
        else:
            rj.outcome.failures.append(FrameFailure(k, int(ids[k]), rj.stream.path(k),
                                                    err.error, err.message))
    rj.unsure.clear()


def _tasks(jobs: list[_RunJob], opts: ProcessingJob,
           prods: tuple[str, ...]) -> Iterator[FrameChunk]:
    # A path travels as a string (workers load and cache it); an object as itself.
    calib = opts.calib
    cal = calib if isinstance(calib, Calibration) or calib is None else str(Path(calib).resolve())
    for job in jobs:
        run, out = str(job.target.path.resolve()), job.output.location
        for rj in job.radars:
            ids, files = rj.stream.frame_ids, job.output.frame_files[rj.radar]
            for s in range(0, len(rj.todo), opts.chunk_size):
                pos = tuple(rj.todo[s: s + opts.chunk_size])
                yield FrameChunk(run, cal, rj.products.calibration_sha256, rj.radar, prods, pos,
                                 tuple(int(ids[k]) for k in pos), out, files, opts.settings)


def _frames_text(frames: slice | None) -> str | None:
    if frames is None:
        return None
    start = "" if frames.start is None else frames.start
    stop = "" if frames.stop is None else frames.stop
    return f"{start}:{stop}"


def _run_chunks(active: list[_RunJob], opts: ProcessingJob, prods: tuple[str, ...],
                report: BatchReport, bar: Progress) -> None:
    """Finish the radars with nothing to do, hand the others' chunks to the executor, record
    what comes back, and finish each radar as its last chunk returns."""
    chunks = {(job.output.location, rj.radar): (job, rj)
              for job in active for rj in job.radars}
    for job in active:
        for rj in job.radars:
            if rj.chunks_left == 0:
                _finish_radar(job, rj, prods)
    n_tasks = sum(rj.chunks_left for job in active for rj in job.radars)
    if not n_tasks:
        report.executor = "nothing to do"
        return
    # No more workers than tasks: one task runs here, without a pool.
    ex = (opts.executor if opts.executor is not None
          else make_executor(min(opts.jobs or os.cpu_count() or 1, n_tasks)))
    stopped = False
    try:
        report.executor = ex.description
        tasks = _tasks(active, opts, prods)
        for chunk, res in ex.imap_unordered(process_chunk, tasks, errors="return"):
            job, rj = chunks[(chunk.out, chunk.radar)]
            if isinstance(res, TaskError):
                rj.unsure += [(k, res) for k in chunk.positions]
                bar.update(len(chunk.positions), failed=len(chunk.positions))
            else:
                rj.outcome.done += len(res.done)
                rj.outcome.failures += res.failures
                rj.outcome.worker_seconds += res.seconds
                report.workers[res.worker] = max(report.workers.get(res.worker, 0),
                                                 res.peak_memory)
                bar.update(len(chunk.positions), failed=len(res.failures))
            rj.chunks_left -= 1
            if rj.chunks_left == 0:
                _finish_radar(job, rj, prods)
    except KeyboardInterrupt:
        stopped = True  # Ctrl-C: stop within a second, not after the chunks in flight
        raise
    finally:
        if opts.executor is None:
            ex.terminate() if stopped else ex.close()


def process_targets(targets: Sequence[RunTarget], report_path: str | os.PathLike | None,
                    job: ProcessingJob | None = None, **options: Any) -> BatchReport:
    """Process runs, each into its own output folder, through one executor.

    Parameters
    ----------
    targets
        Runs and their output folders.
    report_path
        Where to write the JSON report (None: not written).
    job
        What to do (default: :class:`ProcessingJob`'s defaults).
    **options
        Fields of :class:`ProcessingJob` that replace ``job``'s (``calib``, ``radars``,
        ``products``, ``frames``, ``overwrite``, ``settings``, ``executor``, ``jobs``,
        ``chunk_size``, ``progress``, ``strict``, ``desc``).

    Returns
    -------
    BatchReport
    """
    t0 = time.perf_counter()
    opts = ProcessingJob.of(job, **options)
    prods = check_products(opts.products)
    if opts.chunk_size < 1:
        raise ColoradarError(f"chunk size must be at least 1 frame, got {opts.chunk_size}")
    radars = opts.radars
    report = BatchReport(options={
        "products": list(prods), "radars": radars if isinstance(radars, str) else list(radars),
        "frames": _frames_text(opts.frames), "chunk_size": opts.chunk_size,
        "overwrite": opts.overwrite, "settings": settings_record(opts.settings)})
    _check_radars(radars)
    planned, requests = _plan(targets, opts, report)
    # The folders are asked everything at once: checked (all before any is written), locked,
    # prepared; what comes back is which frames are complete and where new ones go.
    outputs = JobOutputs.open(requests, prods, opts.overwrite)
    active = [job for job in planned if job.radars]
    bar = None
    try:
        for rjob, plan in zip(active, outputs.plans, strict=True):
            rjob.plan = plan
            _set_todo(rjob, plan.complete, opts.chunk_size)
        total = sum(len(rj.todo) for rjob in active for rj in rjob.radars)
        # A resumed job counts the frames already complete too (46/149, not 0/103).
        skipped = sum(rj.outcome.skipped for rjob in active for rj in rjob.radars)
        bar = Progress(total + skipped, desc=opts.desc, enabled=opts.progress and total > 0,
                       initial=skipped)
        _run_chunks(active, opts, prods, report, bar)
    except WorkerStartupError as exc:
        report.error = str(exc)
        raise
    except BaseException:
        report.interrupted = True
        raise
    finally:
        if bar is not None:
            bar.close()
        report.finish(time.perf_counter() - t0)
        # The report first, then the locks: a job's folder is not released half-reported.
        report.path = outputs.close(report_path, report.to_text())
    return report


def _select_runs(found: dict[str, Path], patterns: Sequence[str], root: Path) -> dict[str, Path]:
    chosen: dict[str, Path] = {}
    for pat in patterns:
        hits = [n for n in found if fnmatch.fnmatchcase(n, pat)]
        if not hits:
            raise MissingDataError(f"{root}: no run matches {pat!r} (runs: "
                                   f"{', '.join(found) or 'none'})")
        chosen.update((n, found[n]) for n in hits)
    return dict(sorted(chosen.items()))


def process_dataset(root: str | os.PathLike, out: str | os.PathLike, *,
                    runs: Sequence[str] | None = None, **options: Any) -> BatchReport:
    """Process every run (folder or zip) of a dataset root; run ``<name>`` goes to
    ``out/<name>/``, laid out as :func:`~coloradar.batch.run_processing.process_run` lays out
    its output, and the report to ``out/process_report.json``.

    Parameters
    ----------
    root
        Dataset folder holding run folders and/or run zips (and ``calib/``).
    out
        Output root.
    runs
        Run names or shell patterns (``"*_hallways_*"``) to process; None = all.
    **options
        As for :func:`process_targets`: ``job`` (a :class:`ProcessingJob`) and/or its fields
        (``calib``, ``radars``, ``products``, ``frames``, ``overwrite``, ``settings``,
        ``executor``, ``jobs``, ``chunk_size``, ``progress``).

    Returns
    -------
    BatchReport
    """
    root_p, out_p = Path(root), Path(out)
    if not root_p.is_dir():
        raise MissingDataError(f"{root_p}: dataset root folder not found")
    out_r = out_p.resolve()
    # An output folder kept inside the root is not a run of it.
    found = {n: p for n, p in find_runs(root_p).items() if not _inside(p.resolve(), out_r)}
    if runs is not None:
        found = _select_runs(found, runs, root_p)
    if not found:
        raise MissingDataError(f"{root_p}: no runs (run folders or run .zip files) in this "
                               "folder")
    targets = [RunTarget(p, out_p / n) for n, p in found.items()]
    if "job" not in options:
        options.setdefault("desc", f"process {len(targets)} runs")
    return process_targets(targets, out_p / REPORT, **options)


def process(path: str | os.PathLike, out: str | os.PathLike, *,
            runs: Sequence[str] | None = None, **options: Any) -> BatchReport:
    """``coloradar process``: one run (folder or zip) into ``out``, or a dataset root's runs
    into ``out/<run>/`` (:func:`process_dataset`); the report goes to
    ``out/process_report.json``.

    Parameters
    ----------
    path
        A run folder, a run zip, or a dataset root.
    out
        Output folder.
    runs
        With a dataset root: run names or shell patterns to process.
    **options
        As for :func:`process_targets`.
    """
    p = Path(path)
    if not p.exists():
        raise MissingDataError(f"{p}: no such run or dataset folder")
    if p.suffix == ".zip" or is_run_folder(p):
        if runs is not None:
            raise ColoradarError(f"{p} is a run; runs can be selected only from a dataset root")
        if "job" not in options:
            options.setdefault("desc", p.name.removesuffix(".zip"))
        return process_targets([RunTarget(p, Path(out))], Path(out) / REPORT, strict=True,
                               **options)
    return process_dataset(p, out, runs=runs, **options)
