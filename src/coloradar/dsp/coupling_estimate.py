"""The radar's antenna coupling measured from a run's own frames (``coupling_calib.txt``).

The coupling (TX→RX leakage, radome and near-field returns) is the same in every chirp of every
frame; a scene's returns are not, while the rig moves: a target's range, and so its phase,
changes from frame to frame, and a target moving relative to the radar sits away from zero
Doppler. The estimate therefore takes, per frame, the static part of every chirp (the
Doppler-windowed chirp mean: zero Doppler, with the window's low sidelobes keeping moving
targets out) and combines the frames per channel and range bin with a statistic that
ignores what is not common to most of them (:data:`STATISTICS`).

It is written in the file's own representation, the one :func:`coloradar.dsp.coupling_signal`
turns back into samples and the processor subtracts (docs/conventions.md §2): the
*unwindowed, unnormalised* FFT over the samples of the raw (uncalibrated) ADC counts
(``scipy.fft.fft``), bins ``0 … K−1``, ordered ``[tx][rx][range]``. The ADC's DC offset is in
bin 0, as in the released files.

What no statistic can tell apart from coupling: a return that stays at one range with one
phase in every frame (a rig standing still, an object carried with the rig). A run with the rig
moving through the scene is what the estimate needs; its :attr:`CouplingEstimate.spread` says
how much the frames varied about it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sized
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
import scipy.fft as sfft

from ..calib import CouplingCalib, RadarCalib
from ..errors import FormatError, MissingDataError, SettingsError
from .windows import WindowName, coherent_window

__all__ = ["STATISTICS", "CouplingEstimate", "CouplingStatistic", "combine_profiles",
           "estimate_coupling", "static_profile"]

CouplingStatistic = Literal["trimmed", "median", "mean"]
"""How the frames' static profiles are combined per channel and range bin: ``"trimmed"`` the
mean of the frames within ``TRIM`` robust deviations of the complex median (default),
``"median"`` the complex median (real and imaginary parts), ``"mean"`` the plain mean (not
robust: for comparison)."""
STATISTICS: tuple[CouplingStatistic, ...] = get_args(CouplingStatistic)

TRIM = 3.0
"""Frames farther than ``TRIM`` times the median distance from the complex median are left out
of the trimmed mean. For frames that differ by noise only, the distance is Rayleigh
distributed and 0.2 % of the frames lie beyond it (``exp(−ln2·TRIM²)``)."""


@dataclass(frozen=True, eq=False)
class CouplingEstimate:
    """A coupling estimate and how well the frames determine it.

    Attributes
    ----------
    coupling
        The estimate, as ``coupling_calib.txt`` holds it (complex64 ``(tx, rx, range)``,
        unwindowed, unnormalised range FFT of raw ADC counts).
    frames
        Number of frames combined.
    spread
        float32 ``(tx, rx, range)``: RMS deviation of one frame's static profile about the
        estimate (noise and the scene's returns) [counts, same scale as ``coupling``], from the
        median deviation (robust to a few frames with strong returns).
    standard_error
        float32 ``(tx, rx, range)``: the estimate's expected error from that spread
        (``spread / √frames kept``; the median's ``√(π/2)`` larger).
    """

    coupling: CouplingCalib
    frames: int
    spread: np.ndarray
    standard_error: np.ndarray


def static_profile(adc: np.ndarray, num_range_bins: int,
                   doppler_window: WindowName = "hann") -> np.ndarray:
    """The static part of one frame, in the coupling file's representation.

    Parameters
    ----------
    adc
        complex ``(tx, rx, chirp, sample)`` raw ADC frame [counts].
    num_range_bins
        Range bins kept (``K``).
    doppler_window
        Weights of the chirp mean (``"hann"``, ``"blackman"`` or ``"none"``), scaled to sum
        to 1: a signal the same in every chirp passes unchanged, one moving by ``d`` Doppler
        bins is suppressed by the window's sidelobe at ``d``.

    Returns
    -------
    numpy.ndarray
        complex64 ``(tx, rx, K)``: unwindowed, unnormalised FFT over samples of the weighted
        chirp mean.
    """
    x = np.asarray(adc)
    if x.ndim != 4 or not np.iscomplexobj(x):
        raise FormatError(f"expected a complex (tx, rx, chirp, sample) ADC frame, got "
                          f"{x.dtype} {x.shape}")
    if not 0 < num_range_bins <= x.shape[-1]:
        raise SettingsError(f"num_range_bins must lie in 1..{x.shape[-1]} (samples per chirp), "
                            f"got {num_range_bins}")
    w = coherent_window(doppler_window, x.shape[2])
    chirp_mean = np.tensordot(x, w, axes=([2], [0]))                     # (tx, rx, sample)
    return sfft.fft(chirp_mean, axis=-1)[..., :num_range_bins].astype(np.complex64)


def combine_profiles(profiles: np.ndarray, statistic: CouplingStatistic = "trimmed"
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Combine the static profiles of many frames, per channel and range bin.

    Parameters
    ----------
    profiles
        complex ``(frames, ...)``.
    statistic
        One of :data:`STATISTICS`.

    Returns
    -------
    estimate : numpy.ndarray
        complex64 ``(...)``.
    spread : numpy.ndarray
        float32 ``(...)``: RMS deviation of one frame about the median, from the median
        deviation (``median|z − m| / √ln2`` for complex Gaussian deviations).
    standard_error : numpy.ndarray
        float32 ``(...)``: expected error of ``estimate``.
    """
    if statistic not in STATISTICS:
        raise SettingsError(f"unknown coupling statistic {statistic!r}; expected one of "
                            f"{', '.join(STATISTICS)}")
    p = np.asarray(profiles, dtype=np.complex128)
    n = p.shape[0]
    med = np.median(p.real, axis=0) + 1j * np.median(p.imag, axis=0)
    dist = np.abs(p - med)
    mdist = np.median(dist, axis=0)
    spread = mdist / np.sqrt(np.log(2.0))
    if statistic == "median":
        est, err = med, spread * np.sqrt(np.pi / 2.0 / n)
    elif statistic == "mean":
        est, err = p.mean(axis=0), spread / np.sqrt(n)
    else:
        keep = dist <= TRIM * mdist
        kept = keep.sum(axis=0)                       # ≥ 1: at least half lie within mdist
        est = np.where(keep, p, 0.0).sum(axis=0) / kept
        err = spread / np.sqrt(kept)
    return est.astype(np.complex64), spread.astype(np.float32), err.astype(np.float32)


def _range_bins(radar: RadarCalib | int) -> tuple[int, tuple[int, ...] | None]:
    if isinstance(radar, RadarCalib):
        k = (radar.coupling.num_range_bins if radar.coupling is not None
             else radar.heatmap.num_range_bins)
        return k, radar.frame_shape
    return int(radar), None


def estimate_coupling(frames: Iterable[np.ndarray], radar: RadarCalib | int, *,
                      statistic: CouplingStatistic = "trimmed",
                      doppler_window: WindowName = "hann",
                      progress: Callable[[int, int], None] | None = None,
                      total: int | None = None) -> CouplingEstimate:
    """Estimate each virtual channel's coupling from a run's ADC frames.

    Parameters
    ----------
    frames
        Raw ADC frames, complex ``(tx, rx, chirp, sample)`` [counts] (a radar's
        ``Sequence.radar(name).adc`` stream, or any iterable of arrays), taken while the rig
        moves.
    radar
        The radar's :class:`~coloradar.calib.RadarCalib` (range bins ``K`` of its coupling
        file, else of its heatmap grid; frames must have its frame shape), or ``K`` itself.
    statistic
        How frames are combined (:data:`STATISTICS`); ``"trimmed"`` by default.
    doppler_window
        Window of each frame's chirp mean (:func:`static_profile`).
    progress
        ``progress(done, total)`` after each frame.
    total
        Frames expected, for ``progress`` (default: ``len(frames)`` when it has one).

    Returns
    -------
    CouplingEstimate
        ``coupling.num_doppler_bins`` is the frames' chirp loops, as in the released files.

    Raises
    ------
    MissingDataError
        No frames.
    FormatError
        A frame whose shape differs from the radar's (or the first frame's).
    """
    k, shape = _range_bins(radar)
    if total is None:
        total = len(frames) if isinstance(frames, Sized) else 0
    profiles = []
    for i, adc in enumerate(frames):
        a = np.asarray(adc)
        if shape is None:
            shape = a.shape
        if a.shape != shape or not np.iscomplexobj(a):
            raise FormatError(f"ADC frame {i}: expected complex (tx, rx, chirp, sample) = "
                              f"{shape}, got {a.dtype} {a.shape}")
        profiles.append(static_profile(a, k, doppler_window))
        if progress is not None:
            progress(i + 1, max(total, i + 1))
    if not profiles or shape is None:
        raise MissingDataError("no ADC frames to estimate the coupling from")
    est, spread, err = combine_profiles(np.stack(profiles), statistic)
    return CouplingEstimate(CouplingCalib(est, int(shape[2])), len(profiles), spread, err)
