"""Summaries of runs and datasets: counts, durations, rates, timestamp gaps (``coloradar info``)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import ColoradarError
from ..formats.layout import COLORADAR
from .sequence import Sequence

__all__ = ["StreamSummary", "format_sequence_summary", "summarize_sequence", "summarize_timestamps"]


@dataclass
class StreamSummary:
    """Statistics of one stream's timestamps.

    Attributes
    ----------
    name
        Stream name (``cascade/adc``, ``imu``…).
    count
        Number of usable frames or samples.
    start, duration
        First timestamp and last − first [s].
    rate
        1 / median interval [Hz] (nan with fewer than two samples).
    gaps
        ``(index, length_s)`` of every interval longer than 1.5× the median one.
    non_monotonic
        Number of intervals that are zero or negative.
    issues
        Inconsistencies found when reading (e.g. timestamp/frame count mismatch) or the error
        that prevented reading.
    errors
        How many of ``issues`` are errors (an unreadable stream, a malformed frame file, a
        timestamp that is not finite, duplicated or decreasing) rather than inconsistencies
        the readers work around (``coloradar info`` exits 1 when a stream has any).
    """

    name: str
    count: int = 0
    start: float = float("nan")
    duration: float = float("nan")
    rate: float = float("nan")
    gaps: list[tuple[int, float]] = field(default_factory=list)
    non_monotonic: int = 0
    issues: list[str] = field(default_factory=list)
    errors: int = 0


def summarize_timestamps(name: str, t: np.ndarray, gap_factor: float = 1.5) -> StreamSummary:
    """Statistics of a float64 ``(N,)`` timestamp array (see :class:`StreamSummary`)."""
    s = StreamSummary(name, count=int(t.size))
    if t.size:
        s.start = float(t[0])
        s.duration = float(t[-1] - t[0])
    if t.size >= 2:
        dt = np.diff(t)
        med = float(np.median(dt))
        s.rate = 1.0 / med if med > 0 else float("nan")
        s.non_monotonic = int(np.sum(dt <= 0))
        if med > 0:
            idx = np.flatnonzero(dt > gap_factor * med)
            s.gaps = [(int(i), float(dt[i])) for i in idx]
    return s


def summarize_sequence(seq: Sequence) -> list[StreamSummary]:
    """One :class:`StreamSummary` per stream present in ``seq``; reading problems become issues."""
    out = []
    for key in seq.available():
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # reported through ``issues`` instead
                bad = []
                if key in ("imu", "groundtruth", "vicon"):
                    obj = getattr(seq, key)
                    ts, issues, faults = obj.timestamps, obj.issues, obj.timestamp_faults
                else:
                    sensor, product = key.split("/")
                    stream = getattr(getattr(seq, sensor), product)
                    ts, issues = stream.timestamps, stream.issues
                    faults = stream.timestamp_faults
                    bad = stream.check_files()
            s = summarize_timestamps(key, ts)
            s.issues = list(issues) + bad
            s.errors = len(bad) + len(faults)
            if s.non_monotonic and not faults:  # e.g. a reader that does not check
                s.errors += 1
        except ColoradarError as exc:
            s = StreamSummary(key, issues=[f"unreadable: {exc}"], errors=1)
        out.append(s)
    return out


def _fmt_gaps(s: StreamSummary) -> str:
    if not s.gaps:
        return "none"
    longest = max(g for _, g in s.gaps)
    return f"{len(s.gaps)} (longest {longest:.3f} s)"


def format_sequence_summary(seq: Sequence, summaries: list[StreamSummary] | None = None) -> str:
    """A human-readable table of ``seq``'s streams and calibration."""
    summaries = summarize_sequence(seq) if summaries is None else summaries
    kind = "" if seq.layout.name == "coloradar" else f", {seq.layout.title} layout"
    lines = [f"run {seq.name}  ({seq.location}{kind})"]
    header = f"  {'stream':<24}{'frames':>8}{'duration':>11}{'rate':>10}  gaps"
    lines.append(header)
    for s in summaries:
        dur = f"{s.duration:9.2f} s" if np.isfinite(s.duration) else f"{'-':>11}"
        rate = f"{s.rate:7.2f} Hz" if np.isfinite(s.rate) else f"{'-':>10}"
        lines.append(f"  {s.name:<24}{s.count:>8}{dur:>11}{rate:>10}  {_fmt_gaps(s)}")
        if s.non_monotonic and not any("timestamp" in m for m in s.issues):
            lines.append(f"    ! {s.non_monotonic} timestamps do not increase")
        lines.extend(f"    ! {msg}" for msg in s.issues)
    return "\n".join(lines)


def format_calibration_summary(seq_or_calib) -> str:
    """Calibration lines for ``info``: source and each radar's derived quantities."""
    calib = getattr(seq_or_calib, "calib", seq_or_calib)
    layout = getattr(seq_or_calib, "layout", COLORADAR)
    lines = [f"calibration: {calib.source}"]
    for name in layout.radars:
        lines.append(f"  {name}: {calib.radar(name).summary()}")
    shown = [t for t in sorted(calib.transforms)
             if layout.name == COLORADAR.name or t in layout.transforms]
    lines.append(f"  transforms: {', '.join(shown) or 'none'}")
    if calib.presets:
        lines.append(f"  ! built-in presets, not this calibration's own: {', '.join(calib.presets)}")
    return "\n".join(lines)
