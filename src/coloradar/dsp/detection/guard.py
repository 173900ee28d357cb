"""The guard stage of detection: which of the resolved sources are points. A point must be the
maximum of its own beam over its 3 × 3 range–Doppler neighbourhood (peak grouping), must not be
the leak of a return beyond the last processed range bin, and must not be explained by a
stronger cell's window sidelobes in its direction (sidelobe guard).

Input: the sources of the resolution stage and the CFAR's cells; output: a keep mask and each
source's beam neighbourhood (which the point stage refines range and Doppler on). Settings:
:class:`~coloradar.dsp.settings.GuardSettings`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...calib import RadarCalib
from ..array import OverlapMode, combine_channels
from ..cube_stage import CubeStage
from ..detect import sidelobe_envelope, sidelobe_pairs
from ..settings import GuardSettings
from ..tdm import alias_phase, tdm_phase
from ..windows import window
from ._common import c64, f64
from .beams import Beams
from .cfar_stage import CFARCells

__all__ = ["Explainers", "GuardStage", "Sources"]


@dataclass(frozen=True)
class Explainers:
    """CFAR cells that may explain weaker points by their sidelobes (those inside
    ``min_range`` included): Doppler and range bins and statistic, ``(K,)`` each."""

    d: np.ndarray
    r: np.ndarray
    power: np.ndarray


@dataclass(frozen=True)
class Sources:
    """Resolved sources (:meth:`~coloradar.dsp.detection.resolve.ResolveStage.resolve`): their
    cells' Doppler and range bins and aliases, direction sines, beam powers, float64 ``(P,)``,
    and beam weights complex64 ``(M, P)``."""

    d: np.ndarray
    r: np.ndarray
    alias: np.ndarray | None
    uy: np.ndarray
    uz: np.ndarray
    peak: np.ndarray
    steer: np.ndarray


class GuardStage:
    """Peak grouping by beams, the edge test and the sidelobe guard of one radar's points.

    Parameters
    ----------
    calib
        The radar's calibration.
    cube, beams
        The cube stage (windows, TDM) and the detection beams.
    settings
        The stage's settings.
    overlap, peak_grouping
        ``ArraySettings.overlap`` and ``CFARSettings.peak_grouping``.
    """

    def __init__(self, calib: RadarCalib, cube: CubeStage, beams: Beams,
                 settings: GuardSettings, overlap: OverlapMode, peak_grouping: bool) -> None:
        self.calib, self.cube, self.beams = calib, cube, beams
        self.settings, self.overlap, self.peak_grouping = settings, overlap, peak_grouping
        cs = cube.settings
        ns, nd = calib.waveform.num_samples, cube.doppler_fft_size
        # Sidelobe envelopes (Doppler wraps: lags up to nd//2).
        self.env_doppler = sidelobe_envelope(window(cs.doppler_window, calib.waveform.num_chirps),
                                             nd, nd // 2 + 1)
        self.env_range = sidelobe_envelope(window(cs.range_window, ns), cube.range_fft_size,
                                           cube.num_range_bins)
        # The last processed range bin: a tone within half a bin of it gives at most this
        # power ratio to the bin before (window main lobe); beyond it, more.
        self.edge_ratio = _edge_ratio(window(cs.range_window, ns), cube.range_fft_size)

    def keep(self, rd: np.ndarray, rd_next: np.ndarray | None, found: CFARCells,
             src: Sources, floor: np.ndarray, explain: Explainers
             ) -> tuple[np.ndarray, np.ndarray]:
        """Which sources are points (bool ``(P,)``), and the beam of each source's 3 × 3
        neighbourhood (:meth:`beam_neighbourhood`); ``floor`` float64 ``(P,)`` the beam power a
        noise peak reaches in each source's cell."""
        stat, noise = found.stat, found.noise
        pd, pr, palias, steer = src.d, src.r, src.alias, src.steer
        nr = stat.shape[1]
        # Beam of the 3×3 range–Doppler neighbourhood at each point's direction.
        nb = self.beam_neighbourhood(rd, pd, pr, palias, steer, rd_next)  # (P, 3, 3)
        keep = np.ones(pd.size, dtype=bool)
        if self.peak_grouping and pd.size:
            # A point is a maximum of its own beam over its neighbours: a target one bin from
            # a stronger one in another direction stays, the skirt of one target goes.
            centre = nb[:, 1, 1]
            keep &= np.all(nb.reshape(-1, 9) <= centre[:, None] * (1 + 1e-6), axis=1)
        if nr > 1 and pd.size and found.next_row is None:
            # A return beyond the last processed bin leaks into it with a slope no target
            # inside (within half a bin of it) can make.
            last = pr == nr - 1
            keep &= ~(last & (nb[:, 1, 1] > self.edge_ratio * nb[:, 1, 0]))
        if self.settings.sidelobe_guard and pd.size and explain.d.size > 1:
            # (beam power above the level a noise peak reaches: the direction is a maximum)
            keep &= self.sidelobes(rd, (pd, pr), palias, steer, nb[:, 1, 1] - floor, floor,
                                   stat[pd, pr] - noise[pd, pr], stat[pd, pr], explain)
        return keep, nb

    def beam_neighbourhood(self, rd: np.ndarray, d: np.ndarray, r: np.ndarray,
                           alias: np.ndarray | None, steer: np.ndarray,
                           rd_next: np.ndarray | None = None) -> np.ndarray:
        """Bartlett beam power at each point's direction in the 3 × 3 range–Doppler cells
        around its cell: float64 ``(P, 3, 3)`` [Doppler offset −1..1, range offset −1..1].

        ``rd`` and ``rd_next`` without TDM phases (as
        :meth:`~coloradar.dsp.detection.detector.Detector.detect`). Each Doppler bin gets its
        own TDM compensation (across the Doppler edge that of the unwrapped neighbour)
        and the point's alias; range neighbours beyond the map repeat the edge cell.
        """
        ntx, nrx, nd, nr = rd.shape
        p = d.size
        out = np.zeros((p, 3, 3))
        if p == 0:
            return out
        kb = self.beams.tables
        if kb is not None and self.overlap == "first":
            nxt = (rd_next[..., 0].reshape(ntx * nrx, nd)
                   if rd_next is not None and rd_next.shape[-1] else np.zeros((0, 0)))
            kb["k"].beam_neighbourhood(
                c64(rd.reshape(ntx * nrx, nd, nr)), c64(nxt), kb["chan"], kb["tx"], ntx,
                np.ascontiguousarray(d, dtype=np.int64), np.ascontiguousarray(r, dtype=np.int64),
                f64(np.zeros(p) if alias is None else alias), self.cube.tdm is not None,
                c64(steer), out)
            return out
        m2 = float(self.beams.grid.num_elements) ** 2
        for i, j in enumerate((-1, 0, 1)):
            dn = (d + j) % nd
            ph = None
            if self.cube.tdm is not None:
                ph = tdm_phase(ntx, (d + j - dn).astype(np.float64), nd)
            if alias is not None:
                a = alias_phase(ntx, alias)
                ph = a if ph is None else ph * a
            for k, jr in enumerate((-1, 0, 1)):
                rn = np.clip(r + jr, 0, nr - 1)
                v = rd[:, :, dn, rn]
                if jr == 1 and rd_next is not None and rd_next.shape[-1]:
                    beyond = r + 1 >= nr
                    v = np.where(beyond[None, None, :], rd_next[:, :, dn, 0], v)
                if self.cube.tdm is not None:
                    v = v * self.cube.tdm_at(dn)
                if ph is not None:
                    v = v * ph[:, None, :]
                el = combine_channels(v, self.calib.antenna.virtual, self.overlap)
                out[:, i, k] = np.abs(np.einsum("mp,mp->p", el, steer)) ** 2 / m2
        return out

    def sidelobes(self, rd: np.ndarray, cells: tuple[np.ndarray, np.ndarray],
                  alias: np.ndarray | None, steer: np.ndarray, beam_excess: np.ndarray,
                  beam_floor: np.ndarray, cell_excess: np.ndarray, cell_pow: np.ndarray,
                  explain: Explainers) -> np.ndarray:
        """Sidelobe guard on points: True = keep.

        First on the summed power (:func:`~coloradar.dsp.detect.sidelobe_pairs`): which
        stronger cells, two or more bins away, could explain a point's cell by the windows'
        worst-case leakage. Then per such pair in the point's own direction: leakage of cell
        ``j`` into the point's cell is ``E_d·E_r`` times ``j``'s beam, so the point stays
        when its beam power above the noise exceeds the margin times ``E_d·E_r·B_j(u)``;
        a weaker target in another direction is then kept beside a strong one.
        """
        d, r = cells
        exp_d, exp_r = explain.d, explain.r
        margin = 10.0 ** (self.settings.sidelobe_margin_db / 10)
        pi, pj, leak = sidelobe_pairs(d, r, cell_pow, cell_excess,
                                      (exp_d, exp_r, explain.power),
                                      (self.env_doppler, self.env_range), rd.shape[2], margin)
        keep = np.ones(d.size, dtype=bool)
        if pi.size == 0:
            return keep
        ntx = rd.shape[0]
        jd, jr = exp_d[pj], exp_r[pj]
        v = rd[:, :, jd, jr]
        if self.cube.tdm is not None:
            v = v * self.cube.tdm_at(jd)
        if alias is not None:
            v = v * alias_phase(ntx, alias[pi])[:, None, :]
        el = combine_channels(v, self.calib.antenna.virtual, self.overlap)
        bj = np.abs(np.einsum("mp,mp->p", el, steer[:, pi])) ** 2 / float(
            self.beams.grid.num_elements) ** 2
        # Only a point outside cell j's main lobe is rescued by its direction (there the beam
        # of j has fallen below half its peak, which is at most j's mean element power).
        peak_j = np.mean(np.abs(el) ** 2, axis=0)
        # and only when it stands clear of the noise (twice the level a noise peak reaches)
        explained = ((beam_excess[pi] < margin * leak * bj) | (bj >= 0.5 * peak_j)
                     | (beam_excess[pi] < beam_floor[pi]))
        keep[pi[explained]] = False
        return keep


def _edge_ratio(win: np.ndarray, fft_size: int) -> float:
    """``|W(½)|² / |W(1½)|²``: power of a tone's cell over the next cell when it lies half a
    bin beyond the cell centre (``W`` the window's DTFT in FFT bins, zero padding included)."""
    w = np.asarray(win, dtype=np.float64)
    k = np.arange(w.size)

    def resp(nu: float) -> float:
        return float(np.abs(np.sum(w * np.exp(-2j * np.pi * nu * k / fft_size))) ** 2)

    return resp(0.5) / max(resp(1.5), 1e-300)
