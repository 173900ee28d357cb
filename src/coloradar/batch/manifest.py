"""What an output folder was made with, and who is writing it.

``<out>/process_manifest.json`` records, per radar and product, the processing settings and a
fingerprint of the radar calibration the frames there were computed with. A rerun with the
same settings resumes (complete frames are kept); a rerun with different ones is refused
unless ``overwrite`` — frames computed two ways never mix silently in one folder. The manifest
also records, for each radar, a version of every input frame file (size and modification
time): a frame whose input was rewritten since its output was made (a re-simulated run, a
repaired file) is stale, and a rerun processes it again instead of counting it complete. An
output
folder without a manifest that already holds products (written by something else) is refused
likewise.

``<out>/.process.lock`` is held (``flock``) while a job writes a run's output, so that two
jobs never write the same folder at once. The lock goes with the process: a killed job leaves
no stale lock behind.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path
from typing import Any

from .. import __version__
from ..calib import (
    RadarCalib,
    format_antenna_cfg,
    format_coupling_calib,
    format_heatmap_cfg,
    format_phase_frequency_calib,
    format_waveform_cfg,
)
from ..dataset import FrameStream
from ..dsp import ProcessingSettings
from ..errors import FormatError, OutputExistsError, WriteError
from ..formats.atomic import make_output_dir, write_text_if_changed
from ..formats.source import read_file_text

try:  # POSIX; elsewhere jobs are not guarded against each other
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "MANIFEST",
    "OutputLock",
    "calibration_fingerprint",
    "input_versions",
    "read_manifest",
    "settings_differences",
    "settings_record",
    "stale_frames",
    "write_manifest",
]

MANIFEST = "process_manifest.json"
LOCK = ".process.lock"
FORMAT = "coloradar-process-manifest/1"
# Settings that change how fast, not what, is computed (the heatmap engines agree within float32
# rounding: tests/test_dsp_heatmap.py), so switching them must not refuse a resume.
_NOT_OUTPUT = ("workers", "engine")


def calibration_fingerprint(calib: RadarCalib) -> str:
    """SHA-256 of everything in a radar calibration that the processing reads."""
    parts = [format_waveform_cfg(calib.waveform), format_antenna_cfg(calib.antenna, ""),
             format_heatmap_cfg(calib.heatmap)]
    if calib.coupling is not None:
        parts.append(format_coupling_calib(calib.coupling))
    if calib.phase_frequency is not None:
        parts.append(format_phase_frequency_calib(calib.phase_frequency))
    h = hashlib.sha256()
    for p in parts:
        h.update(p.encode())
        h.update(b"\0")
    return h.hexdigest()


def input_versions(stream: FrameStream) -> dict[str, str]:
    """Frame number (as text, a JSON key) to the version of its ADC file
    (:meth:`~coloradar.dataset.FrameStream.versions`), for every frame of ``stream`` whatever
    ``--frames`` selects; what the manifest records under ``inputs/<radar>``."""
    return {str(int(i)): v for i, v in zip(stream.frame_ids, stream.versions(), strict=True)}


def stale_frames(manifest: dict[str, Any] | None, radar: str, current: dict[str, str],
                 have_output: set[int]) -> list[int]:
    """Frame numbers among ``have_output`` whose input differs from the one recorded when their
    output was made: a changed version, or a frame the record does not know. A manifest without
    a record for ``radar`` (written before inputs were recorded) vouches for every frame."""
    stored = ((manifest or {}).get("inputs") or {}).get(radar)
    if not isinstance(stored, dict):
        return []
    return sorted(i for i in have_output
                  if str(i) in current and stored.get(str(i)) != current[str(i)])


def settings_record(settings: ProcessingSettings | None) -> dict[str, Any]:
    """The settings that decide the output, as JSON values."""
    s = settings or ProcessingSettings()
    rec = {f.name: getattr(s, f.name) for f in dataclasses.fields(s) if f.name not in _NOT_OUTPUT}
    return json.loads(json.dumps(rec))


def settings_differences(stored: dict[str, Any], current: dict[str, Any]) -> list[str]:
    """``"name: old -> new"`` for every setting that differs (a setting unknown to the file,
    added by a later version, counts as its default)."""
    defaults = settings_record(ProcessingSettings())
    diff = []
    for name in sorted(set(stored) | set(current)):
        old = stored.get(name, defaults.get(name))
        new = current.get(name, defaults.get(name))
        if old != new:
            diff.append(f"{name}: {old!r} -> {new!r}")
    return diff


def read_manifest(out: Path) -> dict[str, Any] | None:
    """The manifest of an output folder, None when there is none.

    Raises
    ------
    OutputExistsError
        When the file is there but unreadable (it cannot vouch for the files beside it).
    """
    path = out / MANIFEST
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


def write_manifest(out: Path, run: str, entries: dict[str, dict[str, Any]],
                   inputs: dict[str, dict[str, str]] | None = None) -> None:
    """Write (atomically, only when its content changes) the manifest with ``entries``:
    ``"<radar>/<product>" -> {"settings": ..., "calibration_sha256": ...}``, and ``inputs``:
    ``"<radar>" -> {frame number: version of its input file}`` (:func:`input_versions`)."""
    record: dict[str, Any] = {"format": FORMAT, "run": run, "coloradar_version": __version__,
                              "products": dict(sorted(entries.items()))}
    if inputs:
        record["inputs"] = dict(sorted(inputs.items()))
    text = json.dumps(record, indent=1) + "\n"
    write_text_if_changed(out / MANIFEST, text)


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
        make_output_dir(self.path.parent)
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
