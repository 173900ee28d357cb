"""Compiled per-detection beam kernels (:mod:`coloradar.dsp.detection.peaks` and
:mod:`~coloradar.dsp.detection.guard`): steering, Newton refinement, elevation search, azimuth
peaks, near-field focusing and the 3 × 3 neighbourhood's beams."""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from ._jit import _Announced, _jit

__all__ = ["azimuth_peaks", "beam_neighbourhood", "elevation_search", "focus_multiply",
           "newton_refine", "steer_columns"]


# ------------------------------------------------------------------ per-detection kernels
# Beams of single detections at arbitrary direction sines (coloradar.dsp.processor's
# detection stages). Element m sits at integer grid positions (az_pos[m], el_pos[m]), so its
# steering factor exp(j(ca·az_pos·u_y + cb·el_pos·u_z)) is a product of two powers of one
# phasor per axis: a few complex multiplications per position instead of a sine and a cosine
# per element (float64 throughout; the numpy path rounds the phases to float32, ~3e-5 rad).


@numba.njit(inline="always")
def _powers(c: float, u: float, out: Any) -> None:  # pragma: no cover - compiled
    # out[k] = exp(j·c·u·k), k = 0 … len − 1: the first 8 by repeated multiplication, then
    # each from the one 8 before (independent products that pipeline; error ~k·1e-16)
    e = complex(math.cos(c * u), math.sin(c * u))
    n = out.size
    v = 1.0 + 0.0j
    for k in range(min(n, 8)):
        out[k] = v
        v *= e
    for k in range(8, n):                           # v = e⁸ here
        out[k] = out[k - 8] * v


@_jit(nogil=True)
def steer_columns(ca: float, cb: float, az_pos: Any, el_pos: Any, uy: Any, uz: Any,
                  out: Any) -> None:  # pragma: no cover - compiled
    """``out[m, p] = exp(j(ca·az_pos[m]·uy[p] + cb·el_pos[m]·uz[p]))``, complex64 ``(M, P)``
    (:func:`coloradar.dsp.angle.steering` with ``ca = πρ·s_az``, ``cb = πρ·s_el``)."""
    pa = np.empty(np.max(az_pos) + 1, np.complex128)
    pe = np.empty(np.max(el_pos) + 1, np.complex128)
    for p in range(uy.size):
        _powers(ca, uy[p], pa)
        _powers(cb, uz[p], pe)
        for m in range(az_pos.size):
            out[m, p] = pa[az_pos[m]] * pe[el_pos[m]]


@numba.njit(inline="always")
def _beam(x: Any, az_pos: Any, el_pos: Any, pa: Any, pe: Any) -> complex:  # pragma: no cover
    acc = 0.0 + 0.0j
    for m in range(az_pos.size):
        acc += x[m] * (pa[az_pos[m]] * pe[el_pos[m]])
    return acc


@_jit(nogil=True)
def newton_refine(x: Any, ca: float, cb: float, az_pos: Any, el_pos: Any, uy: Any, uz: Any,
                  max_step_y: float, max_step_z: float, iterations: int, elevation: bool,
                  out_uy: Any, out_uz: Any, out_power: Any) -> None:  # pragma: no cover
    """:func:`coloradar.dsp.angle.newton_refine` of vectors ``x`` complex64 ``(K, M)``: each
    step's beam, gradient and Hessian in one pass over the elements; writes the refined sines
    and ``|B|²/M²`` (float64 ``(K,)``)."""
    k_n, m_n = x.shape
    pa = np.empty(np.max(az_pos) + 1, np.complex128)
    pe = np.empty(np.max(el_pos) + 1, np.complex128)
    for k in range(k_n):
        y, z = uy[k], uz[k]
        xk = x[k]
        _powers(ca, y, pa)
        _powers(cb, z, pe)
        # (the start's beam power comes from the first moment pass, which sums the same
        # terms in the same order as _beam: one pass over the elements less)
        p0 = -1.0
        for it in range(max(iterations, 1)):
            bv = sa = sb = saa = sbb = sab = 0.0 + 0.0j
            for m in range(m_n):
                v = xk[m] * (pa[az_pos[m]] * pe[el_pos[m]])
                a = ca * az_pos[m]
                b = cb * el_pos[m]
                bv += v
                sa += v * a
                sb += v * b
                saa += v * (a * a)
                sbb += v * (b * b)
                sab += v * (a * b)
            if it == 0:
                p0 = bv.real * bv.real + bv.imag * bv.imag
                if iterations < 1:
                    break
            by, bz = 1j * sa, 1j * sb                 # dB/du_y, dB/du_z
            cbv = bv.conjugate()
            gy = 2.0 * (cbv * by).real
            gz = 2.0 * (cbv * bz).real
            hyy = 2.0 * (abs(by) ** 2 - (cbv * saa).real)
            hzz = 2.0 * (abs(bz) ** 2 - (cbv * sbb).real)
            hyz = 2.0 * ((by.conjugate() * bz).real - (cbv * sab).real)
            sy = sz = 0.0
            if elevation:
                det = hyy * hzz - hyz * hyz
                if hyy < 0 and det > 0:
                    sy = -(hzz * gy - hyz * gz) / det
                    sz = -(hyy * gz - hyz * gy) / det
            elif hyy < 0:
                sy = -gy / hyy
            sy = min(max(sy, -max_step_y), max_step_y)
            sz = min(max(sz, -max_step_z), max_step_z)
            _powers(ca, y + sy, pa)
            _powers(cb, z + sz, pe)
            b1 = _beam(xk, az_pos, el_pos, pa, pe)
            p1 = b1.real * b1.real + b1.imag * b1.imag
            if p1 > p0:
                y, z, p0 = y + sy, z + sz, p1
            else:                                     # phasors of the point kept
                _powers(ca, y, pa)
                _powers(cb, z, pe)
        out_uy[k], out_uz[k] = y, z
        out_power[k] = p0 / (m_n * m_n)


@numba.njit(inline="always")
def _log_parabola(v0: float, v1: float, v2: float) -> float:  # pragma: no cover - compiled
    # coloradar.dsp.angle.refine_peak's offset (circular axis)
    l0 = math.log(max(v0, 1e-300))
    l1 = math.log(max(v1, 1e-300))
    l2 = math.log(max(v2, 1e-300))
    den = l0 - 2.0 * l1 + l2
    if not den < 0:
        return 0.0
    return min(max(0.5 * (l0 - l2) / den, -0.5), 0.5)


@_jit(nogil=True)
def _row_groups(row: Any, n_rows: int) -> tuple[Any, Any]:  # pragma: no cover - compiled
    """Elements grouped by elevation row, in their order within a row (a counting sort):
    ``order`` int64 ``(M,)`` and the start of each row in it, ``row_start`` ``(rows + 1,)``."""
    row_start = np.zeros(n_rows + 1, np.int64)
    for m in range(row.size):
        row_start[row[m] + 1] += 1
    for q in range(n_rows):
        row_start[q + 1] += row_start[q]
    fill = row_start[:-1].copy()
    order = np.empty(row.size, np.int64)
    for m in range(row.size):
        order[fill[row[m]]] = m
        fill[row[m]] += 1
    return order, row_start


@_jit(nogil=True)
def elevation_search(x: Any, ca: float, az_pos: Any, row: Any, row_steer: Any, el_sines: Any,
                     uy: Any, rho: float, out_uz: Any, out_power: Any) -> None:  # pragma: no cover
    """Strongest elevation beam of each vector ``x`` complex64 ``(P, M)`` along its azimuth
    ``uy``: elements steered in azimuth and summed per elevation row (``row[m]``), the rows
    beamformed with ``row_steer`` complex64 ``(rows, n_el)`` over the grid's elevation sines
    (invisible directions give 0), the first maximum refined by a log-parabola (circular);
    writes its sine (``rho`` the grid's element spacing in half wavelengths) and
    ``|B|²/M²``."""
    p_n, m_n = x.shape
    n_rows, ne = row_steer.shape
    pa = np.empty(np.max(az_pos) + 1, np.complex128)
    acc = np.empty(n_rows, np.complex128)
    order, row_start = _row_groups(row, n_rows)
    sr = np.empty((n_rows, ne))
    si = np.empty((n_rows, ne))
    for q in range(n_rows):
        for e in range(ne):
            sr[q, e] = row_steer[q, e].real
            si[q, e] = row_steer[q, e].imag
    s2 = el_sines * el_sines
    vr = np.empty(ne)
    vi = np.empty(ne)
    bz = np.empty(ne)
    for p in range(p_n):
        _powers(ca, uy[p], pa)
        for q in range(n_rows):                  # each row's elements in turn
            a = 0.0 + 0.0j
            for i in range(row_start[q], row_start[q + 1]):
                m = order[i]
                a += x[p, m] * pa[az_pos[m]]
            acc[q] = a
        vr[:] = 0.0
        vi[:] = 0.0
        for q in range(n_rows):                  # elevation bins innermost (vectorised)
            ar, ai = acc[q].real, acc[q].imag
            for e in range(ne):
                vr[e] += ar * sr[q, e] - ai * si[q, e]
                vi[e] += ar * si[q, e] + ai * sr[q, e]
        lim = 1.0 - uy[p] * uy[p]
        for e in range(ne):
            bz[e] = vr[e] * vr[e] + vi[e] * vi[e] if s2[e] <= lim else 0.0
        ie = 0
        for e in range(1, ne):
            if bz[e] > bz[ie]:
                ie = e
        fe = ie + _log_parabola(bz[(ie - 1) % ne], bz[ie], bz[(ie + 1) % ne])
        out_uz[p] = 2.0 * (fe - ne // 2) / (ne * rho)
        out_power[p] = bz[ie] / (m_n * m_n)


@_jit(nogil=True)
def azimuth_peaks(profile: Any, relative: float, floor: Any, out_k: Any,
                  out_a: Any) -> int:  # pragma: no cover - compiled
    """:func:`coloradar.dsp.angle.azimuth_peaks` of float32 profiles ``(K, A)`` (the same
    peaks in the same order): writes the profile and bin of each peak to ``out_k``,
    ``out_a`` (int64, at least ``K·A`` long) and returns how many. ``floor`` float64
    ``(K,)``; ``relative`` is applied in float32, as numpy does with a Python float."""
    k_n, a_n = profile.shape
    rel = np.float32(relative)
    n = 0
    for k in range(k_n):
        row = profile[k]
        top = row[0]
        arg = 0
        for a in range(1, a_n):
            if top != top:                               # argmax stops at a NaN, as numpy's
                break
            if row[a] > top or row[a] != row[a]:
                top, arg = row[a], a
        lim = rel * top
        start = n
        for a in range(a_n):
            v = row[a]
            if a == arg or (v > row[(a - 1) % a_n] and v >= row[(a + 1) % a_n]
                            and v >= lim and v >= floor[k]):
                # strongest first, ties in bin order (a stable insertion)
                j = n
                while j > start and row[out_a[j - 1]] < v:
                    out_a[j] = out_a[j - 1]
                    j -= 1
                out_a[j] = a
                out_k[n] = k
                n += 1
    return n


@_jit(nogil=True)
def beam_neighbourhood(rd: Any, nxt: Any, chan: Any, tx_of: Any, num_tx: int, d: Any, r: Any,
                       alias: Any, tdm: bool, steer: Any, out: Any) -> None:  # pragma: no cover
    """Beam power ``|Σ_m v_m·steer[m, p]|²/M²`` of each point's direction in the 3 × 3 cells
    around its range–Doppler cell (``out`` float64 ``(P, 3, 3)``, Doppler then range offset
    −1..1). ``rd`` complex64 ``(channels, doppler, range)`` without TDM phases (Doppler index
    ``i`` ↔ signed bin ``i − doppler//2``), element ``m`` read from channel ``chan[m]`` of TX
    slot ``tx_of[m]``; ``nxt`` ``(channels, doppler)`` the range bin after the last (or
    ``(0, 0)``). With ``tdm`` each cell gets the TDM phase of its Doppler bin (a neighbour
    across the edge: of the unwrapped bin), every cell the point's alias phase."""
    _, nd, nr = rd.shape
    m_n = chan.size
    m2 = float(m_n * m_n)
    ph = np.empty((3, num_tx), np.complex128)
    acc = np.empty((3, 3), np.complex128)
    dn = np.empty(3, np.int64)
    rn = np.empty(3, np.int64)
    for p in range(d.size):
        for i in range(3):
            dd = d[p] + i - 1
            dn[i] = dd % nd
            rn[i] = min(max(r[p] + i - 1, 0), nr - 1)
            for t in range(num_tx):
                ang = -2.0 * math.pi * t * alias[p] / num_tx
                if tdm:                                   # at the unwrapped bin
                    ang -= 2.0 * math.pi * t * (dd - nd // 2) / (nd * num_tx)
                ph[i, t] = complex(math.cos(ang), math.sin(ang))
        beyond = nxt.shape[0] > 0 and r[p] + 1 >= nr
        acc[:] = 0.0
        # element-major: each element's 3 × 3 cells lie in 3 short rows of its channel
        for m in range(m_n):
            c, t = chan[m], tx_of[m]
            s = complex(steer[m, p])
            for i in range(3):
                f = ph[i, t] * s
                di = dn[i]
                acc[i, 0] += rd[c, di, rn[0]] * f
                acc[i, 1] += rd[c, di, rn[1]] * f
                acc[i, 2] += (nxt[c, di] if beyond else rd[c, di, rn[2]]) * f
        for i in range(3):
            for k in range(3):
                v = acc[i, k]
                out[p, i, k] = (v.real * v.real + v.imag * v.imag) / m2



@_jit(nogil=True)
def focus_multiply(x: Any, uy: Any, uz: Any, rho: Any, t_yz: Any, t_sq: Any, tx_idx: Any,
                   r_yz: Any, r_sq: Any, rx_idx: Any, ref: Any, wavenumber: float,
                   by_row: bool) -> None:  # pragma: no cover - compiled
    """``x[·, m] *= exp(jθ_m)`` in place: the near-field focusing phase of an array in the
    y–z plane (:meth:`coloradar.dsp.angle.NearField.focus_sines`), at sines
    ``(uy[p], uz[p])`` (scaled onto the visible disc's edge where beyond it) and range
    ``rho[p]`` [m]. ``x`` complex64 ``(P, M)`` with ``by_row``, else ``(M, P)``.

    ``θ_m = −k/(2ρ)·(|t|² − (t·u)² + |r|² − (r·u)²) + ref_m`` is a TX term plus an RX term
    plus a constant, so ``exp(jθ_m)`` is a product of one phasor per TX position
    (``t_yz`` float64 ``(T, 2)``, ``t_sq`` ``(T,)`` = ``|t|²``, element ``m``'s at
    ``tx_idx[m]``), one per RX position (``r_yz``, ``r_sq``, ``rx_idx``) and ``ref`` complex128
    ``(M,)`` (``exp(j·ref_m)``): a sine and cosine per antenna position (28 on the cascade)
    instead of per element (134), in one pass with no temporaries. (float64 phases; numpy's
    are float32: they agree to float32 rounding.)"""
    m_n = tx_idx.size
    et = np.empty(t_sq.size, np.complex128)
    er = np.empty(r_sq.size, np.complex128)
    for p in range(uy.size):
        y = uy[p]
        z = uz[p]
        s2 = y * y + z * z
        if s2 > 1.0:
            sc = 1.0 / math.sqrt(s2)
            y *= sc
            z *= sc
        a = -wavenumber / (2.0 * max(rho[p], 1e-3))
        for i in range(t_sq.size):
            d = t_yz[i, 0] * y + t_yz[i, 1] * z
            th = a * (t_sq[i] - d * d)
            et[i] = complex(math.cos(th), math.sin(th))
        for i in range(r_sq.size):
            d = r_yz[i, 0] * y + r_yz[i, 1] * z
            th = a * (r_sq[i] - d * d)
            er[i] = complex(math.cos(th), math.sin(th))
        if by_row:
            for m in range(m_n):
                x[p, m] *= et[tx_idx[m]] * er[rx_idx[m]] * ref[m]
        else:
            for m in range(m_n):
                x[m, p] *= et[tx_idx[m]] * er[rx_idx[m]] * ref[m]


azimuth_peaks = _Announced(azimuth_peaks)
beam_neighbourhood = _Announced(beam_neighbourhood)
elevation_search = _Announced(elevation_search)
focus_multiply = _Announced(focus_multiply)
newton_refine = _Announced(newton_refine)
steer_columns = _Announced(steer_columns)
