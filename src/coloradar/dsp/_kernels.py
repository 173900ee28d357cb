"""Compiled kernels used when numba is installed (engine ``"numba"``, :mod:`coloradar.dsp.heatmap`).

Imported only when numba is installed (``pip install coloradar[accel]``). The functions live at
module level so that numba's on-disk cache finds them again in every new process instead of
compiling for seconds each time.

Where numba finds no writable cache folder (a service account, a read-only container: the
package folder read-only and ``NUMBA_CACHE_DIR`` unset or unwritable), numba refuses
``cache=True`` at import with ``RuntimeError: cannot cache function … no locator available``.
The kernels are then compiled without a cache (in every process) and one
:class:`RuntimeWarning` says so. Whenever a kernel is not in the cache yet, one line on stderr
says that the first frame compiles them (a few seconds), instead of a silent pause.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Callable
from typing import Any

import numba
import numpy as np

__all__ = ["CACHE_PROBLEM", "gather_rows", "peak_over_doppler", "prepare_chirps"]

CACHE_PROBLEM: str | None = None
"""Why the kernels are not cached on disk in this process (None: they are)."""

_CACHED: list[Any] = []          # the dispatchers compiled with cache=True


def _jit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit(cache=True, **options)``, or without the cache where numba has no folder
    to write it to (then :data:`CACHE_PROBLEM` says why)."""
    def wrap(fn: Callable[..., Any]) -> Any:
        global CACHE_PROBLEM
        if CACHE_PROBLEM is None:
            try:
                disp = numba.njit(cache=True, **options)(fn)
            except RuntimeError as exc:          # "cannot cache function …: no locator available"
                if "cannot cache" not in str(exc):
                    raise
                CACHE_PROBLEM = str(exc)
            else:
                _CACHED.append(disp)
                return disp
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


def _announce() -> None:
    """One warning when there is no cache; one stderr line when the first frame will compile."""
    if CACHE_PROBLEM is not None:
        warnings.warn("coloradar: numba finds no writable folder for its cache (set "
                      "NUMBA_CACHE_DIR to a writable folder to keep the compiled kernels); the "
                      "DSP kernels are compiled again in every process (a few seconds on the "
                      f"first frame). numba said: {CACHE_PROBLEM}", RuntimeWarning, stacklevel=2)
        return
    if not all(_is_cached(d) for d in _CACHED):
        print("coloradar: compiling the numba DSP kernels on the first frame (a few seconds, "
              "once: they are cached on disk)", file=sys.stderr, flush=True)


@_jit(fastmath={"contract", "nnan"}, nogil=True)
def _update(best: Any, arg: Any, d: Any, vr: Any, vi: Any) -> None:  # pragma: no cover
    for a in range(best.size):
        p = vr[a] * vr[a] + vi[a] * vi[a]
        b = best[a]
        arg[a] = d if p > b else arg[a]              # first maximum wins, as argmax
        best[a] = max(b, p)

# "nnan" (inputs are finite: ADC counts) lets LLVM turn the running maximum into vector
# max/blend instructions; without it the comparisons stay scalar and cost half the kernel.
@_jit(fastmath={"contract", "nnan"}, nogil=True)
def peak_over_doppler(spec: Any, steer: Any, n_even: int, el_plus: Any, el_minus: Any,
                      az_read: Any, velocities: Any, scale: float, out: Any,
                      r0: int) -> None:  # pragma: no cover - compiled
    # Azimuth is the innermost loop (contiguous, vectorised); the elevation DFT over the
    # occupied rows, the power and the running Doppler maximum stay in registers.
    # Paired (n_even >= 0): steering row p gives elevation bin el_plus[p] as E + O and
    # el_minus[p] (FFT index + n/2) as E − O, E/O the sums over even/odd rows (rows
    # sorted even first). Unpaired (n_even < 0): row p gives bin el_plus[p] only.
    # The + and − maxima live in separate arrays: LLVM vectorises the loop only when it
    # can tell the stores apart.
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
    sr = np.empty((n_st, rows), np.float32)
    si = np.empty((n_st, rows), np.float32)
    for e in range(n_st):
        for q in range(rows):
            sr[e, q] = steer[e, q].real
            si[e, q] = steer[e, q].imag
    peak_p[:] = -1.0
    peak_m[:] = -1.0
    bins_p[:] = 0
    bins_m[:] = 0
    for r in range(n):
        for d in range(nd):
            for q in range(rows):               # de-interleave once, use n_st times
                s, xrq, xiq = spec[q, r, d], xr[q], xi[q]
                for a in range(naz):
                    xrq[a] = s[a].real
                    xiq[a] = s[a].imag
            dd = np.int32(d)
            x0r, x0i = xr[0], xi[0]
            if rows == 4 and n_even == 3:       # the cascade (rows 0, 4, 6 | 1)
                x1r, x1i, x2r, x2i, x3r, x3i = xr[1], xi[1], xr[2], xi[2], xr[3], xi[3]
                for e in range(n_st):
                    c0r, c0i, c1r, c1i = sr[e, 0], si[e, 0], sr[e, 1], si[e, 1]
                    c2r, c2i, c3r, c3i = sr[e, 2], si[e, 2], sr[e, 3], si[e, 3]
                    for a in range(naz):
                        vr = (c0r * x0r[a] - c0i * x0i[a] + c1r * x1r[a] - c1i * x1i[a]
                              + c2r * x2r[a] - c2i * x2i[a])
                        vi = (c0r * x0i[a] + c0i * x0r[a] + c1r * x1i[a] + c1i * x1r[a]
                              + c2r * x2i[a] + c2i * x2r[a])
                        wr = c3r * x3r[a] - c3i * x3i[a]
                        wi = c3r * x3i[a] + c3i * x3r[a]
                        p = (vr + wr) * (vr + wr) + (vi + wi) * (vi + wi)
                        b = peak_p[r, e, a]
                        bins_p[r, e, a] = dd if p > b else bins_p[r, e, a]  # first max wins (argmax)
                        peak_p[r, e, a] = max(b, p)
                        p = (vr - wr) * (vr - wr) + (vi - wi) * (vi - wi)
                        b = peak_m[r, e, a]
                        bins_m[r, e, a] = dd if p > b else bins_m[r, e, a]
                        peak_m[r, e, a] = max(b, p)
            elif rows == 2 and n_even == 1:     # the single chip (row 0 | 1)
                x1r, x1i = xr[1], xi[1]
                for e in range(n_st):
                    c0r, c0i, c1r, c1i = sr[e, 0], si[e, 0], sr[e, 1], si[e, 1]
                    for a in range(naz):
                        vr = c0r * x0r[a] - c0i * x0i[a]
                        vi = c0r * x0i[a] + c0i * x0r[a]
                        wr = c1r * x1r[a] - c1i * x1i[a]
                        wi = c1r * x1i[a] + c1i * x1r[a]
                        p = (vr + wr) * (vr + wr) + (vi + wi) * (vi + wi)
                        b = peak_p[r, e, a]
                        bins_p[r, e, a] = dd if p > b else bins_p[r, e, a]
                        peak_p[r, e, a] = max(b, p)
                        p = (vr - wr) * (vr - wr) + (vi - wi) * (vi - wi)
                        b = peak_m[r, e, a]
                        bins_m[r, e, a] = dd if p > b else bins_m[r, e, a]
                        peak_m[r, e, a] = max(b, p)
            else:                               # any other layout
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
def prepare_chirps(adc: Any, coupling: Any, gain: Any, chirp_weight: Any, dc_removal: bool,
                   out: Any) -> None:  # pragma: no cover - compiled
    """``out[t, r, c, :ns] = (adc − coupling − mean_n(adc − coupling)) · gain[t, r] · w[c]``.

    All complex arrays are passed as float32 views (re, im interleaved along the last axis),
    which lets LLVM vectorise the loops. One pass over the ADC frame replaces four numpy
    passes; samples beyond ``ns`` (zero padding) are left untouched.
    ``coupling`` is ``(tx, rx, 2·ns)`` or empty (no coupling); ``gain`` ``(tx, rx, 2·ns)``
    (calibration × range window); ``chirp_weight`` ``(chirps,)`` (Doppler window × (−1)^c).
    """
    ntx, nrx, nc, ns2 = adc.shape
    ns = ns2 // 2
    has_c = coupling.size > 0
    for t in range(ntx):
        for r in range(nrx):
            g = gain[t, r]
            cp = coupling[t, r] if has_c else g
            for c in range(nc):
                x = adc[t, r, c]
                y = out[t, r, c]
                if has_c:
                    for k in range(ns2):
                        y[k] = x[k] - cp[k]
                else:
                    for k in range(ns2):
                        y[k] = x[k]
                mr = np.float32(0.0)
                mi = np.float32(0.0)
                if dc_removal:
                    sr = 0.0
                    si = 0.0
                    for n in range(ns):
                        sr += y[2 * n]
                        si += y[2 * n + 1]
                    mr = np.float32(sr / ns)
                    mi = np.float32(si / ns)
                w = chirp_weight[c]
                for n in range(ns):
                    vr = y[2 * n] - mr
                    vi = y[2 * n + 1] - mi
                    gr = g[2 * n] * w
                    gi = g[2 * n + 1] * w
                    y[2 * n] = vr * gr - vi * gi
                    y[2 * n + 1] = vr * gi + vi * gr


_announce()
