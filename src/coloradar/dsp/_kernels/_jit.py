"""How the compiled kernels are built: numba's on-disk cache where it has a folder, a
warning where it has none, and a notice on the first compile (:mod:`coloradar.dsp._kernels`)."""

from __future__ import annotations

import sys
import warnings
from collections.abc import Callable
from typing import Any

import numba

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

