"""What a processed run's manifest records: the settings, calibration and inputs of its products.

``<out>/process_manifest.json``, read and written by :class:`.output_folder.ProcessedRun`,
records per radar and product the processing settings and a fingerprint of the radar
calibration the frames there were computed with, and per radar a version of every input frame
file (size and modification time). This module holds only the content of that record and the
rules read from it (which settings differ, which frames are stale): pure functions, no files.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from typing import Any

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

__all__ = [
    "FORMAT",
    "calibration_fingerprint",
    "input_versions",
    "settings_differences",
    "settings_record",
    "stale_frames",
]

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
