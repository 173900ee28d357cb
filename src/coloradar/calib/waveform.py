"""The FMCW chirp and frame configuration (``waveform_cfg.txt``) and the quantities derived from it."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

from ..errors import CalibrationError, CalibrationWarning
from ._parse import get_number, key_values

__all__ = ["SPEED_OF_LIGHT", "WaveformConfig", "check_waveform_bounds", "format_waveform_cfg",
           "parse_waveform_cfg"]

SPEED_OF_LIGHT = 299_792_458.0
"""Speed of light in vacuum [m/s]."""


@dataclass(frozen=True)
class WaveformConfig:
    """Chirp and frame parameters of a TDM-MIMO FMCW radar.

    Times are in seconds, frequencies in Hz, the slope in Hz/s. ``num_chirps`` is the number of
    chirp *loops* per frame; each loop has one chirp per TX (time-division MIMO), so a frame has
    ``num_chirps * num_tx`` chirps.
    """

    num_rx: int
    num_tx: int
    num_samples: int
    num_chirps: int
    sample_rate: float
    start_frequency: float
    idle_time: float
    adc_start_time: float
    ramp_end_time: float
    slope: float

    def __post_init__(self) -> None:
        check_waveform_bounds({f: getattr(self, f) for f in _BOUNDS}, "waveform")

    # --- sizes ---------------------------------------------------------------------------------
    @property
    def frame_shape(self) -> tuple[int, int, int, int]:
        """Shape ``(tx, rx, chirp, sample)`` of one ADC frame."""
        return (self.num_tx, self.num_rx, self.num_chirps, self.num_samples)

    @property
    def frame_nbytes(self) -> int:
        """Size of one ADC frame file in bytes (int16 I and Q)."""
        return self.num_tx * self.num_rx * self.num_chirps * self.num_samples * 4

    # --- timing --------------------------------------------------------------------------------
    @property
    def chirp_period(self) -> float:
        """Time from one chirp's start to the next's (idle + ramp) [s]."""
        return self.idle_time + self.ramp_end_time

    @property
    def tdm_period(self) -> float:
        """Time between two chirps of the same TX (one chirp loop) [s]."""
        return self.num_tx * self.chirp_period

    @property
    def sampling_time(self) -> float:
        """Duration of the sampled part of a chirp, ``num_samples / sample_rate`` [s]."""
        return self.num_samples / self.sample_rate

    # --- range ---------------------------------------------------------------------------------
    @property
    def bandwidth(self) -> float:
        """Swept bandwidth during sampling [Hz]."""
        return self.slope * self.sampling_time

    @property
    def range_bin_width(self) -> float:
        """Range spanned by one range-FFT bin without zero padding, ``c·fs/(2·S·Ns)`` [m]."""
        return SPEED_OF_LIGHT * self.sample_rate / (2.0 * self.slope * self.num_samples)

    @property
    def max_range(self) -> float:
        """Unambiguous range of complex (I/Q) sampling, ``c·fs/(2·S)`` [m]."""
        return self.range_bin_width * self.num_samples

    # --- carrier and velocity ------------------------------------------------------------------
    @property
    def center_frequency(self) -> float:
        """Carrier frequency at the middle of the sampling window [Hz]."""
        return self.start_frequency + self.slope * (self.adc_start_time + self.sampling_time / 2)

    @property
    def wavelength(self) -> float:
        """Wavelength at :attr:`center_frequency` [m]."""
        return SPEED_OF_LIGHT / self.center_frequency

    @property
    def max_velocity(self) -> float:
        """Unambiguous radial velocity with TDM, ``λ/(4·Ntx·Tc)`` [m/s]; velocities lie in [-v, v)."""
        return self.wavelength / (4.0 * self.tdm_period)

    @property
    def velocity_bin_width(self) -> float:
        """Doppler resolution without zero padding, ``λ/(2·Nc·Ntx·Tc)`` [m/s]."""
        return self.wavelength / (2.0 * self.num_chirps * self.tdm_period)

    @property
    def frame_duration(self) -> float:
        """Active time of one frame, ``num_chirps · Ntx · Tc`` [s]."""
        return self.num_chirps * self.tdm_period


_KEYS = {
    "num_rx": ("num_rx", int),
    "num_tx": ("num_tx", int),
    "num_adc_samples_per_chirp": ("num_samples", int),
    "num_chirps_per_frame": ("num_chirps", int),
    "adc_sample_frequency": ("sample_rate", float),
    "start_frequency": ("start_frequency", float),
    "idle_time": ("idle_time", float),
    "adc_start_time": ("adc_start_time", float),
    "ramp_end_time": ("ramp_end_time", float),
    "frequency_slope": ("slope", float),
}


_FILE_KEY = {field: key for key, (field, _) in _KEYS.items()}

# Physically sensible ranges, generous around what FMCW radars use (TI xWR/MMWCAS: 1–16 chips,
# 60–81 GHz carriers, ≤ 25 Msps, slopes ≤ 250 MHz/µs, chirps of tens of µs): a value outside is
# a broken file (a unit error, a NaN), never a radar to process. ``(low, high, unit, low_open)``.
_BOUNDS: dict[str, tuple[float, float, str, bool]] = {
    "num_rx": (1, 256, "", False),
    "num_tx": (1, 256, "", False),
    "num_samples": (1, 65536, "", False),
    "num_chirps": (1, 65536, "", False),
    "sample_rate": (1e4, 1e9, "Hz", False),
    "start_frequency": (1e9, 1e12, "Hz", False),
    "idle_time": (0.0, 1e-2, "s", False),
    "adc_start_time": (0.0, 1e-2, "s", False),
    "ramp_end_time": (0.0, 1e-2, "s", True),
    "slope": (1e9, 1e16, "Hz/s", False),
}


def check_waveform_bounds(values: dict[str, float], where: str) -> None:
    """Refuse a non-finite value or one outside its physically sensible range.

    Parameters
    ----------
    values
        Field name (as in :class:`WaveformConfig`) to value; fields not given are not checked.
    where
        The file (or ``"waveform"``) named in the message.

    Raises
    ------
    CalibrationError
        Naming ``where``, the key as the file spells it, the value and the accepted range.
    """
    for f, v in values.items():
        if f not in _BOUNDS:
            continue
        lo, hi, unit, lo_open = _BOUNDS[f]
        ok = math.isfinite(v) and (lo < v if lo_open else lo <= v) and v <= hi
        if not ok:
            u = f" {unit}" if unit else ""
            raise CalibrationError(
                f"{where}: {_FILE_KEY[f]} = {v!r}{u} is not physically sensible; expected a "
                f"finite value in {'(' if lo_open else '['}{lo:g}, {hi:g}]{u}")


def _fix_units(values: dict[str, Any], name: str) -> dict[str, Any]:
    """Correct the unit defects of the real cascade file, with a warning for each change.

    Chirp times of TI radars are microseconds to a few hundred microseconds. A value above 10 ms
    was written in µs; a ramp that ends before the sampling window does was scaled by 1e-6.
    """
    out = dict(values)
    for key in ("idle_time", "adc_start_time", "ramp_end_time"):
        v = out[key]
        if v > 1e-2:
            out[key] = v * 1e-6
            warnings.warn(f"{name}: {key} = {v!r} s is not a chirp time; read it as µs "
                          f"-> {out[key]!r} s", CalibrationWarning, stacklevel=4)
    sampling_end = out["adc_start_time"] + values["num_samples"] / out["sample_rate"]
    ramp = out["ramp_end_time"]
    if ramp < sampling_end:
        fixed = ramp * 1e6
        if sampling_end <= fixed <= 1e-3:
            out["ramp_end_time"] = fixed
            warnings.warn(f"{name}: ramp_end_time = {ramp!r} s ends before the ADC sampling does "
                          f"({sampling_end:.3g} s); scaled by 1e6 -> {fixed!r} s",
                          CalibrationWarning, stacklevel=4)
        else:
            raise CalibrationError(f"{name}: ramp_end_time {ramp!r} s ends before the ADC sampling "
                                   f"window ({sampling_end:.3g} s) and no unit fix explains it")
    return out


def parse_waveform_cfg(text: str, name: str = "waveform_cfg.txt") -> WaveformConfig:
    """Parse a ``waveform_cfg.txt`` text, correcting known unit defects with a warning."""
    kv = key_values(text, name)
    values = {field: get_number(kv, key, name, kind) for key, (field, kind) in _KEYS.items()}
    # Sizes and frequencies are checked before the unit fixes use them, the times after (a
    # time in µs is a known defect, corrected with a warning).
    check_waveform_bounds({f: v for f, v in values.items() if not f.endswith("_time")}, name)
    fixed = _fix_units(values, name)
    check_waveform_bounds(fixed, name)
    return WaveformConfig(**fixed)


def format_waveform_cfg(w: WaveformConfig) -> str:
    """The dataset's ``waveform_cfg.txt`` text for ``w``."""
    return "".join(f"{key} {getattr(w, field)!r}\n" for key, (field, _) in _KEYS.items())
