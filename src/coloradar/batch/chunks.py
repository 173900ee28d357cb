"""The unit of work of batch processing: one chunk of one radar's frames of one run.

:func:`process_chunk` runs in a worker (a pool process, a Dask worker thread, or this
process): it opens the run itself, processes its frames one at a time (memory: one frame and
its products), writes each product file atomically (through
:func:`coloradar.formats.atomic.atomic_write_bytes`, to the file the output folder named:
:attr:`FrameChunk.files`), and returns only a small :class:`ChunkResult`. A frame that fails is
recorded and the chunk goes on.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

from ..calib import Calibration
from ..dataset import FrameStream, open_sequence
from ..dsp import ProcessingSettings, RadarProcessor
from ..errors import ColoradarError
from ..formats.atomic import atomic_write_bytes
from ..formats.binary import encode_heatmap, encode_pointcloud

try:
    import resource
except ImportError:  # pragma: no cover - not on Windows
    resource = None  # type: ignore[assignment]

__all__ = ["ChunkResult", "FrameChunk", "FrameFailure", "process_chunk", "worker_peak_memory"]

CalibLike = Calibration | str | None


@dataclass(frozen=True)
class FrameChunk:
    """Frames of one radar of one run to process (what travels to a worker).

    Attributes
    ----------
    run
        Run folder or zip.
    calib
        A calib folder/zip path, None (found beside the run), or a Calibration object.
    calib_key
        Fingerprint of the radar calibration (worker-side cache key).
    radar
        ``"cascade"`` or ``"single_chip"``.
    products
        Products to write.
    positions, frame_ids
        Positions in the run's ADC stream and the file numbers the driver saw there.
    out
        This run's output folder.
    files
        ``(head, tail)`` per product (in the order of ``products``): frame number ``n`` goes to
        ``head + str(n) + tail``
        (:meth:`~coloradar.batch.output_folder.ProcessedRun.frame_file_parts`).
    settings
        Processing settings.
    """

    run: str
    calib: CalibLike
    calib_key: str
    radar: str
    products: tuple[str, ...]
    positions: tuple[int, ...]
    frame_ids: tuple[int, ...]
    out: str
    files: tuple[tuple[str, str], ...]
    settings: ProcessingSettings | None = None


@dataclass(frozen=True)
class FrameFailure:
    """A frame that could not be processed.

    Attributes
    ----------
    position, frame_id
        Position in the ADC stream and file number.
    file
        The ADC file (path or ``archive.zip:member``).
    error, message
        Exception type name and message.
    """

    position: int
    frame_id: int
    file: str
    error: str
    message: str


@dataclass
class ChunkResult:
    """What a worker sends back: frames written, frames failed, time and memory used."""

    done: list[int] = field(default_factory=list)
    failures: list[FrameFailure] = field(default_factory=list)
    seconds: float = 0.0
    worker: str = ""
    peak_memory: int = 0


def worker_peak_memory() -> int:
    """Peak resident memory of this process so far [bytes] (0 where unknown)."""
    if resource is None:  # pragma: no cover
        return 0
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


# Opened runs and processors, per thread (Dask runs tasks in threads), a couple at most so
# that memory stays bounded: consecutive chunks of one run reuse them.
_local = threading.local()
_CACHE_SIZE = 2


def _open(chunk: FrameChunk) -> tuple[FrameStream, RadarProcessor]:
    cache: OrderedDict[Any, Any] = getattr(_local, "cache", None) or OrderedDict()
    _local.cache = cache
    key = (chunk.run, chunk.calib if isinstance(chunk.calib, str | None) else None,
           chunk.calib_key, chunk.radar, chunk.settings)
    if key in cache:
        cache.move_to_end(key)
        return cache[key]
    seq = open_sequence(chunk.run, calib=chunk.calib)
    opened = (seq.radar(chunk.radar).adc,
              RadarProcessor(seq.calib.radar(chunk.radar), chunk.settings))
    cache[key] = opened
    while len(cache) > _CACHE_SIZE:
        cache.popitem(last=False)
    return opened


def _process_frame(stream: FrameStream, proc: RadarProcessor, chunk: FrameChunk,
                   k: int, fid: int) -> None:
    if int(stream.frame_ids[k]) != fid:
        raise ColoradarError(f"{stream.path(k)}: the run changed while it was being processed "
                             f"(expected frame {fid} at position {k})")
    prods = chunk.products
    hm, pts = proc.products(stream[k], "heatmaps" in prods, "pointclouds" in prods)
    for product, (head, tail) in zip(prods, chunk.files, strict=True):
        if product == "heatmaps" and hm is not None:
            data = encode_heatmap(hm)
        elif product == "pointclouds" and pts is not None:
            data = encode_pointcloud(pts, 5)
        else:
            continue
        atomic_write_bytes(f"{head}{fid}{tail}", data)


def process_chunk(chunk: FrameChunk) -> ChunkResult:
    """Process a chunk's frames and write their product files; never raises for bad data.

    Returns
    -------
    ChunkResult
        Positions written, failures (frame, file, error), wall time [s], worker
        ``host:pid`` and its peak memory [bytes].
    """
    t0 = time.perf_counter()
    res = ChunkResult(worker=f"{socket.gethostname()}:{os.getpid()}")
    try:
        stream, proc = _open(chunk)
    except Exception as exc:
        res.failures = [FrameFailure(k, fid, str(chunk.run), type(exc).__name__, str(exc))
                        for k, fid in zip(chunk.positions, chunk.frame_ids, strict=True)]
    else:
        for k, fid in zip(chunk.positions, chunk.frame_ids, strict=True):
            try:
                _process_frame(stream, proc, chunk, k, fid)
            except Exception as exc:
                try:
                    where = stream.path(k)
                except Exception:
                    where = str(chunk.run)
                res.failures.append(FrameFailure(k, fid, where, type(exc).__name__, str(exc)))
            else:
                res.done.append(k)
    res.seconds = time.perf_counter() - t0
    res.peak_memory = worker_peak_memory()
    return res
