"""The CFAR stage of detection: the detection statistic (channels' power, whitened by their noise),
CFAR on it, and the grouping of a target's cells into peaks.

Input: the range–Doppler cube without TDM phases ``(tx, rx, doppler, range)``; output:
:class:`CFARCells`, the statistic, the CFAR's mask (grouped) and noise estimate. Settings:
:class:`~coloradar.dsp.settings.CFARSettings`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...calib import RadarCalib
from ..cfar import (
    CFARConfig,
    CFAREdge,
    cfar_window,
    effective_looks,
    effective_train_cells,
    power_correlation,
    range_floor,
    run_cfar,
)
from ..cube_stage import CubeStage
from ..detect import channel_noise
from ..settings import CFARSettings
from ..windows import window
from ._common import c64, compiled_kernels, f64

__all__ = ["STRONG_NEIGHBOUR", "CFARCells", "CFARStage", "group_peaks"]

STRONG_NEIGHBOUR = 10.0
"""A 2D peak this many times its CFAR noise (10 dB) has its neighbours examined too."""


@dataclass(frozen=True)
class CFARCells:
    """What the CFAR stage finds in one frame (maps ``(doppler, range)``).

    Attributes
    ----------
    stat
        float64 detection statistic.
    mask
        bool: CFAR detections, grouped into peaks with ``peak_grouping``.
    noise
        float64 CFAR noise estimate (+inf where the CFAR does not test).
    plain_at
        The plain power sum (float32) at given flat ``doppler·nr + range`` cells.
    sig2
        float64 ``(tx·rx,)`` channels' noise powers (None without whitening).
    next_row
        float64 ``(doppler,)`` statistic of the range bin after the last one (None where not
        computed).
    """

    stat: np.ndarray
    mask: np.ndarray
    noise: np.ndarray
    plain_at: Callable[[np.ndarray], np.ndarray]
    sig2: np.ndarray | None
    next_row: np.ndarray | None


class CFARStage:
    """Detection statistic, CFAR and peak grouping of one radar.

    Parameters
    ----------
    calib
        The radar's calibration.
    cube
        The cube stage (FFT sizes, range bins, windows).
    settings
        The stage's settings.
    coupling_subtraction
        Whether the coupling file is subtracted (channels it lacks are left out of the
        zero-Doppler bin's statistic).
    num_elements
        Unique virtual elements of the detection beams (beam noise per unit of statistic).
    """

    def __init__(self, calib: RadarCalib, cube: CubeStage, settings: CFARSettings,
                 coupling_subtraction: bool, num_elements: int) -> None:
        s = self.settings = settings
        self.calib, self.cube, self.num_elements = calib, cube, num_elements
        self.engine = cube.engine
        self.compiled = compiled_kernels(self.engine)
        w, cs = calib.waveform, cube.settings
        ntx, nrx, nc, ns = w.frame_shape
        nd = cube.doppler_fft_size
        # The map sums ntx·nrx channels of independent noise: that many exponential looks
        # (with "whiten"); cfar_looks="auto" measures fewer where the cells' power is common
        # to the channels (clutter, phase noise).
        self.looks = ntx * nrx
        # Windowed FFT bins are correlated: the training mean counts as fewer independent
        # cells (cfar.effective_train_cells).
        h = [g + t for g, t in zip(s.cfar_guard, s.cfar_train, strict=True)]
        corr = (power_correlation(window(cs.doppler_window, nc), nd, 2 * h[0]),
                power_correlation(window(cs.range_window, ns), cube.range_fft_size, 2 * h[1]))
        n_all, n_half = cfar_window(s.cfar_guard, s.cfar_train, split_axis=1)
        n_half = max(n_half, 1)
        e_all, e_half = effective_train_cells(s.cfar_guard, s.cfar_train, corr, split_axis=1,
                                              wrap=(nd, None))
        self.cell_factor = {"ca": e_all / n_all, "go": e_half / n_half,
                            "so": e_half / n_half, "os": 1.0}[s.cfar_kind]
        # The CA training set's independent-cell equivalent: the looks are measured on the
        # ratio of every cell to its CA estimate, whatever the CFAR kind (cfar.effective_looks).
        self.ca_factor, self.ca_train = e_all / n_all, e_all
        self.first_range = int(np.ceil(s.min_range / cube.range_bin_width))
        # Range bins notched by DC removal: the window's half-width in bins, zero padding
        # included (periodic Hann: 3 taps, Blackman: 5).
        taps = {"none": 0, "hann": 1, "blackman": 2}[cs.range_window]
        self.notch_bins = (int(np.ceil((taps + 1) * cube.range_fft_size / ns))
                           if cs.dc_removal else 0)
        # Channels whose coupling the file does not hold (the single chip's all-zero TX 2
        # block): their leakage stays in the zero-Doppler bin at every range, so that bin's
        # detection statistic leaves them out (scaled to the same noise mean).
        self.uncoupled = None
        cpl = calib.coupling
        if coupling_subtraction and cpl is not None and cpl.missing_tx:
            miss = np.zeros((ntx, nrx), dtype=bool)
            miss[list(cpl.missing_tx)] = True
            self.uncoupled = miss.ravel()

    def run(self, rd: np.ndarray, rd_next: np.ndarray | None = None) -> CFARCells:
        """Statistic, CFAR and peak grouping of a range–Doppler cube ``rd`` without TDM phases;
        ``rd_next`` ``(tx, rx, doppler, 1 or 0)``, the same for the range bin after the last
        one, when computed (a return beyond the processed range then makes no local maximum at
        the last bin)."""
        stat, plain_at, looks, sig2 = self.statistic(rd)
        nxt = None
        if rd_next is not None and rd_next.shape[-1]:
            m2 = np.square(np.abs(rd_next[..., 0])).reshape(-1, rd_next.shape[2])
            wts = (np.ones(m2.shape[0]) if sig2 is None else sig2.mean() / sig2)
            nxt = self.exclude_row(wts[:, None] * m2, rd_next.shape[2])
        mask, noise = self.cfar_mask(stat, looks)
        if self.settings.peak_grouping:
            # Cells that peak along Doppler or along range: a target one bin from a stronger
            # one (in the other axis) is no 2D maximum of the summed power, but it is one of
            # its own beam; the beam test of the guard stage decides (docs/dsp.md, "Grouping").
            mask = self.group(stat, mask, noise, nxt)
        return CFARCells(stat, mask, noise, plain_at, sig2, nxt)

    def group(self, stat: np.ndarray, mask: np.ndarray, noise: np.ndarray,
              nxt: np.ndarray | None) -> np.ndarray:
        """:func:`group_peaks`, compiled with the numba engine."""
        if self.compiled is None:
            return group_peaks(stat, mask, noise, nxt)
        grouped = np.empty(stat.shape, dtype=bool)
        self.compiled.group_peaks(
            np.ascontiguousarray(stat), np.ascontiguousarray(mask),
            np.ascontiguousarray(noise), f64(nxt if nxt is not None else np.zeros(0)),
            float(STRONG_NEIGHBOUR), grouped)
        return grouped

    def statistic(self, rd: np.ndarray
                       ) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray], int,
                                  np.ndarray | None]:
        """Detection statistic ``(doppler, range)`` float64, the plain power sum (float32)
        at given flat ``doppler·nr + range`` cells, the looks the CFAR threshold is computed
        for (``noise_weighting``), and the channels' noise powers (float64 ``(tx·rx,)``;
        None without whitening)."""
        s = self.settings
        ntx, nrx, nd, nr = rd.shape
        if self.compiled is not None:
            mag2 = np.empty((ntx * nrx, nd * nr), dtype=np.float32)
            self.compiled.power(c64(rd).reshape(-1).view(np.float32),
                                mag2.reshape(-1))
        else:
            mag2 = np.abs(rd).reshape(ntx * nrx, nd * nr)
            np.square(mag2, out=mag2)
        if s.noise_weighting == "off":
            plain = mag2.sum(axis=0)
            return (plain.reshape(nd, nr).astype(np.float64), plain.__getitem__, self.looks,
                    None)
        # Inverse-noise weights: each term a unit exponential times the mean noise power, so
        # the sum is a Ntx·Nrx-look chi-square whatever the channel gains.
        sig2 = channel_noise(mag2.reshape(ntx * nrx, nd, nr),
                             int(np.ceil(s.min_range / self.cube.range_bin_width)),
                             engine=self.engine)
        wts = (sig2.mean() / sig2).astype(np.float32)
        stat = (wts @ mag2).reshape(nd, nr).astype(np.float64)
        if self.uncoupled is not None:
            z = nd // 2
            keep = ~self.uncoupled
            row = wts[keep] @ mag2.reshape(ntx * nrx, nd, nr)[keep, z, :]
            stat[z] = row * (wts.sum() / wts[keep].sum())
        # The plain sum is read at the few points' cells only: summed there, channel after
        # channel as numpy sums the whole map along axis 0 (cumsum's last row: the same
        # float32 values), instead of a pass over the map.
        return stat, lambda i: np.cumsum(mag2[:, i], axis=0)[-1], self.looks, sig2

    def exclude_row(self, weighted: np.ndarray, nd: int) -> np.ndarray:
        """Detection statistic ``(doppler,)`` of one range bin from weighted channel powers
        ``(channels, doppler)``, the zero-Doppler bin without the channels of unknown
        coupling (as :meth:`statistic`)."""
        out = weighted.sum(axis=0).astype(np.float64)
        if self.uncoupled is not None:
            keep = ~self.uncoupled
            out[nd // 2] = weighted[keep, nd // 2].sum() * (weighted.shape[0] / keep.sum())
        return out

    def cfar_mask(self, stat: np.ndarray, looks: float) -> tuple[np.ndarray, np.ndarray]:
        """CFAR on the detection statistic: bool mask and noise estimate, ``(doppler, range)``
        (cells the CFAR does not test: False and +inf); ``looks`` the channels summed, replaced
        with ``cfar_looks="auto"`` by those measured on the map (:meth:`measured_looks`)."""
        s = self.settings
        if s.cfar_looks == "auto":
            looks = self.measured_looks(stat, looks)
        return self._run(stat, looks)

    def measured_looks(self, stat: np.ndarray, looks: float) -> float:
        """Effective looks of the statistic ``(doppler, range)``: moments of the cells beyond
        ``min_range`` over their CA noise estimate (:func:`~coloradar.dsp.cfar.effective_looks`;
        the CA pass assumes ``looks``, which only decides which cells its excision replaces)."""
        s = self.settings
        cmodes: tuple[CFAREdge, CFAREdge] = ("wrap", "truncate")
        r0 = max(0, min(max(self.notch_bins, self.first_range),
                        stat.shape[1] - s.cfar_guard[1] - s.cfar_train[1] - 1))
        part = stat[:, r0:]
        floor = self._floor(part)
        if floor is not None:
            part = part / floor
        res = run_cfar(part, CFARConfig("ca", s.cfar_guard, s.cfar_train, s.pfa,
                                        s.cfar_rank, looks, cmodes, 1, self.ca_factor,
                                        s.cfar_excision))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = part / res.noise
        return effective_looks(ratio, self.ca_train, looks, pfa=s.pfa)

    def _run(self, stat: np.ndarray, looks: float) -> tuple[np.ndarray, np.ndarray]:
        s = self.settings
        # Range edges: training cells beyond the map are left out ("truncate"), not mirrored
        # (mirrored copies made the edge cells fire ~5x too often). OS needs a full window.
        cmodes: tuple[CFAREdge, CFAREdge] = ("wrap", "mirror" if s.cfar_kind == "os" else "truncate")
        # DC removal notches the first range bins (the window spreads the notch): they would
        # lower the noise estimate of their neighbours, so the CFAR map starts after them.
        r0 = max(0, min(self.notch_bins, stat.shape[1] - s.cfar_guard[1] - s.cfar_train[1] - 1))
        part = stat[:, r0:]
        floor = self._floor(part)
        res = run_cfar(part if floor is None else part / floor,
                       CFARConfig(s.cfar_kind, s.cfar_guard, s.cfar_train, s.pfa, s.cfar_rank,
                                  looks, cmodes, 1, self.cell_factor, s.cfar_excision))
        mask = np.zeros(stat.shape, dtype=bool)
        mask[:, r0:] = res.detections
        noise = np.full(stat.shape, np.inf)
        noise[:, r0:] = res.noise if floor is None else res.noise * floor
        return mask, noise

    def _floor(self, stat: np.ndarray) -> np.ndarray | None:
        """float64 ``(range,)``: the floor the CFAR divides ``stat`` by along range
        (``cfar_range_floor``, :func:`~coloradar.dsp.cfar.range_floor`); None when off."""
        return range_floor(stat) if self.settings.cfar_range_floor else None

    def beam_noise_factor(self, sig2: np.ndarray | None) -> float:
        """Mean beam noise (heatmap units) per unit of the detection statistic's noise."""
        m = self.num_elements
        if sig2 is None:
            return 1.0 / (m * self.looks)
        first = self.calib.antenna.virtual.first_pair
        nrx = self.calib.antenna.num_rx
        used = sig2[first[:, 0] * nrx + first[:, 1]]
        return float(used.sum() / (m * m * sig2.sum()))


def group_peaks(stat: np.ndarray, mask: np.ndarray, noise: np.ndarray,
                nxt: np.ndarray | None) -> np.ndarray:
    """The detection mask after peak grouping (numpy; :func:`~coloradar.dsp._kernels.group_peaks`
    is the compiled one): CFAR cells ``mask`` that are maxima of their 3 × 3 neighbourhood of
    ``stat`` ``(doppler, range)`` (Doppler wrapped; the bin after the last range bin,
    ``nxt`` ``(doppler,)``, compared where given; diagonals with range mirrored), and CFAR
    cells that peak along one axis within one cell of a peak ``STRONG_NEIGHBOUR`` times
    its ``noise``."""
    nd, nr = stat.shape
    # (neighbours compared in place, no rolled copies of the map)
    along_d = np.empty(stat.shape, dtype=bool)
    along_d[1:] = stat[1:] >= stat[:-1]
    along_d[0] = stat[0] >= stat[-1]
    along_d[:-1] &= stat[:-1] >= stat[1:]
    along_d[-1] &= stat[-1] >= stat[0]
    along_r = np.ones(stat.shape, dtype=bool)
    along_r[:, :-1] = stat[:, :-1] >= stat[:, 1:]
    if nxt is not None:
        along_r[:, -1] = stat[:, -1] >= nxt
    along_r[:, 1:] &= stat[:, 1:] >= stat[:, :-1]
    peaks = mask & along_d & along_r
    # The 3×3 maximum (Doppler wrapped, range mirrored) on the few cells left: the
    # cross is the two tests above, the diagonals remain (a mirrored range edge
    # repeats the inner column: the same diagonals).
    cd, cr = np.nonzero(peaks)
    if cd.size and nr > 1:
        lo = np.where(cr > 0, cr - 1, 1)
        hi = np.where(cr < nr - 1, cr + 1, nr - 2)
        dm, dp = (cd - 1) % nd, (cd + 1) % nd
        v = stat[cd, cr]
        diag = ((v >= stat[dm, lo]) & (v >= stat[dm, hi]) & (v >= stat[dp, lo])
                & (v >= stat[dp, hi]))
        peaks[cd[~diag], cr[~diag]] = False
    # Cells that peak along one axis only are examined beside a strong 2D peak (a
    # target one bin from a stronger one); elsewhere they would add noise crossings.
    strong = peaks & (stat >= STRONG_NEIGHBOUR * noise)
    # (the 3×3 dilation of the few strong cells, Doppler wrapped, range clipped)
    sd, sr = np.nonzero(strong)
    beside = np.zeros(stat.shape, dtype=bool)
    for o in (-1, 0, 1):
        beside[((sd + o) % nd)[:, None],
               np.clip(sr[:, None] + np.array([-1, 0, 1]), 0, nr - 1)] = True
    return peaks | (mask & (along_d | along_r) & beside)
