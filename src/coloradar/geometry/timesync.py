"""Putting streams on one timeline: nearest-neighbour association and time windows.

Every ColoRadar stream has its own clock samples and count (docs/conventions.md §1), so frames of two
sensors are paired by time. All functions here sort once and use :func:`numpy.searchsorted`:
O((N + M) log M), never an N x M distance table.
"""

from __future__ import annotations

import numpy as np

__all__ = ["associate", "nearest_indices", "window_indices"]


def _sorted(reference: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    ref = np.asarray(reference, dtype=np.float64).reshape(-1)
    if ref.size > 1 and np.any(np.diff(ref) < 0):
        order = np.argsort(ref, kind="stable")
        return ref[order], order
    return ref, None


def nearest_indices(query: np.ndarray, reference: np.ndarray,
                    tolerance: float | None = None) -> np.ndarray:
    """Index of the reference time nearest to each query time.

    Parameters
    ----------
    query
        float64 ``(N,)`` [s], any order.
    reference
        float64 ``(M,)`` [s], any order (sorted internally once when needed).
    tolerance
        Largest accepted ``|query - reference|`` [s]; None accepts any distance.

    Returns
    -------
    numpy.ndarray
        int64 ``(N,)``: index into ``reference``, or -1 where the nearest reference time is
        farther than ``tolerance`` (or ``reference`` is empty). Ties go to the earlier time.
        Several queries may share one reference (see :func:`associate` for one-to-one pairs).
    """
    q = np.asarray(query, dtype=np.float64).reshape(-1)
    ref, order = _sorted(reference)
    if ref.size == 0:
        return np.full(q.size, -1, dtype=np.int64)
    hi = np.clip(np.searchsorted(ref, q, side="left"), 1, max(ref.size - 1, 1))
    lo = hi - 1
    if ref.size == 1:
        idx = np.zeros(q.size, dtype=np.int64)
    else:
        idx = np.where(np.abs(q - ref[lo]) <= np.abs(ref[hi] - q), lo, hi).astype(np.int64)
    if tolerance is not None:
        idx[~(np.abs(ref[idx] - q) <= tolerance)] = -1
    if order is not None:
        idx = np.where(idx >= 0, order[np.maximum(idx, 0)], -1)
    return idx


def associate(a: np.ndarray, b: np.ndarray, tolerance: float,
              mutual: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Pair the frames of two streams by time.

    Parameters
    ----------
    a, b
        float64 timestamps ``(N,)`` and ``(M,)`` [s].
    tolerance
        Largest accepted time difference of a pair [s] (e.g. half the slower stream's period).
    mutual
        True (default): keep a pair only when each is the other's nearest, so every frame is
        used at most once. False: every ``a`` frame gets its nearest ``b`` frame within
        ``tolerance`` (a ``b`` frame may be used several times).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        int64 index arrays ``(K,)`` into ``a`` and ``b``, ascending in ``a``.
    """
    ia_all = np.arange(np.asarray(a).size, dtype=np.int64)
    ib = nearest_indices(a, b, tolerance)
    ok = ib >= 0
    if mutual:
        back = nearest_indices(b, a, tolerance)
        ok &= back[np.maximum(ib, 0)] == ia_all
    return ia_all[ok], ib[ok]


def window_indices(timestamps: np.ndarray, start: float | None = None,
                   end: float | None = None) -> np.ndarray:
    """Indices of the (ascending) ``timestamps`` with ``start <= t < end`` [s]; None = open."""
    t = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    lo = 0 if start is None else int(np.searchsorted(t, start, side="left"))
    hi = t.size if end is None else int(np.searchsorted(t, end, side="left"))
    return np.arange(lo, max(lo, hi), dtype=np.int64)
