"""The typed, frozen records of a rig's calibration: one radar's (:class:`RadarCalib`) and the
whole rig's (:class:`Calibration`: both radars and the extrinsics).

They are read from files by :mod:`.sensor` and built from built-in values by :mod:`.presets`;
this module imports neither.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from ..errors import CalibrationError, MissingDataError
from .antenna import AntennaConfig
from .coupling import CouplingCalib
from .heatmap_grid import HeatmapConfig
from .phase_frequency import PhaseFrequencyCalib
from .transforms import Extrinsic
from .waveform import WaveformConfig

__all__ = ["RADARS", "SENSORS", "Calibration", "RadarCalib"]

RADARS = ("cascade", "single_chip")
"""Names of the two radars, as in the dataset's folder names."""

SENSORS = ("cascade", "single_chip", "lidar", "imu", "vicon")
"""Sensors that have a ``transforms/base_to_<sensor>.txt``."""


@dataclass(frozen=True, eq=False)
class RadarCalib:
    """Everything needed to read and process one radar's data.

    Attributes
    ----------
    name
        ``"cascade"`` or ``"single_chip"``.
    waveform, antenna, heatmap
        Chirp/frame configuration, antenna layout, heatmap grid.
    coupling
        Coupling profile to subtract, or None when not calibrated.
    phase_frequency
        Cascade per-channel calibration, or None (single chip, or not calibrated).
    source
        Where it was read from (a path, or ``"preset"``).
    """

    name: str
    waveform: WaveformConfig
    antenna: AntennaConfig
    heatmap: HeatmapConfig
    coupling: CouplingCalib | None = None
    phase_frequency: PhaseFrequencyCalib | None = None
    source: str = "preset"

    def __post_init__(self) -> None:
        w, a = self.waveform, self.antenna
        where = f"{self.name} calibration ({self.source})"
        if (w.num_tx, w.num_rx) != (a.num_tx, a.num_rx):
            raise CalibrationError(f"{where}: waveform has {w.num_tx} TX x {w.num_rx} RX but the "
                                   f"antenna layout {a.num_tx} x {a.num_rx}")
        if self.heatmap.num_range_bins > w.num_samples:
            raise CalibrationError(f"{where}: {self.heatmap.num_range_bins} heatmap range bins "
                                   f"but only {w.num_samples} samples per chirp")
        if self.coupling is not None:
            c = self.coupling
            if (c.num_tx, c.num_rx) != (w.num_tx, w.num_rx) or c.num_range_bins > w.num_samples:
                raise CalibrationError(f"{where}: coupling is {c.num_tx} x {c.num_rx} x "
                                       f"{c.num_range_bins}, waveform {w.num_tx} x {w.num_rx} x "
                                       f"{w.num_samples}")
        if self.phase_frequency is not None:
            p = self.phase_frequency
            if (p.num_tx, p.num_rx) != (w.num_tx, w.num_rx):
                raise CalibrationError(f"{where}: phase/frequency calib is {p.num_tx} x "
                                       f"{p.num_rx}, waveform {w.num_tx} x {w.num_rx}")

    @property
    def frame_shape(self) -> tuple[int, int, int, int]:
        """``(tx, rx, chirp, sample)`` shape of an ADC frame."""
        return self.waveform.frame_shape

    @property
    def near_field_reference(self) -> float | None:
        """Range [m] at which the channel calibration focuses the array: the reflector of the
        phase/frequency calibration when its phases carry that reflector's near-field phases
        (:meth:`PhaseFrequencyCalib.reference_range`), else None (no calibration, or phases
        without a near-field term). Processing focuses relative to it (docs/dsp.md)."""
        if self.phase_frequency is None:
            return None
        return self.phase_frequency.reference_range(self.waveform.num_samples)

    @property
    def heatmap_shape(self) -> tuple[int, int, int]:
        """``(el, az, range)`` shape of one heatmap channel."""
        return self.heatmap.shape

    def summary(self) -> str:
        """A few lines describing the radar, for ``coloradar info``."""
        w, h, v = self.waveform, self.heatmap, self.antenna.virtual
        extra = []
        if self.coupling is not None:
            extra.append("coupling")
        if self.phase_frequency is not None:
            extra.append("phase/frequency")
        return (f"{w.num_tx} TX x {w.num_rx} RX ({v.num_unique} unique virtual elements), "
                f"{w.num_chirps} loops x {w.num_samples} samples; "
                f"range bin {w.range_bin_width:.4f} m (max {w.max_range:.1f} m), "
                f"v_max {w.max_velocity:.2f} m/s (bin {w.velocity_bin_width:.3f} m/s); "
                f"heatmap {h.num_elevation_bins}x{h.num_azimuth_bins}x{h.num_range_bins} "
                f"(el x az x range); calib: {', '.join(extra) or 'none'}")


@dataclass(frozen=True, eq=False)
class Calibration:
    """Calibration of the ColoRadar rig.

    Attributes
    ----------
    cascade, single_chip
        The two radars' calibrations.
    transforms
        ``base_T_sensor`` extrinsics by sensor name (``cascade``, ``single_chip``, ``lidar``,
        ``imu``, ``vicon``).
    source
        Where it was read from, or ``"preset"``.
    presets
        The values that are not the calibration's own but built-in presets (the real rig's),
        e.g. ``("lidar extrinsic",)`` or ``("single_chip radar",)``: what a user must be told
        whenever they are used (:meth:`preset_note`).
    """

    cascade: RadarCalib
    single_chip: RadarCalib
    transforms: Mapping[str, Extrinsic] = field(default_factory=dict)
    source: str = "preset"
    presets: tuple[str, ...] = ()

    def preset_note(self, values: Iterable[str] | None = None) -> str:
        """One line saying which of ``values`` (default: all) are built-in presets, e.g.
        ``"calibration: built-in preset for lidar extrinsic (not this run's own)"``; empty
        when none is."""
        wanted = self.presets if values is None else [v for v in values if v in self.presets]
        if not wanted:
            return ""
        return (f"calibration: built-in preset{'s' if len(wanted) > 1 else ''} for "
                f"{', '.join(wanted)} (not this run's own)")

    def radar(self, name: str) -> RadarCalib:
        """The calibration of radar ``name`` (``"cascade"`` or ``"single_chip"``)."""
        if name not in RADARS:
            raise MissingDataError(f"unknown radar {name!r}; expected one of {', '.join(RADARS)}")
        return getattr(self, name)
