"""Compiled kernels of the several-source resolution (:mod:`coloradar.dsp.detection.resolve`):
joint least-squares amplitudes, keep tests and the secondary peaks' residuals and bounds."""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from ._jit import _Announced, _jit
from .beams import _powers, _row_groups

__all__ = ["joint_amplitudes", "joint_powers", "joint_residuals", "joint_round", "secondary_bound",
           "secondary_bound_focused", "secondary_residual"]


@numba.njit(cache=False)
def _cell_amplitudes(x: Any, row: int, w: Any, cols: Any, n: int,
                     out: Any) -> None:  # pragma: no cover - compiled
    # Least-squares amplitudes of the sources conj(w[:, cols[i]]), i < n, in the vector
    # x[row]: a lone source its beam value, several the normal equations (Gaussian
    # elimination with partial pivoting); written to out[cols[i]].
    m_n = x.shape[1]
    if n == 1:
        acc = 0.0 + 0.0j
        for m in range(m_n):
            acc += x[row, m] * w[m, cols[0]]
        out[cols[0]] = acc / m_n
        return
    g = np.zeros((n, n + 1), np.complex128)              # [Gram | right-hand side]
    for i in range(n):
        for m in range(m_n):
            wi = complex(w[m, cols[i]])
            g[i, n] += wi * x[row, m]
            for j in range(i, n):
                g[i, j] += wi * complex(w[m, cols[j]]).conjugate()
        for j in range(i):
            g[i, j] = g[j, i].conjugate()
    for col in range(n):
        piv = col
        for i in range(col + 1, n):
            if abs(g[i, col]) > abs(g[piv, col]):
                piv = i
        if piv != col:
            for j in range(n + 1):
                g[col, j], g[piv, j] = g[piv, j], g[col, j]
        if g[col, col] == 0.0:
            continue                                      # a source the others explain
        for i in range(col + 1, n):
            f = g[i, col] / g[col, col]
            for j in range(col, n + 1):
                g[i, j] -= f * g[col, j]
    for i in range(n - 1, -1, -1):
        if g[i, i] == 0.0:
            # two sources with the same weights (the same direction): the fit is the
            # others' alone, and this one gets nothing (then fails the keep tests)
            out[cols[i]] = 0.0
            continue
        v = g[i, n]
        for j in range(i + 1, n):
            v -= g[i, j] * out[cols[j]]
        out[cols[i]] = v / g[i, i]


@_jit(nogil=True)
def joint_amplitudes(x: Any, w: Any, starts: Any, out: Any) -> None:  # pragma: no cover
    """Least-squares amplitudes of every cell's sources: the peaks ``starts[c] …
    starts[c + 1] − 1`` belong to cell ``c`` (``starts`` ends with P), whose vector is
    ``x[starts[c]]`` (complex64 ``(P, M)``, one row per peak) and whose sources are the
    columns ``conj(w[:, p])`` (complex64 ``(M, P)``). A lone source gets its beam value
    ``Σ_m x_m w_m / M``; several are solved jointly (normal equations, Gaussian elimination
    with partial pivoting). Writes complex128 ``out`` ``(P,)``."""
    for c in range(starts.size - 1):
        s0, n = starts[c], starts[c + 1] - starts[c]
        _cell_amplitudes(x, s0, w, np.arange(s0, s0 + n), n, out)



@numba.njit(inline="always")
def _alive_of_cell(alive: Any, s0: int, s1: int, cols: Any) -> int:  # pragma: no cover
    # the peaks s0 … s1 − 1 still alive, into cols; how many
    n = 0
    for p in range(s0, s1):
        if alive[p]:
            cols[n] = p
            n += 1
    return n


@numba.njit(inline="always")
def _fit_total(w: Any, amps: Any, cols: Any, n: int, total: Any) -> None:  # pragma: no cover
    # Σ_i conj(w[:, cols[i]])·amps[cols[i]]: the fitted sources of a cell, summed
    total[:] = 0.0
    for i in range(n):
        q = cols[i]
        for m in range(total.size):
            total[m] += complex(w[m, q]).conjugate() * amps[q]


@_jit(nogil=True)
def joint_round(x: Any, w: Any, starts: Any, alive: Any, floor: Any, dyn: float,
                f_threshold: Any, residual_test: bool, amps: Any,
                count: Any) -> bool:  # pragma: no cover - compiled
    """One round of the keep tests of cells with several sources
    (:meth:`coloradar.dsp.detection.resolve.ResolveStage.resolve`): each cell's joint
    least-squares amplitudes of its alive peaks (cell ``c``: peaks ``starts[c] …
    starts[c + 1] − 1``, its strongest first; vector ``x[p]`` complex64 ``(P, M)``, weights
    ``w`` complex64 ``(M, P)``); a source stays while its power reaches the cell's noise
    ``floor[p]``, ``dyn`` times the cell's strongest and, with ``residual_test``, the F-test
    floor of what the fit leaves (``f_threshold[ν]·RSS/ν/M``, ``ν = max(M − 2n, 1)``); the
    strongest alive source of a cell always stays. Updates ``alive`` (bool ``(P,)``), writes
    the amplitudes (complex128 ``(P,)``, alive peaks) and the sources left per cell
    (``count`` int64 ``(cells,)``); returns whether a cell still has several."""
    m_n = x.shape[1]
    cols = np.empty(x.shape[0], np.int64)
    total = np.empty(m_n, np.complex128)
    multi = False
    for c in range(starts.size - 1):
        n = _alive_of_cell(alive, starts[c], starts[c + 1], cols)
        _cell_amplitudes(x, starts[c], w, cols, n, amps)
        # (|·| then squared as numpy's abs(·)**2 does; numba's |·| is hypot, numpy's its
        # own: the powers agree to 1 ulp. A NaN power makes the cell's top NaN, as numpy's
        # maximum.reduceat does, and then only the strongest source stays.)
        top = 0.0
        for i in range(n):
            v = abs(amps[cols[i]])
            p2 = v * v
            if p2 > top or p2 != p2:
                top = p2
            if top != top:
                break
        rf = 0.0
        if residual_test:
            _fit_total(w, amps, cols, n, total)
            rss = 0.0
            for m in range(m_n):
                v = abs(complex(x[starts[c], m]) - total[m])
                rss += v * v
            nu = max(m_n - 2 * n, 1)
            rf = f_threshold[nu] * rss / nu / m_n
        kept = 0
        for i in range(n):
            q = cols[i]
            v = abs(amps[q])
            pw = v * v
            if i > 0 and not (pw >= floor[q] and pw >= top * dyn and pw >= rf):
                alive[q] = False
            else:
                kept += 1
        count[c] = kept
        multi = multi or kept > 1
    return multi


@_jit(nogil=True)
def joint_residuals(x: Any, w: Any, starts: Any, alive: Any, count: Any,
                    out_x: Any, out_p: Any) -> int:  # pragma: no cover - compiled
    """For each alive source of a cell that has several (``count[c] > 1``; cells, ``x``
    and ``w`` as :func:`joint_round`): the cell's vector less the joint fit of its other
    sources, ``x − Σ_q conj(w_q)·a_q + conj(w_p)·a_p`` (``a`` the joint amplitudes), into
    the rows of ``out_x`` (complex64 ``(≥ K, M)``) and the peak into ``out_p`` (int64);
    returns ``K``. Each source is then refined on its own row."""
    m_n = x.shape[1]
    cols = np.empty(x.shape[0], np.int64)
    amps = np.empty(x.shape[0], np.complex128)
    total = np.empty(m_n, np.complex128)
    k = 0
    for c in range(starts.size - 1):
        if count[c] < 2:
            continue
        n = _alive_of_cell(alive, starts[c], starts[c + 1], cols)
        _cell_amplitudes(x, starts[c], w, cols, n, amps)
        _fit_total(w, amps, cols, n, total)
        for i in range(n):
            q = cols[i]
            for m in range(m_n):
                out_x[k, m] = (complex(x[q, m]) - total[m]
                               + complex(w[m, q]).conjugate() * amps[q])
            out_p[k] = q
            k += 1
    return k


@_jit(nogil=True)
def joint_powers(x: Any, w: Any, starts: Any, alive: Any, count: Any,
                 peak: Any) -> None:  # pragma: no cover - compiled
    """``peak[p] = |a_p|²`` of each alive source of a cell with several (cells, ``x``, ``w``
    as :func:`joint_round`; ``a`` the joint amplitudes), float64 ``(P,)`` in place."""
    cols = np.empty(x.shape[0], np.int64)
    amps = np.empty(x.shape[0], np.complex128)
    for c in range(starts.size - 1):
        if count[c] < 2:
            continue
        n = _alive_of_cell(alive, starts[c], starts[c + 1], cols)
        _cell_amplitudes(x, starts[c], w, cols, n, amps)
        for i in range(n):
            v = abs(amps[cols[i]])
            peak[cols[i]] = v * v


@_jit(nogil=True)
def secondary_residual(x: Any, w: Any, first: Any, resid: Any, top: Any) -> None:  # pragma: no cover
    """For every peak ``p`` of a cell whose strongest peak is ``first[p]``: the beam of the
    cell's vector less the strongest source's fit, ``|s_p − s_f·c_fp|²`` with ``s`` the beam
    values ``Σ_m x_m w_m / M`` and ``c_fp = Σ_m conj(w_mf) w_mp / M`` the array's cross
    pattern (``resid``), and ``|s_f|²`` (``top``); float64 ``(P,)``. ``x`` complex64 ``(P, M)``,
    ``w`` complex64 ``(M, P)``."""
    p_n, m_n = x.shape
    amp = np.empty(p_n, np.complex128)
    for p in range(p_n):
        acc = 0.0 + 0.0j
        for m in range(m_n):
            acc += x[p, m] * w[m, p]
        amp[p] = acc / m_n
    for p in range(p_n):
        f = first[p]
        a = amp[f]
        top[p] = a.real * a.real + a.imag * a.imag
        if f == p:
            resid[p] = top[p]
            continue
        c = 0.0 + 0.0j
        for m in range(m_n):
            c += complex(w[m, f]).conjugate() * w[m, p]
        v = amp[p] - a * (c / m_n)
        resid[p] = v.real * v.real + v.imag * v.imag


@_jit(nogil=True)
def secondary_bound(x: Any, w_first: Any, first: Any, uy: Any, ca: float, az_pos: Any,
                    row: Any, n_rows: int, out_bound: Any, out_top: Any) -> None:  # pragma: no cover
    """Upper bound, over every elevation, of the residual beam power of secondary peaks.

    Peak ``p`` (vector ``x[p]`` complex64 ``(P, M)``, azimuth sine ``uy[p]``) belongs to a
    cell whose strongest source has weights ``w_first[:, first[p]]`` (complex64
    ``(M, F)``) and beam value ``s_f = Σ_m x_m w_m / M``; the cell's vector less that source's
    fit, ``r = x − s_f·conj(w_f)``, steered in azimuth and summed per elevation row
    (``row[m]``, ``n_rows`` rows) gives ``A_q``, and ``|Σ_m r_m w_m(u)|/M ≤ Σ_q |A_q| / M``
    whatever the elevation of ``u`` (each row's elevation phase has modulus 1). Writes that
    bound squared (``out_bound``) and ``|s_f|²`` (``out_top``), float64 ``(P,)``.
    """
    p_n, m_n = x.shape
    pa = np.empty(np.max(az_pos) + 1, np.complex128)
    acc = np.empty(n_rows, np.complex128)
    for p in range(p_n):
        f = first[p]
        a = 0.0 + 0.0j
        for m in range(m_n):
            a += x[p, m] * w_first[m, f]
        a /= m_n
        out_top[p] = a.real * a.real + a.imag * a.imag
        _powers(ca, uy[p], pa)
        acc[:] = 0.0
        for m in range(m_n):
            r = x[p, m] - a * complex(w_first[m, f]).conjugate()
            acc[row[m]] += r * pa[az_pos[m]]
        b = 0.0
        for q in range(n_rows):
            b += abs(acc[q])
        b /= m_n
        out_bound[p] = b * b


_TWO_PI = 2.0 * math.pi


@numba.njit(inline="always")
def _expj(t: float) -> complex:  # pragma: no cover - compiled
    # exp(jt) without libm calls: t reduced to [−π, π], the Taylor series of exp(jt/8)
    # (error < 1e-10 there), squared three times
    h = (t - _TWO_PI * math.floor(t * (1.0 / _TWO_PI) + 0.5)) * 0.125
    h2 = h * h
    c = 1.0 - h2 * (0.5 - h2 * (1.0 / 24 - h2 * (1.0 / 720 - h2 * (1.0 / 40320))))
    sn = h * (1.0 - h2 * (1.0 / 6 - h2 * (1.0 / 120 - h2 * (1.0 / 5040 - h2 * (1.0 / 362880)))))
    for _ in range(3):
        c, sn = c * c - sn * sn, 2.0 * c * sn
    return complex(c, sn)


@_jit(nogil=True)
def secondary_bound_focused(x: Any, w_first: Any, first: Any, uy: Any, rho: Any, floor: Any,
                            dyn: float, ca: float, az_pos: Any, row: Any, n_rows: int, sq: Any,
                            cyy: Any, cyz: Any, czz: Any, ref: Any, ty2: Any, it: Any, ry2: Any,
                            ir: Any, wavenumber: float, u_grid: float, half_step: float,
                            out_bound: Any, out_top: Any) -> None:  # pragma: no cover
    """:func:`secondary_bound` for beams focused at range ``rho[p]`` [m] (float64 ``(P,)``).

    Element ``m``'s focusing phase at sines ``(u_y, u_z)`` is
    ``θ_m = −k/(2ρ)·(sq_m − Q_m(u)) + ref_m``, ``Q_m = cyy_m·u_y² + cyz_m·u_y·u_z +
    czz_m·u_z²`` (:meth:`coloradar.dsp.angle.NearField.planar_terms`; directions beyond the
    visible disc scaled onto its edge): it changes with the elevation within a row, so the
    row sums of :func:`secondary_bound` alone bound nothing. Here the row sums ``A_q`` take
    the residual ``r`` steered in azimuth and multiplied by ``exp(jc_m)``, ``c_m`` the phase at
    ``(y_0, 0)``, ``y_0 = min(|u_y|, 1)``. Over every elevation the search can return at
    ``u_y`` (a visible bin, ``|u_z| ≤ √(1 − u_y²)``, up to ``half_step`` beyond; ``|u_z| ≤
    u_grid`` in any case), the directions as focused (scaled onto the disc's edge where
    beyond it) have ``|u_y'| ∈ [y_1, y_0]`` and ``|u_z'| ≤ z_max``, so
    ``|Q_m(u') − Q_m(y_0, 0)| ≤ ΔQ_m = cyy_m(y_0² − y_1²) + |cyz_m|·y_0·z_max +
    czz_m·z_max²`` and, with ``|e^{ja} − e^{jb}| ≤ |a − b|``::

        |Σ_m r_m w_m(u)| / M ≤ (Σ_q |A_q| + k/(2ρ)·Σ_m |r_m|·ΔQ_m + ε·Σ_m |r_m|) / M

    at every elevation, ``ε = 1e-4`` rad covering the float32 phases of the weights. The
    sums over ``|r_m|`` are per cell (its peaks, consecutive, share ``r``), and so is the
    factor ``exp(−jk·sq_m/(2ρ) + j·ref_m)`` of ``exp(jc_m)``; the rest,
    ``exp(jk·y_0²·cyy_m/(2ρ))`` with ``cyy_m = ty2[it[m]] + ry2[ir[m]]`` (the squared y of
    the element's TX and RX), is a product of one factor per TX and one per RX. Cheaper first:
    Cauchy–Schwarz, ``‖r‖²/M``, per cell; where that is already below the peak's test
    (``floor[p]``, ``dyn·|s_f|²``) it is the bound written and the row sums are skipped.
    Writes the bound on the residual beam power (``out_bound``) and ``|s_f|²``
    (``out_top``), float64 ``(P,)``.
    """
    p_n, m_n = x.shape
    pa = np.empty(np.max(az_pos) + 1, np.complex128)
    order, row_start = _row_groups(row, n_rows)
    r = np.empty(m_n, np.complex128)
    re = np.empty(m_n, np.complex128)          # r_m·exp(−jk·sq_m/(2ρ) + j·ref_m), per cell
    et = np.empty(ty2.size, np.complex128)
    ex = np.empty(ry2.size, np.complex128)
    a = 0.0 + 0.0j
    s0 = s2 = syy = syz = szz = 0.0
    re_of = -1                                  # the cell whose factors re holds
    for p in range(p_n):
        f = first[p]
        if p == 0 or f != first[p - 1]:         # a new cell: its residual and sums
            a = 0.0 + 0.0j
            for m in range(m_n):
                a += x[p, m] * w_first[m, f]
            a /= m_n
            s0 = s2 = syy = syz = szz = 0.0
            for m in range(m_n):
                rm = x[p, m] - a * complex(w_first[m, f]).conjugate()
                r[m] = rm
                v2 = rm.real * rm.real + rm.imag * rm.imag
                v = math.sqrt(v2)                # (not abs: hypot is slow)
                s0 += v
                s2 += v2
                syy += v * cyy[m]
                syz += v * abs(cyz[m])
                szz += v * czz[m]
        top = a.real * a.real + a.imag * a.imag
        out_top[p] = top
        cs = s2 / m_n * (1.0 + 1e-6)
        if cs < floor[p] or cs < dyn * top:
            out_bound[p] = cs
            continue
        scale = wavenumber / (2.0 * max(rho[p], 1e-3))
        if re_of != f:                          # (the peaks of a cell share the range)
            re_of = f
            for m in range(m_n):
                re[m] = r[m] * _expj(-scale * sq[m] + ref[m])
        _powers(ca, uy[p], pa)
        # (Q_m(−u) = Q_m(u) and the elevations searched are symmetric: |u_y| will do)
        y = abs(uy[p])
        zm = math.sqrt(max(1.0 - y * y, 0.0))
        u_max = min(u_grid, zm + half_step) if y * y <= 1.0 else u_grid
        y0 = min(y, 1.0)
        if u_max > zm:
            # beyond the edge: (u_y, u_z) scaled onto it, |u_y'| down to y/s at u_z = u_max
            s1 = math.sqrt(y * y + u_max * u_max)
            y1, z_max = y / s1, u_max / s1
        else:
            y1, z_max = y0, u_max
        beta = scale * y0 * y0
        for i in range(ty2.size):
            et[i] = _expj(beta * ty2[i])
        for i in range(ry2.size):
            ex[i] = _expj(beta * ry2[i])
        b = 0.0
        for q in range(n_rows):                  # each row's elements in turn
            aq = 0.0 + 0.0j
            for i in range(row_start[q], row_start[q + 1]):
                m = order[i]
                aq += re[m] * pa[az_pos[m]] * (et[it[m]] * ex[ir[m]])
            b += math.sqrt(aq.real * aq.real + aq.imag * aq.imag)
        dev = syy * (y0 * y0 - y1 * y1) + syz * y0 * z_max + szz * z_max * z_max
        b += scale * dev + 1e-4 * s0
        b /= m_n
        out_bound[p] = b * b * (1.0 + 1e-6)


joint_amplitudes = _Announced(joint_amplitudes)
joint_powers = _Announced(joint_powers)
joint_residuals = _Announced(joint_residuals)
joint_round = _Announced(joint_round)
secondary_bound = _Announced(secondary_bound)
secondary_bound_focused = _Announced(secondary_bound_focused)
secondary_residual = _Announced(secondary_residual)
