"""Taper windows for the range and Doppler FFTs.

Windows are *periodic* (DFT-even): ``hann[n] = 0.5 − 0.5·cos(2πn/N)``. A periodic cosine-sum
window is an exact short kernel in the DFT domain (3 taps for Hann, 5 for Blackman), which is
what makes the coupling subtraction of :mod:`coloradar.dsp.cube` exact for any window.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np
from scipy.signal import get_window

from ..errors import SettingsError

__all__ = ["WINDOWS", "WindowName", "coherent_window", "window"]

WindowName = Literal["hann", "blackman", "none"]
"""Names accepted wherever a window is a setting."""
WINDOWS: tuple[WindowName, ...] = get_args(WindowName)


def window(name: WindowName, n: int) -> np.ndarray:
    """The periodic window ``name`` of length ``n``.

    Parameters
    ----------
    name
        ``"hann"``, ``"blackman"`` or ``"none"`` (rectangular).
    n
        Length in samples.

    Returns
    -------
    numpy.ndarray
        float64 ``(n,)``.
    """
    if name not in WINDOWS:
        raise SettingsError(f"unknown window {name!r}; expected one of {', '.join(WINDOWS)}")
    if name == "none":
        return np.ones(n)
    return get_window(name, n, fftbins=True).astype(np.float64)


def coherent_window(name: WindowName, n: int) -> np.ndarray:
    """``window(name, n)`` scaled to unit coherent gain (its samples sum to 1).

    An FFT of a windowed tone of amplitude ``a`` at a bin centre then peaks at exactly ``a``,
    whatever the window and the length.
    """
    w = window(name, n)
    return w / w.sum()
