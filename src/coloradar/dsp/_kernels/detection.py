"""Compiled kernels of the CFAR and alias stages (:mod:`coloradar.dsp.detection.cfar_stage`,
:mod:`~coloradar.dsp.detection.alias`): peak grouping, the channels' noise medians, and the
two-source fits of the alias choice."""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from ._jit import _Announced, _jit

__all__ = ['group_peaks', 'median_bits', 'source_pairs']


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
    ``strong`` times its noise. (:func:`coloradar.dsp.detection.cfar_stage.group_peaks` in one pass.)"""
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


group_peaks = _Announced(group_peaks)
median_bits = _Announced(median_bits)
source_pairs = _Announced(source_pairs)
