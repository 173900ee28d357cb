"""The several-source resolution of detection: each angle peak refined off the grid, and which
secondary peaks of a cell are sources rather than the strongest one's sidelobes.

Input: the peaks of the peaks stage (:class:`~coloradar.dsp.detection.peaks.Peaks`) with their
cells' vectors; output: the kept sources' directions, beam powers and beam weights. Settings:
:class:`~coloradar.dsp.settings.AngleSettings`.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import f as f_dist

from ..settings import AngleSettings
from ._common import c64, f64, firsts, groups
from .beams import Beams

__all__ = ["MAX_SOURCES", "ResolveStage"]

MAX_SOURCES = 4
"""Most angle peaks examined per range–Doppler cell (strongest first)."""


class ResolveStage:
    """Several-source resolution of one radar's detections.

    Parameters
    ----------
    beams
        The detection beams.
    settings
        The angle settings (refinement, ``angle_pfa``, ``angle_dynamic_range_db``).
    """

    COMPILED_JOINT = True
    """Whether the numba engine refines cells with several sources with the compiled keep
    tests (:func:`~coloradar.dsp._kernels.joint_round`); False runs the numpy loop (the
    tests compare them)."""

    def __init__(self, beams: Beams, settings: AngleSettings) -> None:
        self.beams, self.settings = beams, settings
        self.refine = settings.angle_refine and settings.angle_method == "fft"
        """Whether directions are refined by Newton steps."""
        self.dynamic = 10.0 ** (-settings.angle_dynamic_range_db / 10)
        # F(2, 2ν) quantiles at angle_pfa/M for ν = 0..M complex degrees of freedom left
        # (index 0 unused): the residual test of residual_floor.
        m = beams.grid.num_elements
        nu = np.arange(m + 1)
        self.f_threshold = np.r_[np.inf, f_dist.isf(settings.angle_pfa / m, 2, 2 * nu[1:])]

    def resolve(self, x: np.ndarray, ci: np.ndarray, uy: np.ndarray, uz: np.ndarray,
                peak: np.ndarray, rho: np.ndarray, floor: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Refine the spectrum peaks and decide which secondary peaks are sources.

        ``x`` complex ``(P, M)``: the vector of each peak's cell; ``ci`` the cell of each peak,
        the strongest of each cell first. The strongest peak of a cell is refined by Newton
        steps on the focused beam. A secondary peak counts when, with the strongest source's
        response removed (its amplitude times the array's focused cross pattern), what is
        left in its direction is above the cell's noise ``floor`` and within
        ``angle_dynamic_range_db`` of the strongest: sidelobes of the strongest vanish there,
        a second scatterer does not. Cells with several sources are refined jointly (each
        source's direction on the vector less the others' least-squares fit).

        Returns
        -------
        tuple
            ``(u_y, u_z, power, weights, ci)`` of the kept peaks; ``weights`` ``(M, P)`` as
            :meth:`Beams.steer <coloradar.dsp.detection.beams.Beams.steer>`.
        """
        m = float(self.beams.grid.num_elements)
        primary = np.ones(ci.size, dtype=bool)
        primary[1:] = ci[1:] != ci[:-1]
        if self.refine and primary.any():
            uy[primary], uz[primary], peak[primary] = self.beams.newton(
                x[primary], uy[primary], uz[primary], rho[primary])
        wp = None
        if self.beams.tables is not None:
            deferred = np.isnan(uz) & ~primary     # secondaries without their elevation yet
            if deferred.any():
                uy, uz, peak, ci, x, rho, primary, wp = self._screen_secondaries(
                    x, ci, uy, uz, peak, rho, floor, primary, deferred)
        if wp is None:
            w = self.beams.steer(uy, uz, rho)                                # (M, P)
        else:
            # the primaries' weights were made for the screening (each column depends on
            # its own peak only: the same values); only the secondaries' are new
            w = np.empty((wp.shape[0], ci.size), dtype=wp.dtype)
            w[:, primary] = wp
            if not primary.all():
                sec = ~primary
                w[:, sec] = self.beams.steer(uy[sec], uz[sec], rho[sec])
        if primary.all():
            return uy, uz, peak, w, ci
        # amplitude of each cell's strongest source and its response in the other directions
        first = np.flatnonzero(primary)[np.cumsum(primary) - 1]        # primary peak of each
        sec = ~primary
        kb = self.beams.tables
        if kb is not None:
            resid, top = np.empty((2, ci.size))
            kb["k"].secondary_residual(c64(x), c64(w), first.astype(np.int64), resid, top)
            resid, top = resid[sec], top[sec]
        else:
            amp = np.einsum("pm,mp->p", x, w) / m
            cross = np.einsum("mp,mp->p", np.conj(w[:, first[sec]]), w[:, sec]) / m
            resid = np.abs(amp[sec] - amp[first[sec]] * cross) ** 2
            top = np.abs(amp[first[sec]]) ** 2
        ok = np.ones(ci.size, dtype=bool)
        ok[sec] = (resid >= floor[ci[sec]]) & (resid >= top * self.dynamic)
        uy, uz, peak, w, ci, x, rho = (uy[ok], uz[ok], peak[ok], w[:, ok], ci[ok], x[ok],
                                       rho[ok])
        return self._joint(x, w, ci, uy, uz, peak, rho, floor)

    def _joint(self, x: np.ndarray, w: np.ndarray, ci: np.ndarray, uy: np.ndarray,
               uz: np.ndarray, peak: np.ndarray, rho: np.ndarray, floor: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Cells with several sources after the secondary test, refined jointly (as
        :meth:`resolve` returns)."""
        kb = self.beams.tables
        # Joint least-squares amplitudes of each cell's remaining sources (sidelobes of a
        # second source get little of it), then each source refined on its cell's vector
        # less the others' fit; all batched over cells (at most MAX_SOURCES per cell).
        cell_of, count = groups(ci)
        if count.max() < 2:
            return uy, uz, peak, w, ci
        rank = np.arange(ci.size) - np.concatenate([[0], np.cumsum(count)[:-1]])[cell_of]
        keep = rank < MAX_SOURCES
        uy, uz, peak, w, ci, x, rho, rank, cell_of = (
            uy[keep], uz[keep], peak[keep], w[:, keep], ci[keep], x[keep], rho[keep],
            rank[keep], cell_of[keep])
        lone = None
        several = np.bincount(cell_of)[cell_of] > 1
        if not several.all():
            # Cells with one source are final. Every step below works cell by cell, so only
            # the cells with several take part (the same numbers, smaller arrays); the lone
            # ones join them again at the end, in cell order.
            one = ~several
            lone = uy[one], uz[one], peak[one], w[:, one], ci[one]
            uy, uz, peak, w, ci, x, rho, rank = (uy[several], uz[several], peak[several],
                                                 w[:, several], ci[several], x[several],
                                                 rho[several], rank[several])
        if (kb is not None and self.COMPILED_JOINT
                and (not self.beams.focus or self.beams.focus_tables is not None)):
            uy, uz, peak, w, ci = self._joint_compiled(x, w, ci, uy, uz, peak, rho, floor)
        else:
            uy, uz, peak, w, ci = self._joint_numpy(x, w, ci, uy, uz, peak, rho, floor,
                                                    cell_of if lone is None else None, rank)
        return self.join_lone(lone, uy, uz, peak, w, ci)

    def _joint_compiled(self, x: np.ndarray, w: np.ndarray, ci: np.ndarray, uy: np.ndarray,
                        uz: np.ndarray, peak: np.ndarray, rho: np.ndarray, floor: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_joint_numpy` with its numpy glue compiled (numba engine)."""
        kb = self.beams.tables
        assert kb is not None
        # the loop below with its numpy glue compiled: the keep tests and the vectors
        # less the other sources' fit in kernels, the refinement steps by the same
        # kernels as the loop's (called from here: linked into one compiled loop they
        # cost seconds more of compiling on the first frame)
        starts = np.flatnonzero(firsts(ci, end=True))
        alive = np.ones(ci.size, dtype=bool)
        count = np.empty(starts.size - 1, dtype=np.int64)
        amps = np.empty(ci.size, dtype=np.complex128)
        xc, w = c64(x), np.ascontiguousarray(w, dtype=np.complex64)
        floor_p = f64(floor[ci])
        for it in range(3):
            multi_left = kb["k"].joint_round(xc, w, starts, alive, floor_p,
                                             float(self.dynamic), self.f_threshold,
                                             it > 0, amps, count)
            if not multi_left or it == 2:
                break
            xp = np.empty(xc.shape, dtype=np.complex64)
            j = np.empty(ci.size, dtype=np.int64)
            k = kb["k"].joint_residuals(xc, w, starts, alive, count, xp, j)
            xp, j = xp[:k], j[:k]
            self._refine_apart(xp, j, uy, uz, rho, w)
        kb["k"].joint_powers(xc, w, starts, alive, count, peak)
        uy, uz, peak, w, ci = uy[alive], uz[alive], peak[alive], w[:, alive], ci[alive]
        return uy, uz, peak, w, ci

    def _joint_numpy(self, x: np.ndarray, w: np.ndarray, ci: np.ndarray, uy: np.ndarray,
                     uz: np.ndarray, peak: np.ndarray, rho: np.ndarray, floor: np.ndarray,
                     cell_of: np.ndarray | None, rank: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Up to three rounds: joint least-squares amplitudes of each cell's sources, the keep
        tests, and each source refined on its cell's vector less the others' fit
        (``cell_of``: each peak's cell index, None to compute it from ``ci``)."""
        if cell_of is None:
            cell_of = groups(ci)[0]
        for it in range(3):
            amps = self.joint_amplitudes(x, w, cell_of, rank)
            pw = np.abs(amps) ** 2
            starts = np.flatnonzero(firsts(cell_of))
            top = np.maximum.reduceat(pw, starts)
            ok = (pw >= floor[ci]) & (pw >= top[cell_of] * self.dynamic)
            if it > 0:
                # once the directions are refined jointly, against what the fit leaves
                ok &= pw >= self.residual_floor(x, w, amps, cell_of, starts)
            ok[rank == 0] = True
            uy, uz, peak, w, ci, x, rho, amps = (uy[ok], uz[ok], peak[ok], w[:, ok], ci[ok],
                                                 x[ok], rho[ok], amps[ok])
            cell_of, count = groups(ci)
            rank = np.arange(ci.size) - np.concatenate([[0], np.cumsum(count)[:-1]])[cell_of]
            multi = count[cell_of] > 1
            if not multi.any() or it == 2:
                break
            amps = self.joint_amplitudes(x, w, cell_of, rank)
            model = np.conj(w) * amps[None, :]                          # (M, P) fitted sources
            starts = np.flatnonzero(firsts(cell_of))
            total = np.add.reduceat(model.T, starts, axis=0)            # peaks grouped by cell
            xp = (x - total[cell_of] + model.T)[multi]                  # vector less the others
            j = np.flatnonzero(multi)
            self._refine_apart(xp, j, uy, uz, rho, w)
        amps = self.joint_amplitudes(x, w, cell_of, rank)
        multi = count[cell_of] > 1
        peak[multi] = np.abs(amps[multi]) ** 2
        return uy, uz, peak, w, ci

    def _refine_apart(self, xp: np.ndarray, j: np.ndarray, uy: np.ndarray, uz: np.ndarray,
                      rho: np.ndarray, w: np.ndarray) -> None:
        """Sources ``j`` refined each on its cell's vector less the other sources' fit ``xp``
        ``(J, M)``: their directions ``uy, uz`` and weights ``w`` updated in place (one step of
        both joint loops)."""
        # elevation afresh on what is left (two sources fool the sparse rows)
        uz[j], _ = self.beams.elevation_search(xp, uy[j], rho[j])
        if self.refine:
            uy[j], uz[j], _ = self.beams.newton(xp, uy[j], uz[j], rho[j])
        w[:, j] = self.beams.steer(uy[j], uz[j], rho[j])

    @staticmethod
    def join_lone(lone: tuple[np.ndarray, ...] | None, uy: np.ndarray, uz: np.ndarray,
                  peak: np.ndarray, w: np.ndarray, ci: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The cells with one source (``lone``: their ``uy, uz, peak, w, ci``) back among
        the others, in cell order."""
        if lone is None:
            return uy, uz, peak, w, ci
        order = np.argsort(np.concatenate((lone[4], ci)), kind="stable")
        uy, uz, peak, ci = (np.concatenate((a, b))[order] for a, b in zip(
            (lone[0], lone[1], lone[2], lone[4]), (uy, uz, peak, ci), strict=True))
        w = np.concatenate([lone[3], w], axis=1)[:, order]
        return uy, uz, peak, w, ci

    def _screen_secondaries(self, x: np.ndarray, ci: np.ndarray, uy: np.ndarray,
                            uz: np.ndarray, peak: np.ndarray, rho: np.ndarray,
                            floor: np.ndarray, primary: np.ndarray, deferred: np.ndarray
                            ) -> tuple[np.ndarray, ...]:
        """Drop the secondary peaks that the residual test below rejects at every elevation
        (compiled path): its residual beam power is at most ``(Σ_q |A_q| / M)²``, ``A_q`` the
        residual's azimuth-steered sum over elevation row ``q``
        (:func:`~coloradar.dsp._kernels.secondary_bound`; with focusing, plus what the
        focusing phases' change over the elevations can add,
        :func:`~coloradar.dsp._kernels.secondary_bound_focused`); the others get their
        elevation search now. Returns ``uy, uz, peak, ci, x, rho, primary`` of the peaks kept
        and the primaries' weights ``(M, primaries)`` (as :meth:`Beams.steer
        <coloradar.dsp.detection.beams.Beams.steer>`)."""
        kb = self.beams.tables
        assert kb is not None
        lead = np.cumsum(primary) - 1                   # each peak's primary, among primaries
        wp = self.beams.steer(uy[primary], uz[primary], rho[primary])
        bound, top = np.empty((2, ci.size))
        n_rows = int(kb["row"].max()) + 1
        if not self.beams.focus:
            kb["k"].secondary_bound(c64(x), wp, lead.astype(np.int64), f64(uy), kb["ca"],
                                    kb["az"], kb["row"], n_rows, bound, top)
        else:
            # focused beams: each element's phase changes with the elevation within a row;
            # the bound adds what that change can contribute over the elevations searched
            assert self.beams.near_terms is not None
            g = self.beams.grid
            ne = g.num_el
            half = 1.0 / (ne * g.rho)                   # half an elevation bin (sine)
            u_grid = 2.0 * half * max(ne // 2 + 0.5, ne - 0.5 - ne // 2)
            sq, cyy, cyz, czz, ref = self.beams.near_terms
            # (cyy = t_y² + r_y²: one phase factor per TX and one per RX, not per element)
            assert self.beams.near_factors is not None
            ty2, it, ry2, ir = self.beams.near_factors
            # (only the deferred peaks: the primaries' bound is not used)
            bound[:], top[:] = np.inf, 0.0
            j = np.flatnonzero(deferred)
            bj, tj = np.empty((2, j.size))
            kb["k"].secondary_bound_focused(
                c64(x[j]), wp, lead[j].astype(np.int64), f64(uy[j]), f64(rho[j]),
                f64(floor[ci[j]]), float(self.dynamic), kb["ca"], kb["az"],
                kb["row"], n_rows, sq, cyy, cyz, czz, ref, ty2, it.astype(np.int64), ry2,
                ir.astype(np.int64), self.beams.near.wavenumber, u_grid, half, bj, tj)
            bound[j], top[j] = bj, tj
        hopeless = deferred & ((bound < floor[ci]) | (bound < top * self.dynamic))
        keep = ~hopeless
        uy, uz, peak, ci, x, rho, primary, deferred = (
            uy[keep], uz[keep], peak[keep], ci[keep], x[keep], rho[keep], primary[keep],
            deferred[keep])
        if deferred.any():
            uz[deferred], peak[deferred] = self.beams.elevation_search(x[deferred], uy[deferred],
                                                                       rho[deferred])
        return uy, uz, peak, ci, x, rho, primary, wp

    def residual_floor(self, x: np.ndarray, w: np.ndarray, amps: np.ndarray,
                       cell_of: np.ndarray, starts: np.ndarray) -> np.ndarray:
        """Power a source of a cell must reach against what the cell's joint fit leaves.

        The generalised likelihood-ratio test of one more source when the noise level is
        unknown: the cell's vector ``x`` (M unique elements) less the fit of its ``n``
        sources leaves ``RSS``, an estimate ``σ̂² = RSS/ν`` of the per-element noise with
        ``ν = M − 2n`` complex degrees of freedom (each source: a complex amplitude and two
        direction sines). A source's least-squares power ``|s|²`` then has
        ``M|s|²/σ̂² ~ F(2, 2ν)`` under noise alone, and the test, taken over about M
        independent beams, keeps it at ``angle_pfa``. On thermal noise alone ``σ̂²`` is the
        noise and the test is the beam-noise floor; where the cell holds more than its point
        sources explain (an extended surface, several scatterers within a resolution cell),
        what is left is model error, and a secondary peak must stand out of it — else its
        elevation, measured by the cascade's 48 off-row elements against that error, lands
        anywhere (docs/dsp.md, "Several scatterers in one cell").

        Returns
        -------
        numpy.ndarray
            float64 ``(P,)``: the power floor of each source in beam units (``|s|²``).
        """
        m = w.shape[0]
        model = np.conj(w) * amps[None, :]                              # (M, P)
        total = np.add.reduceat(model.T, starts, axis=0)                # (C, M)
        first = x[starts]                                               # each cell's vector
        rss = np.sum(np.abs(first - total) ** 2, axis=1)                # (C,)
        count = np.diff(np.append(starts, cell_of.size))
        nu = np.maximum(m - 2 * count, 1)
        return (self.f_threshold[nu] * rss / nu / m)[cell_of]

    def joint_amplitudes(self, x: np.ndarray, w: np.ndarray, cell_of: np.ndarray,
                         rank: np.ndarray) -> np.ndarray:
        """Least-squares amplitudes of every cell's sources, batched: the sources of a cell
        are the columns ``conj(w)`` of its peaks; ``x`` the cell's vector per peak. A cell
        with one source gets its beam value; only cells with several are solved."""
        kb = self.beams.tables
        if kb is not None and cell_of.size and np.all(np.diff(cell_of) >= 0):
            # (the peaks of a cell are consecutive, as resolve keeps them)
            starts = np.flatnonzero(firsts(cell_of, end=True))
            amps = np.empty(cell_of.size, dtype=np.complex128)
            kb["k"].joint_amplitudes(c64(x), c64(w), starts.astype(np.int64), amps)
            return amps
        out = np.einsum("pm,mp->p", x, w) / float(w.shape[0])
        counts = np.bincount(cell_of)
        multi = counts[cell_of] > 1
        if not multi.any():
            return out
        x, w, rank = x[multi], w[:, multi], rank[multi]
        cell_of = groups(cell_of[multi])[0]
        ncell = int(cell_of.max()) + 1
        nmax = int(rank.max()) + 1
        m = w.shape[0]
        a = np.zeros((ncell, m, nmax), dtype=np.complex128)
        a[cell_of, :, rank] = np.conj(w.T)
        xc = np.zeros((ncell, m), dtype=np.complex128)
        xc[cell_of] = x
        gram = np.einsum("cmi,cmj->cij", np.conj(a), a)                 # (C, n, n)
        used = np.zeros((ncell, nmax), dtype=bool)
        used[cell_of, rank] = True
        idx = np.arange(nmax)
        gram[:, idx, idx] += np.where(used, 0.0, 1.0)                   # padded columns
        rhs = np.einsum("cmn,cm->cn", np.conj(a), xc)
        try:
            sol = np.linalg.solve(gram, rhs[..., None])[..., 0]
        except np.linalg.LinAlgError:
            # two sources of a cell with the same weights (one direction): the least-squares
            # fit of minimum norm (the compiled kernel gives the duplicate nothing instead)
            sol = (np.linalg.pinv(gram) @ rhs[..., None])[..., 0]
        out[multi] = sol[cell_of, rank]
        return out
