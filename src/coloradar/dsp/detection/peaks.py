"""The peaks stage of detection: the angle peaks of each detected cell — the strongest source's
direction and, with ``multi_peak``, every other significant peak of the cell's azimuth profile
(or Capon spectrum), each with a first elevation and beam power.

Input: :class:`Cells`, the detected cells' channel vectors compensated for TDM and alias;
output: :class:`Peaks`. Settings: :class:`~coloradar.dsp.settings.AngleSettings`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...calib import RadarCalib
from ..angle import azimuth_peaks, capon_spectrum, refine_peak, row_profile
from ..array import OverlapMode, combine_channels
from ..cube_stage import CubeStage
from ..settings import AngleSettings
from ..tdm import alias_phase, tdm_phase
from ._common import firsts
from .beams import Beams

__all__ = ["Cells", "PeakStage", "Peaks"]


@dataclass(frozen=True)
class Cells:
    """Detected range–Doppler cells that make points (beyond ``min_range``), ``K`` of them.

    Attributes
    ----------
    d, r
        int64 ``(K,)`` Doppler and range bins.
    d_ref
        float64 ``(K,)`` Doppler bin refined on the statistic (log-parabola).
    vectors
        complex ``(K, M)``: each cell's unique virtual elements, compensated for TDM at
        ``d_ref`` and for the alias.
    alias
        int ``(K,)`` Doppler alias of each cell, or None (search off).
    beam_noise
        float64 ``(K,)`` mean noise power of the cell's beam (heatmap units).
    alias_confidence
        float64 ``(K,)`` confidence of each cell's alias (``AliasStage.confidence``), or None
        (search off).
    """

    d: np.ndarray
    r: np.ndarray
    d_ref: np.ndarray
    vectors: np.ndarray
    alias: np.ndarray | None
    beam_noise: np.ndarray
    alias_confidence: np.ndarray | None = None


@dataclass(frozen=True)
class Peaks:
    """Angle peaks of the cells, the strongest of each cell first (``P`` of them).

    Attributes
    ----------
    ci
        int64 ``(P,)`` cell of each peak (index into :class:`Cells`).
    uy, uz
        float64 ``(P,)`` direction sines (``uz`` NaN where the compiled path defers a
        secondary peak's elevation to the resolution stage).
    peak
        float64 ``(P,)`` beam power at the peak.
    floor
        float64 ``(K,)`` beam power a noise peak reaches in each cell.
    cell_range
        float64 ``(K,)`` each cell's range [m] (focusing).
    """

    ci: np.ndarray
    uy: np.ndarray
    uz: np.ndarray
    peak: np.ndarray
    floor: np.ndarray
    cell_range: np.ndarray


class PeakStage:
    """Angle peaks of one radar's detected cells.

    Parameters
    ----------
    calib
        The radar's calibration.
    cube, beams
        The cube stage (TDM, range bins) and the detection beams.
    settings
        The angle settings.
    overlap
        ``ArraySettings.overlap``.
    """

    def __init__(self, calib: RadarCalib, cube: CubeStage, beams: Beams,
                 settings: AngleSettings, overlap: OverlapMode) -> None:
        self.calib, self.cube, self.beams = calib, cube, beams
        self.settings, self.overlap = settings, overlap
        # Secondary angle peaks: above the array's sidelobes and above the beam noise
        # (exponential beam power; about one independent beam per unique element).
        self.floor_factor = float(np.log(beams.grid.num_elements / settings.angle_pfa))
        self.dynamic = 10.0 ** (-settings.angle_dynamic_range_db / 10)

    def capon(self, rcube: np.ndarray, cells: Cells) -> np.ndarray:
        """Capon (MVDR) spectra ``(K, el, az)`` of the cells from their chirps' snapshots."""
        ntx, nd = rcube.shape[0], self.cube.doppler_fft_size
        r, alias = cells.r, cells.alias
        k_signed = cells.d_ref - nd // 2
        snaps = rcube[:, :, :, r]                                        # (tx, rx, chirp, K)
        if self.cube.tdm is not None:
            ph = tdm_phase(ntx, k_signed, nd)
            if alias is not None:
                ph = ph * alias_phase(ntx, alias)
            snaps = snaps * ph[:, None, None, :]
        snaps = combine_channels(snaps, self.calib.antenna.virtual, self.overlap)
        return capon_spectrum(self.beams.grid, snaps.transpose(2, 1, 0), cells.vectors,
                              self.settings.capon_loading, workers=self.cube.settings.workers)

    def find(self, cells: Cells, rcube: np.ndarray) -> Peaks:
        """The angle peaks of ``cells`` (``rcube``: the range cube, for Capon's snapshots)."""
        s, b = self.settings, self.beams
        d, r, vectors = cells.d, cells.r, cells.vectors
        spec = self.capon(rcube, cells) if s.angle_method == "capon" and d.size else None
        floor = self.floor_factor * cells.beam_noise
        rho_cell = np.maximum(r, 1) * self.cube.range_bin_width
        rel = self.dynamic if s.multi_peak else np.inf
        if s.angle_method == "fft":
            # Sources and their azimuths from the filled row (the noise floor of a row beam
            # is M/M_row times that of the full beam), each elevation from the rows' sums.
            prof = row_profile(b.grid, vectors, workers=self.cube.settings.workers,
                               row=b.row_sel)
            prof = np.where(b.visible_az[None], prof, 0.0)
            ci, ia = b.azimuth_peaks(prof, rel, floor * b.row_noise if s.multi_peak
                                     else np.full(d.size, np.inf))
            na = b.grid.num_az
            fa = refine_peak(np.stack([prof[ci, (ia - 1) % na], prof[ci, ia],
                                       prof[ci, (ia + 1) % na]], axis=1), ia, na, wrap=True)
            uy = 2.0 * (fa - na // 2) / (na * b.grid.rho)
            if b.tables is not None and (not b.focus or b.near_terms is not None):
                # Secondary peaks get their elevation in the resolution stage once their
                # cell's strongest source is known (most are its sidelobes and need none):
                # NaN here.
                lead = firsts(ci) if ci.size else np.zeros(0, dtype=bool)
                uz, peak = np.full(ci.size, np.nan), np.zeros(ci.size)
                uz[lead], peak[lead] = b.elevation_search(vectors[ci[lead]], uy[lead],
                                                          rho_cell[ci[lead]])
            else:
                uz, peak = b.elevation_search(vectors[ci], uy, rho_cell[ci])
        else:
            if spec is None:
                g = b.grid
                spec = np.zeros((0, g.num_el, g.num_az))
            masked = np.where(b.visible[None], spec, 0.0)
            ci, ia = azimuth_peaks(masked.max(axis=1), rel, floor if s.multi_peak
                                   else np.full(d.size, np.inf))
            ie = masked[ci, :, ia].argmax(axis=1)
            uy, uz, peak = b.peak_directions(spec, ci, ie, ia)
        return Peaks(ci, uy, uz, peak, floor, rho_cell)
