"""The machine-readable record of a batch job (``OUT/process_report.json``) and its summary.

Layout of the JSON file::

    {"format": "coloradar-process-report/1", "status": "ok" | "failed" | "interrupted",
     "coloradar_version", "started", "finished" (UTC ISO 8601), "seconds", "executor",
     "options": {products, radars, frames, chunk_size, overwrite, settings},
     "totals": {"frames", "done", "skipped", "failed"},
     "frames_per_second",                 # frames done / wall time
     "workers": {"host:pid": peak resident memory [bytes]},
     "runs": {"<run>": {"path", "out", "error", "note",
                        "radars": {"<radar>": {"frames", "done", "skipped", "failed",
                                               "worker_seconds", "error",
                                               "failures": [{"frame_id", "position", "file",
                                                             "error", "message"}]}}}}}

``frames`` counts the frames asked for, ``skipped`` those already complete in OUT,
``done`` those written now, ``failed`` the others (each listed under ``failures``). A run
``error`` (it could not be opened, say) or a radar ``error`` counts as one failure; a ``note``
says why a run had nothing to do (no ADC frames of the radars asked for).
"""

from __future__ import annotations

import datetime
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import __version__
from ..formats import atomic_write_text
from .chunks import FrameFailure

__all__ = ["REPORT", "BatchReport", "RadarOutcome", "RunOutcome"]

REPORT = "process_report.json"


@dataclass
class RadarOutcome:
    """Frames of one radar of one run: asked for, written, already complete, failed."""

    frames: int = 0
    done: int = 0
    skipped: int = 0
    failures: list[FrameFailure] = field(default_factory=list)
    worker_seconds: float = 0.0
    error: str | None = None

    @property
    def failed(self) -> int:
        return len(self.failures) + (self.error is not None)

    def to_json(self) -> dict[str, Any]:
        return {"frames": self.frames, "done": self.done, "skipped": self.skipped,
                "failed": self.failed, "worker_seconds": round(self.worker_seconds, 3),
                "error": self.error,
                "failures": [{"frame_id": f.frame_id, "position": f.position, "file": f.file,
                              "error": f.error, "message": f.message}
                             for f in sorted(self.failures, key=lambda f: f.position)]}


@dataclass
class RunOutcome:
    """One run of a batch."""

    name: str
    path: str
    out: str
    radars: dict[str, RadarOutcome] = field(default_factory=dict)
    error: str | None = None
    note: str | None = None

    @property
    def failed(self) -> int:
        return sum(r.failed for r in self.radars.values()) + (self.error is not None)

    def to_json(self) -> dict[str, Any]:
        return {"path": self.path, "out": self.out, "error": self.error, "note": self.note,
                "radars": {r: o.to_json() for r, o in self.radars.items()}}


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


@dataclass
class BatchReport:
    """Everything a batch job did; :meth:`write` saves it, :meth:`summary` describes it.

    Attributes
    ----------
    runs
        Run name -> :class:`RunOutcome`.
    workers
        Worker ``host:pid`` -> peak resident memory [bytes].
    error
        Why the job as a whole could not run (its workers could not start), or None.
    """

    executor: str = ""
    options: dict[str, Any] = field(default_factory=dict)
    runs: dict[str, RunOutcome] = field(default_factory=dict)
    workers: dict[str, int] = field(default_factory=dict)
    started: str = field(default_factory=_now)
    finished: str = ""
    seconds: float = 0.0
    interrupted: bool = False
    path: Path | None = None
    error: str | None = None

    def totals(self) -> dict[str, int]:
        """Frames asked for, done, skipped and failed over all runs."""
        t = {"frames": 0, "done": 0, "skipped": 0, "failed": 0}
        for run in self.runs.values():
            t["failed"] += run.error is not None
            for r in run.radars.values():
                t["frames"] += r.frames
                t["done"] += r.done
                t["skipped"] += r.skipped
                t["failed"] += r.failed
        return t

    @property
    def ok(self) -> bool:
        """True when nothing failed and the job was not interrupted."""
        return not self.interrupted and self.error is None and self.totals()["failed"] == 0

    @property
    def status(self) -> str:
        return "interrupted" if self.interrupted else "ok" if self.ok else "failed"

    @property
    def frames_per_second(self) -> float:
        return self.totals()["done"] / self.seconds if self.seconds > 0 else 0.0

    def failures(self) -> list[tuple[str, str, FrameFailure]]:
        """``(run, radar, failure)`` for every failed frame."""
        return [(name, radar, f) for name, run in self.runs.items()
                for radar, o in run.radars.items() for f in o.failures]

    def to_json(self) -> dict[str, Any]:
        return {"format": "coloradar-process-report/1", "status": self.status,
                "coloradar_version": __version__, "started": self.started,
                "finished": self.finished, "seconds": round(self.seconds, 3),
                "executor": self.executor, "error": self.error, "options": self.options,
                "totals": self.totals(),
                "frames_per_second": round(self.frames_per_second, 3),
                "workers": dict(sorted(self.workers.items())),
                "runs": {n: r.to_json() for n, r in sorted(self.runs.items())}}

    def to_text(self) -> str:
        """The JSON report as saved (``process_report.json``)."""
        return json.dumps(self.to_json(), indent=1) + "\n"

    def write(self, path: str | os.PathLike) -> Path:
        """Write the JSON report atomically; returns its path."""
        self.path = Path(path)
        atomic_write_text(self.path, self.to_text())
        return self.path

    def summary(self, max_failures: int = 10) -> str:
        """Lines for the screen: per run and radar counts, the first failures, totals."""
        lines = [f"FAILED: {self.error}"] if self.error else []
        for name, run in sorted(self.runs.items()):
            if run.error:
                lines.append(f"{name}: FAILED: {run.error}")
                continue
            if run.note and not run.radars:
                lines.append(f"{name}: nothing to do ({run.note})")
                continue
            parts = []
            for radar, o in run.radars.items():
                if o.error:
                    parts.append(f"{radar} FAILED: {o.error}")
                    continue
                txt = f"{radar} {o.done + o.skipped}/{o.frames} frames"
                extra = [f"{o.skipped} already done"] if o.skipped else []
                if o.failed:
                    extra.append(f"{o.failed} FAILED")
                parts.append(txt + (f" ({', '.join(extra)})" if extra else ""))
            lines.append(f"{name}: " + "; ".join(parts) + f" -> {run.out}")
        fails = self.failures()
        for run_name, radar, f in fails[:max_failures]:
            msg = f.message.removeprefix(f"{f.file}: ")
            lines.append(f"  failed: {run_name} {radar} frame {f.frame_id} ({f.file}): "
                         f"{f.error}: {msg}")
        if len(fails) > max_failures:
            lines.append(f"  … and {len(fails) - max_failures} more failures (see the report)")
        t = self.totals()
        peak = max(self.workers.values(), default=0)
        how = [f"{self.frames_per_second:.1f} frames/s", self.executor]
        if peak:
            how.append(f"peak worker memory {peak / 2**20:.0f} MiB")
        frames = "frame" if t["done"] == 1 else "frames"
        lines.append(f"{t['done']} {frames} processed, {t['skipped']} already complete, "
                     f"{t['failed']} failed in {self.seconds:.1f} s ({'; '.join(how)})"
                     + (" — INTERRUPTED" if self.interrupted else ""))
        if self.path is not None:
            lines.append(f"report: {self.path}")
        return "\n".join(lines)

    def finish(self, seconds: float) -> None:
        self.seconds = seconds
        self.finished = _now()
