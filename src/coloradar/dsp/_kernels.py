"""Compiled kernels used when numba is installed (engine ``"numba"``, :mod:`coloradar.dsp.heatmap`).

Imported only when numba is installed (``pip install coloradar[accel]``). The functions live at
module level so that numba's on-disk cache finds them again in every new process instead of
compiling for seconds each time.

Where numba finds no writable cache folder (a service account, a read-only container: the
package folder read-only and ``NUMBA_CACHE_DIR`` unset or unwritable), numba refuses
``cache=True`` at import with ``RuntimeError: cannot cache function … no locator available``.
The kernels are then compiled without a cache (in every process) and one
:class:`RuntimeWarning` says so. When a kernel about to run is not in the cache yet, one line
on stderr (once per process) says that numba compiles them (a few seconds), instead of a
silent pause.
"""

from __future__ import annotations

import math
import sys
import warnings
from collections.abc import Callable
from typing import Any

import numba
import numpy as np

__all__ = ["CACHE_PROBLEM", "LANES", "azimuth_peaks", "beam_neighbourhood", "elevation_search",
           "focus_multiply", "gather_rows", "group_peaks", "joint_amplitudes", "joint_powers",
           "joint_residuals", "joint_round", "median_bits", "newton_refine", "peak_over_doppler",
           "peak_over_doppler_planar", "power", "prepare_chirps", "secondary_bound",
           "secondary_bound_focused", "secondary_residual", "source_pairs", "steer_columns"]

CACHE_PROBLEM: str | None = None
"""Why the kernels are not cached on disk in this process (None: they are)."""


def _jit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit(cache=True, **options)``, or without the cache where numba has no folder
    to write it to (then :data:`CACHE_PROBLEM` says why)."""
    def wrap(fn: Callable[..., Any]) -> Any:
        global CACHE_PROBLEM
        if CACHE_PROBLEM is None:
            try:
                return numba.njit(cache=True, **options)(fn)
            except RuntimeError as exc:          # "cannot cache function …: no locator available"
                if "cannot cache" not in str(exc):
                    raise
                CACHE_PROBLEM = str(exc)
        return numba.njit(**options)(fn)
    return wrap


def _is_cached(disp: Any) -> bool:
    """Whether ``disp`` has an overload for this machine in its on-disk cache (numba's cache
    index, read through its internals: any failure counts as "not cached")."""
    try:
        magic = disp.targetctx.codegen().magic_tuple()
        index = disp._cache._cache_file._load_index()
        return any(key[1] == magic for key in index)
    except Exception:                                # numba internals differ: assume a compile
        return False


def _warn_no_cache() -> None:
    """One warning per process when numba has nowhere to keep the compiled kernels."""
    if CACHE_PROBLEM is not None:
        warnings.warn("coloradar: numba finds no writable folder for its cache (set "
                      "NUMBA_CACHE_DIR to a writable folder to keep the compiled kernels); the "
                      "DSP kernels are compiled again in every process (a few seconds on the "
                      f"first frame). numba said: {CACHE_PROBLEM}", RuntimeWarning, stacklevel=2)


_ANNOUNCED = False


class _Announced:
    """A kernel that says, once per process, that numba is about to compile it (the first
    frame then takes seconds) when its machine code is not in the on-disk cache."""

    def __init__(self, kernel: Any) -> None:
        self.kernel = kernel
        self.checked = False

    def __call__(self, *args: Any) -> Any:
        global _ANNOUNCED
        if not self.checked:
            self.checked = True
            if not _ANNOUNCED and CACHE_PROBLEM is None and not _is_cached(self.kernel):
                _ANNOUNCED = True
                print("coloradar: compiling the numba DSP kernels (a few seconds, once: they "
                      "are cached on disk)", file=sys.stderr, flush=True)
        return self.kernel(*args)


_FM = {"contract", "nnan"}


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
                # one call site per inlined helper (each site is a copy of its loops for
                # LLVM to optimise: two sites of each made this kernel's first compile
                # take twice as long)
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
                    # a fixed trip count and the (peak, rate) pairs as one float32 axis:
                    # LLVM writes them with vector interleaves (half the time of this loop
                    # with n lanes, measured)
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


@_jit(nogil=True, fastmath={"contract"})
def prepare_chirps(adc: Any, channels: Any, coupling: Any, gain: Any, chirp_weight: Any,
                   dc_removal: bool, out: Any) -> None:  # pragma: no cover - compiled
    """``out[k, c, :ns] = (adc − coupling − mean_n(adc − coupling)) · gain · w[c]`` of channel
    ``channels[k]``.

    All complex arrays are passed as float32 views (re, im interleaved along the last axis),
    which lets LLVM vectorise the loops. Two passes over each chirp (its mean, then the
    result) replace four numpy passes over the frame; samples beyond ``ns`` (zero padding)
    are left untouched. ``adc`` is
    ``(tx, rx, chirp, 2·ns)``; ``channels`` int ``(K,)`` the flat ``tx·num_rx + rx``
    indices to prepare (all, or only those a heatmap reads); ``out`` ``(K, chirp, 2·nfft)``.
    ``coupling`` is ``(tx, rx, 2·ns)`` or empty (no coupling); ``gain`` ``(tx, rx, 2·ns)``
    (calibration × range window); ``chirp_weight`` ``(chirps,)`` (Doppler window × (−1)^c).
    """
    nrx, nc, ns2 = adc.shape[1], adc.shape[2], adc.shape[3]
    ns = ns2 // 2
    has_c = coupling.size > 0
    for k in range(channels.size):
        t, r = channels[k] // nrx, channels[k] % nrx
        # the coupling's own mean over samples, once per channel: mean(x − c) = mean(x) − mean(c)
        cmr = 0.0
        cmi = 0.0
        if has_c and dc_removal:
            for n in range(ns):
                cmr += coupling[t, r, 2 * n]
                cmi += coupling[t, r, 2 * n + 1]
        for c in range(nc):
            # two passes over the chirp: its mean, then (x − c − mean)·gain·w straight into out
            mr = np.float32(0.0)
            mi = np.float32(0.0)
            if dc_removal:
                # four partial sums per part: one running float64 sum is a chain of
                # dependent adds (latency-bound, most of this kernel's time); four chains
                # overlap. float64 throughout, so the float32 mean is the same but for
                # the rare sum that lies on a float32 rounding boundary.
                s0r = s1r = s2r = s3r = 0.0
                s0i = s1i = s2i = s3i = 0.0
                n4 = ns - ns % 4
                for n in range(0, 2 * n4, 8):
                    s0r += adc[t, r, c, n]
                    s0i += adc[t, r, c, n + 1]
                    s1r += adc[t, r, c, n + 2]
                    s1i += adc[t, r, c, n + 3]
                    s2r += adc[t, r, c, n + 4]
                    s2i += adc[t, r, c, n + 5]
                    s3r += adc[t, r, c, n + 6]
                    s3i += adc[t, r, c, n + 7]
                for n in range(n4, ns):
                    s0r += adc[t, r, c, 2 * n]
                    s0i += adc[t, r, c, 2 * n + 1]
                sr = (s0r + s1r) + (s2r + s3r)
                si = (s0i + s1i) + (s2i + s3i)
                mr = np.float32((sr - cmr) / ns)
                mi = np.float32((si - cmi) / ns)
            w = chirp_weight[c]
            if has_c:
                for n in range(ns):
                    vr = adc[t, r, c, 2 * n] - coupling[t, r, 2 * n] - mr
                    vi = adc[t, r, c, 2 * n + 1] - coupling[t, r, 2 * n + 1] - mi
                    gr = gain[t, r, 2 * n] * w
                    gi = gain[t, r, 2 * n + 1] * w
                    out[k, c, 2 * n] = vr * gr - vi * gi
                    out[k, c, 2 * n + 1] = vr * gi + vi * gr
            else:
                for n in range(ns):
                    vr = adc[t, r, c, 2 * n] - mr
                    vi = adc[t, r, c, 2 * n + 1] - mi
                    gr = gain[t, r, 2 * n] * w
                    gi = gain[t, r, 2 * n + 1] * w
                    out[k, c, 2 * n] = vr * gr - vi * gi
                    out[k, c, 2 * n + 1] = vr * gi + vi * gr


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


@_jit(nogil=True)
def group_peaks(stat: Any, mask: Any, noise: Any, nxt: Any, strong: float,
                out: Any) -> None:  # pragma: no cover - compiled
    """The detection mask after peak grouping, ``out`` bool ``(doppler, range)``.

    ``stat`` float64 ``(doppler, range)`` the detection statistic, ``mask`` its CFAR
    detections, ``noise`` the CFAR noise (+inf where untested), ``nxt`` float64
    ``(doppler,)`` the statistic of the range bin after the last (empty: not computed).
    A cell is a *peak* when it passes the CFAR and is a maximum of its 3 × 3 neighbourhood
    (Doppler wrapped; along range, the bin after the last compared where ``nxt`` is given,
    else the edge is no bar; the diagonals with range mirrored at the edges); cells that
    pass the CFAR and peak along one axis only are kept within one cell of a peak at least
    ``strong`` times its noise. (:func:`coloradar.dsp.processor._group_peaks` in one pass.)"""
    nd, nr = stat.shape
    has_nxt = nxt.size > 0
    along = np.zeros((nd, nr), np.uint8)         # bit 0: along Doppler, bit 1: along range
    out[:] = False
    beside = np.zeros((nd, nr), np.bool_)
    for i in range(nd):
        im, ip = (i - 1) % nd, (i + 1) % nd
        for j in range(nr):
            v = stat[i, j]
            ad = v >= stat[im, j] and v >= stat[ip, j]
            if j < nr - 1:
                ar = v >= stat[i, j + 1]
            else:
                ar = v >= nxt[i] if has_nxt else True
            if j > 0:
                ar = ar and v >= stat[i, j - 1]
            along[i, j] = np.uint8(ad) | (np.uint8(ar) << 1)
            if not (mask[i, j] and ad and ar):
                continue
            if nr > 1:
                lo = j - 1 if j > 0 else 1
                hi = j + 1 if j < nr - 1 else nr - 2
                if not (v >= stat[im, lo] and v >= stat[im, hi] and v >= stat[ip, lo]
                        and v >= stat[ip, hi]):
                    continue
            out[i, j] = True
            if v >= strong * noise[i, j]:
                for o in (im, i, ip):
                    for q in range(max(j - 1, 0), min(j + 2, nr)):
                        beside[o, q] = True
    for i in range(nd):
        for j in range(nr):
            if not out[i, j] and mask[i, j] and along[i, j] != 0 and beside[i, j]:
                out[i, j] = True


@_jit(nogil=True)
def median_bits(power: Any, cells: Any, k: int, out: Any) -> bool:  # pragma: no cover
    """The ``k``-th smallest (0-based) of ``power[c, cells]`` for every row ``c``, as the
    int32 bit pattern of the float32 value (``out`` int32 ``(C,)``); ``power`` float32
    ``(C, N)``, ``cells`` int ``(K,)``. Non-negative float32 values order as their bit
    patterns: a 1024-bucket histogram of the top bits finds the bucket holding the ``k``-th
    value, and only that bucket's few values are sorted (two passes over the cells instead
    of numpy's gather and introselect). Returns False, leaving ``out`` unfinished, where a
    value is negative or NaN (whose bits do not order as the values)."""
    bits = power.view(np.int32)
    n = cells.size
    hist = np.zeros(1024, np.int64)
    buf = np.empty(n, np.int32)
    for r in range(power.shape[0]):
        hist[:] = 0
        for i in range(n):
            v = bits[r, cells[i]]
            if v < 0 or v > 0x7F800000:
                return False
            hist[v >> 21] += 1
        below = 0
        b = 0
        while below + hist[b] <= k:
            below += hist[b]
            b += 1
        m = 0
        for i in range(n):
            v = bits[r, cells[i]]
            if (v >> 21) == b:
                buf[m] = v
                m += 1
        out[r] = _select(buf, m, k - below)
    return True


@numba.njit(cache=False)
def _select(buf: Any, m: int, k: int) -> Any:  # pragma: no cover - compiled
    # the k-th smallest of buf[:m] (Hoare's selection, reordering buf; no compiled sort
    # to build, a second of numba's time on the first frame)
    lo, hi = 0, m - 1
    while lo < hi:
        a, b, c = buf[lo], buf[(lo + hi) >> 1], buf[hi]
        piv = max(min(a, b), min(max(a, b), c))          # median of three
        i, j = lo, hi
        while i <= j:
            while buf[i] < piv:
                i += 1
            while buf[j] > piv:
                j -= 1
            if i <= j:
                buf[i], buf[j] = buf[j], buf[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return buf[k]


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
    (:meth:`coloradar.dsp.processor.RadarProcessor._resolve_peaks`): each cell's joint
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


@numba.njit(inline="always")
def _pair_explained(b: Any, n: int, p: int, q: int, cross: Any, m: int) -> float:  # pragma: no cover
    """Power of vector ``n`` explained by the joint least-squares fit of sources ``p, q``:
    ``bᴴG⁻¹b`` with ``G = [[M, c], [c*, M]]``, ``c = a_pᴴa_q`` (−inf where G is singular)."""
    bp, bq, c = b[n, p], b[n, q], cross[q, p]
    det = m * m - (c.real * c.real + c.imag * c.imag)
    if not det > 1e-6 * m * m:
        return -np.inf
    num = (m * (bp.real * bp.real + bp.imag * bp.imag + bq.real * bq.real + bq.imag * bq.imag)
           - 2.0 * (c * bp.conjugate() * bq).real)
    return num / max(det, 1e-9 * m * m)


@numba.njit(inline="always")
def _pair_partner(b: Any, n: int, keep: int, cross: Any, gain: Any, m: int) -> int:  # pragma: no cover
    """The direction adding most beside source ``keep``: argmax over ``g`` of
    ``|b_g − (a_gᴴa_keep)·b_keep/M|² / a_gᴴP⊥a_g`` (first maximum, as numpy's argmax)."""
    coef = b[n, keep] / m
    best, arg = -np.inf, 0
    for g in range(b.shape[1]):
        v = b[n, g] - cross[keep, g] * coef
        e = (v.real * v.real + v.imag * v.imag) / gain[keep, g]
        if e > best:
            best, arg = e, g
    return arg


@_jit(nogil=True)
def source_pairs(b: Any, i1: Any, total: Any, rss1: Any, cross: Any, gain: Any, m: int,
                 iterations: int, out: Any) -> None:  # pragma: no cover - compiled
    """Two-source residuals of line-array vectors from their beams: alternating projection
    from the beam peak ``i1`` and a joint polish of one grid step (the steps of
    :func:`coloradar.dsp.detect.source_fit_residuals`, whose numpy twin they mirror).
    ``b`` complex128 ``(N, G)`` beams ``aᴴx``; ``i1`` int64 ``(N,)``; ``total``, ``rss1``
    float64 ``(N,)``; ``cross`` complex128 ``(G, G)`` = ``a_gᴴa_i`` at ``[i, g]``; ``gain``
    float64 ``(G, G)``. Writes float64 ``out`` ``(N,)``: ``min(RSS₂, RSS₁)``."""
    g_n = b.shape[1]
    for n in range(b.shape[0]):
        p = i1[n]
        q = _pair_partner(b, n, p, cross, gain, m)
        for _ in range(iterations):
            p = _pair_partner(b, n, q, cross, gain, m)
            q = _pair_partner(b, n, p, cross, gain, m)
        best = _pair_explained(b, n, p, q, cross, m)
        for _ in range(2):
            for d1 in range(-1, 2):
                for d2 in range(-1, 2):
                    pp = min(max(p + d1, 0), g_n - 1)
                    qq = min(max(q + d2, 0), g_n - 1)
                    e = _pair_explained(b, n, pp, qq, cross, m)
                    if e > best:
                        p, q, best = pp, qq, e
        r = rss1[n]
        if np.isfinite(best):
            r = min(max(total[n] - best, 0.0), r)
        out[n] = r


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


@_jit(nogil=True, fastmath=_FM)
def power(values: Any, out: Any) -> None:  # pragma: no cover - compiled
    """``out[i] = re² + im²`` of complex values given as interleaved float32 ``(2N,)``;
    ``out`` float32 ``(N,)`` (``|·|²`` without numpy's ``hypot`` and a second pass)."""
    for i in range(out.size):
        a = values[2 * i]
        b = values[2 * i + 1]
        out[i] = a * a + b * b

_warn_no_cache()
gather_rows = _Announced(gather_rows)
peak_over_doppler = _Announced(peak_over_doppler)
peak_over_doppler_planar = _Announced(peak_over_doppler_planar)
prepare_chirps = _Announced(prepare_chirps)
power = _Announced(power)
beam_neighbourhood = _Announced(beam_neighbourhood)
focus_multiply = _Announced(focus_multiply)
elevation_search = _Announced(elevation_search)
joint_amplitudes = _Announced(joint_amplitudes)
joint_round = _Announced(joint_round)
joint_residuals = _Announced(joint_residuals)
joint_powers = _Announced(joint_powers)
group_peaks = _Announced(group_peaks)
median_bits = _Announced(median_bits)
azimuth_peaks = _Announced(azimuth_peaks)
newton_refine = _Announced(newton_refine)
secondary_bound = _Announced(secondary_bound)
secondary_bound_focused = _Announced(secondary_bound_focused)
secondary_residual = _Announced(secondary_residual)
source_pairs = _Announced(source_pairs)
steer_columns = _Announced(steer_columns)
