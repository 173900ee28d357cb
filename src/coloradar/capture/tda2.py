"""MMWCAS capture folders, as the TDA2 capture board writes them.

One pair of files per device and recording segment: ``<device>_<nnnn>_data.bin`` (the ADC
words, frame after frame) and ``<device>_<nnnn>_idx.bin`` (an index: a 24-byte header
``tag, version, flags, numIdx`` (uint32) and ``dataFileSize`` (uint64), then one 48-byte entry
per frame: ``tag, version`` (uint16), ``flags`` (uint32), ``width, height`` (uint16), four
uint32 metadata sizes, ``size`` (uint32), ``timestamp`` (uint64), ``offset`` (uint64)), for the
devices ``master``, ``slave1``, ``slave2``, ``slave3``. The layout of the index follows TI's
cascade scripts (``getValidNumFrames.m``); the timestamps' unit is not documented there and is
chosen from the configured frame period (docs/capture.md).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FormatError, MissingDataError

__all__ = ["DEVICES", "IDX_ENTRY", "IDX_HEADER", "CascadeFiles", "FrameIndex",
           "find_cascade_files", "read_idx", "timestamp_unit"]

DEVICES = ("master", "slave1", "slave2", "slave3")
"""The four AWR2243 of the MMWCAS-RF-EVM, in the order their RX channels are stacked."""

IDX_HEADER = np.dtype([("tag", "<u4"), ("version", "<u4"), ("flags", "<u4"), ("numIdx", "<u4"),
                       ("dataFileSize", "<u8")])
IDX_ENTRY = np.dtype([("tag", "<u2"), ("version", "<u2"), ("flags", "<u4"), ("width", "<u2"),
                      ("height", "<u2"), ("meta", "<u4", (4,)), ("size", "<u4"),
                      ("timestamp", "<u8"), ("offset", "<u8")])

_NAME = re.compile(r"^(master|slave1|slave2|slave3)_(\d+)_(data|idx)\.bin$")


@dataclass(frozen=True)
class CascadeFiles:
    """The files of a capture folder: per segment number, the data and index file of each
    device (``segments[k][device] = (data, idx)``)."""

    folder: Path
    segments: tuple[dict[str, tuple[Path, Path]], ...]


def find_cascade_files(folder: Path) -> CascadeFiles:
    """The capture's files, segment by segment.

    Raises
    ------
    MissingDataError
        No ``master_*_data.bin`` in the folder, or a device's data or index file missing (named).
    """
    found: dict[int, dict[tuple[str, str], Path]] = {}
    for p in folder.iterdir():
        m = _NAME.match(p.name)
        if m:
            found.setdefault(int(m.group(2)), {})[(m.group(1), m.group(3))] = p
    if not any(("master", "data") in f for f in found.values()):
        raise MissingDataError(f"{folder}: no master_<nnnn>_data.bin; an MMWCAS capture folder "
                               "holds master/slave1/slave2/slave3_<nnnn>_data.bin and _idx.bin")
    segments = []
    for k in sorted(found):
        files = found[k]
        seg = {}
        for dev in DEVICES:
            for kind in ("data", "idx"):
                if (dev, kind) not in files:
                    raise MissingDataError(f"{folder}: missing {dev}_{k:04d}_{kind}.bin (each of "
                                           f"{', '.join(DEVICES)} has a _data.bin and an "
                                           "_idx.bin per segment)")
            seg[dev] = (files[(dev, "data")], files[(dev, "idx")])
        segments.append(seg)
    return CascadeFiles(folder, tuple(segments))


@dataclass(frozen=True)
class FrameIndex:
    """What an ``_idx.bin`` says of its data file.

    Attributes
    ----------
    num_frames
        ``numIdx``: the frames the data file holds.
    data_size
        ``dataFileSize``: the bytes written into the data file (TI: "total data size written
        into file"); a preallocated data file is larger.
    timestamps, sizes, offsets
        Per frame: the uint64 timestamp, the uint32 byte size, the uint64 byte offset in the
        data file (int64 arrays but the timestamps).
    """

    num_frames: int
    data_size: int
    timestamps: np.ndarray
    sizes: np.ndarray
    offsets: np.ndarray


def read_idx(path: Path) -> FrameIndex:
    """The header and the ``numIdx`` entries of an ``_idx.bin``.

    Raises
    ------
    FormatError
        A file shorter than its header, an index of 0 frames, or fewer entries than
        ``numIdx`` says.
    """
    raw = path.read_bytes()
    if len(raw) < IDX_HEADER.itemsize:
        raise FormatError(f"{path}: {len(raw)} bytes, shorter than the {IDX_HEADER.itemsize}-byte "
                          "index header")
    head = np.frombuffer(raw[:IDX_HEADER.itemsize], dtype=IDX_HEADER)[0]
    n = int(head["numIdx"])
    body = raw[IDX_HEADER.itemsize:]
    have = len(body) // IDX_ENTRY.itemsize
    if n == 0:
        # The frames' times come from here alone: an empty index leaves them unknown.
        raise FormatError(f"{path}: the index header says 0 frames; the capture's frame times "
                          "are unknown (an interrupted recording?)")
    if have < n:
        raise FormatError(f"{path}: the header says {n} frames but the index holds {have} "
                          f"entries of {IDX_ENTRY.itemsize} bytes")
    entries = np.frombuffer(body[:n * IDX_ENTRY.itemsize], dtype=IDX_ENTRY)
    return FrameIndex(n, int(head["dataFileSize"]), entries["timestamp"].astype(np.uint64),
                      entries["size"].astype(np.int64), entries["offset"].astype(np.int64))


def timestamp_unit(ticks: np.ndarray, frame_period: float) -> float:
    """Seconds per timestamp tick: of 1 ns, 1 µs, 1 ms, the one whose median frame spacing is
    closest (in ratio) to the configured period; 1 µs when there are fewer than two frames."""
    if ticks.size < 2:
        return 1e-6
    d = float(np.median(np.diff(ticks.astype(np.float64))))
    if d <= 0:
        return 1e-6
    return min((1e-9, 1e-6, 1e-3), key=lambda u: abs(np.log(d * u / frame_period)))
