"""Physics forward model of a TDM-MIMO FMCW radar: point scatterers -> raw ADC frame.

The IF (beat) signal of TI's complex baseband (docs/conventions.md §3) for a scatterer with round-trip
delay τ is ``exp(+j2π(S·τ·t + f0·τ))``: a longer delay is a higher beat frequency and a larger
phase. For scatterer k, TX t, RX r, chirp loop c and sample n::

    t_n      = adc_start_time + n / fs                      (time within the chirp)
    T(c, t)  = (c·Ntx + t) · (idle_time + ramp_end_time)    (start of TX t's chirp in loop c)
    τ        = (2·(R + vr·T) − u·p_tx − u·p_rx) / c0
    x[t,r,c,n] = Σ_k a_k/R_k² · exp(j2π (f0 + S·t_n)·τ0_k) · exp(j2π f_c·(τ − τ0_k))

with u the unit vector to the scatterer, p_tx/p_rx the antenna positions (y = az·λd/2,
z = el·λd/2 at ``F_design``), vr > 0 receding, and f_c the carrier at mid-sampling. This is
the narrowband far-field model: range migration within one frame (< 2 cm for |vr| < 2 m/s
over a cascade frame) is neglected, so the signal factors into a beat term over samples and a
phase term over (TX, RX, chirp), and the sum over scatterers is one complex matrix product per
block of scatterers.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from ..calib import PhaseFrequencyCalib, RadarCalib
from ..calib.waveform import SPEED_OF_LIGHT
from ..errors import SettingsError

__all__ = ["apply_channel_errors", "slow_times", "synthesize_adc"]


def slow_times(calib: RadarCalib) -> np.ndarray:
    """Start time of every chirp relative to the frame start, float64 ``(tx, chirp)`` [s]."""
    w = calib.waveform
    c = np.arange(w.num_chirps)
    t = np.arange(w.num_tx)
    return (c[None, :] * w.num_tx + t[:, None]) * w.chirp_period


def _cis(phase: np.ndarray, dtype) -> np.ndarray:
    """``exp(j·phase)``; for complex64 the float64 phase is reduced modulo 2π before the cast,
    so that carrier phases of tens of thousands of radians lose nothing in single precision."""
    if dtype == np.complex128:
        return np.exp(1j * phase)
    p = np.mod(phase, 2.0 * np.pi).astype(np.float32)
    out = np.empty(p.shape, dtype=np.complex64)
    out.real = np.cos(p)
    out.imag = np.sin(p)
    return out


def synthesize_adc(
    calib: RadarCalib,
    positions: np.ndarray,
    velocities: np.ndarray | None = None,
    amplitudes: np.ndarray | complex = 1.0,
    *,
    noise_std: float = 0.0,
    rng: np.random.Generator | int | None = None,
    azimuth_sign: float = 1.0,
    elevation_sign: float = 1.0,
    precision: Literal["double", "single"] = "double",
    block: int = 1024,
) -> np.ndarray:
    """Synthesize one ADC frame of point scatterers (no quantisation, no channel errors).

    Parameters
    ----------
    calib
        The radar's calibration (waveform and antenna layout are used).
    positions
        float ``(K, 3)``: scatterer positions in the radar frame at the frame start [m]
        (x boresight, y left, z up).
    velocities
        float ``(K, 3)``: scatterer velocity relative to the radar, in the radar frame [m/s];
        only its radial part matters. None = static.
    amplitudes
        complex ``(K,)`` or scalar: amplitude in ADC counts a scatterer would have at 1 m;
        the frame carries ``a/R²`` (free-space two-way falloff).
    noise_std
        Standard deviation of the complex white noise per I and per Q component [counts].
    rng
        Random generator or seed for the noise.
    azimuth_sign, elevation_sign
        +1 when the antenna file's ``az`` (``el``) coordinate grows toward +y (+z), as the
        project assumes; -1 simulates a sensor mounted mirrored.
    precision
        ``"double"`` (complex128 arithmetic: the reference) or ``"single"`` (complex64
        exponentials and matrix products, phases still formed in float64: agrees with
        ``"double"`` to ~1e-5 relative and is several times faster for whole scenes).
    block
        Scatterers per matrix product (bounds memory).

    Returns
    -------
    numpy.ndarray
        complex64 ``(tx, rx, chirp, sample)`` in ADC counts.
    """
    if precision not in ("double", "single"):
        raise SettingsError(f"precision must be 'double' or 'single', got {precision!r}")
    dtype = np.complex128 if precision == "double" else np.complex64
    w, ant = calib.waveform, calib.antenna
    p = np.atleast_2d(np.asarray(positions, dtype=np.float64)).reshape(-1, 3)
    k = p.shape[0]
    v = (np.zeros_like(p) if velocities is None
         else np.atleast_2d(np.asarray(velocities, dtype=np.float64)).reshape(-1, 3))
    a = np.broadcast_to(np.asarray(amplitudes, dtype=np.complex128), (k,))
    ntx, nrx, nc, ns = w.frame_shape
    out = np.zeros((ntx * nrx * nc, ns), dtype=dtype)
    f_fast = w.start_frequency + w.slope * (w.adc_start_time + np.arange(ns) / w.sample_rate)
    kfac = 2.0 * np.pi * w.center_frequency / SPEED_OF_LIGHT
    sign = np.array([azimuth_sign, elevation_sign])
    tx_yz = ant.tx_positions * sign * ant.half_wavelength                         # (Ntx, 2)
    rx_yz = ant.rx_positions * sign * ant.half_wavelength                         # (Nrx, 2)
    ts = slow_times(calib)                                                        # (Ntx, Nc)
    buf = np.empty((min(block, max(k, 1)), ntx, nrx, nc), dtype=dtype)
    for s in range(0, k, block):
        pk, vk, ak = p[s:s + block], v[s:s + block], a[s:s + block]
        m = len(pk)
        r = np.linalg.norm(pk, axis=1)
        if np.any(r <= 0):
            raise SettingsError("a scatterer lies at the radar's origin")
        u = pk / r[:, None]
        vr = np.einsum("ij,ij->i", u, vk)
        tau0 = 2.0 * r / SPEED_OF_LIGHT
        beat = _cis(2.0 * np.pi * tau0[:, None] * f_fast[None, :], dtype)          # (m, Ns)
        # Path-length change over TX, RX and chirp relative to 2R; the phase term factors into
        # (TX, chirp) and RX parts, so exponentials are taken on the small factors only.
        d_tx = -(u[:, 1:2] * tx_yz[None, :, 0] + u[:, 2:3] * tx_yz[None, :, 1])   # (m, Ntx)
        d_rx = -(u[:, 1:2] * rx_yz[None, :, 0] + u[:, 2:3] * rx_yz[None, :, 1])   # (m, Nrx)
        e_txc = _cis(kfac * (d_tx[:, :, None] + 2.0 * vr[:, None, None] * ts[None]), dtype)
        # The complex amplitude and the 1/R² falloff ride on the small RX factor.
        e_rx = _cis(kfac * d_rx, dtype) * (ak / r**2).astype(dtype)[:, None]
        ph = buf[:m]
        np.multiply(e_txc[:, :, None, :], e_rx[:, None, :, None], out=ph)
        out += ph.reshape(m, -1).T @ beat
    frame = out.reshape(ntx, nrx, nc, ns)
    if noise_std > 0:
        g = np.random.default_rng(rng)
        frame = frame + noise_std * (g.standard_normal(frame.shape)
                                     + 1j * g.standard_normal(frame.shape))
    return frame.astype(np.complex64)


def apply_channel_errors(adc: np.ndarray, errors: PhaseFrequencyCalib) -> np.ndarray:
    """Impose the per-channel errors that a cascade phase/frequency calibration describes.

    Channel (t, r) gets the delay and complex gain that the calibration removes (docs/conventions.md §2):
    ``x[n] · (P[t,r]/P[0,0]) · exp(+j2π (f[t,r] − f[0,0]) · n / Ns)``, assuming the capture's
    slope and sampling rate equal the frame's. Applying this and then the calibration gives the
    input back.

    Parameters
    ----------
    adc
        complex ``(tx, rx, chirp, sample)``.
    errors
        The calibration whose errors to impose.

    Returns
    -------
    numpy.ndarray
        complex64, same shape.
    """
    ns = adc.shape[-1]
    n = np.arange(ns)
    df = errors.relative_frequency()                                              # (tx, rx)
    ramp = np.exp(2j * np.pi * df[:, :, None] * n[None, None, :] / ns)            # (tx, rx, Ns)
    gain = 1.0 / errors.relative_phase()                                          # P/P00
    return (adc * (gain[:, :, None] * ramp)[:, :, None, :]).astype(np.complex64)
