"""Dependency-free progress display for long jobs, shared by every command.

:class:`Progress` is one bar with rate and ETA; :class:`StageProgress` shows several concurrent
stages (e.g. a simulator's lidar, cascade and single-chip frames) on one line. Both are also
callables ``progress(done, total)``, the callback signature the library's long functions take.
On a terminal they redraw one line; otherwise (logs, CI) they print a line at most every few
seconds, so that a redirected log stays readable.

Ctrl-C: :func:`interrupt_handling` (the command line's) remembers an interrupt as well as
raising ``KeyboardInterrupt``, and every progress update raises it again. Python ignores an
exception raised inside a weakref callback or a ``__del__`` (h5py runs such callbacks on every
dataset access), so an interrupt that lands there would otherwise be lost and the job finish
with exit 0; with this, it stops at the next unit of work.
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, TextIO

__all__ = ["Progress", "StageProgress", "check_interrupted", "interrupt_handling"]

_interrupted = False


def _on_sigint(signum: int, frame: Any) -> None:
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


@contextmanager
def interrupt_handling() -> Iterator[None]:
    """Within the block, Ctrl-C (SIGINT) raises ``KeyboardInterrupt`` and is remembered, so that
    :func:`check_interrupted` (called by every progress update) raises it again where the first
    one was swallowed. Only in the main thread (elsewhere the block changes nothing)."""
    global _interrupted
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _interrupted = False
    previous = signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        _interrupted = False


def check_interrupted() -> None:
    """Raise ``KeyboardInterrupt`` when Ctrl-C was pressed within :func:`interrupt_handling`
    (whether or not the first ``KeyboardInterrupt`` reached the caller)."""
    if _interrupted:
        raise KeyboardInterrupt


def _fmt_time(s: float) -> str:
    if s != s or s == float("inf"):
        return "--:--"
    s = round(s)
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m:02d}:{sec:02d}"


class Progress:
    """Progress over ``total`` units, written to ``stream`` (stderr by default).

    Parameters
    ----------
    total
        Number of units (frames) expected.
    desc
        A short label printed before the bar.
    unit
        Name of a unit, for the rate (``frames/s``).
    stream
        Where to write; None for stderr. ``enabled=False`` silences it.
    min_interval
        Seconds between redraws (terminal) or lines (non-terminal, multiplied by 10).
    initial
        Units already done before this job (a resumed one): counted in the bar, not in the
        rate.
    """

    def __init__(self, total: int, desc: str = "", unit: str = "frames", stream: TextIO | None = None,
                 enabled: bool = True, min_interval: float = 0.2, initial: int = 0):
        self.total = max(int(total), 0)
        self.initial = max(int(initial), 0)
        self.desc = desc
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.done = self.initial
        self.failed = 0
        self.start = time.perf_counter()
        self._last = 0.0
        self._shown: tuple[int, int] | None = None  # (done, failed) last drawn
        # The first unit pays for start-up (imports, compiles, a pool starting): the ETA uses
        # the rate after it, and is not shown until that rate is known.
        self._ref: tuple[float, int] | None = None  # (time, done) at the first update
        self._ended = False
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._interval = min_interval if self._tty else max(min_interval * 10, 2.0)

    @property
    def rate(self) -> float:
        """Units per second so far."""
        el = time.perf_counter() - self.start
        return (self.done - self.initial) / el if el > 0 else 0.0

    def eta(self) -> float | None:
        """Seconds left at the rate measured since the first update, or None while no such
        rate is known (before a second update, or when nothing is left)."""
        if self.done >= self.total:
            return 0.0
        if self._ref is None:
            return None
        t_ref, done_ref = self._ref
        el = time.perf_counter() - t_ref
        if self.done <= done_ref or el <= 0:
            return None
        return (self.total - self.done) * el / (self.done - done_ref)

    def line(self) -> str:
        """The current progress line."""
        frac = self.done / self.total if self.total else 1.0
        width = 24
        bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
        eta = self.eta()
        eta_text = "" if eta is None else f" ETA {_fmt_time(eta)}"
        fail = f", {self.failed} failed" if self.failed else ""
        return (f"{self.desc} [{bar}] {self.done}/{self.total} {self.unit} "
                f"{self.rate:.1f} {self.unit}/s elapsed "
                f"{_fmt_time(time.perf_counter() - self.start)}{eta_text}{fail}")

    def __call__(self, done: int, total: int) -> None:
        """Callback form: ``done`` of ``total`` units are finished."""
        self.total = max(int(total), 0)
        self.update(int(done) - self.done)

    def update(self, n: int = 1, failed: int = 0) -> None:
        """Count ``n`` more units done (``failed`` of them failed) and redraw if due; raises
        ``KeyboardInterrupt`` after a Ctrl-C (:func:`check_interrupted`)."""
        check_interrupted()
        self.done += n
        self.failed += failed
        now = time.perf_counter()
        if self._ref is None:
            self._ref = (now, self.done)
        if self.enabled and (now - self._last >= self._interval or self.done >= self.total):
            self._last = now
            self._write()

    def _write(self) -> None:
        self._shown = (self.done, self.failed)
        if self._tty:
            # A finished bar ends its line itself: callers using the callback form never close.
            end = "\n" if self.total and self.done >= self.total else ""
            self.stream.write("\r" + self.line() + "\x1b[K" + end)
            self._ended = bool(end)
        else:
            self.stream.write(self.line() + "\n")
        self.stream.flush()

    def close(self) -> None:
        """Draw the final state and end the line."""
        if self.enabled:
            if self._shown != (self.done, self.failed):
                self._write()
            if self._tty and not self._ended:
                self.stream.write("\n")
            self.stream.flush()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class StageProgress:
    """Progress of several concurrent stages on one stderr line (redrawn on a terminal,
    a line every few seconds otherwise)."""

    def __init__(self, label: str, stream=None, enabled: bool = True):
        self.label = label
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.stages: dict[str, tuple[int, int]] = {}
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self._last = 0.0
        self._drawn = False
        self._text = ""

    def __call__(self, stage: str, done: int, total: int) -> None:
        check_interrupted()
        self.stages[stage] = (done, total)
        now = time.monotonic()
        finished = all(d >= t for d, t in self.stages.values())
        if not self.enabled or (now - self._last < (0.2 if self._tty else 5.0) and not finished):
            return
        text = "  ".join(f"{s} {d}/{t}" for s, (d, t) in self.stages.items())
        if text == self._text:
            return
        self._last, self._text = now, text
        end = "" if self._tty else "\n"
        print(f"\r{self.label}: {text}\033[K" if self._tty else f"{self.label}: {text}",
              end=end, file=self.stream, flush=True)
        self._drawn = True

    def close(self) -> None:
        """End the progress line."""
        if self.enabled and self._drawn and self._tty:
            print(file=self.stream)
