"""Stage 4: TDM-MIMO Doppler phase compensation.

With time-division MIMO, TX slot ``t`` of chirp loop ``c`` starts at ``(c·Ntx + t)·Tc``
(docs/conventions.md §3). A target whose Doppler frequency is ``k/n`` cycles per loop (signed Doppler bin
``k`` of an ``n``-point Doppler FFT) therefore reaches TX slot ``t`` with an extra phase
``2π·k·t/(n·Ntx)``, which the angle FFT would read as a spurious angle. Compensation multiplies
TX ``t`` by ``exp(−j2π·k·t/(n·Ntx))``, exact at bin centres and for fractional ``k``.
"""

from __future__ import annotations

import numpy as np

from .cube import signed_doppler_bins

__all__ = ["compensate_tdm", "tdm_phase"]


def tdm_phase(num_tx: int, doppler_bins: np.ndarray | float, fft_size: int) -> np.ndarray:
    """Compensation factors ``exp(−j2π·k·t/(n·Ntx))``.

    Parameters
    ----------
    num_tx
        Number of TX slots per chirp loop.
    doppler_bins
        Signed (possibly fractional) Doppler bins ``k``, any shape ``S``.
    fft_size
        Doppler FFT length ``n``.

    Returns
    -------
    numpy.ndarray
        complex64 ``(num_tx, *S)``.
    """
    k = np.asarray(doppler_bins, dtype=np.float64)
    t = np.arange(num_tx).reshape((num_tx,) + (1,) * k.ndim)
    return np.exp(-2j * np.pi * t * k / (fft_size * num_tx)).astype(np.complex64)


def compensate_tdm(rd_cube: np.ndarray) -> np.ndarray:
    """Compensate a range–Doppler cube whose Doppler axis is centred (as :func:`doppler_fft`).

    Parameters
    ----------
    rd_cube
        complex ``(tx, rx, doppler, range)``.

    Returns
    -------
    numpy.ndarray
        complex64, same shape.
    """
    ntx, _, nd, _ = rd_cube.shape
    ph = tdm_phase(ntx, signed_doppler_bins(nd), nd)
    return (rd_cube * ph[:, None, :, None]).astype(np.complex64, copy=False)
