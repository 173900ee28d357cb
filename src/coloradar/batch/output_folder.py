"""A processed run's output folder: its paths, manifest, valid and stale frames, lock and files.

One run's output (``OUT`` for ``coloradar process RUN``, ``OUT/<run name>`` for a dataset) is laid
out as a ColoRadar run (:data:`coloradar.formats.layout.COLORADAR`), so that ``open_sequence``
reads it back::

    <out>/process_manifest.json                      what the products were made with
    <out>/.process.lock                              held while a job writes the folder
    <out>/<radar>/heatmaps/{timestamps.txt, heatmap_cfg.txt, data/heatmap_<i>.bin}
    <out>/<radar>/pointclouds/{timestamps.txt, data/radar_pointcloud_<i>.bin}

:class:`ProcessedRun` is the one object that knows this folder; the driver
(:mod:`coloradar.batch.driver`) plans and dispatches work and asks it everything else, in three
coarse calls: :meth:`JobOutputs.open` (check every folder of the job, then lock and prepare each:
overwrite, partial files, stale frames, manifest; returns the frames already complete and where
new ones go), :meth:`ProcessedRun.finish_radar` as each radar's frames are in (timestamps), and
:meth:`JobOutputs.close` (the job's report, then the locks). Workers write frame files to the
names it gives (:meth:`ProcessedRun.frame_file_parts`) through
:func:`coloradar.formats.atomic.atomic_write_bytes`, the one atomic writer everything here uses.

**Valid and complete frames.** A frame's product file is valid when it has the size its kind
requires: a heatmap exactly ``el × az × range × 2`` float32 values of the processor's grid, a
point cloud a whole number of 5-float32 rows (an empty cloud is a valid, empty file). A frame is
complete when every requested product has a valid file. Files are only ever written atomically
(:mod:`coloradar.formats.atomic`), so a file with a final name was written whole; the size check
also catches files damaged afterwards. What an interrupted write left
(:func:`~coloradar.formats.atomic.is_partial_file`) is removed from the folder before a job
writes it.

**Manifest.** ``process_manifest.json`` records, per radar and product, the processing settings
and a fingerprint of the radar calibration the frames there were computed with
(:mod:`.manifest`). A rerun with the same settings resumes (complete frames are kept); a rerun
with different ones is refused unless ``overwrite`` — frames computed two ways never mix silently
in one folder. It also records, for each radar, a version of every input frame file (size and
modification time): a frame whose input was rewritten since its output was made is stale, and a
rerun processes it again instead of counting it complete. An output folder without a manifest
that already holds products (written by something else) is refused likewise.

**Lock.** ``.process.lock`` is held (``flock``) while a job writes the folder, so that two jobs
never write it at once. The lock goes with the process: a killed job leaves no stale lock behind.
"""

from __future__ import annotations

import json
import os
import re
import warnings
from collections.abc import Iterable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..errors import (
    ColoradarError,
    DataWarning,
    FormatError,
    OutputExistsError,
    WriteError,
)
from ..formats.atomic import clean_partial_files, output_dir_error, write_text_if_changed
from ..formats.layout import COLORADAR, LAYOUTS, PROCESS_PRODUCTS
from ..formats.source import read_file_text
from ..formats.text import format_timestamps
from .manifest import FORMAT, settings_differences, stale_frames

try:  # POSIX; elsewhere jobs are not guarded against each other
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "LOCK",
    "MANIFEST",
    "PRODUCTS",
    "FolderPlan",
    "JobOutputs",
    "OutputLock",
    "OutputRequest",
    "ProcessedRun",
    "RadarProducts",
    "check_folders",
    "frame_file",
    "is_valid_size",
    "output_paths",
    "timestamps_text",
]

PRODUCTS = PROCESS_PRODUCTS
"""Products ``coloradar process`` can write."""
MANIFEST = "process_manifest.json"
LOCK = ".process.lock"

# Both radars name their product files alike (coloradar.formats.layout.COLORADAR).
PREFIX = {p: COLORADAR.frame(f"cascade/{p}").prefix for p in PRODUCTS}
POINT_BYTES = 5 * 4
_FRAME_RE = re.compile(r"^(?P<prefix>[a-z_]+)_(?P<num>\d+)\.bin$")
# Folders of a run that ``process`` never writes: an output folder holding one is a run.
_RUN_PARTS = tuple(dict.fromkeys(
    m for lay in LAYOUTS.values() for m in lay.run_markers
    if not any(m == s.folder for s in lay.frames.values()
               if s.sensor in lay.radars and s.product in PRODUCTS)))


def _make_dir(path: Path) -> None:
    """Create a folder of the output (and its parents) if needed; a WriteError when it cannot."""
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise output_dir_error(path, exc) from None


def is_valid_size(product: str, size: int, heatmap_bytes: int) -> bool:
    """Whether a product file of ``size`` bytes can be complete (see the module notes)."""
    if product == "heatmaps":
        return size == heatmap_bytes
    return size % POINT_BYTES == 0


def output_paths(out: str | os.PathLike, radar: str, product: str) -> tuple[Path, Path]:
    """``(product folder, data folder)`` of one radar's product under ``out``."""
    return ProcessedRun(out).paths(radar, product)


def frame_file(out: str | os.PathLike, radar: str, product: str, frame_id: int) -> Path:
    """The file of frame number ``frame_id`` of a product (named like the dataset's own)."""
    return ProcessedRun(out).frame_file(radar, product, frame_id)


def timestamps_text(frame_ids: np.ndarray, timestamps: np.ndarray, written: np.ndarray) -> str:
    """Timestamps file for the frames ``written`` of a stream with these frames.

    Readers pair line ``j`` with frame ``base + j``, ``base`` being 1 when the first file is
    number 1 and 0 otherwise (``docs/layout.md``), so the lines run from that base to the last
    written frame. The rule for a frame that produced nothing (its input had no finite time,
    could not be read, or its processing failed: the report lists it): its line reads ``nan``,
    never a time, so that the line and the missing file agree, and the stream readers pass it
    over without a warning (:func:`coloradar.dataset.streams.open_frame_stream`).

    Parameters
    ----------
    frame_ids, timestamps
        int ``(N,)`` file numbers and float64 ``(N,)`` times [s] of the ADC stream.
    written
        int ``(M,)`` file numbers that have output files.
    """
    if written.size == 0:
        return ""
    base = 1 if written.min() == 1 else 0
    last = int(written.max())
    lines = np.full(last - base + 1, np.nan)
    keep = np.isin(frame_ids, written) & (frame_ids >= base)
    lines[frame_ids[keep] - base] = timestamps[keep]
    return format_timestamps(lines)


@dataclass
class RadarProducts:
    """What one radar's products in the folder are made with and from.

    Attributes
    ----------
    radar
        ``"cascade"`` or ``"single_chip"``.
    settings
        The settings record (:func:`~.manifest.settings_record`).
    calibration_sha256
        Fingerprint of the radar calibration (:func:`~.manifest.calibration_fingerprint`).
    heatmap_bytes
        Size of a complete heatmap file [bytes].
    heatmap_cfg
        Text of ``heatmap_cfg.txt``.
    inputs
        Frame number (text) → version of its ADC file (:func:`~.manifest.input_versions`).
    """

    radar: str
    settings: dict
    calibration_sha256: str
    heatmap_bytes: int
    heatmap_cfg: str
    inputs: dict[str, str] = field(default_factory=dict)


class OutputLock:
    """An exclusive, non-blocking lock on an output folder, held while a job writes it.

    Raises
    ------
    OutputExistsError
        When another process holds it.
    """

    def __init__(self, out: Path):
        self.path = out / LOCK
        self._fd: int | None = None

    def __enter__(self) -> OutputLock:
        if fcntl is None:  # pragma: no cover
            return self
        _make_dir(self.path.parent)
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise WriteError(f"{self.path}: cannot create the output lock "
                                 f"({exc.strerror or exc})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                raise OutputExistsError(f"{self.path.parent}: another coloradar process is "
                                        "writing this output now; wait for it to finish") from None
            # The file may have been removed by a job that just finished: lock the live one.
            try:
                same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                self._fd = fd
                return self
            os.close(fd)

    def __exit__(self, *exc) -> None:
        if self._fd is not None:
            try:
                self.path.unlink()
            except FileNotFoundError:
                pass
            os.close(self._fd)
            self._fd = None


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


class ProcessedRun:
    """The output folder of one processed run (see the module notes for what it holds).

    Parameters
    ----------
    root
        The folder (``OUT`` or ``OUT/<run name>``); nothing is created until asked.
    """

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)

    def __repr__(self) -> str:
        return f"ProcessedRun({str(self.root)!r})"

    # -- paths ---------------------------------------------------------------------------------
    def paths(self, radar: str, product: str) -> tuple[Path, Path]:
        """``(product folder, data folder)`` of one radar's product."""
        st = COLORADAR.frame(f"{radar}/{product}")
        return self.root / st.folder, self.root / st.data

    def frame_file(self, radar: str, product: str, frame_id: int) -> Path:
        """The file of frame number ``frame_id`` of a product (named like the dataset's own)."""
        return self.root / COLORADAR.frame(f"{radar}/{product}").frame_path(frame_id)

    def frame_file_parts(self, radar: str, product: str) -> tuple[str, str]:
        """``(head, tail)``: the file of frame number ``n`` of a product is ``head + str(n) +
        tail`` (:meth:`frame_file` as strings, for workers to name the files they write)."""
        st = COLORADAR.frame(f"{radar}/{product}")  # frame files: <data>/<prefix>_<n>.bin
        return str(self.root / st.data / f"{st.prefix}_"), ".bin"

    @property
    def location(self) -> str:
        """The folder as an absolute path string: how it travels to workers (and names them)."""
        return str(self.root.resolve())

    @property
    def manifest_path(self) -> Path:
        """``<root>/process_manifest.json``."""
        return self.root / MANIFEST

    # -- what is on disk -----------------------------------------------------------------------
    def _frame_files(self, radar: str, product: str) -> Iterable[tuple[int, os.DirEntry]]:
        try:
            entries = list(os.scandir(self.paths(radar, product)[1]))
        except FileNotFoundError:
            return
        for e in entries:
            m = _FRAME_RE.match(e.name)
            if m and m["prefix"] == PREFIX[product]:
                yield int(m["num"]), e

    def valid_frames(self, radar: str, product: str, heatmap_bytes: int) -> set[int]:
        """Frame numbers whose ``product`` file exists with a valid size."""
        ok = set()
        for num, e in self._frame_files(radar, product):
            try:
                if e.is_file() and is_valid_size(product, e.stat().st_size, heatmap_bytes):
                    ok.add(num)
            except FileNotFoundError:   # removed meanwhile
                continue
        return ok

    def has_output(self, radar: str, product: str) -> bool:
        """Whether a product folder holds anything of ours (frame files or a timestamps file)."""
        folder = self.paths(radar, product)[0]
        if (folder / "timestamps.txt").exists() or (folder / "heatmap_cfg.txt").exists():
            return True
        return next(iter(self._frame_files(radar, product)), None) is not None

    def remove_product(self, radar: str, product: str) -> int:
        """Delete a product's frame files and its timestamps/heatmap_cfg (``--overwrite``).

        Only files named as this product's own are touched; anything else in the folder stays.
        Returns the number of files removed.
        """
        folder = self.paths(radar, product)[0]
        n = 0
        for _num, e in self._frame_files(radar, product):
            os.unlink(e.path)
            n += 1
        for name in ("timestamps.txt", "heatmap_cfg.txt"):
            try:
                (folder / name).unlink()
                n += 1
            except FileNotFoundError:
                pass
        return n

    # -- manifest ------------------------------------------------------------------------------
    def read_manifest(self) -> dict[str, Any] | None:
        """The folder's manifest, None when there is none.

        Raises
        ------
        OutputExistsError
            When the file is there but unreadable (it cannot vouch for the files beside it).
        """
        path = self.manifest_path
        if not path.exists():
            return None
        try:
            text = read_file_text(path)
        except FormatError as exc:  # not UTF-8
            raise OutputExistsError(f"{exc}; pass overwrite=True (--overwrite) to replace this "
                                    "output") from None
        try:
            data = json.loads(text)
            if data.get("format") != FORMAT or not isinstance(data.get("products"), dict):
                raise ValueError(f"expected format {FORMAT!r} with a products table")
        except (ValueError, AttributeError) as exc:
            raise OutputExistsError(f"{path}: unreadable processing manifest ({exc}); pass "
                                    "overwrite=True (--overwrite) to replace this output") from None
        return data

    def write_manifest(self, run: str, entries: dict[str, dict[str, Any]],
                       inputs: dict[str, dict[str, str]] | None = None) -> None:
        """Write (atomically, only when its content changes) the manifest with ``entries``:
        ``"<radar>/<product>" -> {"settings": ..., "calibration_sha256": ...}``, and ``inputs``:
        ``"<radar>" -> {frame number: version of its input file}``."""
        record: dict[str, Any] = {"format": FORMAT, "run": run, "coloradar_version": __version__,
                                  "products": dict(sorted(entries.items()))}
        if inputs:
            record["inputs"] = dict(sorted(inputs.items()))
        write_text_if_changed(self.manifest_path, json.dumps(record, indent=1) + "\n")

    # -- before writing ------------------------------------------------------------------------
    def check_writable(self, run: Path) -> None:
        """Refuse a folder that is a file, lies inside ``run``, or is itself a run."""
        root, out = run.resolve(), self.root.resolve()
        probe = out  # the output folder, or the nearest of its parents that exists
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent
        if not probe.is_dir():
            raise WriteError(f"{self.root}: expected an output folder, but {probe} is a file")
        if _inside(out, root):
            raise ColoradarError(f"{self.root}: the output folder lies inside the run {run}; "
                                 "choose an output folder outside it (coloradar never writes "
                                 "into a run)")
        found = [p for p in _RUN_PARTS if (out / p).exists()]
        if found:
            raise ColoradarError(f"{self.root}: this is a ColoRadar run (it has "
                                 f"{', '.join(found)}), not an output folder; coloradar never "
                                 "writes into a run")

    def conflicts(self, radars: Sequence[RadarProducts], prods: tuple[str, ...],
                  overwrite: bool) -> list[str]:
        """Why this folder may not be resumed with these products (empty: it may)."""
        if overwrite or not radars:
            return []
        manifest = self.read_manifest()
        entries = manifest["products"] if manifest else {}
        if manifest and manifest.get("coloradar_version") != __version__:
            warnings.warn(f"{self.root}: resuming output made by coloradar "
                          f"{manifest.get('coloradar_version')} with {__version__}; pass "
                          "--overwrite to redo it all with this version", UserWarning,
                          stacklevel=4)
        found = []
        for rp in radars:
            for p in prods:
                folder = self.paths(rp.radar, p)[0]
                entry = entries.get(f"{rp.radar}/{p}")
                if entry is None:
                    if self.has_output(rp.radar, p):
                        found.append(f"{folder} holds output that has no entry in the manifest "
                                     "(made by something else or an older coloradar)")
                    continue
                diffs = settings_differences(entry.get("settings", {}), rp.settings)
                if entry.get("calibration_sha256") != rp.calibration_sha256:
                    diffs.append("the radar calibration differs")
                if diffs:
                    found.append(f"{folder} was made with other settings ({'; '.join(diffs)})")
        return found

    def lock(self) -> OutputLock:
        """The folder's lock (a context manager)."""
        return OutputLock(self.root)

    def prepare(self, run: str, radars: Sequence[RadarProducts], prods: tuple[str, ...],
                overwrite: bool) -> dict[str, set[int]]:
        """Under the lock: clear what ``overwrite`` replaces, remove partial files and stale
        frames, record the settings and inputs; returns each radar's complete frame numbers."""
        _make_dir(self.root)
        try:
            manifest = self.read_manifest()
        except OutputExistsError:
            if not overwrite:
                raise
            manifest = None
        entries = dict(manifest["products"]) if manifest else {}
        folders = [self.root]
        for rp in radars:
            for p in prods:
                folder, data = self.paths(rp.radar, p)
                if overwrite:
                    if f"{rp.radar}/{p}" in entries:
                        self.remove_product(rp.radar, p)
                    elif self.has_output(rp.radar, p):
                        # Not recorded as ours (a downloaded dataset's heatmaps, say): never delete.
                        raise OutputExistsError(
                            f"{folder}: holds {p} that process_manifest.json does not record as "
                            "made by coloradar; not deleting them, even with --overwrite: choose "
                            "another output folder")
                _make_dir(data)
                folders += [folder, data]
                entries[f"{rp.radar}/{p}"] = {"settings": rp.settings,
                                              "calibration_sha256": rp.calibration_sha256}
        clean_partial_files(folders)
        inputs = dict((manifest or {}).get("inputs") or {})  # radars not processed now stay
        for rp in radars:
            if not overwrite:
                self._remove_stale(manifest, rp)
            inputs[rp.radar] = rp.inputs
        complete = {rp.radar: self.complete_frames(rp, prods) for rp in radars}
        self.write_manifest(run, entries, inputs)
        return complete

    def _remove_stale(self, manifest: dict | None, rp: RadarProducts) -> None:
        """Delete the product files of frames whose input was rewritten since they were made (a
        re-simulated run, a repaired file): they are stale, and ours (the manifest records
        them), so they are redone rather than resumed. Every product the manifest records is
        cleared, requested now or not, so that none is later taken as made from the new input."""
        recorded = (manifest or {}).get("products") or {}
        prods = [p for p in PRODUCTS if f"{rp.radar}/{p}" in recorded]
        have = set().union(*(self.valid_frames(rp.radar, p, rp.heatmap_bytes) for p in prods))
        stale = stale_frames(manifest, rp.radar, rp.inputs, have)
        if not stale:
            return
        for i in stale:
            for p in prods:
                self.frame_file(rp.radar, p, i).unlink(missing_ok=True)
        warnings.warn(f"{self.root / rp.radar}: the ADC files of {len(stale)} frame(s) changed "
                      f"since their output was made (first: frame {stale[0]}); processing them "
                      "again", DataWarning, stacklevel=5)

    # -- after writing -------------------------------------------------------------------------
    def complete_frames(self, rp: RadarProducts, prods: Sequence[str]) -> set[int]:
        """Frame numbers with a valid file of every product in ``prods``."""
        return set.intersection(*(self.valid_frames(rp.radar, p, rp.heatmap_bytes)
                                  for p in prods))

    def finish_radar(self, rp: RadarProducts, prods: Sequence[str], frame_ids: np.ndarray,
                     timestamps: np.ndarray) -> set[int]:
        """A radar's frames are all written: rewrite each product's ``timestamps.txt`` (and
        ``heatmap_cfg.txt``) from the frames valid on disk; returns the complete frame numbers.

        Parameters
        ----------
        frame_ids, timestamps
            int ``(N,)`` file numbers and float64 ``(N,)`` times [s] of the radar's ADC stream.
        """
        valid = {p: self.valid_frames(rp.radar, p, rp.heatmap_bytes) for p in prods}
        known = set(frame_ids.tolist())
        for p in prods:
            folder = self.paths(rp.radar, p)[0]
            written = np.array(sorted(valid[p] & known), dtype=np.int64)
            if p == "heatmaps":
                write_text_if_changed(folder / "heatmap_cfg.txt", rp.heatmap_cfg)
            write_text_if_changed(folder / "timestamps.txt",
                                  timestamps_text(frame_ids, timestamps, written))
        return set.intersection(*valid.values())


def check_folders(targets: Sequence[tuple[Path, Path]]) -> list[ProcessedRun]:
    """The output folders of ``(run, out)`` pairs, each checked by
    :meth:`ProcessedRun.check_writable` (the first that may not be written raises)."""
    folders = [ProcessedRun(out) for _run, out in targets]
    for f, (run, _out) in zip(folders, targets, strict=True):
        f.check_writable(run)
    return folders


@dataclass
class OutputRequest:
    """What a processing job asks of one run's output folder.

    Attributes
    ----------
    run
        The run (the folder may not lie inside it).
    out
        The output folder.
    name
        The run's name (recorded in the manifest).
    radars
        What each radar's products are to be made with; empty when the run has nothing to
        write (it could not be opened, or has none of the radars asked for): its folder is
        still checked, but neither locked nor written.
    """

    run: Path
    out: Path
    name: str
    radars: list[RadarProducts] = field(default_factory=list)


@dataclass
class FolderPlan:
    """An output folder opened for a job: checked, locked and prepared.

    Attributes
    ----------
    folder
        The folder.
    location
        The folder as an absolute path string (:attr:`ProcessedRun.location`).
    complete
        Radar -> frame numbers already complete (every product valid on disk): not to redo.
    frame_files
        Radar -> ``(head, tail)`` of each product asked for, in order
        (:meth:`ProcessedRun.frame_file_parts`).
    """

    folder: ProcessedRun
    location: str
    complete: dict[str, set[int]]
    frame_files: dict[str, tuple[tuple[str, str], ...]]


class JobOutputs:
    """The output folders of one processing job, opened together and closed together.

    :meth:`open` checks every folder before it writes any (nothing inside a run; a manifest that
    agrees with the settings, or ``overwrite``), then locks and prepares each; :meth:`close`
    writes the job's report and releases the locks. In between, the driver finishes each radar
    as its frames are in (:meth:`ProcessedRun.finish_radar`).

    Attributes
    ----------
    plans
        One :class:`FolderPlan` per request that has radars to write, in request order.
    """

    def __init__(self) -> None:
        self.plans: list[FolderPlan] = []
        self._locks = ExitStack()

    @classmethod
    def open(cls, requests: Sequence[OutputRequest], prods: tuple[str, ...],
             overwrite: bool) -> JobOutputs:
        """Check, lock and prepare the folders of ``requests``.

        Raises
        ------
        coloradar.errors.ColoradarError, WriteError
            A folder that may not be written (a file, inside a run, a run itself).
        OutputExistsError
            Output made otherwise (other settings, no manifest) and no ``overwrite``, listing
            the first three such folders; or another job holding a lock.
        """
        folders = check_folders([(r.run, r.out) for r in requests])
        active = [(f, r) for f, r in zip(folders, requests, strict=True) if r.radars]
        conflicts = [c for f, r in active for c in f.conflicts(r.radars, prods, overwrite)]
        if conflicts:
            more = f"; and {len(conflicts) - 3} more" if len(conflicts) > 3 else ""
            raise OutputExistsError("output exists: " + "; ".join(conflicts[:3]) + more
                                    + "; rerun with the same settings to resume it, or pass "
                                    "overwrite=True (--overwrite) to redo it")
        job = cls()
        with job._locks:
            for f, _r in active:
                job._locks.enter_context(f.lock())
            for f, r in active:
                complete = f.prepare(r.name, r.radars, prods, overwrite)
                files = {rp.radar: tuple(f.frame_file_parts(rp.radar, p) for p in prods)
                         for rp in r.radars}
                job.plans.append(FolderPlan(f, f.location, complete, files))
            job._locks = job._locks.pop_all()  # opened: held until close()
        return job

    def close(self, report_path: str | os.PathLike | None = None,
              report: str | None = None) -> Path | None:
        """Write the job's report text to ``report_path`` (when given), then release the locks.

        Returns
        -------
        pathlib.Path or None
            Where the report was written.
        """
        try:
            if report_path is None or report is None:
                return None
            path = Path(report_path)
            _make_dir(path.parent)
            clean_partial_files([path.parent], path.name)
            write_text_if_changed(path, report)
            return path
        finally:
            self._locks.close()
