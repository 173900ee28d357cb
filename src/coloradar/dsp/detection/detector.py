"""Detection as a chain of stages, composed by :class:`Detector`::

    range–Doppler cube (without TDM phases)
      → CFARStage    statistic, CFAR, peak grouping            → CFARCells
      → cells        Doppler refined, TDM compensated, alias   → Cells      (AliasStage)
      → PeakStage    angle peaks of each cell                   → Peaks
      → ResolveStage Newton refinement, several sources         → Sources
      → GuardStage   beam grouping, edge test, sidelobe guard   → keep mask
      → PointStage   range, range rate, position                → Detections
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...calib import RadarCalib
from ..angle import refine_peak
from ..array import combine_channels
from ..cube_stage import CubeStage
from ..detect import Detections
from ..settings import ProcessingSettings
from ..tdm import alias_phase, tdm_phase
from .alias import AliasStage
from .beams import Beams
from .cfar_stage import CFARCells, CFARStage
from .guard import Explainers, GuardStage, Sources
from .peaks import Cells, PeakStage
from .points import PointStage
from .resolve import ResolveStage

__all__ = ["Detector"]


class Detector:
    """The detection stages of one radar, composed.

    Parameters
    ----------
    calib
        The radar's calibration.
    settings
        All settings (each stage takes its group).
    cube
        The cube stage whose cubes are detected on.
    """

    def __init__(self, calib: RadarCalib, settings: ProcessingSettings,
                 cube: CubeStage) -> None:
        s = settings
        self.calib, self.cube, self.overlap = calib, cube, s.overlap
        self.beams = Beams(calib, s.array, s.angle, s.phase_frequency_calibration, cube.engine)
        self.cfar = CFARStage(calib, cube, s.cfar, s.coupling_subtraction,
                              self.beams.grid.num_elements)
        calibrated = s.phase_frequency_calibration and calib.phase_frequency is not None
        self.alias = AliasStage(calib, cube, self.beams, s.alias, s.overlap, s.angle_pfa,
                                calibrated)
        self.peaks = PeakStage(calib, cube, self.beams, s.angle, s.overlap)
        self.resolve = ResolveStage(self.beams, s.angle)
        self.guard = GuardStage(calib, cube, self.beams, s.guard, s.overlap, s.peak_grouping)
        self.points = PointStage(calib, cube, s.points, s.array)

    def detect(self, rcube: np.ndarray, rd: np.ndarray, rd_next: np.ndarray | None = None
               ) -> Detections:
        """Detections of a range–Doppler cube ``rd`` *without* its TDM phases
        (``CubeStage.doppler(…, compensate=False)``: the power map does not need them, and the
        cells read get them from :meth:`CubeStage.tdm_at
        <coloradar.dsp.cube_stage.CubeStage.tdm_at>`); ``rcube`` the range cube (Capon's
        snapshots); ``rd_next`` (tx, rx, doppler, 1 or 0), the same for the range bin after
        the last one, when computed (a return beyond the processed range then makes no local
        maximum at the last bin)."""
        found = self.cfar.run(rd, rd_next)
        cells, explain = self.cells(rd, found)
        pk = self.peaks.find(cells, rcube)
        ci = pk.ci
        uy, uz, peak, steer, ci = self.resolve.resolve(cells.vectors[ci], ci, pk.uy, pk.uz,
                                                       pk.peak, pk.cell_range[ci], pk.floor)
        palias = cells.alias[ci] if cells.alias is not None else None
        src = Sources(cells.d[ci], cells.r[ci], palias, uy, uz, peak, steer)
        keep, nb = self.guard.keep(rd, rd_next, found, src, pk.floor[ci], explain)
        kept = Sources(src.d[keep], src.r[keep], palias[keep] if palias is not None else None,
                       uy[keep], uz[keep], peak[keep], steer[:, keep])
        det = self.points.place(kept, nb[keep], cells.d_ref[ci[keep]], found)
        if cells.alias_confidence is not None:
            det = replace(det, alias_confidence=cells.alias_confidence[ci[keep]])
        return det

    def cells(self, rd: np.ndarray, found: CFARCells) -> tuple[Cells, Explainers]:
        """The detected cells beyond ``min_range`` with their compensated vectors and aliases,
        and every detected cell as a possible explainer of sidelobes."""
        stat, noise = found.stat, found.noise
        nd = stat.shape[0]
        d, r = np.nonzero(found.mask)
        near = r < int(np.ceil(self.cfar.settings.min_range / self.cube.range_bin_width))
        # Cells inside min_range still explain sidelobes (guard); they make no points.
        explain = Explainers(d, r, stat[d, r])
        d, r = d[~near], r[~near]
        d_ref = refine_peak(np.stack([stat[(d - 1) % nd, r], stat[d, r],
                                      stat[(d + 1) % nd, r]], axis=1), d, nd, wrap=True)
        k_signed = d_ref - nd // 2
        ntx = rd.shape[0]
        vecs = rd[:, :, d, r]                                           # (tx, rx, K)
        if self.cube.tdm is not None:
            # bin-centre compensation, then the fractional remainder
            vecs = vecs * self.cube.tdm_at(d)
            vecs = vecs * tdm_phase(ntx, d_ref - d, nd)[:, None, :]
        # Beam noise per cell: the CFAR noise of the statistic, per channel, on the beam of the
        # unique elements (|aᴴn|²/M² has mean Σ_m σ_m²/M²).
        beam_noise = noise[d, r] * self.cfar.beam_noise_factor(found.sig2)
        alias, conf = self.alias.choose(vecs, k_signed,
                                        beam_noise * self.beams.grid.num_elements)
        if alias is not None:
            vecs = vecs * alias_phase(ntx, alias)[:, None, :]
        vectors = combine_channels(vecs, self.calib.antenna.virtual, self.overlap).T  # (K, M)
        return Cells(d, r, d_ref, vectors, alias, beam_noise, conf), explain

    def cell_aliases(self, rd: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The CFAR cells of ``rd`` (TDM-compensated at the bin centres) whose best Doppler alias
        is not the folded one, as detections choose it at the bin centre: their Doppler bins,
        range bins and aliases; None where the search is off or no cell passes the CFAR."""
        if self.alias.hypotheses.size < 2 or self.alias.fold:
            return None
        stat, _, looks, sig2 = self.cfar.statistic(rd)
        mask, noise = self.cfar.cfar_mask(stat, looks)
        d, r = np.nonzero(mask)
        if d.size == 0:
            return None
        nd = rd.shape[2]
        elem_noise = (noise[d, r] * self.cfar.beam_noise_factor(sig2)
                      * self.beams.grid.num_elements)
        alias, _ = self.alias.choose(rd[:, :, d, r], (d - nd // 2).astype(np.float64),
                                     elem_noise)
        assert alias is not None
        moved = alias != 0
        return d[moved], r[moved], alias[moved]
