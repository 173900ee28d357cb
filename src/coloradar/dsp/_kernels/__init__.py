"""Compiled kernels used when numba is installed (engine ``"numba"``, :mod:`coloradar.dsp.heatmap`).

Imported only when numba is installed (``pip install coloradar[accel]``). The functions live at
module level so that numba's on-disk cache finds them again in every new process instead of
compiling for seconds each time. One module per stage of the chain:

============  =======================================================================
cube          the range pass (coupling, DC removal, calibration, windows) and ``|·|²``
heatmap       angle spectra: elevation stage, power and maximum over Doppler
detection     CFAR stage (peak grouping, noise medians) and the alias choice's fits
beams         per-detection beams: steering, Newton, elevation search, focusing
resolve       several sources in one cell: joint amplitudes, keep tests, bounds
============  =======================================================================

Each kernel's contract — what it computes, stated once — is the numpy function it replaces
(:data:`coloradar.dsp.engines.CONTRACTS` names each pair; ``tests/test_dsp_engines.py`` runs
the table).

Where numba finds no writable cache folder (a service account, a read-only container: the
package folder read-only and ``NUMBA_CACHE_DIR`` unset or unwritable), numba refuses
``cache=True`` at import with ``RuntimeError: cannot cache function … no locator available``.
The kernels are then compiled without a cache (in every process) and one
:class:`RuntimeWarning` says so. When a kernel about to run is not in the cache yet, one line
on stderr (once per process) says that numba compiles them (a few seconds), instead of a
silent pause.
"""

from __future__ import annotations

from . import _jit
from .beams import (
    azimuth_peaks,
    beam_neighbourhood,
    elevation_search,
    focus_multiply,
    newton_refine,
    steer_columns,
)
from .cube import power, prepare_chirps
from .detection import group_peaks, median_bits, source_pairs
from .heatmap import LANES, gather_rows, peak_over_doppler, peak_over_doppler_planar
from .resolve import (
    joint_amplitudes,
    joint_powers,
    joint_residuals,
    joint_round,
    secondary_bound,
    secondary_bound_focused,
    secondary_residual,
)

CACHE_PROBLEM: str | None = _jit.CACHE_PROBLEM
"""Why the kernels are not cached on disk in this process (None: they are)."""

__all__ = ["CACHE_PROBLEM", "LANES", "azimuth_peaks", "beam_neighbourhood", "elevation_search",
           "focus_multiply", "gather_rows", "group_peaks", "joint_amplitudes", "joint_powers",
           "joint_residuals", "joint_round", "median_bits", "newton_refine", "peak_over_doppler",
           "peak_over_doppler_planar", "power", "prepare_chirps", "secondary_bound",
           "secondary_bound_focused", "secondary_residual", "source_pairs", "steer_columns"]

_jit._warn_no_cache()
