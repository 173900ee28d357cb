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

__all__ = ["azimuth_peaks", "azimuth_sidelobe_ratio", "bartlett_spectrum", "capon_spectrum",
           "covariance", "newton_refine", "refine_peak", "steering"]


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


def steering(grid: AngleGrid, uy: np.ndarray, uz: np.ndarray) -> np.ndarray:
    """Conjugate steering vectors of the grid's unique elements at arbitrary direction sines.

    ``exp(+jπρ(s_az·p_az,m·u_y + s_el·p_el,m·u_z))``: the factor that the Bartlett beam
    ``Σ_m x_m·(·)`` of :func:`bartlett_spectrum` applies, evaluated off the FFT grid.

    Returns
    -------
    numpy.ndarray
        complex64 ``(M, K)``.
    """
    phase = np.pi * grid.rho * (grid.azimuth_sign * grid.az_pos[:, None] * np.asarray(uy)[None, :]
                                + grid.elevation_sign * grid.el_pos[:, None]
                                * np.asarray(uz)[None, :])
    return np.exp(1j * phase).astype(np.complex64)


def azimuth_sidelobe_ratio(grid: AngleGrid) -> float:
    """Peak sidelobe level of the array's azimuth profile, relative to its main lobe (linear).

    The azimuth profile of a spectrum is its maximum over elevation at each azimuth bin. For
    one point target (equal amplitude on every unique element) that profile is the array's
    pattern, the same at every steering in direction-sine space; outside the main lobe
    (from the peak out to the first minimum on each side) its largest value over the peak
    is the level below which a second peak of a spectrum may be the first one's sidelobe.
    """
    spec = bartlett_spectrum(grid, np.ones((1, grid.num_elements), dtype=np.complex64))[0]
    prof = np.roll(spec.max(axis=0).astype(np.float64), -int(np.argmax(spec.max(axis=0))))
    n = prof.size
    right = 1
    while right < n // 2 and prof[right + 1] < prof[right]:
        right += 1
    left = 1
    while left < n // 2 and prof[-left - 1] < prof[-left]:
        left += 1
    outside = prof[right:n - left + 1]
    return float(outside.max() / prof[0]) if outside.size else 0.0


def azimuth_peaks(spec: np.ndarray, visible: np.ndarray, relative: float, floor: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every significant peak of each spectrum's azimuth profile.

    As TI's cascade DOA (mmWave Studio's ``DOACascade``/``DOA_BF_PeakDet_loc``: several peaks
    along azimuth, the elevation of each by its maximum), a peak of the azimuth profile
    (the maximum over elevation per azimuth bin, visible region only; the axis is circular,
    as an FFT spectrum) counts when it is at least ``relative`` times the strongest peak
    (above the array's sidelobes) and above ``floor``. The strongest peak always counts.

    Parameters
    ----------
    spec
        float ``(K, num_el, num_az)`` spectra.
    visible
        bool ``(num_el, num_az)``.
    relative
        Linear fraction of the strongest peak.
    floor
        float ``(K,)``: absolute threshold per spectrum (noise).

    Returns
    -------
    tuple
        int64 arrays ``(k, el, az)`` of the peaks, the strongest of each spectrum first.
    """
    k = spec.shape[0]
    if k == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e, e
    masked = np.where(visible[None], spec, 0.0)
    prof = masked.max(axis=1)                                           # (K, az)
    arg_el = masked.argmax(axis=1)
    left, right = np.roll(prof, 1, axis=1), np.roll(prof, -1, axis=1)
    top = prof.max(axis=1, keepdims=True)
    is_peak = (prof > left) & (prof >= right) & (prof > 0)
    ok = is_peak & (prof >= relative * top) & (prof >= floor[:, None])
    best = prof.argmax(axis=1)
    ok[np.arange(k), best] = True
    kk, ia = np.nonzero(ok)
    # strongest first within each spectrum
    order = np.lexsort((-prof[kk, ia], kk))
    kk, ia = kk[order], ia[order]
    return kk.astype(np.int64), arg_el[kk, ia].astype(np.int64), ia.astype(np.int64)


def newton_refine(grid: AngleGrid, vectors: np.ndarray, uy: np.ndarray, uz: np.ndarray,
                  max_step: tuple[float, float], iterations: int = 2, elevation: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Maximise the Bartlett beam power ``|B(u)|²`` off the grid by Newton steps.

    ``B(u) = Σ_m x_m exp(jπρ(s_az p_m u_y + s_el q_m u_z))``; its gradient and Hessian in
    ``(u_y, u_z)`` are sums over the elements, so each step costs a few dot products per
    detection. Steps are limited to ``max_step`` (a fraction of the grid spacing, per axis)
    and a step that lowers the power is not taken, so the result never leaves the peak the
    grid found.

    Parameters
    ----------
    grid
        Angle grid of the unique elements.
    vectors
        complex ``(K, M)``.
    uy, uz
        float ``(K,)`` starting direction sines.
    max_step
        Largest step along ``(u_y, u_z)``.
    iterations
        Newton steps.
    elevation
        Refine ``u_z`` too (off: azimuth only).

    Returns
    -------
    tuple
        ``(u_y, u_z, power)`` float64 ``(K,)``; power in the units of
        :func:`bartlett_spectrum`.
    """
    x = np.asarray(vectors, dtype=np.complex128)
    m = grid.num_elements
    a = np.pi * grid.rho * grid.azimuth_sign * grid.az_pos.astype(np.float64)
    b = np.pi * grid.rho * grid.elevation_sign * grid.el_pos.astype(np.float64)
    uy = np.asarray(uy, dtype=np.float64).copy()
    uz = np.asarray(uz, dtype=np.float64).copy()

    def beam(uy_: np.ndarray, uz_: np.ndarray):
        e = np.exp(1j * (a[None, :] * uy_[:, None] + b[None, :] * uz_[:, None]))
        z = x * e
        return z

    def power(uy_: np.ndarray, uz_: np.ndarray) -> np.ndarray:
        return np.abs(beam(uy_, uz_).sum(axis=1)) ** 2

    p0 = power(uy, uz)
    for _ in range(iterations):
        z = beam(uy, uz)
        bv = z.sum(axis=1)
        by, bz = 1j * (z @ a), 1j * (z @ b)
        byy, bzz, byz = -(z @ (a * a)), -(z @ (b * b)), -(z @ (a * b))
        cb = np.conj(bv)
        gy = 2 * np.real(cb * by)
        gz = 2 * np.real(cb * bz)
        hyy = 2 * np.real(np.abs(by) ** 2 + cb * byy)
        hzz = 2 * np.real(np.abs(bz) ** 2 + cb * bzz)
        hyz = 2 * np.real(np.conj(by) * bz + cb * byz)
        if elevation:
            det = hyy * hzz - hyz**2
            good = (hyy < 0) & (det > 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                sy = np.where(good, -(hzz * gy - hyz * gz) / det, 0.0)
                sz = np.where(good, -(hyy * gz - hyz * gy) / det, 0.0)
        else:
            good = hyy < 0
            with np.errstate(divide="ignore", invalid="ignore"):
                sy = np.where(good, -gy / hyy, 0.0)
            sz = np.zeros_like(sy)
        sy = np.clip(np.nan_to_num(sy), -max_step[0], max_step[0])
        sz = np.clip(np.nan_to_num(sz), -max_step[1], max_step[1])
        p1 = power(uy + sy, uz + sz)
        better = p1 > p0
        uy = np.where(better, uy + sy, uy)
        uz = np.where(better, uz + sz, uz)
        p0 = np.where(better, p1, p0)
    return uy, uz, p0 / float(m * m)
