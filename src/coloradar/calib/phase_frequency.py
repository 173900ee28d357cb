"""Cascade per-channel phase and frequency calibration (``phase_frequency_calib.txt``).

The four chips of the cascade board have their own LO paths: each (TX, RX) channel has a
phase offset and a small delay, measured on a corner reflector at about 3 m. The file gives, per
channel, the reflector's (fractional) range bin ``f[t, r]`` (≈ 51) and the complex phase
``P[t, r]``. The correction is relative to channel (tx 0, rx 0) (docs/conventions.md §2)::

    A_fcal[n] = A[n] · exp(−j2π (f[t,r] − f[0,0]) · (S/S_cal)·(fs_cal/fs) · n / Ns)
    A_pcal    = A_fcal · P[0,0] / P[t,r]

Near field. The reflector is in the array's near field (the cascade's 16 cm aperture has its
Fraunhofer distance near 15 m), so ``P`` holds the hardware's phases *and* the reflector's
spherical-wave phases: the calibration focuses every channel at the reflector's range
``R0``. :meth:`PhaseFrequencyCalib.reference_range` gives ``R0`` from the peak bins
(``mean f · c·fs_cal/(2·S_cal·Ns)``: the release's file, 51.2 of 256 bins of 5.93 cm, 3.04 m),
for processing that focuses relative to it (docs/dsp.md, "Near field"). A calibration whose
phases carry no such term (the simulator's: its far-field frames have none) says so with
``near_field=False``, written as the coloradar key ``"nearFieldPhases": false`` (absent in
the dataset's files, which mean True).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from ..formats.atomic import atomic_write_text, new_output_path
from ..formats.source import read_file_text
from ._parse import check_finite, readonly
from .waveform import SPEED_OF_LIGHT

__all__ = ["PhaseFrequencyCalib", "format_phase_frequency_calib", "identity_phase_calib",
           "parse_phase_frequency_calib", "read_phase_frequency_calib",
           "write_phase_frequency_calib"]


@dataclass(frozen=True, eq=False)
class PhaseFrequencyCalib:
    """Per-channel calibration of a cascade radar.

    Attributes
    ----------
    frequency
        float64 ``(tx, rx)``: the reflector's range bin seen by each channel.
    phase
        complex128 ``(tx, rx)``: the reflector's complex response per channel.
    slope, sample_rate
        Chirp slope [Hz/s] and sampling rate [Hz] of the calibration capture.
    near_field
        True (the dataset's files): the phases were measured on a reflector on boresight at the
        range of the peak bins, so they carry its near-field phases (:meth:`reference_range`).
        False: they carry none (a calibration made for far-field frames, as the simulator's).
    """

    frequency: np.ndarray
    phase: np.ndarray
    slope: float
    sample_rate: float
    near_field: bool = True

    def __post_init__(self) -> None:
        f = readonly(np.asarray(self.frequency, dtype=np.float64))
        p = readonly(np.asarray(self.phase, dtype=np.complex128))
        if f.ndim != 2 or f.shape != p.shape:
            raise CalibrationError(f"phase/frequency calib: shapes {f.shape} and {p.shape} differ")
        if np.any(p == 0):
            raise CalibrationError("phase/frequency calib: a phase entry is zero (cannot divide)")
        object.__setattr__(self, "frequency", f)
        object.__setattr__(self, "phase", p)

    @property
    def num_tx(self) -> int:
        return int(self.frequency.shape[0])

    @property
    def num_rx(self) -> int:
        return int(self.frequency.shape[1])

    def relative_frequency(self) -> np.ndarray:
        """``f[t, r] − f[0, 0]``: delay of each channel relative to the reference, in range bins."""
        return self.frequency - self.frequency[0, 0]

    def relative_phase(self) -> np.ndarray:
        """``P[0,0] / P[t,r]``: the complex factor that aligns each channel to the reference."""
        return self.phase[0, 0] / self.phase

    def reference_range(self, num_samples: int) -> float | None:
        """Range [m] of the calibration's reflector, whose near-field phases the phases carry.

        The mean peak bin times the capture's range-bin width ``c·fs_cal/(2·S_cal·Ns)``, with
        ``Ns`` = ``num_samples`` the capture's FFT size (the frame's: the frequency correction
        assumes the same, :func:`coloradar.dsp.cube.phase_frequency_factors`). The mean over
        channels measures the range from the virtual array's phase centre (each channel sees
        its pair's mean distance), plus the hardware's common delay (a few cm: ~1 % of the
        near-field phases, which scale as 1/R0). None when :attr:`near_field` is False.
        """
        if not self.near_field:
            return None
        if num_samples < 1:
            raise CalibrationError(f"reference_range: num_samples must be >= 1, got {num_samples}")
        width = SPEED_OF_LIGHT * self.sample_rate / (2.0 * self.slope * num_samples)
        return float(np.mean(self.frequency) * width)


def parse_phase_frequency_calib(text: str, name: str = "phase_frequency_calib.txt"
                                ) -> PhaseFrequencyCalib:
    """Parse the one-line JSON ``{"antennaCalib": {...}}`` file."""
    try:
        root = json.loads(text)
        c = root["antennaCalib"]
        ntx, nrx = int(c["numTx"]), int(c["numRx"])
        # Flat lists in the real file; nested [tx][rx] lists are accepted too.
        freq = np.asarray(c["frequencyCalibrationMatrix"], dtype=np.float64).ravel()
        ph = np.asarray(c["phaseCalibrationMatrix"], dtype=np.float64).ravel()
        slope, fs = float(c["frequencySlope"]), float(c["samplingRate"])
        near = c.get("nearFieldPhases", True)
    except json.JSONDecodeError as exc:
        raise CalibrationError(f"{name}: not valid JSON ({exc})") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise CalibrationError(f"{name}: expected antennaCalib with numTx, numRx, frequencySlope, "
                               f"samplingRate and the two matrices ({exc!r})") from None
    if freq.size != ntx * nrx or ph.size != 2 * ntx * nrx:
        raise CalibrationError(f"{name}: expected {ntx * nrx} frequency and {2 * ntx * nrx} phase "
                               f"values for {ntx} tx x {nrx} rx, found {freq.size} and {ph.size}")
    if not isinstance(near, bool):
        raise CalibrationError(f"{name}: nearFieldPhases must be true or false, got {near!r}")
    check_finite(freq, name, "frequencyCalibrationMatrix")
    check_finite(ph, name, "phaseCalibrationMatrix")
    for key, v, lo, hi in (("frequencySlope", slope, 1e9, 1e16), ("samplingRate", fs, 1e4, 1e9)):
        if not (math.isfinite(v) and lo <= v <= hi):
            raise CalibrationError(f"{name}: {key} = {float(v):g} is not physically sensible; expected "
                                   f"a finite value in [{lo:g}, {hi:g}]")
    phase = (ph[0::2] + 1j * ph[1::2]).reshape(ntx, nrx)
    return PhaseFrequencyCalib(freq.reshape(ntx, nrx), phase, slope, fs, near_field=near)


def format_phase_frequency_calib(c: PhaseFrequencyCalib) -> str:
    """The dataset's one-line JSON text for ``c``."""
    ph = np.empty(c.phase.size * 2)
    ph[0::2] = c.phase.real.ravel()
    ph[1::2] = c.phase.imag.ravel()
    body: dict[str, object] = {
        "numTx": c.num_tx, "numRx": c.num_rx, "frequencySlope": c.slope,
        "samplingRate": c.sample_rate,
        "frequencyCalibrationMatrix": c.frequency.ravel().tolist(),
        "phaseCalibrationMatrix": ph.tolist()}
    if not c.near_field:
        body["nearFieldPhases"] = False                 # coloradar's key (module docstring)
    return json.dumps({"antennaCalib": body}) + "\n"


def read_phase_frequency_calib(path: str | os.PathLike[str]) -> PhaseFrequencyCalib:
    """Read a ``phase_frequency_calib.txt`` (the release's, or one written by
    ``coloradar calibrate phase``); errors name the file."""
    return parse_phase_frequency_calib(read_file_text(path), str(path))


def write_phase_frequency_calib(path: str | os.PathLike[str], c: PhaseFrequencyCalib,
                                overwrite: bool = False) -> None:
    """Write ``c`` as a ``phase_frequency_calib.txt``, atomically (whole or not at all).

    Raises
    ------
    OutputExistsError
        ``path`` exists and ``overwrite`` is not set.
    """
    atomic_write_text(new_output_path(path, overwrite), format_phase_frequency_calib(c))


def identity_phase_calib(num_tx: int, num_rx: int, slope: float,
                         sample_rate: float) -> PhaseFrequencyCalib:
    """The calibration of a board whose channels are matched (unit phases, equal delays, no
    near-field phases): what a simulated board without planted errors is, and what tells the
    chain that its channel phases can be trusted (the Doppler alias search, docs/dsp.md)."""
    return PhaseFrequencyCalib(np.zeros((num_tx, num_rx)),
                               np.ones((num_tx, num_rx), dtype=np.complex128), slope,
                               sample_rate, near_field=False)
