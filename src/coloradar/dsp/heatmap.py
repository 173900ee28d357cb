"""Stage 7: the dataset-format heatmap, peak over Doppler of the 2D angle spectrum.

``heatmap[el, az, r, 0]`` is ``max_d |A_d(el, az, r)|²`` and ``heatmap[el, az, r, 1]`` the
range rate of the maximising Doppler bin, where ``A_d`` is the angle spectrum of range–Doppler
cell ``(d, r)``. That needs the spectrum of every cell (for the cascade, 2048 cells × 4096
bins); it is computed range chunk by range chunk so that the spectra stay in cache:

* azimuth FFT only over the elevation rows the aperture spans (7 of 32 for the cascade, 4 of
  them occupied),
* elevation FFT of those rows, zero padded to the grid,
* ``|·|`` and the Doppler index packed into the low mantissa bits, so that one fast
  ``max`` over the Doppler axis yields both the peak and its bin (an ``argmax`` over a
  non-contiguous axis costs more than every FFT together).

Clearing the ``b`` index bits (4 for 16 Doppler bins, 7 for 128) truncates the peak magnitude
by less than ``2^-(23−b)`` relatively (its power by less than twice that); Doppler bins whose
magnitudes agree that closely tie, and the higher bin wins.
"""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from .array import AngleGrid

__all__ = ["CHUNK_SIZE", "heatmap_from_elements"]

CHUNK_SIZE = 1 << 18
"""Spectrum values per chunk by default (2 MiB of complex64: stays in a core's L2 cache)."""


def heatmap_from_elements(elements: np.ndarray, grid: AngleGrid, velocities: np.ndarray,
                          workers: int = 1, chunk_size: int = CHUNK_SIZE) -> np.ndarray:
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
    chunk_size
        Spectrum values computed per chunk (bounds memory and keeps the work in cache).

    Returns
    -------
    numpy.ndarray
        float32 ``(num_el, num_az, range, 2)``: channel 0 the peak power over Doppler,
        normalised by ``M²`` (a target of amplitude ``a`` at bin centres gives ``|a|²``),
        channel 1 the range rate of that peak [m/s].
    """
    m, nd, nr = elements.shape
    bits = max(1, int(np.ceil(np.log2(nd))))
    low = np.int32((1 << bits) - 1)
    didx = np.arange(nd, dtype=np.int32)[:, None, None]
    w_el, w_az = int(grid.el_pos.max()) + 1, int(grid.az_pos.max()) + 1
    rc = max(1, min(nr, chunk_size // (nd * grid.n_el * grid.n_az)))
    rows = np.zeros((rc, nd, w_el, w_az), dtype=np.complex64)
    packed = np.empty((nr, grid.n_el, grid.n_az), dtype=np.int32)
    for r0 in range(0, nr, rc):
        r1 = min(nr, r0 + rc)
        buf = rows[: r1 - r0]
        buf[:, :, grid.el_pos, grid.az_pos] = elements[:, :, r0:r1].transpose(2, 1, 0)
        spec = sfft.fft(buf, n=grid.n_az, axis=3, workers=workers)
        spec = sfft.fft(spec, n=grid.n_el, axis=2, workers=workers, overwrite_x=True)
        mag = np.abs(spec).view(np.int32)                  # positive floats order like ints
        np.bitwise_and(mag, ~low, out=mag)
        np.bitwise_or(mag, didx, out=mag)
        np.max(mag, axis=1, out=packed[r0:r1])
    sel = packed[:, grid.el_read[:, None], grid.az_read[None, :]]   # (range, el, az)
    out = np.empty((grid.num_el, grid.num_az, nr, 2), dtype=np.float32)
    peak = (sel & ~low).view(np.float32) * np.float32(1.0 / m)
    out[..., 0] = np.square(peak).transpose(1, 2, 0)
    out[..., 1] = np.asarray(velocities, dtype=np.float32)[sel & low].transpose(1, 2, 0)
    return out
