"""Lazy, indexable streams of frames and in-memory tables (IMU, poses) of one run."""

from __future__ import annotations

import operator
import re
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import SupportsIndex, overload

import numpy as np

from ..errors import (
    ColoradarError,
    DataWarning,
    FormatError,
    FrameIndexError,
    MissingDataError,
    ReadError,
)
from ..formats.source import Source
from ..formats.text import parse_imu, parse_poses, parse_timestamps

__all__ = ["FrameStream", "ImuData", "PoseData", "open_frame_stream", "read_timestamps"]

Decoder = Callable[[bytes, str], np.ndarray]


def read_timestamps(src: Source, rel: str) -> np.ndarray:
    """Read a timestamps file of ``src`` as float64 seconds; a clear error when it is missing.

    The values are returned as written: non-finite and non-increasing ones included (the
    stream readers below report and handle them, see :func:`timestamp_faults`)."""
    return parse_timestamps(_read_timestamps_text(src, rel), src.describe(rel))


def _read_timestamps_text(src: Source, rel: str) -> str:
    if not src.exists(rel):
        folder = rel.rsplit("/", 1)[0] if "/" in rel else ""
        present = ", ".join(src.listdir(folder)) if src.is_dir(folder) else "nothing"
        raise MissingDataError(f"{src.describe(rel)}: timestamps file not found "
                               f"(the folder holds: {present})")
    return src.read_text(rel)


def _line_numbers(text: str) -> np.ndarray:
    """1-based line number of each value row of a table file (blank and ``#`` lines hold none,
    as for :func:`numpy.loadtxt`)."""
    body = text.rstrip()
    if not _SKIPPED_LINE.search(body):  # the usual file: row k is line k (found in C)
        return np.arange(1, body.count("\n") + 2 if body else 1, dtype=np.int64)
    return np.array([i for i, ln in enumerate(text.splitlines(), start=1)
                     if ln.split("#", 1)[0].strip()], dtype=np.int64)


_SKIPPED_LINE = re.compile(r"^[ \t\r\f\v]*(#|$)", re.MULTILINE)


def _lines_text(lines: np.ndarray, limit: int = 5) -> str:
    """``line 7`` / ``lines 7, 9, 12 and 3 more``."""
    shown = ", ".join(str(int(v)) for v in lines[:limit])
    more = f" and {lines.size - limit} more" if lines.size > limit else ""
    return f"line{'s' if lines.size > 1 else ''} {shown}{more}"


def _increasing_subset(t: np.ndarray) -> np.ndarray:
    """bool mask of a longest strictly increasing subsequence of ``t``: the fewest samples to
    leave out so that the rest increase (one stray time, early or late, costs one sample, not
    every sample up to where the times catch up with it). O(N log N), patience sorting."""
    import bisect

    tails: list[float] = []       # smallest last value of an increasing run of each length
    tail_idx: list[int] = []
    prev = np.full(t.size, -1, dtype=np.int64)
    for i, v in enumerate(t.tolist()):
        k = bisect.bisect_left(tails, v)
        if k == len(tails):
            tails.append(v)
            tail_idx.append(i)
        else:
            tails[k] = v
            tail_idx[k] = i
        prev[i] = tail_idx[k - 1] if k else -1
    keep = np.zeros(t.size, dtype=bool)
    i = tail_idx[-1] if tail_idx else -1
    while i >= 0:
        keep[i] = True
        i = int(prev[i])
    return keep


def timestamp_faults(t: np.ndarray, lines: np.ndarray, what: str = "sample",
                     drop_disorder: bool = False) -> tuple[np.ndarray, list[str]]:
    """Which timestamps are usable, and what is wrong with the rest.

    Parameters
    ----------
    t
        float64 ``(N,)`` timestamps [s] as read.
    lines
        int ``(N,)`` the file line of each (for the messages).
    what
        What one timestamp stamps (``"frame"``, ``"sample"``), for the messages.
    drop_disorder
        Leave out duplicated and out-of-order samples too (the fewest that make the rest
        strictly increase): what tables that are integrated or interpolated (IMU, poses) need.
        False: keep them, reported (frames, whose files are each worth keeping).

    Returns
    -------
    keep : numpy.ndarray
        bool ``(N,)``: False for a timestamp that is not a finite number (``nan``, ``inf``):
        no time can be given to its sample, which is left out; and, with ``drop_disorder``,
        for duplicated and out-of-order ones.
    faults : list of str
        One message per kind of fault, naming the lines and what was done.
    """
    keep = np.isfinite(t)
    faults = []
    done = "left out" if drop_disorder else "kept"
    if not keep.all():
        bad = np.flatnonzero(~keep)
        faults.append(f"{_lines_text(lines[bad])}: timestamp {float(t[bad[0]])!r} is not a "
                      f"finite time; {bad.size} {what}(s) left out")
    fin = np.flatnonzero(keep)
    tf = t[fin]
    if tf.size >= 2:
        dt = np.diff(tf)
        dup = np.flatnonzero(dt == 0) + 1
        back = np.flatnonzero(dt < 0) + 1
        if drop_disorder and (dup.size or back.size):
            # Which samples of a disordered stretch are the strays is a choice: the fewest.
            out = fin[~_increasing_subset(tf)]
            keep[out] = False
            first = int((back if back.size else dup)[0])
            faults.append(f"{_lines_text(lines[out])}: timestamps duplicated or out of order "
                          f"(e.g. {float(tf[first]):.6f} after {float(tf[first - 1]):.6f}); "
                          f"{out.size} {what}(s) left out so that the rest increase")
        else:
            if dup.size:
                faults.append(f"{_lines_text(lines[fin[dup]])}: duplicated timestamp (the same "
                              f"as the line before); {dup.size} duplicated {what}(s) {done}")
            if back.size:
                first = int(back[0])
                faults.append(f"{_lines_text(lines[fin[back]])}: timestamp earlier than the "
                              f"line before ({float(tf[first]):.6f} after "
                              f"{float(tf[first - 1]):.6f}); {back.size} out-of-order "
                              f"{what}(s) {done}")
    return keep, faults


class FrameStream:
    """A sequence of frames stored one file each, read only when indexed.

    Supports ``len()``, integer indexing (negative too), slicing (a view, nothing is read),
    and iteration. Frame ``k`` of the stream is the ``k``-th timestamp that has a file.

    Attributes
    ----------
    name
        ``"<sensor>/<product>"``, e.g. ``"cascade/adc"``.
    timestamps
        float64 ``(N,)``: Unix time of each exposed frame [s].
    frame_ids
        int64 ``(N,)``: the number in each exposed frame's file name (0- or 1-based, as on disk).
    issues
        Human-readable notes about inconsistencies found when the stream was opened.
    timestamp_faults
        Those of ``issues`` that are faults of the timestamps file (a non-finite value, whose
        frame is left out; duplicated or decreasing timestamps, kept): ``coloradar info``
        marks them and exits 1.
    untimed
        ``(frame number, file)`` of each frame file left out because its timestamp is not a
        finite number (the file as a path or ``archive.zip:member``): ``coloradar process``
        reports each as a failed frame.
    """

    def __init__(self, name: str, source: Source, paths: list[str], timestamps: np.ndarray,
                 frame_ids: np.ndarray, decode: Decoder, issues: list[str] | None = None,
                 timestamp_faults: list[str] | None = None,
                 untimed: list[tuple[int, str]] | None = None):
        self.name = name
        self._source = source
        self._paths = paths
        self.timestamps = timestamps
        self.frame_ids = frame_ids
        self._decode = decode
        self.issues = list(issues or [])
        self.timestamp_faults = list(timestamp_faults or [])
        self.untimed = list(untimed or [])

    def __len__(self) -> int:
        return len(self._paths)

    def __repr__(self) -> str:
        return f"<FrameStream {self.name}: {len(self)} frames from {self._source.location}>"

    def path(self, k: int) -> str:
        """Where frame ``k`` is stored (a path, or ``archive.zip:member``)."""
        return self._source.describe(self._paths[self._index(k)])

    def read(self, k: int) -> np.ndarray:
        """Read and decode frame ``k``."""
        rel = self._paths[self._index(k)]
        return self._decode(self._source.read_bytes(rel), self._source.describe(rel))

    def versions(self) -> list[str]:
        """For every frame, a short text that changes whenever its file is rewritten (size and
        modification time, or a zip member's size, CRC and date; see
        :meth:`~coloradar.formats.source.Source.version_key`). Nothing is read: what a
        resumable job records to tell later which inputs changed since it ran."""
        return [self._source.version_key(rel) for rel in self._paths]

    def read_or_skip(self, k: int) -> np.ndarray | None:
        """Frame ``k``, or None with a :class:`~coloradar.DataWarning` naming the file and what
        is wrong when it cannot be read (malformed, not a regular file, vanished): what the
        commands that walk many frames use, so that one bad frame is reported and skipped, as
        ``coloradar process`` does, instead of ending the whole command."""
        try:
            return self.read(k)
        except (FormatError, ReadError, MissingDataError) as exc:
            warnings.warn(f"{exc}; {self.name} frame {k} skipped", DataWarning, stacklevel=2)
            return None

    def check_files(self) -> list[str]:
        """Problems of the frame files, found without reading them: a file that is not a
        regular file, or whose size its kind (and the calibration) does not allow.

        Each distinct size is checked once, by decoding that many zero bytes with the stream's
        own decoder (which checks sizes only), so the rule is the reader's. Returns one line
        per problem (empty: every file has a size the reader accepts).
        """
        problems: list[str] = []
        by_size: dict[int, list[str]] = {}
        for rel in self._paths:
            try:
                by_size.setdefault(self._source.file_size(rel), []).append(rel)
            except ColoradarError as exc:
                problems.append(str(exc))
        for size, rels in sorted(by_size.items()):
            try:
                self._decode(bytes(size), self._source.describe(rels[0]))
            except FormatError as exc:
                more = f" (and {len(rels) - 1} more file(s) of that size)" if len(rels) > 1 else ""
                problems.append(f"{exc}{more}")
        return problems

    def _index(self, k: int) -> int:
        k = operator.index(k)
        n = len(self._paths)
        if not -n <= k < n:
            raise FrameIndexError(f"{self._source.location}: {self.name} frame {k} out of range "
                                  f"(the stream has {n} frames: 0..{n - 1}, or -{n}..-1)")
        return k % n

    @overload
    def __getitem__(self, key: SupportsIndex) -> np.ndarray: ...
    @overload
    def __getitem__(self, key: slice) -> FrameStream: ...
    def __getitem__(self, key: SupportsIndex | slice) -> np.ndarray | FrameStream:
        """Frame ``key`` decoded (an int), or a stream over a slice of the frames (nothing read)."""
        if isinstance(key, slice):
            idx = range(len(self._paths))[key]
            return FrameStream(self.name, self._source, [self._paths[i] for i in idx],
                               self.timestamps[key], self.frame_ids[key], self._decode,
                               self.issues, self.timestamp_faults, self.untimed)
        return self.read(operator.index(key))

    def __iter__(self) -> Iterator[np.ndarray]:
        for k in range(len(self)):
            yield self.read(k)


_FRAME_RE = re.compile(r"^(?P<prefix>.+)_(?P<num>\d+)\.bin$")


def open_frame_stream(name: str, src: Source, folder: str, data_dir: str, prefix: str,
                      decode: Decoder, *, timestamps: str = "timestamps.txt",
                      first_frame: int = 0) -> FrameStream:
    """Index a stream of frame files ``<data_dir>/<prefix>_<i>.bin`` with
    ``<folder>/<timestamps>``.

    Frame numbers may start at 0 (original release) or 1 (derived release, ColoRadar+). The
    ``i``-th timestamp belongs to the file numbered ``base + i``, ``base`` being 0 or 1, whichever
    pairs more files with a timestamp (the layout's ``first_frame`` on a tie). Timestamps without a
    file and files without a timestamp are left out with a :class:`DataWarning` (and noted in
    ``issues``). A timestamp that is not a finite number leaves its frame out, and duplicated or
    decreasing timestamps are kept, each with a :class:`DataWarning` naming the file and lines
    (and noted in ``timestamp_faults``). Frame files of which none has a finite timestamp (an
    empty timestamps file, one of all ``nan``, one numbered for other files) are a
    :class:`FormatError`: no frame of the stream can be placed in time.
    """
    ts_rel = f"{folder}/{timestamps}"
    ts_text = _read_timestamps_text(src, ts_rel)
    ts = parse_timestamps(ts_text, src.describe(ts_rel))
    if not src.is_dir(data_dir):
        raise MissingDataError(f"{src.describe(data_dir)}: frame folder not found")
    ids = []
    for fname in src.listdir(data_dir):
        m = _FRAME_RE.match(fname)
        if m and m["prefix"] == prefix:
            ids.append(int(m["num"]))
    ids_arr = np.array(sorted(ids), dtype=np.int64)
    # Releases number frames from 0 or from 1 and nothing in a run says which: take the base
    # that pairs the most files with a timestamp, and the layout's own on a tie (a 0-based run
    # whose frame_0 is missing must not shift every time by one frame).
    matches = {b: int(np.isin(b + np.arange(ts.size), ids_arr).sum()) for b in (0, 1)}
    base = first_frame if matches[0] == matches[1] else max(matches, key=matches.__getitem__)
    wanted = base + np.arange(ts.size, dtype=np.int64)
    has = np.isin(wanted, ids_arr)
    if ids_arr.size and not np.isfinite(ts[has]).any():
        # Every frame would be left out: a stream that reads as empty would let a command say
        # "nothing to do" over frames that are there.
        what = ("no timestamps" if ts.size == 0 else
                f"none of its {ts.size} timestamps is a finite time of one of the frame files")
        raise FormatError(f"{src.describe(ts_rel)}: {what}, but {src.describe(data_dir)} "
                          f"holds {ids_arr.size} {prefix}_<i>.bin frame files (expected one "
                          "timestamp per frame, Unix seconds, one per line)")
    issues = []
    # Lines without a frame file may be nan: what `coloradar process` writes for a frame of
    # its input that had no file. Only the faults of frames that exist are the user's concern.
    finite, faults = timestamp_faults(ts[has], _line_numbers(ts_text)[: ts.size][has],
                                     "frame")
    for msg in faults:
        warnings.warn(f"{src.describe(ts_rel)}, {msg}", DataWarning, stacklevel=3)
    faults = [f"{src.describe(ts_rel)}, {msg}" for msg in faults]
    # A nan line without a file is a frame that produced nothing (the rule of processed
    # output, docs/batch.md): the line and the folder agree, nothing to warn about.
    n_no_file = int((~has & np.isfinite(ts)).sum())
    n_no_ts = int(ids_arr.size - has.sum())
    if n_no_file or n_no_ts:
        issues.append(f"{ts.size} timestamps but {ids_arr.size} frame files: "
                      f"{n_no_file} timestamps have no file, {n_no_ts} files have no timestamp; "
                      f"using the {int(has.sum())} frames that have both")
        warnings.warn(f"{src.describe(folder)}: {issues[-1]}", DataWarning, stacklevel=3)
    keep = wanted[has][finite]
    paths = [f"{data_dir}/{prefix}_{i}.bin" for i in keep]
    untimed = [(int(i), src.describe(f"{data_dir}/{prefix}_{i}.bin")) for i in wanted[has][~finite]]
    return FrameStream(name, src, paths, ts[has][finite].copy(), keep, decode, issues + faults,
                       faults, untimed)


@dataclass(frozen=True, eq=False)
class ImuData:
    """IMU samples of a run.

    Attributes
    ----------
    timestamps
        float64 ``(N,)`` [s].
    data
        float64 ``(N, 6)``: ax ay az [m/s²] (specific force, gravity included), gx gy gz [rad/s],
        in the IMU frame.
    """

    timestamps: np.ndarray
    data: np.ndarray
    issues: list[str] = field(default_factory=list)
    timestamp_faults: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.timestamps.size)

    @property
    def accelerations(self) -> np.ndarray:
        """``(N, 3)`` specific force [m/s²]."""
        return self.data[:, :3]

    @property
    def angular_rates(self) -> np.ndarray:
        """``(N, 3)`` angular rate [rad/s]."""
        return self.data[:, 3:]


@dataclass(frozen=True, eq=False)
class PoseData:
    """A pose track (ground truth or Vicon).

    Attributes
    ----------
    timestamps
        float64 ``(N,)`` [s].
    poses
        float64 ``(N, 7)``: x y z [m], qx qy qz qw, relative to the start pose.
    """

    timestamps: np.ndarray
    poses: np.ndarray
    issues: list[str] = field(default_factory=list)
    timestamp_faults: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.timestamps.size)

    @property
    def positions(self) -> np.ndarray:
        """``(N, 3)`` translations [m]."""
        return self.poses[:, :3]

    @property
    def quaternions(self) -> np.ndarray:
        """``(N, 4)`` rotations ``qx qy qz qw``."""
        return self.poses[:, 3:]


def _read_table(src: Source, folder: str, rel: str, parse, what: str):
    """Timestamps and rows of an IMU or pose table, with the rows no time or value can be given
    to left out.

    A row whose timestamp or any value is not a finite number (``nan``, ``inf``: a logger's
    dropout) is left out with a :class:`DataWarning` naming the file and lines: a few missing
    samples of a 100 Hz+ table cost an integrator or an interpolator nothing, where a ``nan``
    kept would poison every later estimate. Duplicated or decreasing timestamps are kept and
    reported the same way. Returns ``(timestamps, rows, issues, timestamp_faults, lines)``,
    ``lines`` being the file line of each kept row.
    """
    ts_rel = f"{folder}/timestamps.txt"
    ts_text = _read_timestamps_text(src, ts_rel)
    ts = parse_timestamps(ts_text, src.describe(ts_rel))
    text = src.read_text(rel)
    rows = parse(text, src.describe(rel))
    issues: list[str] = []
    if ts.size != rows.shape[0]:
        n = min(ts.size, rows.shape[0])
        issues.append(f"{ts.size} timestamps but {rows.shape[0]} {what} rows; using the first {n}")
        warnings.warn(f"{src.describe(folder)}: {issues[-1]}", DataWarning, stacklevel=4)
        ts, rows = ts[:n], rows[:n]
    row_lines = _line_numbers(text)[: rows.shape[0]]
    row_ok = np.isfinite(rows).all(axis=1)
    if not row_ok.all():
        bad = np.flatnonzero(~row_ok)
        issues.append(f"{src.describe(rel)}, {_lines_text(row_lines[bad])}: values that are not finite "
                      f"numbers (e.g. {rows[bad[0]].tolist()}); {bad.size} {what} row(s) "
                      "left out")
        warnings.warn(issues[-1], DataWarning, stacklevel=4)
    ts_lines = _line_numbers(ts_text)[: ts.size]
    finite, faults = timestamp_faults(ts[row_ok], ts_lines[row_ok], drop_disorder=True)
    faults = [f"{src.describe(ts_rel)}, {msg}" for msg in faults]
    for msg in faults:
        warnings.warn(msg, DataWarning, stacklevel=4)
    keep = np.flatnonzero(row_ok)[finite]
    return ts[keep], rows[keep], issues + faults, faults, row_lines[keep]


def read_imu(src: Source, folder: str = "imu") -> ImuData:
    """Read ``imu/timestamps.txt`` and ``imu/imu_data.txt``.

    Rows with a non-finite value or timestamp are left out, and duplicated or decreasing
    timestamps reported, with a :class:`DataWarning` naming the file and lines."""
    rel = f"{folder}/imu_data.txt"
    if not src.exists(rel):
        raise MissingDataError(f"{src.describe(rel)}: IMU data file not found")
    ts, rows, issues, faults, _ = _read_table(src, folder, rel, parse_imu, "IMU")
    return ImuData(ts, rows, issues, faults)


def read_poses(src: Source, folder: str, filename: str) -> PoseData:
    """Read ``<folder>/timestamps.txt`` and ``<folder>/<filename>`` (x y z qx qy qz qw lines).

    Rows with a non-finite value or timestamp are left out, and duplicated or decreasing
    timestamps reported, with a :class:`DataWarning` naming the file and lines; a finite
    quaternion that is not of unit norm is a :class:`FormatError`."""
    rel = f"{folder}/{filename}"
    if not src.exists(rel):
        raise MissingDataError(f"{src.describe(rel)}: poses file not found")
    ts, poses, issues, faults, lines = _read_table(src, folder, rel, parse_poses, "pose")
    norms = np.linalg.norm(poses[:, 3:], axis=1)
    if poses.size and not np.all(np.abs(norms - 1) < 1e-2):
        bad = int(np.argmax(np.abs(norms - 1)))
        raise FormatError(f"{src.describe(rel)}, line {lines[bad]}: quaternion norm {norms[bad]:.4f}, "
                          "expected a unit quaternion qx qy qz qw")
    return PoseData(ts, poses, issues, faults)
