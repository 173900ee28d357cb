"""Stage 6: angle spectra for detections — FFT (Bartlett) beamformer and Capon/MVDR.

Both evaluate on an :class:`~coloradar.dsp.array.AngleGrid` (usually finer than the heatmap's)
and return power in the heatmap's units: a lone target of amplitude ``a`` per element peaks at
``|a|²``.

Capon (MVDR, Capon 1969) per detection
--------------------------------------
The covariance ``R`` of the detection's range bin is estimated from the chirp-loop snapshots
(TDM-compensated for the detection's Doppler), with diagonal loading ``δ = loading · tr(R)/M``.
The MVDR weight toward ``u`` is ``w = R⁻¹a/(aᴴR⁻¹a)`` (unit gain toward ``u``, minimum power
elsewhere); applied to the detection's Doppler-domain vector ``v`` it gives

    P(u) = |aᴴ R⁻¹ v|² / (aᴴ R⁻¹ a)²

whose peak is the direction of the target *in that Doppler bin*, with other scatterers of the
same range nulled instead of merely attenuated by sidelobes. ``aᴴR⁻¹v`` is one FFT of
``z = R⁻¹v``; ``aᴴR⁻¹a = Σ_mn R⁻¹_mn·e^{jπρ(p_m − p_n)·u}`` is one FFT of ``R⁻¹`` accumulated on
the difference co-array, so the spectrum costs two small FFTs, not one quadratic form per bin.
"""

from __future__ import annotations

import numpy as np

from .array import AngleGrid, beamform

__all__ = ["bartlett_spectrum", "capon_spectrum", "covariance", "refine_peak"]


def bartlett_spectrum(grid: AngleGrid, vectors: np.ndarray, workers: int = 1) -> np.ndarray:
    """``|aᴴv|²/M²`` for each vector: float32 ``(K, num_el, num_az)`` from complex ``(K, M)``."""
    spec = beamform(grid, vectors, workers=workers)
    mag = np.abs(spec) * np.float32(1.0 / grid.num_elements)
    return np.square(mag, out=mag)


def covariance(snapshots: np.ndarray, loading: float) -> np.ndarray:
    """Diagonally loaded sample covariance and its inverse.

    Parameters
    ----------
    snapshots
        complex ``(K, S, M)``: S snapshots of M elements for each of K problems.
    loading
        Diagonal loading relative to the mean eigenvalue ``tr(R)/M`` (> 0).

    Returns
    -------
    numpy.ndarray
        complex128 ``(K, M, M)``: ``(R + δI)⁻¹`` with ``R = (1/S) Σ_s x_s x_sᴴ``.
    """
    x = np.asarray(snapshots, dtype=np.complex128)
    _, s, m = x.shape
    a = x.transpose(0, 2, 1) / np.sqrt(s)                          # (K, M, S): R = A Aᴴ
    tr = np.einsum("kms,kms->k", a, a.conj()).real
    delta = loading * tr / m + 1e-30
    eye_m = np.eye(m)
    if s < m:
        # Woodbury: (AAᴴ + δI)⁻¹ = (I − A (δI + AᴴA)⁻¹ Aᴴ)/δ — an S×S solve instead of M×M.
        ah = a.conj().transpose(0, 2, 1)
        inner = ah @ a + delta[:, None, None] * np.eye(s)
        return (eye_m - a @ np.linalg.solve(inner, ah)) / delta[:, None, None]
    return np.linalg.inv(a @ a.conj().transpose(0, 2, 1) + delta[:, None, None] * eye_m)


def capon_spectrum(grid: AngleGrid, snapshots: np.ndarray, vectors: np.ndarray | None = None,
                   loading: float = 0.05, workers: int = 1) -> np.ndarray:
    """Capon/MVDR spectrum on the grid.

    Parameters
    ----------
    grid
        Angle grid of the unique virtual elements.
    snapshots
        complex ``(K, S, M)``: snapshots to estimate each problem's covariance from.
    vectors
        complex ``(K, M)`` or None. With vectors: the MVDR output power for that vector,
        ``|aᴴR⁻¹v|²/(aᴴR⁻¹a)²``; without: the MVDR spatial spectrum ``1/(aᴴR⁻¹a)``.
    loading
        Diagonal loading relative to ``tr(R)/M``.

    Returns
    -------
    numpy.ndarray
        float64 ``(K, num_el, num_az)``.
    """
    q = covariance(snapshots, loading)
    k, m, _ = q.shape
    d_el = (grid.el_pos[:, None] - grid.el_pos[None, :]).ravel()
    d_az = (grid.az_pos[:, None] - grid.az_pos[None, :]).ravel()
    den = beamform(grid, q.reshape(k, m * m), d_el, d_az, workers=workers).real.astype(np.float64)
    den = np.maximum(den, 1e-30)
    if vectors is None:
        return 1.0 / den
    z = np.einsum("kmn,kn->km", q, np.asarray(vectors, dtype=np.complex128))
    num = np.abs(beamform(grid, z, workers=workers)).astype(np.float64) ** 2
    return num / den**2


def refine_peak(values: np.ndarray, index: np.ndarray, axis_len: int, wrap: bool) -> np.ndarray:
    """Sub-bin peak offset by a parabola through the logarithm of three samples.

    For a Gaussian-like main lobe (windowed spectra, beams) this is nearly unbiased.

    Parameters
    ----------
    values
        float ``(K, 3)``: power at index−1, index, index+1 (any positive scale).
    index
        int ``(K,)``: peak index along the axis.
    axis_len
        Length of the axis.
    wrap
        Whether the axis is circular; otherwise peaks at the ends are not refined.

    Returns
    -------
    numpy.ndarray
        float64 ``(K,)``: refined position, ``index + δ`` with ``|δ| ≤ 0.5``.
    """
    lv = np.log(np.maximum(np.asarray(values, dtype=np.float64), 1e-300))
    den = lv[:, 0] - 2.0 * lv[:, 1] + lv[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(den < 0, 0.5 * (lv[:, 0] - lv[:, 2]) / den, 0.0)
    delta = np.clip(np.nan_to_num(delta), -0.5, 0.5)
    if not wrap:
        delta = np.where((index <= 0) | (index >= axis_len - 1), 0.0, delta)
    return index + delta
