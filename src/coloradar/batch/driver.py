"""Process the ADC frames of one run or a whole dataset through one executor.

The driver plans (opens every run, picks its frames), checks every output folder before it
writes anything (nothing inside a run; a manifest that agrees with the settings, or
``overwrite``), locks them, finds the frames already complete, and hands chunks of the others
to an executor — a local process pool, this process, or a Dask cluster, one code path. As a
radar of a run finishes, its ``timestamps.txt`` (and ``heatmap_cfg.txt``) are rewritten from
the frames complete on disk. At the end, or when interrupted, ``process_report.json`` records
what was done and what failed.

Resuming: frames whose product files are all complete (:mod:`.layout`) are skipped; the rest
are processed, so a killed job rerun with the same command finishes the work and gives the
same bytes as an uninterrupted one. ``overwrite`` deletes the requested products' frame files
first and redoes every frame.
"""

from __future__ import annotations

import fnmatch
import math
import os
import time
import warnings
from collections.abc import Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..calib import RADARS, Calibration, format_heatmap_cfg
from ..dataset import FrameStream, find_runs, open_sequence
from ..dataset.dataset import is_run_folder
from ..dsp import ProcessingSettings, RadarProcessor
from ..errors import ColoradarError, DataWarning, MissingDataError, OutputExistsError, WriteError
from ..formats import heatmap_nbytes
from ..formats.atomic import make_output_dir, write_text_if_changed
from ..formats.layout import LAYOUTS
from ..progress import Progress
from .chunks import FrameChunk, FrameFailure, process_chunk
from .executors import Executor, TaskError, WorkerStartupError, make_executor
from .layout import (
    PRODUCTS,
    clean_partial_files,
    frame_file,
    output_paths,
    product_has_output,
    remove_product_output,
    timestamps_text,
    valid_frames,
)
from .manifest import (
    OutputLock,
    calibration_fingerprint,
    input_versions,
    read_manifest,
    settings_differences,
    settings_record,
    stale_frames,
    write_manifest,
)
from .report import REPORT, BatchReport, RadarOutcome, RunOutcome

__all__ = ["DEFAULT_CHUNK_SIZE", "RunTarget", "check_products", "process", "process_dataset",
           "process_targets"]

DEFAULT_CHUNK_SIZE = 16
"""Frames per task: long enough (≈ 0.5–1 s) that scheduling costs nothing, short enough that
a killed job loses little and the progress line moves."""

CalibLike = Calibration | str | os.PathLike | None


@dataclass(frozen=True)
class RunTarget:
    """A run to process and the folder its products go to."""

    path: Path
    out: Path


@dataclass
class _RadarJob:
    radar: str
    stream: FrameStream
    calib_key: str
    settings_rec: dict
    positions: list[int]
    heatmap_bytes: int
    heatmap_cfg: str
    outcome: RadarOutcome
    inputs: dict[str, str] = field(default_factory=dict)
    todo: list[int] = field(default_factory=list)
    chunks_left: int = 0
    unsure: list[tuple[int, TaskError]] = field(default_factory=list)


@dataclass
class _RunJob:
    target: RunTarget
    name: str
    outcome: RunOutcome
    radars: list[_RadarJob] = field(default_factory=list)


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


# Folders of a run that ``process`` never writes: an output folder holding one is a run.
_RUN_PARTS = tuple(dict.fromkeys(
    m for lay in LAYOUTS.values() for m in lay.run_markers
    if not any(m == s.folder for s in lay.frames.values()
               if s.sensor in lay.radars and s.product in PRODUCTS)))


def _check_target(t: RunTarget) -> None:
    run, out = t.path.resolve(), t.out.resolve()
    probe = out  # the output folder, or the nearest of its parents that exists
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise WriteError(f"{t.out}: expected an output folder, but {probe} is a file")
    if _inside(out, run):
        raise ColoradarError(f"{t.out}: the output folder lies inside the run {t.path}; choose "
                             "an output folder outside it (coloradar never writes into a run)")
    found = [p for p in _RUN_PARTS if (out / p).exists()]
    if found:
        raise ColoradarError(f"{t.out}: this is a ColoRadar run (it has {', '.join(found)}), "
                             "not an output folder; coloradar never writes into a run")


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


def _plan_run(t: RunTarget, calib: CalibLike, radars, frames: slice | None,
              settings: ProcessingSettings | None, strict: bool) -> _RunJob:
    seq = open_sequence(t.path, calib=calib)
    job = _RunJob(t, seq.name, RunOutcome(seq.name, str(t.path), str(t.out)))
    rec = settings_record(settings)
    for radar in _chosen_radars(seq, radars, strict, job.outcome):
        rc = seq.calib.radar(radar)
        try:
            stream = seq.radar(radar).adc
        except ColoradarError as exc:
            if strict:
                raise
            job.outcome.radars[radar] = RadarOutcome(error=str(exc))
            continue
        positions = list(range(len(stream)))
        if frames is not None:
            positions = positions[frames]
        hcfg = RadarProcessor(rc, settings).heatmap_config()
        job.radars.append(_RadarJob(
            radar, stream, calibration_fingerprint(rc), rec, positions,
            heatmap_nbytes(hcfg.shape), format_heatmap_cfg(hcfg),
            RadarOutcome(frames=len(positions)), input_versions(stream)))
        job.outcome.radars[radar] = job.radars[-1].outcome
    return job


def _conflicts(job: _RunJob, prods: tuple[str, ...], overwrite: bool) -> list[str]:
    """Why this run's output may not be resumed (empty: it may)."""
    if overwrite or not job.radars:
        return []
    out = job.target.out
    manifest = read_manifest(out)
    entries = manifest["products"] if manifest else {}
    if manifest and manifest.get("coloradar_version") != __version__:
        warnings.warn(f"{out}: resuming output made by coloradar "
                      f"{manifest.get('coloradar_version')} with {__version__}; pass "
                      "--overwrite to redo it all with this version", UserWarning, stacklevel=3)
    found = []
    for rj in job.radars:
        for p in prods:
            folder = output_paths(out, rj.radar, p)[0]
            entry = entries.get(f"{rj.radar}/{p}")
            if entry is None:
                if product_has_output(out, rj.radar, p):
                    found.append(f"{folder} holds output that has no entry in the manifest "
                                 "(made by something else or an older coloradar)")
                continue
            diffs = settings_differences(entry.get("settings", {}), rj.settings_rec)
            if entry.get("calibration_sha256") != rj.calib_key:
                diffs.append("the radar calibration differs")
            if diffs:
                found.append(f"{folder} was made with other settings ({'; '.join(diffs)})")
    return found


def _prepare(job: _RunJob, prods: tuple[str, ...], overwrite: bool) -> None:
    """Under the lock: clear what ``overwrite`` replaces, remove partial files, record the
    settings, and find the frames still to do."""
    out = job.target.out
    make_output_dir(out)
    try:
        manifest = read_manifest(out)
    except OutputExistsError:
        if not overwrite:
            raise
        manifest = None
    entries = dict(manifest["products"]) if manifest else {}
    folders = [out]
    for rj in job.radars:
        for p in prods:
            folder, data = output_paths(out, rj.radar, p)
            if overwrite:
                if f"{rj.radar}/{p}" in entries:
                    remove_product_output(out, rj.radar, p)
                elif product_has_output(out, rj.radar, p):
                    # Not recorded as ours (a downloaded dataset's heatmaps, say): never delete.
                    raise OutputExistsError(
                        f"{folder}: holds {p} that process_manifest.json does not record as "
                        "made by coloradar; not deleting them, even with --overwrite: choose "
                        "another output folder")
            make_output_dir(data)
            folders += [folder, data]
            entries[f"{rj.radar}/{p}"] = {"settings": rj.settings_rec,
                                          "calibration_sha256": rj.calib_key}
    clean_partial_files(folders)
    inputs = dict((manifest or {}).get("inputs") or {})  # radars not processed now stay
    for rj in job.radars:
        if not overwrite:
            _remove_stale(manifest, out, rj)
        inputs[rj.radar] = rj.inputs
    write_manifest(out, job.name, entries, inputs)
    for rj in job.radars:
        complete = set.intersection(*(valid_frames(out, rj.radar, p, rj.heatmap_bytes)
                                      for p in prods))
        ids = rj.stream.frame_ids
        rj.todo = [k for k in rj.positions if int(ids[k]) not in complete]
        rj.outcome.skipped = len(rj.positions) - len(rj.todo)


def _remove_stale(manifest: dict | None, out: Path, rj: _RadarJob) -> None:
    """Delete the product files of frames whose input was rewritten since they were made (a
    re-simulated run, a repaired file): they are stale, and ours (the manifest records them),
    so they are redone rather than resumed. Every product the manifest records is cleared,
    requested now or not, so that none is later taken as made from the new input."""
    recorded = (manifest or {}).get("products") or {}
    prods = [p for p in PRODUCTS if f"{rj.radar}/{p}" in recorded]
    have = set().union(*(valid_frames(out, rj.radar, p, rj.heatmap_bytes) for p in prods))
    stale = stale_frames(manifest, rj.radar, rj.inputs, have)
    if not stale:
        return
    for i in stale:
        for p in prods:
            frame_file(out, rj.radar, p, i).unlink(missing_ok=True)
    warnings.warn(f"{out / rj.radar}: the ADC files of {len(stale)} frame(s) changed since their "
                  f"output was made (first: frame {stale[0]}); processing them again",
                  DataWarning, stacklevel=4)


def _finish_radar(job: _RunJob, rj: _RadarJob, prods: tuple[str, ...]) -> None:
    """A radar's chunks are all back: settle lost chunks from the disk, write timestamps."""
    out = job.target.out
    ids = np.asarray(rj.stream.frame_ids)
    valid = {p: valid_frames(out, rj.radar, p, rj.heatmap_bytes) for p in prods}
    complete = set.intersection(*valid.values())
    for k, err in rj.unsure:
        if int(ids[k]) in complete:  # written before its worker died
            rj.outcome.done += 1
        else:
            rj.outcome.failures.append(FrameFailure(k, int(ids[k]), rj.stream.path(k),
                                                    err.error, err.message))
    rj.unsure.clear()
    known = set(ids.tolist())
    for p in prods:
        folder = output_paths(out, rj.radar, p)[0]
        written = np.array(sorted(valid[p] & known), dtype=np.int64)
        if p == "heatmaps":
            write_text_if_changed(folder / "heatmap_cfg.txt", rj.heatmap_cfg)
        write_text_if_changed(folder / "timestamps.txt",
                          timestamps_text(ids, np.asarray(rj.stream.timestamps), written))


def _tasks(jobs: list[_RunJob], calib: CalibLike, prods: tuple[str, ...],
           settings: ProcessingSettings | None, chunk_size: int) -> Iterator[FrameChunk]:
    # A path travels as a string (workers load and cache it); an object as itself.
    cal = calib if isinstance(calib, Calibration) or calib is None else str(Path(calib).resolve())
    for job in jobs:
        run, out = str(job.target.path.resolve()), str(job.target.out.resolve())
        for rj in job.radars:
            ids = rj.stream.frame_ids
            for s in range(0, len(rj.todo), chunk_size):
                pos = tuple(rj.todo[s: s + chunk_size])
                yield FrameChunk(run, cal, rj.calib_key, rj.radar, prods, pos,
                                 tuple(int(ids[k]) for k in pos), out, settings)


def _frames_text(frames: slice | None) -> str | None:
    if frames is None:
        return None
    start = "" if frames.start is None else frames.start
    stop = "" if frames.stop is None else frames.stop
    return f"{start}:{stop}"


def process_targets(targets: Sequence[RunTarget], report_path: str | os.PathLike | None, *,
                    calib: CalibLike = None, radars: str | Sequence[str] = "all",
                    products: Sequence[str] = PRODUCTS, frames: slice | None = None,
                    overwrite: bool = False, settings: ProcessingSettings | None = None,
                    executor: Executor | None = None, jobs: int | None = 1,
                    chunk_size: int = DEFAULT_CHUNK_SIZE, progress: bool = True,
                    strict: bool = False, desc: str = "process") -> BatchReport:
    """Process runs, each into its own output folder, through one executor.

    Parameters
    ----------
    targets
        Runs and their output folders.
    report_path
        Where to write the JSON report (None: not written).
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

    Returns
    -------
    BatchReport
    """
    t0 = time.perf_counter()
    prods = check_products(products)
    if chunk_size < 1:
        raise ColoradarError(f"chunk size must be at least 1 frame, got {chunk_size}")
    report = BatchReport(options={
        "products": list(prods), "radars": radars if isinstance(radars, str) else list(radars),
        "frames": _frames_text(frames), "chunk_size": chunk_size, "overwrite": overwrite,
        "settings": settings_record(settings)})
    if radars != "all":
        for r in [radars] if isinstance(radars, str) else radars:
            if r not in RADARS:
                raise MissingDataError(f"unknown radar {r!r}; expected one of "
                                       f"{', '.join(RADARS)} or all")
    for t in targets:
        _check_target(t)
    planned: list[_RunJob] = []
    for t in targets:
        try:
            job = _plan_run(t, calib, radars, frames, settings, strict)
        except ColoradarError as exc:
            if strict:
                raise
            name = t.path.name.removesuffix(".zip")
            report.runs[name] = RunOutcome(name, str(t.path), str(t.out), error=str(exc))
            continue
        report.runs[job.name] = job.outcome
        planned.append(job)
    conflicts = [c for job in planned for c in _conflicts(job, prods, overwrite)]
    if conflicts:
        more = f"; and {len(conflicts) - 3} more" if len(conflicts) > 3 else ""
        raise OutputExistsError("output exists: " + "; ".join(conflicts[:3]) + more
                                + "; rerun with the "
                                "same settings to resume it, or pass overwrite=True "
                                "(--overwrite) to redo it")
    active = [job for job in planned if job.radars]
    with ExitStack() as stack:
        for job in active:
            stack.enter_context(OutputLock(job.target.out))
        for job in active:
            _prepare(job, prods, overwrite)
        chunks = {}
        for job in active:
            for rj in job.radars:
                rj.chunks_left = math.ceil(len(rj.todo) / chunk_size)
                chunks[(str(job.target.out.resolve()), rj.radar)] = (job, rj)
        total = sum(len(rj.todo) for job in active for rj in job.radars)
        bar = Progress(total, desc=desc, enabled=progress and total > 0)
        ex = executor
        try:
            for job in active:
                for rj in job.radars:
                    if rj.chunks_left == 0:
                        _finish_radar(job, rj, prods)
            if total:
                if ex is None:
                    # No more workers than tasks: one task runs here, without a pool.
                    n_tasks = sum(rj.chunks_left for job in active for rj in job.radars)
                    ex = make_executor(min(jobs or os.cpu_count() or 1, n_tasks))
                report.executor = ex.description
                tasks = _tasks(active, calib, prods, settings, chunk_size)
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
            else:
                report.executor = "nothing to do"
        except WorkerStartupError as exc:
            report.error = str(exc)
            raise
        except BaseException:
            report.interrupted = True
            raise
        finally:
            bar.close()
            if ex is not None and executor is None:
                ex.close()
            report.finish(time.perf_counter() - t0)
            if report_path is not None:
                rp = Path(report_path)
                make_output_dir(rp.parent)
                clean_partial_files([rp.parent], rp.name)
                report.write(report_path)
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
                    runs: Sequence[str] | None = None, **options) -> BatchReport:
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
        As for :func:`process_targets` (``calib``, ``radars``, ``products``, ``frames``,
        ``overwrite``, ``settings``, ``executor``, ``jobs``, ``chunk_size``, ``progress``).

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
    options.setdefault("desc", f"process {len(targets)} runs")
    return process_targets(targets, out_p / REPORT, **options)


def process(path: str | os.PathLike, out: str | os.PathLike, *,
            runs: Sequence[str] | None = None, **options) -> BatchReport:
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
        options.setdefault("desc", p.name.removesuffix(".zip"))
        return process_targets([RunTarget(p, Path(out))], Path(out) / REPORT, strict=True,
                               **options)
    return process_dataset(p, out, runs=runs, **options)
