"""Calibration of a whole rig: both radars and the extrinsics, loaded from a calib folder or zip
(and written back).

The records themselves (:class:`RadarCalib`, :class:`Calibration`) live in :mod:`.rig`, below both
this module and :mod:`.presets`, which builds them from built-in values; they are re-exported
here.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Collection
from dataclasses import replace
from pathlib import Path

from ..errors import CalibrationError, CalibrationWarning, ColoradarError
from ..formats.atomic import atomic_write_text
from ..formats.layout import RunLayout, get_layout
from ..formats.source import Source, open_source
from .antenna import format_antenna_cfg, parse_antenna_cfg
from .coupling import CouplingCalib, format_coupling_calib, parse_coupling_calib, read_coupling_calib
from .heatmap_grid import format_heatmap_cfg, parse_heatmap_cfg
from .phase_frequency import (
    PhaseFrequencyCalib,
    format_phase_frequency_calib,
    parse_phase_frequency_calib,
    read_phase_frequency_calib,
)
from .rig import RADARS, SENSORS, Calibration, RadarCalib
from .transforms import format_transform, parse_transform
from .waveform import format_waveform_cfg, parse_waveform_cfg

__all__ = [
    "RADARS",
    "SENSORS",
    "Calibration",
    "RadarCalib",
    "load_calibration",
    "load_radar_calib",
    "with_coupling",
    "with_phase_calibration",
    "write_calibration",
]

def _read_optional(src: Source, rel: str, parser, what: str):
    if not src.exists(rel):
        return None
    return parser(src.read_text(rel), src.describe(rel))


def load_radar_calib(src: Source, name: str) -> RadarCalib:
    """Read one radar's calibration from the folder ``src`` (``waveform_cfg.txt`` etc.)."""
    required = ("waveform_cfg.txt", "antenna_cfg.txt", "heatmap_cfg.txt")
    missing = [f for f in required if not src.exists(f)]
    if missing:
        raise CalibrationError(f"{src.location}: missing {', '.join(missing)} "
                               f"(present: {', '.join(src.listdir('')) or 'nothing'})")
    return RadarCalib(
        name=name,
        waveform=parse_waveform_cfg(src.read_text("waveform_cfg.txt"),
                                    src.describe("waveform_cfg.txt")),
        antenna=parse_antenna_cfg(src.read_text("antenna_cfg.txt"), src.describe("antenna_cfg.txt")),
        heatmap=parse_heatmap_cfg(src.read_text("heatmap_cfg.txt"), src.describe("heatmap_cfg.txt")),
        coupling=_read_optional(src, "coupling_calib.txt", parse_coupling_calib, "coupling"),
        phase_frequency=_read_optional(src, "phase_frequency_calib.txt",
                                       parse_phase_frequency_calib, "phase/frequency"),
        source=src.location,
    )


def _calib_source(path: str | os.PathLike[str]) -> Source:
    """Find the calibration tree at ``path``: a calib folder/zip, or a folder holding one."""
    p = Path(path)
    if p.is_dir():
        for cand in (p / "calib", p / "calib.zip"):
            if cand.exists():
                return _calib_source(cand)
    src = open_source(p, markers=(*RADARS, "transforms"))
    if not any(src.exists(r) for r in (*RADARS, "transforms")):
        raise CalibrationError(f"{p}: not a ColoRadar calibration (expected cascade/, "
                               "single_chip/ or transforms/ inside)")
    return src


def load_calibration(path: str | os.PathLike[str] | Source | None = None, *,
                     layout: str | RunLayout = "coloradar",
                     sensors: Collection[str] | None = None) -> Calibration:
    """Load the rig calibration.

    Parameters
    ----------
    path
        A calib folder or ``calib.zip`` (holding ``cascade/``, ``single_chip/``,
        ``transforms/``), a dataset root holding one of those, or None for the built-in presets.
        A radar or transform missing from the folder falls back to its preset with a
        :class:`CalibrationWarning`.
    layout
        The dataset layout the folder belongs to (:mod:`coloradar.formats.layout`): which
        radars it calibrates (ColoRadar+ has only the cascade; the other radar takes its
        preset silently) and how its transform files are named (ColoRadar+'s
        ``base_to_radar.txt`` is the cascade's).
    sensors
        The sensors the data at hand has (a run's sensor folders), or None for all: a value
        taken from the presets is warned about only for these (an imported single-chip capture
        hears nothing of the cascade's or the lidar's extrinsics).

    Returns
    -------
    Calibration
    """
    from . import presets

    if path is None:
        return presets.preset_calibration()
    lay = get_layout(layout)
    src = path if isinstance(path, Source) else _calib_source(path)
    radars = {}
    preset_values: list[str] = []
    for name in RADARS:
        if src.is_dir(name):
            try:
                radars[name] = load_radar_calib(src.sub(name), name)
            except ColoradarError:
                raise
        else:
            if name in lay.calib_radars and (sensors is None or name in sensors):
                warnings.warn(f"{src.location}: no {name}/ calibration; using the built-in "
                              "preset", CalibrationWarning, stacklevel=2)
                preset_values.append(f"{name} radar")
            radars[name] = presets.preset_radar(name)
    transforms = dict(presets.PRESET_TRANSFORMS)
    sensor_of = {fname: sensor for sensor, fname in lay.transforms.items()}
    own: set[str] = set()
    if src.is_dir("transforms"):
        for fname in src.listdir("transforms"):
            if fname.startswith("base_to_") and fname.endswith(".txt"):
                rel = f"transforms/{fname}"
                sensor = sensor_of.get(fname, fname[len("base_to_"):-4])
                transforms[sensor] = parse_transform(src.read_text(rel), src.describe(rel))
                own.add(sensor)
        missing = [s for s in lay.transforms if s not in own]
        told = [s for s in missing if sensors is None or s in sensors]
        if told:
            warnings.warn(f"{src.location}: no transforms/"
                          f"{', '.join(lay.transforms[s] for s in told)}; using the built-in "
                          f"preset extrinsic{'s' if len(told) > 1 else ''} of "
                          f"{', '.join(told)} (the real rig's, not this calibration's)",
                          CalibrationWarning, stacklevel=2)
    else:
        missing = list(lay.transforms)
        told = [s for s in missing if sensors is None or s in sensors]
        if told:
            warnings.warn(f"{src.location}: no transforms/ folder; using the built-in rig "
                          f"extrinsics of {', '.join(told)}", CalibrationWarning, stacklevel=2)
    preset_values += [f"{s} extrinsic" for s in missing]
    return Calibration(radars["cascade"], radars["single_chip"], transforms, src.location,
                       tuple(preset_values))


def write_calibration(calib: Calibration, folder: str | os.PathLike[str], *,
                      layout: str | RunLayout = "coloradar") -> Path:
    """Write ``calib`` as a dataset calib folder (``cascade/``, ``single_chip/``, ``transforms/``).

    With ``layout="coloradar_plus"`` only the radars and transforms of that layout are
    written, under its file names (``transforms/base_to_radar.txt`` for the cascade).
    Every file is written atomically. Returns the folder.
    """
    lay = get_layout(layout)
    root = Path(folder)
    for name in lay.calib_radars:
        rc = calib.radar(name)
        d = root / name
        atomic_write_text(d / "waveform_cfg.txt", format_waveform_cfg(rc.waveform))
        atomic_write_text(d / "antenna_cfg.txt", format_antenna_cfg(rc.antenna, f"{name} layout"))
        atomic_write_text(d / "heatmap_cfg.txt", format_heatmap_cfg(rc.heatmap))
        if rc.coupling is not None:
            atomic_write_text(d / "coupling_calib.txt", format_coupling_calib(rc.coupling))
        if rc.phase_frequency is not None:
            atomic_write_text(d / "phase_frequency_calib.txt",
                              format_phase_frequency_calib(rc.phase_frequency))
    for sensor, ext in calib.transforms.items():
        if lay.name == "coloradar" or sensor in lay.transforms:
            fname = lay.transforms.get(sensor, f"base_to_{sensor}.txt")
            atomic_write_text(root / "transforms" / fname, format_transform(ext))
    return root


def with_coupling(calib: Calibration, coupling: CouplingCalib | str | os.PathLike[str],
                  radar: str | None = None) -> Calibration:
    """``calib`` with one radar's coupling calibration replaced (by an estimated
    ``coupling_calib.txt``, say: ``coloradar calibrate coupling``).

    Parameters
    ----------
    calib
        The rig calibration.
    coupling
        A :class:`CouplingCalib` or the path of a ``coupling_calib.txt``.
    radar
        ``"cascade"`` or ``"single_chip"``; None: the radar whose ``(tx, rx)`` the file has.

    Raises
    ------
    CalibrationError
        The file fits neither radar, or not the one named (its size says which it is).
    """
    c = coupling if isinstance(coupling, CouplingCalib) else read_coupling_calib(coupling)
    where = "the coupling calibration" if isinstance(coupling, CouplingCalib) else str(coupling)
    name = _radar_of_size(calib, c.num_tx, c.num_rx, radar, where, "coupling")
    radars = {r: calib.radar(r) for r in RADARS}
    radars[name] = replace(radars[name], coupling=c)    # RadarCalib checks its range bins
    return replace(calib, cascade=radars["cascade"], single_chip=radars["single_chip"])


def with_phase_calibration(calib: Calibration,
                           phase: PhaseFrequencyCalib | str | os.PathLike[str],
                           radar: str | None = None) -> Calibration:
    """``calib`` with one radar's phase/frequency calibration replaced (by one measured with
    ``coloradar calibrate phase``, say).

    Parameters
    ----------
    calib
        The rig calibration.
    phase
        A :class:`PhaseFrequencyCalib` or the path of a ``phase_frequency_calib.txt``.
    radar
        ``"cascade"`` or ``"single_chip"``; None: the radar whose ``(tx, rx)`` the file has.

    Raises
    ------
    CalibrationError
        The file fits neither radar, or not the one named.
    """
    c = phase if isinstance(phase, PhaseFrequencyCalib) else read_phase_frequency_calib(phase)
    where = "the phase calibration" if isinstance(phase, PhaseFrequencyCalib) else str(phase)
    name = _radar_of_size(calib, c.num_tx, c.num_rx, radar, where, "phase")
    radars = {r: calib.radar(r) for r in RADARS}
    radars[name] = replace(radars[name], phase_frequency=c)
    return replace(calib, cascade=radars["cascade"], single_chip=radars["single_chip"])


def _radar_of_size(calib: Calibration, ntx: int, nrx: int, radar: str | None, where: str,
                   what: str) -> str:
    """The radar (``radar``, or the first whose size fits) of a ``ntx × nrx`` calibration
    file, or a :class:`CalibrationError` that names ``where``."""
    fits = [r for r in RADARS
            if (ntx, nrx) == (calib.radar(r).waveform.num_tx, calib.radar(r).waveform.num_rx)]
    name = radar if radar is not None else (fits[0] if fits else None)
    if name is None or name not in fits:
        sizes = ", ".join(f"{r} {calib.radar(r).waveform.num_tx} x "
                          f"{calib.radar(r).waveform.num_rx}" for r in RADARS)
        raise CalibrationError(f"{where}: a {ntx} TX x {nrx} RX {what} calibration "
                               f"does not fit {'the ' + radar if radar else 'either'} radar "
                               f"({sizes})")
    return name
