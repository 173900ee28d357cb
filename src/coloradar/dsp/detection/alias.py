"""The alias choice of detection: which Doppler alias of the TDM-MIMO array's folded range rate
each detection has (:mod:`coloradar.dsp.tdm`).

Input: each detection's channel vector compensated at its folded Doppler; output: its alias
``m`` (the range rate is the folded one plus ``2m·v_max``) and the confidence of that choice.
Settings: :class:`~coloradar.dsp.settings.AliasSettings`.

A hypothesis ``m`` is a phase ``2π·m·t/Ntx`` on TX slot ``t``; so is a board's TX phase error.
The search therefore runs only on a phase-calibrated array; on an uncalibrated one
(``uncalibrated_alias="fold"``, the default) every detection keeps its folded rate, and its
confidence says how well the folded hypothesis fits the nominal phases (docs/dsp.md,
"Doppler beyond ±v_max").
"""

from __future__ import annotations

import numpy as np

from ...calib import RadarCalib
from ..angle import row_profile
from ..array import OverlapMode, combine_channels
from ..cube_stage import CubeStage
from ..detect import source_fit_residuals
from ..settings import AliasSettings
from ..tdm import alias_hypotheses, alias_phase, overlap_pairs
from .beams import Beams

__all__ = ["AliasStage"]


class AliasStage:
    """Doppler alias choice of one radar's detections.

    Parameters
    ----------
    calib
        The radar's calibration.
    cube, beams
        The cube stage (Doppler bins, TDM) and the detection beams (the filled row).
    settings
        The stage's settings.
    overlap
        How overlapping virtual pairs are combined (``ArraySettings.overlap``).
    angle_pfa
        Probability that noise alone makes a second source (``AngleSettings.angle_pfa``).
    calibrated
        Whether the channels reach this stage phase-calibrated (a phase calibration in
        ``calib``, applied). When False and ``settings.uncalibrated_alias`` is ``"fold"``,
        :meth:`choose` keeps the folded hypothesis.
    """

    def __init__(self, calib: RadarCalib, cube: CubeStage, beams: Beams,
                 settings: AliasSettings, overlap: OverlapMode, angle_pfa: float,
                 calibrated: bool = True) -> None:
        self.calib, self.cube, self.beams = calib, cube, beams
        self.settings, self.overlap = settings, overlap
        self.fold = not calibrated and settings.uncalibrated_alias == "fold"
        """True: every detection keeps its folded rate (an uncalibrated array)."""
        ntx = calib.waveform.num_tx
        nd = cube.doppler_fft_size
        # Doppler disambiguation (coloradar.dsp.tdm).
        limit = settings.doppler_unwrap if (cube.tdm is not None and ntx > 1) else 0.0
        vmax = 0.5 * nd * (cube.velocities[1] - cube.velocities[0])
        self.hypotheses = alias_hypotheses(ntx, vmax, limit)
        """int ``(H,)``: the alias hypotheses searched (``[0]``: the search is off)."""
        pairs = overlap_pairs(calib.antenna.virtual)
        self.pairs = pairs if pairs.resolves(self.hypotheses) else None
        self.margin = 10.0 ** (-settings.alias_margin_db / 10)
        # Doppler alias search without overlapping pairs: one- and two-source fits of the
        # filled row under each hypothesis (choose); a second source must explain more than
        # noise reaches in the best of the row's ~M_row beams at angle_pfa.
        self.penalty = float(np.log(beams.row_sel.sum() / angle_pfa))

    def choose(self, vecs: np.ndarray, k_signed: np.ndarray,
               noise: np.ndarray | None = None
                      ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Doppler alias per detection (:mod:`coloradar.dsp.tdm`) and its confidence.

        ``vecs``: complex ``(tx, rx, K)`` compensated at the folded Doppler ``k_signed``;
        ``noise``: float ``(K,)``, the mean noise power per virtual element of each
        detection (None: radars without overlapping pairs score by the row beam's peak).
        Returns ``(None, None)`` when the search is off; else int64 ``(K,)`` aliases and
        float64 ``(K,)`` confidences (:meth:`confidence`; NaN without ``noise``). On an
        uncalibrated array with ``uncalibrated_alias="fold"`` every alias is 0 and its
        confidence is that of the folded hypothesis under the nominal phases.

        Without overlapping pairs the choice is a model selection on the filled row: each
        hypothesis ``m`` is fitted with one source and with two (:func:`~coloradar.dsp.
        detect.source_fit_residuals`), the two-source fit charged ``ln(M_row/angle_pfa)``
        noise powers (what the best of the row's beams reaches on noise alone at
        ``angle_pfa``), and the hypothesis whose better model leaves the least wins. One
        aliased source is no pair of sources at another alias (the best such pair leaves
        8 % of its power on the single chip's 8-element row), and two sources in one cell
        are no aliased single source (≥ 38 % left at 30° apart), so both are told apart
        where the scorer by peak confused them (docs/dsp.md).
        """
        hyps = self.hypotheses
        if hyps.size < 2:
            return None, None
        ntx, nrx, k = vecs.shape
        nd = self.cube.doppler_fft_size
        dv = self.cube.velocities[1] - self.cube.velocities[0]
        rates = (k_signed[:, None] + hyps[None, :] * nd) * dv                  # (K, H)
        allowed = (np.abs(rates) <= self.settings.doppler_unwrap) | (hyps[None, :] == 0)
        if self.pairs is not None:
            score = self.pairs.scores(vecs.reshape(ntx * nrx, k).T, hyps)
        else:
            g = self.beams.grid
            ph = alias_phase(ntx, hyps)                                        # (tx, H)
            score = np.empty((k, hyps.size))
            power = np.empty(k)
            step = 1024
            for k0 in range(0, k, step):
                ks = slice(k0, min(k, k0 + step))
                kk = ks.stop - k0
                cand = vecs[:, :, ks, None] * ph[:, None, None, :]             # (tx, rx, k, H)
                el = combine_channels(cand, self.calib.antenna.virtual, self.overlap)
                # The filled azimuth row: a wrong hypothesis puts a phase step between the TX
                # blocks along it and defocuses it (no elevation ghosts).
                if noise is not None:
                    row = el[self.beams.row_sel].reshape(-1, kk * hyps.size).T       # (k·H, M_row)
                    pen = np.repeat(self.penalty * noise[ks], hyps.size)
                    ok = allowed[ks].reshape(-1)

                    def need(rss1: np.ndarray, kk: int = kk, pen: np.ndarray = pen,
                             ok: np.ndarray = ok) -> np.ndarray:
                        # Where the best one-source fit leaves no more than a second source
                        # is charged, no two-source fit can win: those detections skip it, as
                        # do the hypotheses out of the unwrap range (their score is -inf).
                        lowest = rss1.reshape(kk, hyps.size).min(axis=1)
                        return np.repeat(lowest > pen[::hyps.size], hyps.size) & ok

                    kern = (self.beams.tables["k"].source_pairs
                            if self.beams.tables is not None else None)
                    rss1, rss2 = source_fit_residuals(row, g.az_pos[self.beams.row_sel], g.n_az,
                                                      self.beams.row_bins, fit=need, kernel=kern)
                    left = np.minimum(rss1, rss2 + pen)
                    # power explained by the hypothesis' better model (same |x|² for all)
                    tot = np.sum(np.abs(row) ** 2, axis=1)
                    power[ks] = tot[::hyps.size]
                    sc = (tot - left).reshape(kk, hyps.size)
                else:
                    prof = row_profile(g, el.reshape(el.shape[0], kk * hyps.size).T,
                                       workers=self.cube.settings.workers)
                    prof = np.where(self.beams.visible_az[None], prof, 0.0)
                    sc = prof.reshape(kk, hyps.size, g.num_az).max(axis=2)
                # (optional margin for the folded hypothesis, alias_margin_db)
                sc = np.where(hyps[None, :] == 0, sc, sc * self.margin)
                sc = np.where(allowed[ks], sc, -np.inf)
                score[ks] = sc
        score = np.where(allowed, score, -np.inf)
        folded = np.full(k, int(np.flatnonzero(hyps == 0)[0]), dtype=np.int64)
        rows = power if (self.pairs is None and noise is not None) else None
        if self.fold:
            return hyps[folded], self.confidence(score, folded, vecs, noise, rows)
        best = np.argmax(score, axis=1) if k else np.zeros(0, dtype=np.int64)
        conf = self.confidence(score, best, vecs, noise, rows)
        # Another alias only on evidence: where its probability is below the setting's, the
        # folded rate is kept and the confidence is the folded hypothesis'.
        weak = (best != folded) & (conf < self.settings.alias_min_confidence)   # NaN: kept
        if np.any(weak):
            best = np.where(weak, folded, best)
            conf = np.where(weak, self.confidence(score, folded, vecs, noise, rows), conf)
        return hyps[best], conf

    def confidence(self, score: np.ndarray, best: np.ndarray, vecs: np.ndarray,
                   noise: np.ndarray | None, rows: np.ndarray | None = None) -> np.ndarray:
        """Posterior probability of each detection's chosen hypothesis, float64 ``(K,)``.

        Under white Gaussian noise of power ``noise`` per element and equal priors, a
        hypothesis' log-likelihood is the power its model explains over the noise (single
        chip: ``score / noise``) or its pair coherence times ``Σ|z_a z_b| / noise``
        (overlapping pairs: ``|z_a − z_b e^{jθ}|²/2σ²`` expanded). The probability is the
        chosen one's share of ``Σ_h exp(LL_h)`` over the hypotheses within the unwrap range.

        A cell that no hypothesis' model fits (a real array's diffuse clutter, several
        scatterers, wide-angle element errors: its best model leaves far more than noise) is
        not decided by noise: with ``rows`` (the row power of each detection, single chip)
        the noise is raised to what the best model leaves per remaining degree of freedom
        (``M_row − 2``), so that such cells get low confidences. It is computed with the
        array's phases as they are: on an uncalibrated array it is a flag (low: another alias
        fits the nominal phases better), not a probability.
        """
        k = score.shape[0]
        if noise is None or k == 0:
            return np.full(k, np.nan)
        nz = np.maximum(np.asarray(noise, dtype=np.float64), 1e-30)
        if self.pairs is not None:
            ntx, nrx, _ = vecs.shape
            x = vecs.reshape(ntx * nrx, k).T
            den = np.abs(x[:, self.pairs.a] * np.conj(x[:, self.pairs.b])).sum(axis=1)
            ll = score * (den / nz)[:, None]
        else:
            if rows is not None:
                dof = max(int(self.beams.row_sel.sum()) - 2, 1)
                nz = np.maximum(nz, (rows - np.max(score, axis=1)) / dof)
            ll = score / nz[:, None]
        ll = np.where(np.isfinite(ll), ll, -np.inf)
        top = ll.max(axis=1, keepdims=True)
        w = np.exp(ll - top)
        return np.asarray(w[np.arange(k), best] / w.sum(axis=1), dtype=np.float64)
