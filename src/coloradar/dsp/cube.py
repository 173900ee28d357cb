"""Stages 1–3: ADC frame → calibrated range and range–Doppler cubes.

Every function here is a pure array function on ``(tx, rx, chirp, sample)`` frames (the layout
:func:`coloradar.formats.decode_adc` returns). :class:`~coloradar.dsp.RadarProcessor` fuses
them into precomputed multipliers; these are the same operations one at a time.

Coupling and windows
--------------------
``coupling_calib.txt`` holds the *unwindowed* range FFT ``C[k]`` of a target-free capture for
bins ``0 … K−1``. Rather than subtracting ``C`` from a windowed spectrum (wrong: a window
convolves the spectrum) the processing synthesises the time signal whose unwindowed FFT is
``C`` on those bins and zero elsewhere (:func:`coupling_signal`) and subtracts it from the raw
samples. Every later step (DC removal, calibration, window, FFT) is linear, so this equals
"subtract ``C`` in the unwindowed range-FFT domain" exactly, for any window, zero padding or
calibration. What no processing can remove is the coupling in bins the file does not hold
(``K … Ns−1``, i.e. the negative beat frequencies just below bin 0); a window spreads that
residue into the first one (Hann) or two (Blackman) range bins.
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from ..calib import CouplingCalib, PhaseFrequencyCalib, WaveformConfig
from .windows import WindowName, coherent_window

__all__ = [
    "apply_phase_frequency_calibration",
    "coupling_signal",
    "doppler_fft",
    "phase_frequency_factors",
    "range_fft",
    "remove_dc",
    "signed_doppler_bins",
]


def remove_dc(adc: np.ndarray) -> np.ndarray:
    """Subtract each chirp's mean over samples.

    Parameters
    ----------
    adc
        complex ``(tx, rx, chirp, sample)``.

    Returns
    -------
    numpy.ndarray
        complex64, same shape.
    """
    adc = np.asarray(adc, dtype=np.complex64)
    return adc - adc.mean(axis=-1, keepdims=True)


def phase_frequency_factors(pf: PhaseFrequencyCalib, waveform: WaveformConfig) -> np.ndarray:
    """Per-channel, per-sample factors that apply the cascade calibration (docs/conventions.md §2).

    ``G[t, r, n] = P[0,0]/P[t,r] · exp(−j2π (f[t,r] − f[0,0]) · (S/S_cal)·(fs_cal/fs) · n/Ns)``:
    the frequency term moves every channel's beat frequency onto the reference channel's
    (tx 0, rx 0), the phase term aligns its phase. Relative values only: absolute ones would
    move every range by the ~3 m of the calibration reflector.

    Parameters
    ----------
    pf
        The phase/frequency calibration.
    waveform
        The frame's waveform (its slope and sampling rate rescale the calibration's bins).

    Returns
    -------
    numpy.ndarray
        complex128 ``(tx, rx, sample)``; multiply the frame by ``G[:, :, None, :]``.
    """
    ns = waveform.num_samples
    scale = (waveform.slope / pf.slope) * (pf.sample_rate / waveform.sample_rate)
    df = pf.relative_frequency() * scale                                        # (tx, rx) bins
    n = np.arange(ns)
    ramp = np.exp(-2j * np.pi * df[:, :, None] * n[None, None, :] / ns)
    return pf.relative_phase()[:, :, None] * ramp


def apply_phase_frequency_calibration(adc: np.ndarray, pf: PhaseFrequencyCalib,
                                      waveform: WaveformConfig) -> np.ndarray:
    """Apply :func:`phase_frequency_factors` to a frame; complex64 ``(tx, rx, chirp, sample)``."""
    g = phase_frequency_factors(pf, waveform).astype(np.complex64)
    return np.asarray(adc, dtype=np.complex64) * g[:, :, None, :]


def coupling_signal(coupling: CouplingCalib, num_samples: int) -> np.ndarray:
    """The time-domain coupling signal of every channel, one chirp long.

    Its unwindowed, unnormalised FFT (``np.fft.fft`` over ``num_samples``) equals the file's
    bins ``0 … K−1`` up to ``3K/4`` and rolls off to zero (raised cosine) over the last quarter
    of them; it is zero on the bins the file does not hold.

    Why the roll-off: a real leakage is a near-range tone whose unwindowed spectrum has sinc
    sidelobes in *every* bin, including those beyond ``K`` that the file does not hold. Cutting
    the known spectrum sharply at ``K`` would leave a spectral edge there that the range window
    spreads into the last kept bins (a strong static false target at the maximum range). Far
    from the tone its sidelobes are what the range window suppresses anyway, so they are left
    to it; coupling inside the first ``3K/4`` bins is removed exactly.

    Returns
    -------
    numpy.ndarray
        complex128 ``(tx, rx, sample)``, in ADC counts.
    """
    k = min(coupling.num_range_bins, num_samples)
    spec = np.zeros((*coupling.data.shape[:2], num_samples), dtype=np.complex128)
    spec[..., :k] = coupling.data[..., :k] * coupling_taper(k)
    return np.fft.ifft(spec, axis=-1)


def coupling_taper(k: int) -> np.ndarray:
    """float64 ``(k,)``: 1 up to bin ``3k/4``, then a raised-cosine roll-off to 0 at bin ``k``."""
    start = (3 * k) // 4
    taper = np.ones(k)
    n = k - start
    taper[start:] = 0.5 * (1.0 + np.cos(np.pi * (np.arange(n) + 1) / n))
    return taper


def range_fft(cube: np.ndarray, window: WindowName = "hann", n: int | None = None,
              keep: int | None = None, workers: int = 1) -> np.ndarray:
    """Windowed range FFT over samples, scaled to unit coherent gain.

    A tone of amplitude ``a`` at a bin centre gives ``a`` in its bin.

    Parameters
    ----------
    cube
        complex ``(..., sample)``.
    window
        ``"hann"``, ``"blackman"`` or ``"none"``.
    n
        FFT length (zero padding when larger than the number of samples); None = no padding.
    keep
        Number of leading range bins to return; None = all ``n``.

    Returns
    -------
    numpy.ndarray
        complex64 ``(..., keep)``; bin ``k`` is centred on range ``k · c·fs/(2·S·n)``.
    """
    cube = np.asarray(cube)
    w = coherent_window(window, cube.shape[-1]).astype(np.float32)
    out = sfft.fft((cube * w).astype(np.complex64, copy=False), n=n, axis=-1, workers=workers)
    return out if keep is None else out[..., :keep]


def signed_doppler_bins(n: int) -> np.ndarray:
    """Signed Doppler bin of each index of a shifted Doppler axis: ``arange(n) − n//2``."""
    return np.arange(n) - n // 2


def doppler_fft(rcube: np.ndarray, window: WindowName = "hann", n: int | None = None,
                axis: int = -2, workers: int = 1) -> np.ndarray:
    """Windowed Doppler FFT over chirp loops, zero Doppler centred, unit coherent gain.

    Index ``i`` of the output's Doppler axis is the signed bin ``i − n//2``
    (:func:`signed_doppler_bins`); positive bins are receding targets.

    Parameters
    ----------
    rcube
        complex range cube, chirp loops along ``axis`` (``(tx, rx, chirp, range)`` by default).
    window, n
        Window name and FFT length (None = number of chirp loops).

    Returns
    -------
    numpy.ndarray
        complex64, the chirp axis replaced by ``n`` Doppler bins.
    """
    rcube = np.asarray(rcube)
    nc = rcube.shape[axis]
    n = nc if n is None else n
    # Multiplying loop c by (−1)^c moves the spectrum by n/2 bins: the fftshift for free.
    shift = np.where(np.arange(nc) % 2 == 0, 1.0, -1.0) if n % 2 == 0 else None
    w = coherent_window(window, nc)
    shape = [1] * rcube.ndim
    shape[axis] = nc
    mult = (w if shift is None else w * shift).astype(np.float32).reshape(shape)
    out = sfft.fft((rcube * mult).astype(np.complex64, copy=False), n=n, axis=axis,
                   workers=workers)
    return out if shift is not None else sfft.fftshift(out, axes=axis)
