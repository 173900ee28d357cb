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
    """Read a timestamps file of ``src`` as float64 seconds; a clear error when it is missing."""
    if not src.exists(rel):
        folder = rel.rsplit("/", 1)[0] if "/" in rel else ""
        present = ", ".join(src.listdir(folder)) if src.is_dir(folder) else "nothing"
        raise MissingDataError(f"{src.describe(rel)}: timestamps file not found "
                               f"(the folder holds: {present})")
    return parse_timestamps(src.read_text(rel), src.describe(rel))


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
    """

    def __init__(self, name: str, source: Source, paths: list[str], timestamps: np.ndarray,
                 frame_ids: np.ndarray, decode: Decoder, issues: list[str] | None = None):
        self.name = name
        self._source = source
        self._paths = paths
        self.timestamps = timestamps
        self.frame_ids = frame_ids
        self._decode = decode
        self.issues = list(issues or [])

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
                               self.issues)
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
    ``issues``).
    """
    ts = read_timestamps(src, f"{folder}/{timestamps}")
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
    issues = []
    if ids_arr.size != ts.size or not has.all():
        n_no_file = int((~has).sum())
        n_no_ts = int(ids_arr.size - has.sum())
        issues.append(f"{ts.size} timestamps but {ids_arr.size} frame files: "
                      f"{n_no_file} timestamps have no file, {n_no_ts} files have no timestamp; "
                      f"using the {int(has.sum())} frames that have both")
        warnings.warn(f"{src.describe(folder)}: {issues[-1]}", DataWarning, stacklevel=3)
    keep = wanted[has]
    paths = [f"{data_dir}/{prefix}_{i}.bin" for i in keep]
    return FrameStream(name, src, paths, ts[has].copy(), keep, decode, issues)


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


def _matched(src: Source, folder: str, ts: np.ndarray, rows: np.ndarray, what: str):
    issues = []
    if ts.size != rows.shape[0]:
        n = min(ts.size, rows.shape[0])
        issues.append(f"{ts.size} timestamps but {rows.shape[0]} {what} rows; using the first {n}")
        warnings.warn(f"{src.describe(folder)}: {issues[-1]}", DataWarning, stacklevel=4)
        ts, rows = ts[:n], rows[:n]
    return ts, rows, issues


def read_imu(src: Source, folder: str = "imu") -> ImuData:
    """Read ``imu/timestamps.txt`` and ``imu/imu_data.txt``."""
    ts = read_timestamps(src, f"{folder}/timestamps.txt")
    rel = f"{folder}/imu_data.txt"
    if not src.exists(rel):
        raise MissingDataError(f"{src.describe(rel)}: IMU data file not found")
    data = parse_imu(src.read_text(rel), src.describe(rel))
    return ImuData(*_matched(src, folder, ts, data, "IMU"))


def read_poses(src: Source, folder: str, filename: str) -> PoseData:
    """Read ``<folder>/timestamps.txt`` and ``<folder>/<filename>`` (x y z qx qy qz qw lines)."""
    ts = read_timestamps(src, f"{folder}/timestamps.txt")
    rel = f"{folder}/{filename}"
    if not src.exists(rel):
        raise MissingDataError(f"{src.describe(rel)}: poses file not found")
    poses = parse_poses(src.read_text(rel), src.describe(rel))
    norms = np.linalg.norm(poses[:, 3:], axis=1)
    if poses.size and not np.all(np.abs(norms - 1) < 1e-2):
        bad = int(np.argmax(np.abs(norms - 1)))
        raise FormatError(f"{src.describe(rel)}, line {bad + 1}: quaternion norm {norms[bad]:.4f}, "
                          "expected a unit quaternion qx qy qz qw")
    return PoseData(*_matched(src, folder, ts, poses, "pose"))
