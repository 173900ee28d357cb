"""Stage 8b: detections and point clouds (from ADC-derived cubes or from shipped heatmaps).

Point clouds are float32 ``(N, 5)``: ``x y z intensity range_rate`` in the radar frame (x
boresight, y left, z up). From a range–Doppler detection at range ``R`` and direction sines
``(u_y, u_z)`` the point is ``R·(√(1 − u_y² − u_z²), u_y, u_z)`` — the same as
``(R cos el cos az, R cos el sin az, R sin el)`` with ``el = asin(u_z)``,
``az = atan2(u_y, u_x)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.fft as sfft
from scipy.ndimage import maximum_filter

from ..calib import HeatmapConfig
from ..errors import FormatError
from .array import sines_to_unit
from .cfar import CFAREdge, CFARKind, cfar

__all__ = ["Detections", "channel_noise", "heatmap_cell_xyz", "heatmap_pointcloud", "local_maxima",
           "sidelobe_envelope", "sidelobe_mask", "sidelobe_pairs", "source_fit_residuals"]


@dataclass(frozen=True, eq=False)
class Detections:
    """Detections of one frame; every attribute is an array of length N.

    Attributes
    ----------
    range_bin, doppler_bin
        int64: cell of the range–Doppler map (Doppler index of the centred axis).
    range
        float64 [m], refined between bins.
    range_rate
        float64 [m/s], refined; negative = approaching.
    azimuth, elevation
        float64 [rad]: ``atan2(y, x)`` and ``asin(z/R)`` of the point.
    xyz
        float64 ``(N, 3)`` [m], radar frame.
    intensity
        float64: peak of the angle spectrum, in the heatmap's power units.
    power
        float64: range–Doppler power (sum over virtual channels) of the cell.
    snr
        float64: the detection statistic over its CFAR noise estimate (with noise whitening,
        of the whitened sum).
    alias
        int64 or None: the Doppler alias ``m`` chosen per detection (range rate =
        folded rate + ``2m·v_max``); None when no search ran.
    alias_confidence
        float64 or None: the probability of that alias under the array model (docs/dsp.md,
        "Doppler beyond ±v_max"); on an array without a phase calibration, where the folded
        rate is kept, a low value flags a point whose rate may be aliased. None when no
        search ran.
    """


    range_bin: np.ndarray
    doppler_bin: np.ndarray
    range: np.ndarray
    range_rate: np.ndarray
    azimuth: np.ndarray
    elevation: np.ndarray
    xyz: np.ndarray
    intensity: np.ndarray
    power: np.ndarray
    snr: np.ndarray
    alias: np.ndarray | None = None
    alias_confidence: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.range_bin.size)

    def pointcloud(self) -> np.ndarray:
        """float32 ``(N, 5)``: ``x y z intensity range_rate``."""
        out = np.empty((len(self), 5), dtype=np.float32)
        out[:, :3] = self.xyz
        out[:, 3] = self.intensity
        out[:, 4] = self.range_rate
        return out


def local_maxima(power: np.ndarray, mode: CFAREdge | tuple[CFAREdge, ...]) -> np.ndarray:
    """bool mask of cells not smaller than any of their neighbours (3 cells per axis)."""
    return power >= maximum_filter(power, size=3, mode=mode)


NOISE_CELLS = 1024
"""Cells per channel that :func:`channel_noise` takes its median over (at most)."""


def channel_noise(power: np.ndarray, first_range: int = 0,
                  max_cells: int = NOISE_CELLS, engine: str = "numpy") -> np.ndarray:
    """Noise power of every channel of a range–Doppler power cube, robust to targets.

    The median cell power over the Doppler bins and the range bins from ``first_range`` on,
    divided by ``ln 2`` (the median of an exponential of mean σ² is ``σ²·ln 2``): targets and
    clutter that fill less than half the cells do not move it much. The median is taken over
    every k-th cell, k chosen so that at most ``max_cells`` cells are used: the sample median
    of n exponential cells has a relative standard deviation of ``1/(√n·ln 2)``, 4.5 % at
    n = 1024, which whitening weights do not need to beat (the CFAR normalises each cell by its
    own training cells), while the selection over every cell cost as much as the range FFT.

    Parameters
    ----------
    power
        float ``(channels, doppler, range)``: ``|·|²`` of each channel.
    first_range
        First range bin used (near bins hold coupling residue).
    max_cells
        Most cells per channel the median is taken over.
    engine
        ``"numba"``: the selection compiled (:func:`~coloradar.dsp._kernels.median_bits`,
        the same cell chosen) for float32 powers; ``"numpy"``: numpy's.

    Returns
    -------
    numpy.ndarray
        float64 ``(channels,)``.
    """
    c, nd, nr = power.shape
    if first_range >= nr:
        first_range = 0
    n = nd * (nr - first_range)
    step = -(-n // max(int(max_cells), 1))
    # Every k-th cell of the flattened (Doppler, range) grid spreads over both axes; k odd
    # so that an even range length does not keep the same parity of range bins throughout.
    cells = _noise_cells(nd, nr, first_range, step | 1 if step > 1 else 1)
    mid = cells.size // 2
    flat = power.reshape(c, nd * nr)
    if engine == "numba" and power.dtype == np.float32 and cells.size:
        from ._kernels import median_bits
        med_bits = np.empty(c, dtype=np.int32)
        if median_bits(np.ascontiguousarray(flat), cells, mid, med_bits):
            med = med_bits.view(np.float32).astype(np.float64)
            return np.maximum(med / np.log(2.0), np.finfo(np.float64).tiny)
    # (gathered straight from the map: no copy of the whole map first)
    values = np.take(flat, cells, axis=1)
    if values.dtype == np.float32 and np.all(values >= 0):
        # Non-negative float32 values order as their bit patterns read as int32, and numpy
        # selects among integers faster (a fifth less time): the same cell is chosen.
        bits = np.ascontiguousarray(values).view(np.int32)
        med = np.partition(bits, mid, axis=1)[:, mid].view(np.float32).astype(np.float64)
    else:
        med = np.partition(values, mid, axis=1)[:, mid].astype(np.float64)
    return np.maximum(med / np.log(2.0), np.finfo(np.float64).tiny)


@lru_cache(maxsize=16)
def _noise_cells(nd: int, nr: int, first_range: int, step: int) -> np.ndarray:
    """Flat indices into a ``(nd, nr)`` map of every ``step``-th cell of its range bins from
    ``first_range`` on, the grid flattened Doppler-major (read-only, cached)."""
    d_idx, r_idx = np.divmod(np.arange(0, nd * (nr - first_range), step), nr - first_range)
    out = d_idx * nr + first_range + r_idx
    out.setflags(write=False)
    return out


@lru_cache(maxsize=16)
def _fit_tables(pos: tuple[int, ...], fft_size: int, bins: tuple[int, ...]
                ) -> tuple[np.ndarray, np.ndarray]:
    """Cross patterns and gains of a line array's FFT grid (read-only, cached).

    ``cross[i, g] = a_gᴴa_i`` (complex128 ``(G, G)``): the beam at ``g`` of a unit source at
    ``i``, so that removing a source from a vector moves its beams by a table row instead of
    an FFT; ``gain[i, g] = max(M − |a_gᴴa_i|²/M, 10⁻⁶M)`` (float64 ``(G, G)``): ``a_gᴴP⊥a_g``
    with ``P⊥`` projecting ``a_i`` out.
    """
    p = np.asarray(pos, dtype=np.int64)
    b = np.asarray(bins, dtype=np.int64)
    steer = np.exp(2j * np.pi * np.outer(b, p) / fft_size)               # (G, M): a(u)
    cross = steer @ steer.conj().T
    m = p.size
    # |a_gᴴa_h| depends on the bin difference only: one FFT of the element indicator
    ind = np.zeros(fft_size)
    ind[p] = 1.0
    pattern = np.abs(sfft.fft(ind)) ** 2
    gain = np.maximum(m - pattern[(b[None, :] - b[:, None]) % fft_size] / m, 1e-6 * m)
    cross.setflags(write=False)
    gain.setflags(write=False)
    return cross, gain


def _pair_fit_numpy(b: np.ndarray, i1: np.ndarray, total: np.ndarray, rss1: np.ndarray,
                    cross: np.ndarray, gain: np.ndarray, m: int, iterations: int
                    ) -> np.ndarray:
    """Two-source residuals by alternating projection and a joint polish (the numpy twin
    of :func:`coloradar.dsp._kernels.source_pairs`; see :func:`source_fit_residuals`)."""
    n = b.shape[0]
    k = np.arange(n)
    g = cross.shape[0]

    def partner(keep: np.ndarray) -> np.ndarray:
        # beams of the vector less the kept source's fit: b − (a_gᴴa_keep)·b_keep/M
        left = b - cross[keep] * (b[k, keep] / m)[:, None]
        return np.argmax((left.real ** 2 + left.imag ** 2) / gain[keep], axis=1)

    i2 = partner(i1)
    for _ in range(iterations):
        i1 = partner(i2)
        i2 = partner(i1)

    def explained(p: np.ndarray, q: np.ndarray) -> np.ndarray:
        # joint least squares on (a_p, a_q): bᴴ G⁻¹ b, G = [[M, c], [c*, M]], c = a_pᴴa_q
        bp, bq = b[k, p], b[k, q]
        c = cross[q, p]
        det = m * m - (c.real ** 2 + c.imag ** 2)
        num = (m * (bp.real ** 2 + bp.imag ** 2 + bq.real ** 2 + bq.imag ** 2)
               - 2.0 * np.real(c * np.conj(bp) * bq))
        return np.where(det > 1e-6 * m * m, num / np.maximum(det, 1e-9 * m * m), -np.inf)

    best = explained(i1, i2)
    for _ in range(2):
        for d1 in (-1, 0, 1):
            for d2 in (-1, 0, 1):
                p, q = np.clip(i1 + d1, 0, g - 1), np.clip(i2 + d2, 0, g - 1)
                e = explained(p, q)
                better = e > best
                i1, i2, best = np.where(better, p, i1), np.where(better, q, i2), \
                    np.where(better, e, best)
    rss2 = np.where(np.isfinite(best), np.maximum(total - best, 0.0), rss1)
    return np.minimum(rss2, rss1)


def source_fit_residuals(x: np.ndarray, positions: np.ndarray, fft_size: int,
                         bins: np.ndarray, iterations: int = 2,
                         fit: np.ndarray | Callable[[np.ndarray], np.ndarray] | None = None,
                         kernel: Callable[..., None] | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Residual power of the best one-source and two-source fits of line-array vectors.

    The model selection of the Doppler alias search (docs/dsp.md, "Doppler beyond ±v_max"):
    a vector is ``Σ_k s_k a(u_k) + noise`` with ``n`` = 1 or 2 sources of unknown complex
    amplitude ``s_k`` and direction ``u_k`` on a grid. One source: the beam's peak
    (``RSS₁ = |x|² − max_u |aᴴx|²/M``, the maximum interpolated between grid points). Two
    sources: alternating projection (Ziskind & Wax
    1988) started at the beam's peak, each step taking the direction that adds most beside
    the other source (``|aᴴP⊥x|²/aᴴP⊥a``, ``P⊥`` projecting the other out); coordinate
    steps can stall where two sources about a resolution apart couple their errors, so the
    pair is then polished by joint moves of one grid step. The pair's joint least squares
    gives ``RSS₂`` (a local optimum, ≥ the global one; the tests check it against an
    exhaustive search over all pairs).

    The grid is that of a zero-padded FFT: direction ``g`` is FFT bin ``bins[g]``, steering
    ``a_g[m] = exp(j2π·bins[g]·positions[m]/fft_size)``. The vectors' beams are one FFT;
    the beams of a vector less one source's fit follow from them and a cached table of the
    array's cross patterns (``a_gᴴa_i``), so the projection steps need no transforms.

    Parameters
    ----------
    x
        complex ``(N, M)``: N vectors of M elements.
    positions
        int ``(M,)``: distinct element positions along the line (in grid units).
    fft_size
        FFT length (≥ the positions' span).
    bins
        int ``(G,)``: the FFT bins of the grid's directions.
    iterations
        Rounds of alternating projection after the start.
    fit
        bool ``(N,)``: the vectors that get the two-source fit (None: all), or a function
        returning that mask from ``rss1`` (float64 ``(N,)``); the others get
        ``rss2 = rss1``.
    kernel
        The compiled two-source fit (:func:`coloradar.dsp._kernels.source_pairs`, numba
        engine), or None for numpy; both take the same steps in float64.

    Returns
    -------
    tuple
        float64 ``(rss1, rss2)``, each ``(N,)``, in the units of ``|x|²``; ``rss2 ≤ rss1``.
    """
    x = np.asarray(x)
    n, m = x.shape
    if n == 0:
        e = np.zeros(0)
        return e, e
    pos = np.asarray(positions, dtype=np.int64)
    bins = np.asarray(bins, dtype=np.int64)
    cross, gain = _fit_tables(tuple(pos.tolist()), int(fft_size), tuple(bins.tolist()))
    buf = np.zeros((n, fft_size), dtype=np.result_type(x.dtype, np.complex64))
    buf[:, pos] = x
    b = sfft.fft(buf, axis=1)[:, bins]                                   # (N, G): aᴴx
    k = np.arange(n)
    total = np.sum(np.abs(x) ** 2, axis=1).astype(np.float64)
    pw = np.abs(b) ** 2
    i1 = np.argmax(pw, axis=1)
    # the peak between grid points (parabola through the peak and its neighbours): the grid
    # alone would leave a scalloping residual that grows with the SNR
    p0 = pw[k, i1]
    pm, pp = pw[k, np.maximum(i1 - 1, 0)], pw[k, np.minimum(i1 + 1, bins.size - 1)]
    curv = pm - 2.0 * p0 + pp
    delta = np.where(curv < 0, 0.5 * (pm - pp) / np.where(curv < 0, curv, -1.0), 0.0)
    peak = np.maximum(p0, p0 - 0.25 * (pm - pp) * np.clip(delta, -0.5, 0.5))
    rss1 = np.maximum(total - peak / m, 0.0)
    if callable(fit):
        fit = fit(rss1)
    sel = np.arange(n) if fit is None else np.flatnonzero(fit)
    rss2 = rss1.copy()
    if sel.size:
        bs = np.ascontiguousarray(b[sel], dtype=np.complex128)
        if kernel is not None:
            out = np.empty(sel.size)
            kernel(bs, np.ascontiguousarray(i1[sel], dtype=np.int64), total[sel], rss1[sel],
                   cross, gain, m, iterations, out)
            rss2[sel] = out
        else:
            rss2[sel] = _pair_fit_numpy(bs, i1[sel], total[sel], rss1[sel], cross, gain, m,
                                        iterations)
    return rss1, rss2


def sidelobe_envelope(window: np.ndarray, fft_size: int, num_lags: int,
                      oversample: int = 32) -> np.ndarray:
    """Worst-case power leakage of a windowed tone into bins ``Δ = 0 … num_lags − 1`` away
    from its peak cell, relative to that cell.

    A tone lies within half a bin of its peak cell (offset ``δ``, ``|δ| ≤ ½``); the cell ``Δ``
    bins away holds ``|W(Δ − δ)|²`` against the peak cell's ``|W(δ)|²`` (scalloping loss
    included), so ``E(Δ) = max_{|δ|≤½} |W(Δ−δ)|² / |W(δ)|²``, ``W`` the window's DTFT in units
    of FFT bins (zero padding included). ``E(1) = 1`` (a tone midway between two bins).

    Parameters
    ----------
    window
        float ``(n,)``: the taper.
    fft_size
        FFT length (≥ n).
    num_lags
        Lags returned.
    oversample
        Evaluation points per bin (even).

    Returns
    -------
    numpy.ndarray
        float64 ``(num_lags,)``, ``E(0) = 1``.
    """
    w = np.asarray(window, dtype=np.float64)
    os_ = 2 * max(1, oversample // 2)
    n_eval = int(fft_size) * os_
    resp = np.abs(np.fft.fft(w, n_eval)) ** 2
    j = np.arange(-os_ // 2, os_ // 2 + 1)                      # δ = j / os_
    lags = np.arange(num_lags)
    num = resp[(lags[:, None] * os_ - j[None, :]) % n_eval]
    den = resp[j % n_eval][None, :]
    env = (num / np.maximum(den, 1e-300)).max(axis=1)
    env[0] = 1.0
    return np.minimum(env, 1.0)


def sidelobe_mask(doppler_bin: np.ndarray, range_bin: np.ndarray, power: np.ndarray,
                  excess: np.ndarray, env_doppler: np.ndarray, env_range: np.ndarray,
                  num_doppler: int, margin: float) -> np.ndarray:
    """Which candidates are *not* explained by a stronger candidate's window sidelobes.

    Candidate ``i`` is a sidelobe of a stronger ``j`` when
    ``excess_i < margin · power_j · E_d(|Δd|) · E_r(|Δr|)`` (Doppler lags circular), with
    ``excess`` its power above the noise estimate. Separable windows make a point target's
    range–Doppler response the product of the two, summed over channels alike.

    Parameters
    ----------
    doppler_bin, range_bin
        int ``(K,)``: candidate cells.
    power, excess
        float ``(K,)``: cell power and power above the CFAR noise estimate.
    env_doppler, env_range
        Envelopes from :func:`sidelobe_envelope`.
    num_doppler
        Doppler bins (for circular lags).
    margin
        Linear factor (≥ 1) on the envelope.

    Returns
    -------
    numpy.ndarray
        bool ``(K,)``: True = keep.
    """
    k = power.size
    keep = np.ones(k, dtype=bool)
    if k < 2:
        return keep
    step = max(1, (1 << 20) // k)                  # bound the (rows, K) work arrays
    for i0 in range(0, k, step):
        i = slice(i0, min(k, i0 + step))
        dd = np.abs(doppler_bin[i, None] - doppler_bin[None, :])
        dd = np.minimum(dd, num_doppler - dd)
        dr = np.abs(range_bin[i, None] - range_bin[None, :])
        leak = (env_doppler[np.minimum(dd, env_doppler.size - 1)]
                * env_range[np.minimum(dr, env_range.size - 1)])        # (i, j)
        stronger = power[None, :] > power[i, None]
        explained = stronger & (excess[i, None] < margin * power[None, :] * leak)
        keep[i] = ~explained.any(axis=1)
    return keep


def sidelobe_pairs(doppler_bin: np.ndarray, range_bin: np.ndarray, power: np.ndarray,
                   excess: np.ndarray, refs: tuple[np.ndarray, np.ndarray, np.ndarray],
                   envelopes: tuple[np.ndarray, np.ndarray], num_doppler: int, margin: float,
                   min_lag: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs (point, stronger cell) where the cell's window sidelobes could explain the point.

    ``refs``: the reference cells' Doppler bins, range bins and powers; ``envelopes``: the
    windows' sidelobe envelopes ``(E_d, E_r)`` (:func:`sidelobe_envelope`).
    As :func:`sidelobe_mask`, but between points and a separate set of reference cells, and
    only for references at least ``min_lag`` bins away along range or Doppler (neighbouring
    cells are one target's main lobe: the beam grouping decides there). Point ``i`` is
    explained by reference ``j`` when ``power_j > power_i`` and
    ``excess_i < margin · power_j · E_d(|Δd|) · E_r(|Δr|)``.

    Returns
    -------
    tuple
        int64 ``(P,)`` point indices, int64 ``(P,)`` reference indices and float64 ``(P,)``
        leakage factors ``E_d·E_r`` of every such pair.
    """
    ref_doppler, ref_range, ref_power = refs
    env_doppler, env_range = envelopes
    k, n = power.size, ref_power.size
    out_i, out_j, out_l = [], [], []
    step = max(1, (1 << 20) // max(n, 1))
    for i0 in range(0, k, step):
        i = slice(i0, min(k, i0 + step))
        dd = np.abs(doppler_bin[i, None] - ref_doppler[None, :])
        dd = np.minimum(dd, num_doppler - dd)
        dr = np.abs(range_bin[i, None] - ref_range[None, :])
        leak = (env_doppler[np.minimum(dd, env_doppler.size - 1)]
                * env_range[np.minimum(dr, env_range.size - 1)])
        hit = ((ref_power[None, :] > power[i, None]) & (np.maximum(dd, dr) >= min_lag)
               & (excess[i, None] < margin * ref_power[None, :] * leak))
        a, b = np.nonzero(hit)
        out_i.append(a + i0)
        out_j.append(b)
        out_l.append(leak[a, b])
    if not out_i:
        e = np.zeros(0, dtype=np.int64)
        return e, e, np.zeros(0)
    return (np.concatenate(out_i).astype(np.int64), np.concatenate(out_j).astype(np.int64),
            np.concatenate(out_l))


def heatmap_cell_xyz(config: HeatmapConfig, el: np.ndarray, az: np.ndarray,
                     rng: np.ndarray) -> np.ndarray:
    """Radar-frame positions of heatmap cells: the one heatmap-cell placement of coloradar.

    Parameters
    ----------
    config
        The heatmap's grid (angle lists in radians, range bin width in metres).
    el, az, rng
        int ``(N,)``: elevation, azimuth and range indices of the cells.

    Returns
    -------
    numpy.ndarray
        float64 ``(N, 3)`` [m]: ``r·width·(√(1 − u_y² − u_z²), u_y, u_z)`` with
        ``u_y = sin(azimuth_bins[az])``, ``u_z = sin(elevation_bins[el])`` (an FFT grid
        measures direction sines, see :func:`heatmap_pointcloud`). Corner cells outside the
        visible region (``u_y² + u_z² > 1``) are projected onto its edge so that they keep
        their range.
    """
    u = sines_to_unit(np.sin(config.azimuth_bins[np.asarray(az)]),
                      np.sin(config.elevation_bins[np.asarray(el)]))
    return (np.asarray(rng) * config.range_bin_width)[..., None] * u


def heatmap_pointcloud(heatmap: np.ndarray, config: HeatmapConfig, *, kind: CFARKind = "ca",
                       guard: int | tuple[int, int, int] = (0, 1, 1),
                       train: int | tuple[int, int, int] = (0, 4, 4), pfa: float = 1e-4,
                       threshold: float | None = None, min_range: float = 0.0,
                       peaks_only: bool = True) -> np.ndarray:
    """Point cloud from a heatmap ``(el, az, range, 2)`` (shipped or computed).

    Cells are detected by a 3D CFAR on channel 0 (or, with ``threshold``, by a fixed intensity
    threshold), optionally kept only where they are local maxima, and placed with the angle
    lists of ``config``. An FFT heatmap's azimuth axis measures the direction sine
    ``u_y = cos(el)·sin(az)`` and its elevation axis ``u_z = sin(el)`` (this holds for the shipped
    heatmaps as for coloradar's), so a cell at bin angles ``(α, ε)`` and range ``R = r·width`` is
    placed at ``R·(√(1 − sin²α − sin²ε), sin α, sin ε)``; in the ``el = 0`` plane this is
    ``(R cos α, R sin α, 0)``.

    Parameters
    ----------
    heatmap
        float ``(el, az, range, 2)``.
    config
        The heatmap's grid; for shipped heatmaps the ``heatmap_cfg.txt`` that came with them.
    kind, guard, train, pfa
        CFAR settings (axes el, az, range; edges mirrored). By default the training cells
        lie in the cell's own elevation row: both radars' elevation apertures are a few
        elements, so a target fills much of an elevation column and would raise its own
        threshold. The CFAR assumes exponential cell power; the peak-over-Doppler of a
        heatmap is not, so ``pfa`` is nominal here.
    threshold
        Use a fixed channel-0 threshold instead of CFAR.
    min_range
        Drop cells closer than this [m] (antenna coupling lives there).
    peaks_only
        Keep only local maxima of channel 0.

    Returns
    -------
    numpy.ndarray
        float32 ``(N, 5)``.
    """
    hm = np.asarray(heatmap)
    if hm.ndim != 4 or hm.shape[:3] != config.shape or hm.shape[3] != 2:
        raise FormatError(f"heatmap has shape {hm.shape}; its heatmap_cfg says "
                          f"{(*config.shape, 2)} (el, az, range, 2)")
    p = hm[..., 0].astype(np.float64)
    if threshold is None:
        mask = cfar(p, kind, guard, train, pfa, mode="mirror").detections
    else:
        mask = p > threshold
    if peaks_only:
        mask &= local_maxima(p, "mirror")
    mask[:, :, : int(np.ceil(min_range / config.range_bin_width))] = False
    e, a, r = np.nonzero(mask)
    out = np.empty((e.size, 5), dtype=np.float32)
    out[:, :3] = heatmap_cell_xyz(config, e, a, r)
    out[:, 3] = hm[e, a, r, 0]
    out[:, 4] = hm[e, a, r, 1]
    return out
