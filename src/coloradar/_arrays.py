"""Small array helpers shared across layers (no coloradar imports)."""

from __future__ import annotations

import numpy as np

__all__ = ["readonly"]


def readonly(a: np.ndarray) -> np.ndarray:
    """``a`` (made contiguous) marked read-only, so frozen objects cannot be mutated through
    their arrays."""
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a
