"""Small helpers shared by the detection stages: the peaks' grouping by cell, the arrays the
compiled kernels are built for, and the kernels themselves where the engine is numba."""

from __future__ import annotations

from types import ModuleType
from typing import Any

import numpy as np

__all__ = ["c64", "compiled_kernels", "f64", "firsts", "groups"]


def compiled_kernels(engine: str) -> ModuleType | None:
    """:mod:`coloradar.dsp._kernels` with the numba engine, None with numpy."""
    if engine != "numba":
        return None
    from .. import _kernels
    return _kernels


def groups(ci: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(ci, return_inverse=True, return_counts=True)[1:]`` without the sort where
    ``ci`` is already non-decreasing (the peaks' cells always are: :func:`~coloradar.dsp.
    angle.azimuth_peaks` returns them by cell, and only masks follow)."""
    ci = np.asarray(ci)
    if ci.size == 0 or np.any(ci[1:] < ci[:-1]):
        _, inv, cnt = np.unique(ci, return_inverse=True, return_counts=True)
        return inv.reshape(-1), cnt
    new = firsts(ci)
    cell_of = np.cumsum(new) - 1
    return cell_of, np.diff(np.append(np.flatnonzero(new), ci.size))


def firsts(ci: np.ndarray, end: bool = False) -> np.ndarray:
    """bool ``(N,)`` (``end``: ``(N + 1,)``, True last): True where ``ci`` starts a run of
    equal values (``np.r_[True, ci[1:] != ci[:-1]]``, without ``np.r_``'s parsing cost,
    which counts at a few dozen peaks per frame)."""
    ci = np.asarray(ci)
    n = max(ci.size, 1)                                 # (as np.r_: [True] when empty)
    out = np.empty(n + int(end), dtype=bool)
    out[0] = True
    np.not_equal(ci[1:], ci[:-1], out=out[1:n])
    if end:
        out[-1] = True
    return out


def f64(a: Any) -> np.ndarray:
    """Contiguous float64 (the dtype and layout the compiled kernels are built for)."""
    return np.ascontiguousarray(a, dtype=np.float64)


def c64(a: Any) -> np.ndarray:
    """Contiguous complex64 (the dtype and layout the compiled kernels are built for)."""
    return np.ascontiguousarray(a, dtype=np.complex64)
