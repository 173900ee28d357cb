"""The beams of single detections, shared by the angle stages (peaks, several-source resolution,
guard): the detection grid, steering at any direction, near-field focusing, the elevation search
and Newton refinement of a direction — compiled with the numba engine
(:mod:`coloradar.dsp._kernels.beams`), numpy otherwise, to the same contract."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...calib import RadarCalib
from ...calib.waveform import SPEED_OF_LIGHT
from ..angle import NearField, azimuth_peaks, newton_refine, refine_peak, steering
from ..array import AngleGrid, angle_grid, pair_antennas, phase_centre
from ..settings import AngleSettings, ArraySettings
from ._common import c64, f64

__all__ = ["Beams"]


class Beams:
    """Beams of one radar's detections at arbitrary directions.

    Parameters
    ----------
    calib
        The radar's calibration.
    array, angle
        The settings groups used (signs; oversampling and near-field focusing).
    calibrated
        Whether the phase/frequency calibration is applied (focusing is then relative to its
        reflector, :class:`~coloradar.dsp.angle.NearField`).
    engine
        ``"numba"`` or ``"numpy"``.
    """

    def __init__(self, calib: RadarCalib, array: ArraySettings, angle: AngleSettings,
                 calibrated: bool, engine: str) -> None:
        w, hm = calib.waveform, calib.heatmap
        self.calib = calib
        os_ = angle.angle_oversample
        self.grid: AngleGrid = angle_grid(calib.antenna, w.center_frequency,
                                          os_ * hm.num_elevation_bins,
                                          os_ * hm.num_azimuth_bins, array.azimuth_sign,
                                          array.elevation_sign)
        """:class:`~coloradar.dsp.array.AngleGrid` of detection (the heatmap's, oversampled)."""
        dg = self.grid
        self.visible = (dg.az_sines[None, :] ** 2 + dg.el_sines[:, None] ** 2) <= 1.0
        self.visible_az = np.abs(dg.az_sines) <= 1.0
        rows_el, row_idx = np.unique(dg.el_pos, return_inverse=True)
        self.row_of = np.eye(rows_el.size, dtype=np.complex64)[row_idx]          # (M, rows)
        self.row_steer = np.exp(1j * np.pi * dg.rho * dg.elevation_sign * rows_el[:, None]
                                * dg.el_sines[None, :]).astype(np.complex64)
        _, counts = np.unique(dg.el_pos, return_counts=True)
        # the filled azimuth row (the sources' azimuths, the alias choice), its noise relative
        # to the full beam's and its beams' grid
        self.row_noise = float(dg.num_elements / counts.max())
        self.row_sel = dg.el_pos == rows_el[np.argmax(counts)]
        self.row_bins = dg.az_read[self.visible_az]
        self.step = (2.0 / (dg.num_az * dg.rho), 2.0 / (dg.num_el * dg.rho))
        """Newton steps' sine increments (azimuth, elevation): one grid bin."""
        tx, rx = pair_antennas(calib.antenna, array.azimuth_sign, array.elevation_sign)
        c_true = phase_centre(calib.antenna, array.azimuth_sign, array.elevation_sign)
        # Near field: relative to the range at which the calibration focused the channels.
        ref = calib.near_field_reference
        self.focus = (ref is not None if angle.near_field == "auto" else bool(angle.near_field))
        """Whether beams are focused at the detection's range."""
        self.near = NearField(tx - c_true, rx - c_true,
                              2.0 * np.pi * w.center_frequency / SPEED_OF_LIGHT,
                              reference=ref if calibrated else None)
        self.engine = engine
        self.tables = self._tables()
        """Tables of the compiled kernels (numba engine), else None."""
        # (focusing phase as a quadratic in the sines, for the secondary peaks' bound)
        self.near_terms = self.near.planar_terms() if self.focus else None
        # (its per-TX and per-RX factors: cyy = t_y² + r_y², one phase per TX and one per RX)
        self.near_factors = (
            np.unique(self.near.tx[:, 1] ** 2, return_inverse=True)
            + np.unique(self.near.rx[:, 1] ** 2, return_inverse=True)
            if self.near_terms is not None else None)
        self.focus_tables = (self._planar_focus_tables() if self.near_terms is not None
                             else None)

    def newton(self, xv: np.ndarray, uy0: np.ndarray, uz0: np.ndarray, rr: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Directions of vectors ``xv`` ``(P, M)`` refined from ``(uy0, uz0)`` by Newton steps
        on the (focused at ``rr``) Bartlett beam power: ``(u_y, u_z, power)``."""
        kb = self.tables
        if kb is not None:
            if self.focus:
                xv = self.focused(xv, uy0, uz0, rr)
            out = np.empty((3, np.size(uy0)))
            kb["k"].newton_refine(c64(xv), kb["ca"], kb["cb"], kb["az"], kb["el"],
                                  f64(uy0), f64(uz0), self.step[0], self.step[1], 2, True,
                                  out[0], out[1], out[2])
            return out[0], out[1], out[2]
        if self.focus:
            xv = self.focused(xv, uy0, uz0, rr)
        return newton_refine(self.grid, xv, uy0, uz0, self.step)

    def steer(self, uy: np.ndarray, uz: np.ndarray, rho: np.ndarray) -> np.ndarray:
        """Beam weights ``(M, P)`` complex64 at direction sines ``(u_y, u_z)``, focused at range
        ``rho`` from the phase centre: ``B(u) = Σ_m x_m w_m / M`` is ``s`` for a source
        ``s`` at ``(rho, u)``."""
        kb = self.tables
        if kb is not None:
            w = np.empty((self.grid.num_elements, np.size(uy)), dtype=np.complex64)
            kb["k"].steer_columns(kb["ca"], kb["cb"], kb["az"], kb["el"], f64(uy), f64(uz), w)
            if self.focus:
                w = self.focused(w, uy, uz, rho, rows=False, copy=False)
            return w
        w = steering(self.grid, uy, uz)
        if self.focus:
            w = w * self.near.focus_sines(uy, uz, rho)
        return w

    def azimuth_peaks(self, prof: np.ndarray, rel: float, floor: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~coloradar.dsp.angle.azimuth_peaks`, compiled with the numba engine."""
        kb = self.tables
        if kb is None or prof.dtype != np.float32:
            return azimuth_peaks(prof, rel, floor)
        ci, ia = np.empty((2, prof.size), dtype=np.int64)
        n = kb["k"].azimuth_peaks(np.ascontiguousarray(prof), float(rel), f64(floor), ci, ia)
        return ci[:n], ia[:n]

    def focused(self, x: np.ndarray, uy: np.ndarray, uz: np.ndarray, rho: np.ndarray,
                rows: bool = True, copy: bool = True) -> np.ndarray:
        """``x`` times the near-field focusing phases (:meth:`NearField.focus_sines`) at sines
        ``(uy, uz)`` and ranges ``rho`` (``(K,)`` each); ``x`` complex ``(K, M)`` with
        ``rows``, else ``(M, K)``; ``copy=False`` may multiply ``x`` (complex64) in place.
        Compiled where the array is planar (the cascade), numpy otherwise."""
        kb, tables = self.tables, self.focus_tables
        if kb is None or tables is None:
            f = self.near.focus_sines(uy, uz, rho, transpose=rows)
            if copy:
                return x * f
            x *= f
            return x
        out = np.array(x, dtype=np.complex64, order="C", copy=True) if copy else x
        kb["k"].focus_multiply(out, f64(uy), f64(uz), f64(rho), *tables,
                               self.near.wavenumber, rows)
        return out

    def elevation_search(self, x: np.ndarray, uy: np.ndarray, rho: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
        """Elevation sine of the strongest beam of each vector ``x`` ``(P, M)`` along its
        azimuth ``uy``, and that beam's power: the elements are steered in azimuth and summed
        per elevation row, then the few rows are beamformed over the detection grid's
        elevation bins; the peak is refined by a log-parabola (Newton steps follow)."""
        g = self.grid
        if x.shape[0] == 0:
            return np.zeros(0), np.zeros(0)
        kb = self.tables
        if kb is not None:
            if self.focus:
                # focused at elevation 0, as the numpy path's azimuth steering below
                x = self.focused(x, uy, np.zeros(uy.size), rho)
            out = np.empty((2, uy.size))
            kb["k"].elevation_search(c64(x), kb["ca"], kb["az"], kb["row"], kb["row_steer"],
                                     kb["el_sines"], f64(uy), float(g.rho), out[0], out[1])
            return out[0], out[1]
        wa = self.steer(uy, np.zeros(uy.size), rho)                   # (M, P)
        # (einsum, not BLAS: threaded BLAS sums in an order that varies between runs, and
        # batch processing promises the bytes of serial processing)
        rows = np.einsum("pm,pm,mr->pr", x, wa.T, self.row_of)          # (P, rows)
        bz = np.abs(np.einsum("pr,re->pe", rows, self.row_steer)) ** 2  # (P, n_el)
        vis = uy[:, None] ** 2 + g.el_sines[None, :] ** 2 <= 1.0
        bz = np.where(vis, bz, 0.0)
        ie = np.argmax(bz, axis=1)
        ne = g.num_el
        k = np.arange(ie.size)
        fe = refine_peak(np.stack([bz[k, (ie - 1) % ne], bz[k, ie], bz[k, (ie + 1) % ne]],
                                  axis=1), ie, ne, wrap=True)
        uz = 2.0 * (fe - ne // 2) / (ne * g.rho)
        return uz, bz[k, ie] / float(g.num_elements) ** 2

    def peak_directions(self, spec: np.ndarray, k: np.ndarray, ie: np.ndarray, ia: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Direction sines of spectrum peaks ``(k, ie, ia)`` refined by log-parabolas along
        both axes of the ``(K, el, az)`` spectra, and the peak values."""
        g = self.grid
        ne, na = g.num_el, g.num_az
        fe = refine_peak(np.stack([spec[k, (ie - 1) % ne, ia], spec[k, ie, ia],
                                   spec[k, (ie + 1) % ne, ia]], axis=1), ie, ne, wrap=True)
        fa = refine_peak(np.stack([spec[k, ie, (ia - 1) % na], spec[k, ie, ia],
                                   spec[k, ie, (ia + 1) % na]], axis=1), ia, na, wrap=True)
        uz = 2.0 * (fe - ne // 2) / (ne * g.rho)
        uy = 2.0 * (fa - na // 2) / (na * g.rho)
        return uy, uz, spec[k, ie, ia].astype(np.float64)

    def _planar_focus_tables(self) -> tuple[np.ndarray, ...]:
        """The focusing phases' per-position tables for :func:`~coloradar.dsp._kernels.focus_multiply`:
        the unique TX and RX positions ``(y, z)`` with their ``|·|²`` and each element's
        index into them, and ``exp(j·ref_m)`` (the calibration reflector's phases, 1 without
        a reference)."""
        def positions(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            yz, idx = np.unique(p[:, 1:], axis=0, return_inverse=True)
            return (np.ascontiguousarray(yz, dtype=np.float64), (yz**2).sum(axis=1),
                    idx.reshape(-1).astype(np.int64))
        assert self.near_terms is not None
        ref = self.near_terms[4]
        return (*positions(self.near.tx), *positions(self.near.rx),
                np.exp(1j * ref))

    def _tables(self) -> dict[str, Any] | None:
        """Tables of the compiled per-detection beam kernels (:mod:`coloradar.dsp._kernels`):
        used with the numba engine; near-field focusing multiplies their inputs and outputs
        (a phase per element and detection), as on the numpy path."""
        dg = self.grid
        if self.engine != "numba":
            return None
        from .. import _kernels
        nrx = self.calib.frame_shape[1]
        first = self.calib.antenna.virtual.first_pair
        _, row = np.unique(dg.el_pos, return_inverse=True)
        return {"k": _kernels,
                "ca": float(np.pi * dg.rho * dg.azimuth_sign),
                "cb": float(np.pi * dg.rho * dg.elevation_sign),
                "az": np.ascontiguousarray(dg.az_pos, dtype=np.int64),
                "el": np.ascontiguousarray(dg.el_pos, dtype=np.int64),
                "row": np.ascontiguousarray(row, dtype=np.int64),
                "row_steer": np.ascontiguousarray(self.row_steer),
                "el_sines": np.ascontiguousarray(dg.el_sines, dtype=np.float64),
                "chan": np.ascontiguousarray(first[:, 0] * nrx + first[:, 1], dtype=np.int64),
                "tx": np.ascontiguousarray(first[:, 0], dtype=np.int64)}
