"""The cube stage: ADC frames → calibrated range cube → TDM-compensated range–Doppler cube.

Everything that depends only on the calibration (windows, phase/frequency factors, coupling
signal, TDM phases) is computed once per radar by :class:`CubeStage`; the stage's settings are
:class:`~coloradar.dsp.settings.CubeSettings`. The chain::

    adc (tx, rx, chirp, sample) complex64
      − coupling signal            (cube.coupling_signal: subtracting it = subtracting the file's
                                    unwindowed range FFT)
      − mean per chirp             (DC removal, optional)
      × G[t, r, n]                 (cascade phase/frequency calibration, docs/conventions.md §2)
      × range window × Doppler window × (−1)^c    (unit coherent gain; (−1)^c = fftshift)
      → range FFT, keep the first num_range_bins                          = range_cube(adc)
      → Doppler FFT
      × exp(−j2π k t/(n·Ntx))      (TDM-MIMO compensation)                = range_doppler(adc)
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from ..calib import RadarCalib
from ..calib.waveform import SPEED_OF_LIGHT
from ..errors import FormatError, SettingsError
from .cube import coupling_signal, phase_frequency_factors, signed_doppler_bins
from .settings import CubeSettings
from .tdm import tdm_phase
from .windows import coherent_window

__all__ = ["CubeStage"]


class CubeStage:
    """ADC frames of one radar → range cubes and range–Doppler cubes.

    Parameters
    ----------
    calib
        The radar's calibration.
    settings
        The stage's settings (:attr:`ProcessingSettings.cube
        <coloradar.dsp.settings.ProcessingSettings.cube>`).
    engine
        ``"numba"`` (the range pass compiled) or ``"numpy"`` (resolved, not ``"auto"``).
    """

    def __init__(self, calib: RadarCalib, settings: CubeSettings, engine: str) -> None:
        s = settings
        self.calib = calib
        self.settings = s
        self.engine = engine
        w, hm = calib.waveform, calib.heatmap
        ntx, nrx, nc, ns = w.frame_shape
        self.range_fft_size = int(s.range_fft_size or ns)
        self.doppler_fft_size = int(s.doppler_fft_size or nc)
        # Default: the heatmap grid's range span, whatever the zero padding (padding refines
        # the bins, it must not shorten the range covered).
        self.num_range_bins = int(s.num_range_bins
                                  or -(-hm.num_range_bins * self.range_fft_size // ns))
        if self.range_fft_size < ns or self.doppler_fft_size < nc:
            raise SettingsError(f"FFT sizes must be at least {ns} samples and {nc} chirp loops")
        if not 0 < self.num_range_bins <= self.range_fft_size:
            raise SettingsError(f"num_range_bins must lie in 1..{self.range_fft_size}")
        nd = self.doppler_fft_size
        self.range_bin_width = SPEED_OF_LIGHT * w.sample_rate / (2.0 * w.slope
                                                                 * self.range_fft_size)
        """Range of one range bin [m]."""
        self.velocities = signed_doppler_bins(nd) * (w.wavelength / (2.0 * nd * w.tdm_period))
        """float64 ``(doppler,)``: range rate of each Doppler bin [m/s]."""

        # Per-sample and per-chirp factors, fused into one (tx, rx, chirp, sample) multiplier.
        cal = np.ones((ntx, nrx, ns), dtype=np.complex128)
        if s.phase_frequency_calibration and calib.phase_frequency is not None:
            cal = phase_frequency_factors(calib.phase_frequency, w)
        wd = coherent_window(s.doppler_window, nc)
        if nd % 2 == 0:
            wd = wd * np.where(np.arange(nc) % 2 == 0, 1.0, -1.0)
        self._mult = (cal[:, :, None, :] * coherent_window(s.range_window, ns)
                      * wd[None, None, :, None]).astype(np.complex64)
        # The same factors for the compiled range pass: per channel × per chirp.
        self._gain = (cal * coherent_window(s.range_window, ns)).astype(np.complex64)
        self._chirp_weight = wd.astype(np.float32)
        self.coupling: np.ndarray | None = None
        """complex64 ``(tx, rx, 1, sample)``: the coupling signal subtracted, or None."""
        if s.coupling_subtraction and calib.coupling is not None:
            c = coupling_signal(calib.coupling, ns)
            if s.coupling_domain == "calibrated":
                c = c / cal
            self.coupling = c[:, :, None, :].astype(np.complex64)
        self.tdm: np.ndarray | None = None
        """complex ``(tx, 1, doppler, 1)``: the TDM compensation factors, or None (off)."""
        self.tdm_table = np.zeros((0, 0), dtype=np.complex128)
        """The same factors as ``(tx, doppler)`` (empty when off)."""
        if s.tdm_compensation:
            self.tdm = tdm_phase(ntx, signed_doppler_bins(nd), nd)[:, None, :, None]
            self.tdm_table = np.ascontiguousarray(self.tdm[:, 0, :, 0])          # (tx, doppler)

    def check(self, adc: np.ndarray) -> np.ndarray:
        """``adc`` as an array, or :class:`~coloradar.errors.FormatError` when it is no complex
        ``(tx, rx, chirp, sample)`` frame of this radar."""
        adc = np.asarray(adc)
        if adc.shape != self.calib.frame_shape or not np.iscomplexobj(adc):
            raise FormatError(f"{self.calib.name} ADC frame: expected complex "
                              f"(tx, rx, chirp, sample) = {self.calib.frame_shape}, got "
                              f"{adc.dtype} {adc.shape}")
        return adc

    def range_cube(self, adc: np.ndarray, extra: bool = False) -> np.ndarray:
        """Calibrated range FFT ``(tx, rx, chirp, range)``; chirps carry the Doppler window and
        the ``(−1)^c`` of the Doppler shift. ``extra``: one range bin more than
        ``num_range_bins`` where the FFT has it (detection looks one bin beyond the last)."""
        x = self.check(adc)
        keep = min(self.num_range_bins + int(extra), self.range_fft_size)
        if self.engine == "numba":
            return self.range_cube_compiled(x, keep)
        y = x - self.coupling if self.coupling is not None else x.astype(np.complex64)
        if y.dtype != np.complex64:
            y = y.astype(np.complex64)
        if self.settings.dc_removal:
            y -= y.mean(axis=-1, keepdims=True)
        y *= self._mult
        out = sfft.fft(y, n=self.range_fft_size, axis=-1, workers=self.settings.workers,
                       overwrite_x=True)
        return out[..., :keep]

    def range_cube_compiled(self, x: np.ndarray, keep: int,
                            channels: np.ndarray | None = None) -> np.ndarray:
        """:meth:`range_cube` with coupling, DC removal, calibration and windows in one
        compiled pass (same result to float32 rounding). With ``channels`` (flat
        ``tx·num_rx + rx`` indices) only those, as ``(K, chirp, range)``."""
        from ._kernels import prepare_chirps
        nfft, (ntx, nrx, nc, ns) = self.range_fft_size, x.shape
        chans = np.arange(ntx * nrx) if channels is None else np.asarray(channels)
        x = np.ascontiguousarray(x, dtype=np.complex64)
        y = np.empty((chans.size, nc, nfft), dtype=np.complex64)
        if nfft > ns:
            y[..., ns:] = 0.0
        coupling = (np.ascontiguousarray(self.coupling[:, :, 0, :]).view(np.float32)
                    if self.coupling is not None else np.empty((0, 0, 0), dtype=np.float32))
        prepare_chirps(x.view(np.float32), chans.astype(np.int64), coupling,
                       self._gain.view(np.float32), self._chirp_weight,
                       bool(self.settings.dc_removal), y.view(np.float32))
        out = sfft.fft(y, axis=-1, workers=self.settings.workers, overwrite_x=True)
        out = out[..., :keep]
        return out.reshape(ntx, nrx, nc, -1) if channels is None else out

    def doppler(self, rcube: np.ndarray, compensate: bool = True) -> np.ndarray:
        """Doppler FFT of a range cube; ``compensate=False`` leaves out the TDM phases
        (detection applies them to the few cells it reads, :meth:`tdm_at`)."""
        v = sfft.fft(rcube, n=self.doppler_fft_size, axis=2, workers=self.settings.workers)
        if self.doppler_fft_size % 2:
            v = sfft.fftshift(v, axes=2)
        if compensate and self.tdm is not None:
            v *= self.tdm
        return v

    def tdm_at(self, d: np.ndarray) -> np.ndarray | None:
        """Bin-centre TDM phases of Doppler bins ``d``, complex64 ``(tx, 1, K)`` (the factors
        :meth:`doppler` multiplies the cube by), or None without TDM compensation."""
        return None if self.tdm is None else self.tdm_table[:, d][:, None, :]

    def range_doppler(self, adc: np.ndarray) -> np.ndarray:
        """Calibrated, TDM-compensated range–Doppler cube, complex64 ``(tx, rx, doppler,
        range)`` (see :meth:`coloradar.dsp.RadarProcessor.range_doppler`)."""
        return self.doppler(self.range_cube(adc))
