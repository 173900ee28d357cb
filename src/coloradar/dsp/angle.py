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

from collections.abc import Callable

import numpy as np
import scipy.fft as sfft

from ..errors import SettingsError
from .array import AngleGrid, beamform, sines_to_unit

__all__ = [
    "NearField",
    "azimuth_peaks",
    "bartlett_spectrum",
    "capon_spectrum",
    "covariance",
    "newton_refine",
    "refine_peak",
    "row_profile",
    "steering",
]


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
    neg = den < 0
    delta = np.where(neg, 0.5 * (lv[:, 0] - lv[:, 2]) / np.where(neg, den, -1.0), 0.0)
    delta = np.clip(delta, -0.5, 0.5)
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
    # float32 phases (at most a few hundred radians: ~3e-5 rad of rounding) and cos/sin
    a = np.float32(np.pi * grid.rho * grid.azimuth_sign) * grid.az_pos.astype(np.float32)
    b = np.float32(np.pi * grid.rho * grid.elevation_sign) * grid.el_pos.astype(np.float32)
    phase = (a[:, None] * np.asarray(uy, dtype=np.float32)[None, :]
             + b[:, None] * np.asarray(uz, dtype=np.float32)[None, :])
    out = np.empty(phase.shape, dtype=np.complex64)
    out.real = np.cos(phase)
    out.imag = np.sin(phase)
    return out


def row_profile(grid: AngleGrid, vectors: np.ndarray, workers: int = 1,
                row: np.ndarray | None = None) -> np.ndarray:
    """Azimuth beam power of the most populated elevation row alone, float32 ``(K, num_az)``.

    A row is a line array along azimuth: its spectrum measures ``u_y`` whatever the
    elevation, and two sources make no ghosts in elevation (the sparse elevation rows do:
    the 2D spectrum of two sources can peak between them at a wrong elevation). Used to find
    how many sources a cell holds and their azimuths; the full array refines them. ``row``:
    that row's elements (bool ``(M,)``) where the caller has it already.
    """
    if row is None:
        rows, counts = np.unique(grid.el_pos, return_counts=True)
        row = grid.el_pos == rows[np.argmax(counts)]
    sel = np.asarray(row, dtype=bool)
    x = np.asarray(vectors)[:, sel]
    buf = np.zeros((x.shape[0], grid.n_az), dtype=np.complex64)
    buf[:, grid.az_pos[sel]] = x
    spec = sfft.fft(buf, axis=1, workers=workers)[:, grid.az_read]
    mag = np.abs(spec) * np.float32(1.0 / sel.sum())
    return np.square(mag, out=mag)


def azimuth_peaks(profile: np.ndarray, relative: float, floor: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Every significant peak of each azimuth profile.

    As TI's cascade DOA (mmWave Studio's ``DOACascade``/``DOA_BF_PeakDet_loc``: several peaks
    along azimuth, one elevation for each), a local maximum of the profile (the axis is
    circular, as an FFT spectrum) counts when it is at least ``relative`` times the
    strongest peak and above ``floor``; the strongest peak always counts.

    Parameters
    ----------
    profile
        float ``(K, num_az)`` azimuth profiles (invisible bins zeroed).
    relative
        Linear fraction of the strongest peak.
    floor
        float ``(K,)``: absolute threshold per profile (noise).

    Returns
    -------
    tuple
        int64 arrays ``(k, az)`` of the peaks, the strongest of each profile first.
    """
    k = profile.shape[0]
    if k == 0:
        e = np.zeros(0, dtype=np.int64)
        return e, e
    prof = profile
    left, right = np.roll(prof, 1, axis=1), np.roll(prof, -1, axis=1)
    top = prof.max(axis=1, keepdims=True)
    ok = (prof > left) & (prof >= right) & (prof >= relative * top) & (prof >= floor[:, None])
    ok[np.arange(k), prof.argmax(axis=1)] = True
    kk, ia = np.nonzero(ok)
    order = np.lexsort((-prof[kk, ia], kk))
    return kk[order].astype(np.int64), ia[order].astype(np.int64)


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
    x = np.asarray(vectors, dtype=np.complex64)
    m = grid.num_elements
    a = (np.pi * grid.rho * grid.azimuth_sign * grid.az_pos).astype(np.float32)
    b = (np.pi * grid.rho * grid.elevation_sign * grid.el_pos).astype(np.float32)
    uy = np.asarray(uy, dtype=np.float64).copy()
    uz = np.asarray(uz, dtype=np.float64).copy()

    def beam(uy_: np.ndarray, uz_: np.ndarray):
        ph = (a[None, :] * uy_[:, None].astype(np.float32)
              + b[None, :] * uz_[:, None].astype(np.float32))
        e = np.empty(ph.shape, dtype=np.complex64)
        e.real = np.cos(ph)
        e.imag = np.sin(ph)
        return x * e

    def power(uy_: np.ndarray, uz_: np.ndarray) -> np.ndarray:
        return np.abs(beam(uy_, uz_).sum(axis=1)) ** 2

    ca, cb_ = a.astype(np.complex64), b.astype(np.complex64)
    caa, cbb, cab = ca * ca, cb_ * cb_, ca * cb_
    p0 = power(uy, uz).astype(np.float64)
    for _ in range(iterations):
        z = beam(uy, uz)
        bv = z.sum(axis=1)
        # (einsum, not BLAS: deterministic whatever the threads)
        by, bz = 1j * np.einsum("km,m->k", z, ca), 1j * np.einsum("km,m->k", z, cb_)
        byy = -np.einsum("km,m->k", z, caa)
        bzz = -np.einsum("km,m->k", z, cbb)
        byz = -np.einsum("km,m->k", z, cab)
        cb = np.conj(bv)
        gy = 2 * np.real(cb * by)
        gz = 2 * np.real(cb * bz)
        hyy = 2 * np.real(np.abs(by) ** 2 + cb * byy)
        hzz = 2 * np.real(np.abs(bz) ** 2 + cb * bzz)
        hyz = 2 * np.real(np.conj(by) * bz + cb * byz)
        if elevation:
            det = hyy * hzz - hyz**2
            good = (hyy < 0) & (det > 0)
            safe = np.where(good, det, 1.0)
            sy = np.where(good, -(hzz * gy - hyz * gz) / safe, 0.0)
            sz = np.where(good, -(hyy * gz - hyz * gy) / safe, 0.0)
        else:
            good = hyy < 0
            sy = np.where(good, -gy / np.where(good, hyy, 1.0), 0.0)
            sz = np.zeros_like(sy)
        sy = np.clip(sy, -max_step[0], max_step[0])
        sz = np.clip(sz, -max_step[1], max_step[1])
        p1 = power(uy + sy, uz + sz)
        better = p1 > p0
        uy = np.where(better, uy + sy, uy)
        uz = np.where(better, uz + sz, uz)
        p0 = np.where(better, p1, p0)
    return uy, uz, p0 / float(m * m)


class NearField:
    """Focusing phases of the unique virtual elements for a source at a finite range.

    The far-field steering vector assumes plane waves. A (TX, RX) pair whose antennas sit at
    ``a`` and ``b`` from the array's phase centre sees a source at range ``ρ`` and direction
    ``u`` (from the phase centre) over the round trip ``2ρ − u·(a + b) + q``,
    ``q = (|a|² − (u·a)² + |b|² − (u·b)²)/(2ρ)`` (second order in ``|a|/ρ``). The cascade's
    16 cm aperture has its Fraunhofer distance near 15 m, beyond the processed range, and
    ``k·q`` reaches a radian across it at 4 m: the far-field beam defocuses (shoulders and
    raised sidelobes that look like further targets). Multiplying element ``m`` by
    ``exp(−jk·q_m)`` focuses the beam at ``(ρ, u)``.

    A channel calibration measured on a reflector on boresight at ``R0`` (the cascade's) has
    already removed that reflector's phases ``k·q_m(R0, x̂)`` from every frame: the frames
    carry ``q(ρ, u) − q(R0, x̂)``, and the focusing is relative, ``exp(−jk(q_m − q_m(R0, x̂)))``
    (one constant factor per element on top of the absolute focusing).

    Parameters
    ----------
    tx, rx
        float ``(M, 3)`` [m]: the transmit and receive antenna of each unique element's pair,
        relative to the phase centre (radar frame, signs applied).
    wavenumber
        ``2π f_c / c`` [rad/m].
    reference
        ``R0`` [m]: range of the calibration's boresight reflector whose near-field phases the
        calibration removed (:attr:`coloradar.calib.RadarCalib.near_field_reference`); None:
        absolute focusing (frames whose channels carry the full spherical phases).
    """

    def __init__(self, tx: np.ndarray, rx: np.ndarray, wavenumber: float,
                 reference: float | None = None) -> None:
        self.tx = np.asarray(tx, dtype=np.float64)
        self.rx = np.asarray(rx, dtype=np.float64)
        self.wavenumber = float(wavenumber)
        self.reference = None if reference is None else float(reference)
        self._sq = (self.tx**2).sum(axis=1) + (self.rx**2).sum(axis=1)          # (M,)
        # (t·u)² + (r·u)² as a quadratic form Σ_{i≤j} c_ij·u_i·u_j of the direction: one
        # multiply–add per term and element instead of two dot products (terms whose
        # coefficients all vanish, e.g. those of x on a planar array, are left out)
        self._quad = [(i, j, (1.0 if i == j else 2.0)
                       * (self.tx[:, i] * self.tx[:, j] + self.rx[:, i] * self.rx[:, j]))
                      for i in range(3) for j in range(i, 3)]
        self._quad = [t for t in self._quad if np.any(t[2] != 0.0)]
        self._ref: np.ndarray | None = None
        if self.reference is not None:
            if not self.reference > 0:
                raise SettingsError(f"NearField reference must be > 0 m, got {reference!r}")
            # k·q_m(R0, x̂): the reflector's phases that the calibration removed
            xx = sum((c for i, j, c in self._quad if i == j == 0), np.zeros_like(self._sq))
            self._ref = self.wavenumber * (self._sq - xx) / (2.0 * self.reference)
        # float32 copies of the per-element terms (:meth:`_focus` works in float32): made
        # once here, not at every call
        self._sq32 = self._sq.astype(np.float32)
        self._quad32 = [(i, j, c.astype(np.float32)) for i, j, c in self._quad]
        self._ref32 = None if self._ref is None else self._ref.astype(np.float32)

    def focus(self, unit: np.ndarray, rng: np.ndarray, absolute: bool = False,
              transpose: bool = False) -> np.ndarray:
        """complex64 ``(M, K)``: ``exp(−jk·(q_m − q_m(R0, x̂)))`` for directions ``unit``
        ``(K, 3)`` and ranges ``rng`` ``(K,)`` [m] from the phase centre (``absolute`` or no
        reference: ``exp(−jk·q_m)``); ``transpose``: the same as a C-contiguous ``(K, M)``."""
        u = np.asarray(unit, dtype=np.float64).reshape(-1, 3)
        return self._focus(lambda i: u[:, i], u.shape[0], rng, absolute, transpose)

    def focus_sines(self, uy: np.ndarray, uz: np.ndarray, rng: np.ndarray,
                    transpose: bool = False) -> np.ndarray:
        """:meth:`focus` (relative where there is a reference) at the directions of sines
        ``(u_y, u_z)`` ``(K,)`` (as :func:`~coloradar.dsp.array.sines_to_unit`, without
        forming the unit vectors where none is beyond the visible disc)."""
        uy = np.asarray(uy, dtype=np.float64).reshape(-1)
        uz = np.asarray(uz, dtype=np.float64).reshape(-1)
        s2 = uy**2 + uz**2
        if np.any(s2 > 1.0):
            return self.focus(sines_to_unit(uy, uz), rng, transpose=transpose)
        need_x = any(0 in (i, j) for i, j, _ in self._quad)
        ux = np.sqrt(np.clip(1.0 - s2, 0.0, None)) if need_x else uy
        comps = (ux, uy, uz)
        return self._focus(lambda i: comps[i], uy.size, rng, False, transpose)

    def planar_terms(self) -> tuple[np.ndarray, ...] | None:
        """The focusing phase of :meth:`focus_sines` as a quadratic in the direction sines,
        where the array is planar in y–z (no antenna off the plane x = 0: the cascade's).

        Element ``m``'s phase at ``(u_y, u_z)`` and range ``ρ`` is
        ``−k/(2ρ)·(s_m − c_yy,m·u_y² − c_yz,m·u_y·u_z − c_zz,m·u_z²) + φ_m`` (``φ_m`` the
        reference's constant, 0 without one); for directions beyond the visible disc,
        ``(u_y, u_z)`` scaled onto it (:func:`~coloradar.dsp.array.sines_to_unit`).

        Returns
        -------
        tuple or None
            ``(s, c_yy, c_yz, c_zz, φ)``, float64 ``(M,)`` each ([m²] but ``φ`` [rad]); None
            where an antenna lies off the plane (the phase then depends on ``u_x`` too).
        """
        if np.any(self.tx[:, 0] != 0.0) or np.any(self.rx[:, 0] != 0.0):
            return None
        t, r = self.tx, self.rx
        ref = self._ref if self._ref is not None else np.zeros_like(self._sq)
        return (self._sq.copy(), t[:, 1]**2 + r[:, 1]**2,
                2.0 * (t[:, 1] * t[:, 2] + r[:, 1] * r[:, 2]), t[:, 2]**2 + r[:, 2]**2,
                np.asarray(ref, dtype=np.float64).copy())

    def _focus(self, comp: Callable[[int], np.ndarray], k: int, rng: np.ndarray,
               absolute: bool, transpose: bool) -> np.ndarray:
        """:meth:`focus` from the direction's components ``comp(i)`` (``(K,)`` each)."""
        # −k·q = −k(|t|² + |r|² − (t·u)² − (r·u)²)/(2ρ) (+ k·q(R0, x̂) when relative), the
        # bracket as Σ c_ij·u_i·u_j per element, in float32 (lengths of a few cm: relative
        # error ~1e-7, the complex64 output's own) at half the memory traffic of float64.
        a = (-self.wavenumber / (2.0 * np.maximum(np.asarray(rng, dtype=np.float64), 1e-3))
             ).astype(np.float32)

        def per_element(v: np.ndarray) -> np.ndarray:          # (v float32 already)
            return v[None, :] if transpose else v[:, None]

        def per_detection(v: np.ndarray) -> np.ndarray:
            v = v.astype(np.float32)
            return v[:, None] if transpose else v[None, :]

        shape = (k, self._sq.size) if transpose else (self._sq.size, k)
        ph = np.empty(shape, dtype=np.float32)
        tmp = np.empty(shape, dtype=np.float32)
        np.copyto(ph, per_element(self._sq32))
        for i, j, c in self._quad32:
            ph -= np.multiply(per_element(c), per_detection(comp(i) * comp(j)), out=tmp)
        ph *= per_detection(a)
        if self._ref32 is not None and not absolute:
            ph += per_element(self._ref32)
        out = np.empty(shape, dtype=np.complex64)
        np.cos(ph, out=out.real)
        np.sin(ph, out=out.imag)
        return out
