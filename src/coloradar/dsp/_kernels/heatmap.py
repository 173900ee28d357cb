"""Compiled heatmap kernels (:mod:`coloradar.dsp.heatmap`): the angle spectra's elevation stage,
power and maximum over Doppler, and the planar whole-heatmap kernel."""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from ._jit import _FM, _Announced, _jit

__all__ = ['LANES', 'gather_rows', 'peak_over_doppler', 'peak_over_doppler_planar']


@numba.njit(inline="always", fastmath=_FM)
def _update(best: Any, arg: Any, d: Any, vr: Any, vi: Any) -> None:  # pragma: no cover
    for a in range(best.size):
        p = vr[a] * vr[a] + vi[a] * vi[a]
        b = best[a]
        arg[a] = d if p > b else arg[a]              # first maximum wins, as argmax
        best[a] = max(b, p)


# "nnan" (inputs are finite: ADC counts) lets LLVM turn the running maximum into vector
# max/blend instructions; without it the comparisons stay scalar and cost half the kernel.
@numba.njit(inline="always", fastmath=_FM)
def _elevate(xr: Any, xi: Any, sr: Any, si: Any, n_even: int, peak_p: Any, bins_p: Any,
             peak_m: Any, bins_m: Any, r: int, dd: Any, er: Any, ei: Any, o_r: Any,
             o_i: Any) -> None:  # pragma: no cover - compiled
    # One Doppler bin of range bin r: the elevation DFT of the occupied rows' azimuth
    # spectra xr + j·xi ``(rows, naz)``, its power and the running maximum over Doppler
    # (``peak``/``bins`` ``(n, n_st, naz)``). Azimuth is the innermost loop (contiguous,
    # vectorised); beam values, power and comparison stay in registers.
    # Paired (n_even >= 0): steering row p gives elevation bin el_plus[p] as E + O and
    # el_minus[p] (FFT index + n/2) as E − O, E/O the sums over even/odd rows (rows
    # sorted even first). Unpaired (n_even < 0): row p gives bin el_plus[p] only.
    # Row 0 sits at elevation position 0 in the specialised paths: its steering is 1.
    # Arrays are indexed in full, never sliced, in these loops: each slice of an array
    # costs numba two reference-count calls, more than the loop over azimuth itself.
    # The + and − maxima live in separate arrays: LLVM vectorises the loop only when it
    # can tell the stores apart.
    rows, naz = xr.shape
    n_st = sr.shape[0]
    if rows == 4 and n_even == 3 and sr[0, 0] == 1.0 and si[0, 0] == 0.0:
        # the cascade: rows 0, 4, 6 | 1
        for e in range(n_st):
            c1r, c1i, c2r, c2i = sr[e, 1], si[e, 1], sr[e, 2], si[e, 2]
            c3r, c3i = sr[e, 3], si[e, 3]
            for a in range(naz):
                vr = (xr[0, a] + c1r * xr[1, a] - c1i * xi[1, a] + c2r * xr[2, a]
                      - c2i * xi[2, a])
                vi = (xi[0, a] + c1r * xi[1, a] + c1i * xr[1, a] + c2r * xi[2, a]
                      + c2i * xr[2, a])
                wr = c3r * xr[3, a] - c3i * xi[3, a]
                wi = c3r * xi[3, a] + c3i * xr[3, a]
                p = (vr + wr) * (vr + wr) + (vi + wi) * (vi + wi)
                b = peak_p[r, e, a]
                bins_p[r, e, a] = dd if p > b else bins_p[r, e, a]  # first max wins (argmax)
                peak_p[r, e, a] = max(b, p)
                p = (vr - wr) * (vr - wr) + (vi - wi) * (vi - wi)
                b = peak_m[r, e, a]
                bins_m[r, e, a] = dd if p > b else bins_m[r, e, a]
                peak_m[r, e, a] = max(b, p)
    elif rows == 2 and n_even == 1 and sr[0, 0] == 1.0 and si[0, 0] == 0.0:
        # the single chip: row 0 | 1
        for e in range(n_st):
            c1r, c1i = sr[e, 1], si[e, 1]
            for a in range(naz):
                vr, vi = xr[0, a], xi[0, a]
                wr = c1r * xr[1, a] - c1i * xi[1, a]
                wi = c1r * xi[1, a] + c1i * xr[1, a]
                p = (vr + wr) * (vr + wr) + (vi + wi) * (vi + wi)
                b = peak_p[r, e, a]
                bins_p[r, e, a] = dd if p > b else bins_p[r, e, a]
                peak_p[r, e, a] = max(b, p)
                p = (vr - wr) * (vr - wr) + (vi - wi) * (vi - wi)
                b = peak_m[r, e, a]
                bins_m[r, e, a] = dd if p > b else bins_m[r, e, a]
                peak_m[r, e, a] = max(b, p)
    else:                                           # any other layout
        n_e = rows if n_even < 0 else n_even
        for e in range(n_st):
            er[:] = 0.0
            ei[:] = 0.0
            o_r[:] = 0.0
            o_i[:] = 0.0
            for q in range(rows):
                cr, ci, xqr, xqi = sr[e, q], si[e, q], xr[q], xi[q]
                ar, ai = (er, ei) if q < n_e else (o_r, o_i)
                for a in range(naz):
                    ar[a] += cr * xqr[a] - ci * xqi[a]
                    ai[a] += cr * xqi[a] + ci * xqr[a]
            if n_even < 0:
                _update(peak_p[r, e], bins_p[r, e], dd, er, ei)
                continue
            _update(peak_p[r, e], bins_p[r, e], dd, er + o_r, ei + o_i)
            _update(peak_m[r, e], bins_m[r, e], dd, er - o_r, ei - o_i)


@numba.njit(inline="always")
def _pairs(rows: int, n_even: int, sr: Any, si: Any) -> bool:  # pragma: no cover - compiled
    # whether _elevate2 takes this layout: the single chip's rows 0 | 1
    return rows == 2 and n_even == 1 and sr[0, 0] == 1.0 and si[0, 0] == 0.0


@numba.njit(inline="always", fastmath=_FM)
def _elevate2(xr: Any, xi: Any, yr: Any, yi: Any, sr: Any, si: Any, peak_p: Any,
              bins_p: Any, peak_m: Any, bins_m: Any, vx: Any,
              vy: Any) -> None:  # pragma: no cover - compiled
    # _elevate for two Doppler bins at once (spectra x then y, labels vx then vy) and range
    # index 0. For the single chip the pair's larger power meets the running maximum, so
    # the state arrays are read and written once per two bins (their loads and stores, not
    # the arithmetic, bound that loop: 13 % less time); ties go to the earlier bin, as
    # argmax. The cascade's loop is bound by its arithmetic, and pairing it measured slower
    # (register pressure): other layouts take the bins one at a time (the caller checks
    # _pairs first). Only the single chip's layout (rows 0 | 1) is here.
    naz = xr.shape[1]
    n_st = sr.shape[0]
    for e in range(n_st):
        c1r, c1i = sr[e, 1], si[e, 1]
        for a in range(naz):
            vr, vi, ur, ui = xr[0, a], xi[0, a], yr[0, a], yi[0, a]
            wr = c1r * xr[1, a] - c1i * xi[1, a]
            wi = c1r * xi[1, a] + c1i * xr[1, a]
            zr = c1r * yr[1, a] - c1i * yi[1, a]
            zi = c1r * yi[1, a] + c1i * yr[1, a]
            p = (vr + wr) * (vr + wr) + (vi + wi) * (vi + wi)
            q = (ur + zr) * (ur + zr) + (ui + zi) * (ui + zi)
            lab = vy if q > p else vx
            p = max(p, q)
            b = peak_p[0, e, a]
            bins_p[0, e, a] = lab if p > b else bins_p[0, e, a]
            peak_p[0, e, a] = max(b, p)
            p = (vr - wr) * (vr - wr) + (vi - wi) * (vi - wi)
            q = (ur - zr) * (ur - zr) + (ui - zi) * (ui - zi)
            lab = vy if q > p else vx
            p = max(p, q)
            b = peak_m[0, e, a]
            bins_m[0, e, a] = lab if p > b else bins_m[0, e, a]
            peak_m[0, e, a] = max(b, p)


@numba.njit(inline="always")
def _split_steering(steer: Any) -> tuple[Any, Any]:  # pragma: no cover - compiled
    n_st, rows = steer.shape
    sr = np.empty((n_st, rows), np.float32)
    si = np.empty((n_st, rows), np.float32)
    for e in range(n_st):
        for q in range(rows):
            sr[e, q] = steer[e, q].real
            si[e, q] = steer[e, q].imag
    return sr, si


@_jit(fastmath=_FM, nogil=True)
def peak_over_doppler(spec: Any, steer: Any, n_even: int, el_plus: Any, el_minus: Any,
                      az_read: Any, velocities: Any, scale: float, out: Any,
                      r0: int) -> None:  # pragma: no cover - compiled
    """Peak over Doppler of a chunk of range bins from their azimuth spectra.

    ``spec`` complex64 ``(rows, n, doppler, naz)``: azimuth FFT of the occupied elevation
    rows of ``n`` range bins from ``r0``; ``steer`` complex64 ``(n_st, rows)``; writes
    ``out[:, :, r0:r0 + n]`` (``(num_el, num_az, range, 2)``, see
    :func:`coloradar.dsp.heatmap.heatmap_from_elements`).
    """
    rows, n, nd, naz = spec.shape
    n_st = steer.shape[0]
    n_out = out.shape[1]
    xr = np.empty((rows, naz), np.float32)
    xi = np.empty((rows, naz), np.float32)
    peak_p = np.empty((n, n_st, naz), np.float32)
    bins_p = np.empty((n, n_st, naz), np.int32)
    peak_m = np.empty((n, n_st, naz), np.float32)
    bins_m = np.empty((n, n_st, naz), np.int32)
    er = np.empty(naz, np.float32)
    ei = np.empty(naz, np.float32)
    o_r = np.empty(naz, np.float32)
    o_i = np.empty(naz, np.float32)
    sr, si = _split_steering(steer)
    peak_p[:] = -1.0
    peak_m[:] = -1.0
    bins_p[:] = 0
    bins_m[:] = 0
    for r in range(n):
        for d in range(nd):
            for q in range(rows):               # de-interleave once, use n_st times
                for a in range(naz):
                    v = spec[q, r, d, a]
                    xr[q, a] = v.real
                    xi[q, a] = v.imag
            _elevate(xr, xi, sr, si, n_even, peak_p, bins_p, peak_m, bins_m, r, np.int32(d),
                     er, ei, o_r, o_i)
    for half in range(1 if n_even < 0 else 2):  # range is the output's inner axis
        peak, bins, els = (peak_p, bins_p, el_plus) if half == 0 else (peak_m, bins_m,
                                                                       el_minus)
        for e in range(n_st):
            el = els[e]
            for j in range(n_out):
                a = az_read[j]
                for r in range(n):
                    out[el, j, r0 + r, 0] = peak[r, e, a] * scale
                    out[el, j, r0 + r, 1] = velocities[bins[r, e, a]]


LANES = 16
"""Range bins transformed side by side by the planar kernel (one AVX-512 register of float32)."""


@numba.njit(inline="always", fastmath=_FM)
def _fft_lanes(src_r: Any, src_i: Any, x_r: Any, x_i: Any, y_r: Any, y_i: Any, w_r: Any,
               w_i: Any, q: int, skip: int) -> None:  # pragma: no cover - compiled
    # FFT over axis 1 of row q of src ``(rows, n, LANES)`` (n a power of two), every lane a
    # separate transform: Stockham autosort radix 2 (natural order in, natural order out, no
    # bit reversal), ping-pong y <- src, x <- y, y <- x, ...: the result lies in y after an
    # odd number of stages, in x after an even one. w = exp(−2πj·t/n), t < n/2. The lane loop
    # is innermost: every butterfly is one vector operation on 16 range bins. With skip = 1
    # src already holds the first stage's output (done while gathering, see
    # peak_over_doppler_planar).
    n = src_r.shape[1]
    half = n // 2 >> skip
    m = 1 << skip
    first = True
    while half >= 1:
        for j in range(half):
            wr, wi = w_r[j * m], w_i[j * m]
            for k in range(m):
                i0 = k + j * m
                i1 = i0 + half * m
                o0 = k + 2 * j * m
                o1 = o0 + m
                if first:
                    for t in range(LANES):
                        ar, ai, br, bi = src_r[q, i0, t], src_i[q, i0, t], src_r[q, i1, t], \
                            src_i[q, i1, t]
                        y_r[q, o0, t] = ar + br
                        y_i[q, o0, t] = ai + bi
                        dr, di = ar - br, ai - bi
                        y_r[q, o1, t] = wr * dr - wi * di
                        y_i[q, o1, t] = wr * di + wi * dr
                else:
                    for t in range(LANES):
                        ar, ai, br, bi = x_r[q, i0, t], x_i[q, i0, t], x_r[q, i1, t], \
                            x_i[q, i1, t]
                        y_r[q, o0, t] = ar + br
                        y_i[q, o0, t] = ai + bi
                        dr, di = ar - br, ai - bi
                        y_r[q, o1, t] = wr * dr - wi * di
                        y_i[q, o1, t] = wr * di + wi * dr
        x_r, y_r = y_r, x_r
        x_i, y_i = y_i, x_i
        first = False
        half //= 2
        m *= 2


# peak_over_doppler_planar, why its loops are written as they are: one call site per inlined
# helper (each site is a copy of its loops for LLVM to optimise: two sites of each made this
# kernel's first compile take twice as long); the output of a full block with a fixed trip
# count and the (peak, rate) pairs as one float32 axis: LLVM writes them with vector
# interleaves (half the time of that loop with n lanes, measured).
@_jit(fastmath=_FM, nogil=True)
def peak_over_doppler_planar(cube: Any, gain: Any, channels: Any, row_of: Any, az_pos: Any,
                             steer: Any, n_even: int, el_plus: Any, el_minus: Any,
                             az_read: Any, velocities: Any, out: Any, w_r: Any,
                             w_i: Any) -> None:  # pragma: no cover - compiled
    """The whole heatmap from the range–Doppler cube, range bins as SIMD lanes.

    Element ``m`` is ``cube[channels[m]] · gain[channels[m]]`` (``cube`` complex64
    ``(C, doppler, range)``, ``gain`` complex64 ``(C, doppler)``: the TDM compensation and
    the ``1/M`` of the power's ``1/M²``, applied while gathering), at occupied row
    ``row_of[m]`` and azimuth position ``az_pos[m]``. For :data:`LANES` range
    bins at a time and each Doppler bin: gather the elements into planar (real, imaginary)
    ``(rows, n_az, LANES)`` buffers, FFT every row along azimuth (``n_az = w_r.size·2``, a
    power of two) with the lanes innermost, then the elevation stage over the flattened
    ``(azimuth, lane)`` axis: 2048 contiguous values for the cascade, one long vector loop,
    no de-interleaving, no zero-padded copies, no FFT calls. Writes ``out``
    (``(num_el, num_az, range, 2)``).
    """
    nd, nr = cube.shape[1], cube.shape[2]
    cf = cube.reshape(cube.shape[0], nd, nr).view(np.float32)     # (C, doppler, 2·range)
    out_f = out.reshape(out.shape[0], out.shape[1], 2 * nr)        # (el, az, 2·range)
    n_az = 2 * w_r.size
    n_st, rows = steer.shape
    n_out = out.shape[1]
    flat = n_az * LANES
    src_r = np.zeros((rows, n_az, LANES), np.float32)       # zeros where no element sits
    src_i = np.zeros((rows, n_az, LANES), np.float32)
    # FFT work buffers, one set per Doppler bin of a pair
    a_r = np.empty((2, rows, n_az, LANES), np.float32)
    a_i = np.empty((2, rows, n_az, LANES), np.float32)
    b_r = np.empty((2, rows, n_az, LANES), np.float32)
    b_i = np.empty((2, rows, n_az, LANES), np.float32)
    stages = 0
    while (1 << stages) < n_az:
        stages += 1
    # All elements in the first half of the azimuth points (the single chip: 8 of 64): the
    # FFT's first stage has no second inputs, y[2p] = x[p], y[2p + 1] = w^p·x[p], and the
    # gather writes its output directly (the other points stay zero): one stage fewer.
    skip = 1 if stages > 1 and 2 * (az_pos.max() + 1) <= n_az else 0
    stages -= skip
    if stages % 2 == 1:                         # where _fft_lanes leaves the spectrum
        sp_r, sp_i = a_r.reshape(2, rows, flat), a_i.reshape(2, rows, flat)
    else:
        sp_r, sp_i = b_r.reshape(2, rows, flat), b_i.reshape(2, rows, flat)
    x_r, x_i, y_r, y_i = sp_r[0], sp_i[0], sp_r[1], sp_i[1]
    a0r, a0i, b0r, b0i = a_r[0], a_i[0], b_r[0], b_i[0]
    a1r, a1i, b1r, b1i = a_r[1], a_i[1], b_r[1], b_i[1]
    # the running maximum and the range rate of its Doppler bin (a label, not an index: the
    # output needs no lookup)
    peak_p = np.empty((1, n_st, flat), np.float32)
    bins_p = np.empty((1, n_st, flat), np.float32)
    peak_m = np.empty((1, n_st, flat), np.float32)
    bins_m = np.empty((1, n_st, flat), np.float32)
    er = np.empty(flat, np.float32)
    ei = np.empty(flat, np.float32)
    o_r = np.empty(flat, np.float32)
    o_i = np.empty(flat, np.float32)
    sr, si = _split_steering(steer)
    pairs = _pairs(rows, n_even, sr, si)
    for r0 in range(0, nr, LANES):
        n = min(LANES, nr - r0)
        if n < LANES:                           # last, partial block: idle lanes stay 0
            src_r[:] = 0.0
            src_i[:] = 0.0
        peak_p[:] = -1.0
        peak_m[:] = -1.0
        bins_p[:] = 0.0
        bins_m[:] = 0.0
        for d0 in range(0, nd, 2):
            for d in range(d0, min(d0 + 2, nd)):
                for mm in range(channels.size):
                    c, q, p = channels[mm], row_of[mm], az_pos[mm]
                    g = gain[c, d]
                    gr, gi = g.real, g.imag
                    if skip:
                        hr, hi = gr * w_r[p] - gi * w_i[p], gr * w_i[p] + gi * w_r[p]
                        for t in range(n):
                            v = cube[c, d, r0 + t]
                            src_r[q, 2 * p, t] = gr * v.real - gi * v.imag
                            src_i[q, 2 * p, t] = gr * v.imag + gi * v.real
                            src_r[q, 2 * p + 1, t] = hr * v.real - hi * v.imag
                            src_i[q, 2 * p + 1, t] = hr * v.imag + hi * v.real
                    elif n == LANES:                # full block: a fixed trip count
                        for t in range(LANES):
                            vr, vi = cf[c, d, 2 * (r0 + t)], cf[c, d, 2 * (r0 + t) + 1]
                            src_r[q, p, t] = gr * vr - gi * vi
                            src_i[q, p, t] = gr * vi + gi * vr
                    else:
                        for t in range(n):
                            v = cube[c, d, r0 + t]
                            src_r[q, p, t] = gr * v.real - gi * v.imag
                            src_i[q, p, t] = gr * v.imag + gi * v.real
                br, bi, ar, ai = (b0r, b0i, a0r, a0i) if d == d0 else (b1r, b1i, a1r, a1i)
                for q in range(rows):
                    _fft_lanes(src_r, src_i, br, bi, ar, ai, w_r, w_i, q, skip)
            if d0 + 1 < nd and pairs:
                _elevate2(x_r, x_i, y_r, y_i, sr, si, peak_p, bins_p, peak_m, bins_m,
                          velocities[d0], velocities[d0 + 1])
                continue
            for d in range(d0, min(d0 + 2, nd)):
                xr_, xi_ = (x_r, x_i) if d == d0 else (y_r, y_i)
                _elevate(xr_, xi_, sr, si, n_even, peak_p, bins_p, peak_m, bins_m, 0,
                         velocities[d], er, ei, o_r, o_i)
        for half in range(1 if n_even < 0 else 2):
            peak, bins, els = (peak_p, bins_p, el_plus) if half == 0 else (peak_m, bins_m,
                                                                           el_minus)
            for e in range(n_st):
                el = els[e]
                if n == LANES:
                    for j in range(n_out):
                        a = az_read[j] * LANES
                        for t in range(LANES):
                            out_f[el, j, 2 * (r0 + t)] = peak[0, e, a + t]
                            out_f[el, j, 2 * (r0 + t) + 1] = bins[0, e, a + t]
                    continue
                for j in range(n_out):
                    a = az_read[j] * LANES
                    for t in range(n):
                        out[el, j, r0 + t, 0] = peak[0, e, a + t]
                        out[el, j, r0 + t, 1] = bins[0, e, a + t]


@_jit(nogil=True)
def gather_rows(cube: Any, channels: Any, row_of: Any, az_pos: Any, r0: int,
                buf: Any) -> None:  # pragma: no cover - compiled
    """``buf[row_of[m], i, d, az_pos[m]] = cube[channels[m], d, r0 + i]`` for a range chunk.

    ``cube`` is ``(channels, doppler, range)``; ``buf`` ``(rows, n, doppler, width)`` keeps
    zeros where no element sits (written once, never touched here).
    """
    n, nd = buf.shape[1], buf.shape[2]
    for m in range(channels.size):
        src = cube[channels[m]]
        q, a = row_of[m], az_pos[m]
        for d in range(nd):
            for i in range(n):
                buf[q, i, d, a] = src[d, r0 + i]


gather_rows = _Announced(gather_rows)
peak_over_doppler = _Announced(peak_over_doppler)
peak_over_doppler_planar = _Announced(peak_over_doppler_planar)
