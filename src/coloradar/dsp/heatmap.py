"""Stage 7: the dataset-format heatmap, peak over Doppler of the 2D angle spectrum.

``heatmap[el, az, r, 0]`` is ``max_d |A_d(el, az, r)|² / M²`` and ``heatmap[el, az, r, 1]`` the
range rate of the maximising Doppler bin, where ``A_d(el, az, r) = Σ_m a_m(el, az)* z_m(d, r)``
is the Bartlett beam of range–Doppler cell ``(d, r)`` (see :mod:`coloradar.dsp.array`).

That needs the beam of every cell in every direction (cascade: 2048 cells × 4096 bins = 8.4 M
complex values per frame), most of it over elevation rows the aperture does not occupy (the
cascade's 134 elements sit on 4 of 32 rows, the single chip's 12 on 2 of 16). Per chunk of
range bins (sized to stay in cache) the work is

1. the azimuth FFT of the occupied elevation rows only (zero padded to the azimuth grid);
2. the elevation transform as a dense DFT over those rows — a ``(num_el, rows)`` steering
   matrix times the ``(rows, doppler·azimuth)`` azimuth spectra;
3. the power and the maximum over Doppler with its bin.

The steps run in one of two engines (``engine=``):

``"numba"`` (used when :mod:`numba` is installed: ``pip install coloradar[accel]``)
    one compiled pass per block of 16 range bins (:data:`~coloradar.dsp._kernels.LANES`),
    the range bins as the SIMD lanes: per Doppler bin it gathers the elements (times
    ``doppler_phase`` when given) into planar real/imaginary buffers, does step 1 with
    its own Stockham radix-2 FFT (every butterfly one vector operation on 16 range bins, no
    zero-padded copies or FFT calls) and steps 2–3 over the flattened (azimuth, range)
    axis, computing each beam value, its power and the running Doppler maximum in
    registers; the 8.4 M beam values are never written to memory, and the maximum carries
    the range rate itself. Azimuth grids that are not a power of two take scipy's FFT per
    chunk and a kernel for steps 2–3.
``"numpy"``
    scipy FFTs along azimuth and elevation of the rows the aperture spans (7 of 32 for the
    cascade), ``|·|`` with the Doppler bin packed into the low mantissa bits (4 for 16 bins,
    7 for 128) so that one integer ``max`` over Doppler yields peak and bin (an ``argmax``
    over a non-contiguous axis costs more than every FFT together). Clearing the bits
    truncates the peak magnitude by less than ``2^-(23−b)`` relatively; bins that close tie
    and the higher one wins. (A dense BLAS elevation DFT would be faster on one thread, but
    OpenBLAS starts its threads for these thin products, which on a shared machine made it
    many times slower, and numpy offers no way to stop it.)

Both give the definition to float32 rounding; ``tests/test_dsp_heatmap.py`` checks them against
explicit steering vectors for both radars and both signs.
"""

from __future__ import annotations

import warnings
import weakref
from collections.abc import Callable

import numpy as np
import scipy.fft as sfft

from ..errors import SettingsError
from .array import AngleGrid

__all__ = ["CHUNK_SIZE", "ENGINES", "available_engines", "heatmap_from_elements", "resolve_engine"]

CHUNK_SIZE = 1 << 17
"""Azimuth-spectrum values per chunk by default (1 MiB of complex64: stays in a core's L2)."""

ENGINES = ("auto", "numba", "numpy")
"""Accepted ``engine`` values; ``"auto"`` = ``"numba"`` when importable, else ``"numpy"``."""

_KERNEL: Callable[..., None] | None = None
_KERNEL_ERROR: str | None = None


def _numba_kernel() -> Callable[..., None] | None:
    """The compiled peak-over-Doppler kernel, or None when numba is not installed."""
    global _KERNEL, _KERNEL_ERROR
    if _KERNEL is not None or _KERNEL_ERROR is not None:
        return _KERNEL
    try:
        from ._kernels import peak_over_doppler
    except ImportError as exc:                      # numba is an optional extra
        _KERNEL_ERROR = str(exc)
        return None
    except Exception as exc:                        # a broken numba install: never crash
        _KERNEL_ERROR = f"{type(exc).__name__}: {exc}"
        warnings.warn(f"coloradar: numba is installed but its kernels failed to load "
                      f"({_KERNEL_ERROR}); using the numpy heatmap engine", RuntimeWarning,
                      stacklevel=2)
        return None
    _KERNEL = peak_over_doppler
    return _KERNEL


def available_engines() -> tuple[str, ...]:
    """Engines usable here (``"numpy"`` always; ``"numba"`` when numba imports)."""
    return ("numba", "numpy") if _numba_kernel() is not None else ("numpy",)


def resolve_engine(engine: str) -> str:
    """``"numba"`` or ``"numpy"`` for an ``engine`` setting (``"auto"``: numba if installed).

    Raises
    ------
    SettingsError
        Unknown name.
    ImportError
        ``"numba"`` asked for but numba is not installed.
    """
    if engine not in ENGINES:
        raise SettingsError(f"unknown engine {engine!r}; expected one of {', '.join(ENGINES)}")
    if engine == "auto":
        return "numba" if _numba_kernel() is not None else "numpy"
    if engine == "numba" and _numba_kernel() is None:
        raise ImportError(f"heatmap engine 'numba' needs numba ({_KERNEL_ERROR}); "
                          "pip install coloradar[accel], or use engine='numpy'")
    return engine


def elevation_steering(grid: AngleGrid) -> tuple[np.ndarray, np.ndarray]:
    """Occupied elevation rows and the DFT that takes them to the output elevation bins.

    Returns
    -------
    rows
        int64 ``(R,)``: the elevation positions (half wavelengths) holding elements.
    steer
        complex64 ``(num_el, R)``: ``exp(−j2π·k_i·q/n_el)`` with ``k_i = el_read[i]`` — the
        elevation FFT of :func:`~coloradar.dsp.array.beamform` evaluated on the occupied rows
        only (output bins ascending, sign setting included).
    """
    rows = np.unique(grid.el_pos)
    k = grid.el_read.astype(np.float64)
    steer = np.exp(-2j * np.pi * np.outer(k, rows) / grid.n_el)
    return rows, steer.astype(np.complex64)


def _paired_steering(grid: AngleGrid) -> tuple[np.ndarray, np.ndarray, int, np.ndarray,
                                               np.ndarray]:
    """Rows (even positions first), steering and output bins for the kernel.

    Bins ``k`` and ``k + n/2`` of an ``n``-point elevation DFT differ only in the sign of the
    odd rows' share (``e^{−jπq} = (−1)^q``), so one pass gives both from ``E ± O``. Used when
    every FFT index is an output bin (``n_el == num_el``, even); else ``n_even = −1`` and each
    steering row gives one bin.
    """
    rows = np.unique(grid.el_pos)
    rows = rows[np.argsort(rows % 2, kind="stable")]              # even positions first
    n = grid.n_el
    read = grid.el_read
    if n == grid.num_el and n % 2 == 0:
        where = np.empty(n, dtype=np.int64)
        where[read] = np.arange(read.size)
        k = np.arange(n // 2)
        el_plus, el_minus, n_even = where[k], where[k + n // 2], int(np.sum(rows % 2 == 0))
    else:
        k = read
        el_plus = np.arange(read.size, dtype=np.int64)
        el_minus, n_even = el_plus, -1
    steer = np.exp(-2j * np.pi * np.outer(k.astype(np.float64), rows) / n).astype(np.complex64)
    return rows, steer, n_even, el_plus, el_minus


class _Plan:
    """What the numba engine needs of a grid, computed once per grid (see ``_plan``)."""

    def __init__(self, grid: AngleGrid) -> None:
        self.rows, self.steer, self.n_even, self.el_plus, self.el_minus = _paired_steering(grid)
        self.row_of = np.argsort(self.rows)[np.searchsorted(np.sort(self.rows),
                                                            grid.el_pos)].astype(np.int64)
        self.az_pos = grid.az_pos.astype(np.int64)
        self.az_read = grid.az_read.astype(np.int64)
        n = grid.n_az
        self.planar = n >= 2 and n & (n - 1) == 0      # the planar kernel's radix-2 FFT
        w = np.exp(-2j * np.pi * np.arange(n // 2) / n).astype(np.complex64)
        self.w_r, self.w_i = np.ascontiguousarray(w.real), np.ascontiguousarray(w.imag)


_PLANS: weakref.WeakKeyDictionary[AngleGrid, _Plan] = weakref.WeakKeyDictionary()


def _plan(grid: AngleGrid) -> _Plan:
    plan = _PLANS.get(grid)
    if plan is None:
        plan = _PLANS[grid] = _Plan(grid)
    return plan


def heatmap_from_elements(elements: np.ndarray, grid: AngleGrid, velocities: np.ndarray,
                          workers: int = 1, chunk_size: int = CHUNK_SIZE,
                          engine: str = "auto", channels: np.ndarray | None = None,
                          doppler_phase: np.ndarray | None = None) -> np.ndarray:
    """Heatmap from the per-element range–Doppler cube.

    Parameters
    ----------
    elements
        complex64 ``(M, doppler, range)``: TDM-compensated range–Doppler signal of each unique
        virtual element (order of ``grid``), Doppler axis centred.
    grid
        The angle grid (output sizes, signs).
    velocities
        float ``(doppler,)``: range rate of each Doppler bin [m/s].
    workers
        Threads per azimuth FFT call (scipy.fft).
    chunk_size
        Azimuth-spectrum values per chunk (bounds memory and keeps the work in cache).
    engine
        ``"auto"``, ``"numba"`` or ``"numpy"`` (see the module notes); all give the same
        result to float32 rounding.
    channels
        int ``(M,)`` or None. When given, ``elements`` is a ``(C, doppler, range)`` cube of
        channels and element ``m`` is ``elements[channels[m]]`` (saves copying the elements
        out of a range–Doppler cube).
    doppler_phase
        complex ``(C, doppler)`` or None: factors that multiply each channel (row of
        ``elements``) per Doppler bin first, e.g. the TDM compensation (the numba engine
        applies them while gathering, saving a pass over the cube).

    Returns
    -------
    numpy.ndarray
        float32 ``(num_el, num_az, range, 2)``: channel 0 the peak power over Doppler,
        normalised by ``M²`` (a target of amplitude ``a`` at bin centres gives ``|a|²``),
        channel 1 the range rate of that peak [m/s].
    """
    engine = resolve_engine(engine)
    plan = _plan(grid) if engine == "numba" else None
    if doppler_phase is not None and (plan is None or not plan.planar):
        elements = elements * np.asarray(doppler_phase, dtype=np.complex64)[:, :, None]
        doppler_phase = None
    if channels is not None and engine == "numpy":
        elements, channels = elements[channels], None
    chan = (np.arange(elements.shape[0]) if channels is None
            else np.asarray(channels)).astype(np.int64)
    m, (_, nd, nr) = chan.size, elements.shape
    if m != grid.num_elements or len(velocities) != nd:
        raise SettingsError(f"elements {elements.shape} do not fit the grid's {grid.num_elements} "
                         f"elements and {len(velocities)} Doppler bins")
    width = int(grid.az_pos.max()) + 1
    n_rows, n_az, n_el = np.unique(grid.el_pos).size, grid.n_az, grid.num_el
    vel = np.asarray(velocities, dtype=np.float32)
    scale = np.float32(1.0 / m**2)
    out = np.empty((n_el, grid.num_az, nr, 2), dtype=np.float32)

    if plan is not None:
        kernel = _numba_kernel()
        assert kernel is not None
        from ._kernels import gather_rows
        steer, n_even, el_plus, el_minus = plan.steer, plan.n_even, plan.el_plus, plan.el_minus
        row_of, az_pos, az_read = plan.row_of, plan.az_pos, plan.az_read
        if plan.planar:
            from ._kernels import peak_over_doppler_planar
            gain = np.full((elements.shape[0], nd), 1.0 / m, dtype=np.complex64)
            if doppler_phase is not None:
                gain *= np.asarray(doppler_phase, dtype=np.complex64)
            peak_over_doppler_planar(np.ascontiguousarray(elements, dtype=np.complex64), gain,
                                     chan, row_of, az_pos, steer, n_even, el_plus,
                                     el_minus, az_read, vel, out, plan.w_r, plan.w_i)
            return out
        rc = max(1, min(nr, chunk_size // (n_rows * nd * n_az)))
        buf = np.zeros((n_rows, rc, nd, width), dtype=np.complex64)
        elements = np.ascontiguousarray(elements, dtype=np.complex64)
        for r0 in range(0, nr, rc):
            n = min(nr, r0 + rc) - r0
            b = buf[:, :n]
            gather_rows(elements, chan, row_of, az_pos, r0, b)
            spec = sfft.fft(b, n=n_az, axis=3, workers=workers)        # (rows, n, nd, n_az)
            kernel(spec, steer, n_even, el_plus, el_minus, az_read, vel, float(scale), out, r0)
        return out

    # numpy engine: elevation FFT of the rows the aperture spans; |·| with the Doppler bin packed
    # into the low mantissa bits, so that one integer max over Doppler gives peak and bin.
    bits = max(1, int(np.ceil(np.log2(nd))))
    low = np.int32((1 << bits) - 1)
    didx = np.arange(nd, dtype=np.int32)[:, None, None]
    w_el = int(grid.el_pos.max()) + 1
    rc = max(1, min(nr, chunk_size // (nd * grid.n_el * n_az)))
    grid_rows = np.zeros((rc, nd, w_el, width), dtype=np.complex64)
    packed = np.empty((nr, grid.n_el, n_az), dtype=np.int32)
    for r0 in range(0, nr, rc):
        n = min(nr, r0 + rc) - r0
        g = grid_rows[:n]
        g[:, :, grid.el_pos, grid.az_pos] = elements[:, :, r0:r0 + n].transpose(2, 1, 0)
        spec = sfft.fft(g, n=n_az, axis=3, workers=workers)
        spec = sfft.fft(spec, n=grid.n_el, axis=2, workers=workers, overwrite_x=True)
        mag = np.abs(spec).view(np.int32)                  # positive floats order like ints
        np.bitwise_and(mag, ~low, out=mag)
        np.bitwise_or(mag, didx, out=mag)
        np.max(mag, axis=1, out=packed[r0:r0 + n])
    sel = packed[:, grid.el_read[:, None], grid.az_read[None, :]]       # (range, el, az)
    peak = (sel & ~low).view(np.float32)
    out[..., 0] = (np.square(peak) * scale).transpose(1, 2, 0)
    out[..., 1] = vel[sel & low].transpose(1, 2, 0)
    return out
