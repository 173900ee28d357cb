"""A radar's per-channel phase and gain calibration measured from a run's own frames.

A real board's channels are not matched: each (TX, RX) pair adds its own gain and phase
(``x[t, r] = g[t, r] · ideal[t, r]``). The release's cascade file measured them on a corner
reflector; the single chip's release carries none, and neither does a capture from a user's
own board. Without them the angle spectra defocus, and the Doppler alias test (which reads a
phase per TX slot, docs/dsp.md "Doppler beyond ±v_max") can take a board's TX phase error for
a Doppler alias.

The estimate is a self-calibration over many strong cells of many frames: each cell is taken
to hold one scatterer in an unknown direction ``w = (u_y, u_z)``, so that
``x_k = a_k · g ⊙ s(w_k)`` with ``s`` the virtual array's steering vector. It alternates
between (1) each cell's direction, found on the array calibrated by the current ``g`` (an FFT
beam over the virtual positions, then a local search), and (2) ``g``, the least-squares fit over
the cells whose one-source model explains them best (a trimmed fraction: cells with two
scatterers, a mover whose Doppler aliases, or noise are left out). The first pass finds the
directions on the reference TX's channels alone, where no TX error can reach them.

What the data cannot tell (the gauge). A linear phase ramp across the virtual array moves every
direction by the same amount, and nothing but a target in a known direction can tell the two
apart. The estimate is fixed so: (a) in azimuth, the RX phases (averaged over TX) get no
linear trend along the RX positions (receivers on one chip share its LO and are matched far
better than the TX paths, so a TX phase error is left where it is); where they do not lie on
a line (the cascade's four chips: :data:`MATCHED_RX_DEG`) and the radar's velocity is known
(the run's ground truth), the directions are made to agree with the static scene's Doppler
instead (``rate = −v·u``: :func:`doppler_azimuth_offset`); (b) in elevation, where only the
TX positions differ (the single chip's one raised TX: its phase *is* an elevation offset),
by ``elevation_reference``: ``"scene"`` (default) puts the median elevation of the cells used
at zero (a level radar sees about as much above as below its horizon: walls, not floors,
dominate), ``"tx"`` makes the TX phases trend-free along their elevations (the raised TX
matched to the reference one). Without a velocity an RX phase slope, and with ``"scene"`` the
scene's own median elevation, remain as biases of the azimuth and the elevation; neither
touches the Doppler alias choice, which reads the phase steps between the TX slots of the
azimuth row. Comparisons with a true calibration remove the best-fitting ramps first
(:func:`gauge_aligned_error`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
import scipy.fft as sfft

from ..calib import PhaseFrequencyCalib, RadarCalib
from ..errors import MissingDataError, SettingsError
from .angle import refine_peak
from .tdm import tdm_phase


class SequenceOf(Protocol):
    """Frames with ``len`` and indexing (an ``AdcStream``, a list; None: unreadable)."""

    def __len__(self) -> int: ...

    def __getitem__(self, i: int, /) -> np.ndarray | None: ...


Velocities = Sequence[np.ndarray] | np.ndarray
"""Per frame, the radar's velocity in its own frame, float ``(3,)`` [m/s]."""

__all__ = [
    "PhaseEstimate",
    "PhaseEstimateSettings",
    "SelfCalibration",
    "doppler_azimuth_offset",
    "estimate_phase_calibration",
    "estimation_passes",
    "frame_cells",
    "gauge_aligned_error",
    "measured_calibration",
    "self_calibrate",
]


@dataclass(frozen=True)
class PhaseEstimateSettings:
    """Settings of :func:`estimate_phase_calibration`.

    Attributes
    ----------
    min_snr_db
        Cells whose detection statistic is at least this far above the CFAR noise [dB].
    cells_per_frame
        At most this many of a frame's strongest such cells.
    keep_fraction
        Fraction of the cells, best one-source fits first, that fit the gains each pass.
    iterations
        Passes of direction search and gain fit.
    elevation_reference
        How the elevation gauge is fixed (module docstring): ``"scene"`` or ``"tx"``.
    """

    min_snr_db: float = 15.0
    cells_per_frame: int = 48
    keep_fraction: float = 0.6
    iterations: int = 12
    elevation_reference: Literal["scene", "tx"] = "scene"

    def __post_init__(self) -> None:
        if not 0.0 < self.keep_fraction <= 1.0:
            raise SettingsError(f"keep_fraction must lie in (0, 1], got {self.keep_fraction!r}")
        if self.elevation_reference not in ("scene", "tx"):
            raise SettingsError(f"elevation_reference must be 'scene' or 'tx', got "
                                f"{self.elevation_reference!r}")
        if self.cells_per_frame < 1 or self.iterations < 1:
            raise SettingsError("cells_per_frame and iterations must be >= 1")


@dataclass(frozen=True, eq=False)
class SelfCalibration:
    """What :func:`self_calibrate` finds.

    Attributes
    ----------
    gain
        complex128 ``(tx, rx)``: each channel's gain relative to channel (0, 0), gauge fixed.
    phase_std_deg
        float64 ``(tx, rx)``: the noise uncertainty of each channel's phase [deg] (least
        squares over the cells used; the gauge is not uncertain, it is a choice).
    residual
        float64 ``(K,)``: fraction of each cell's power its one-source fit leaves.
    used
        bool ``(K,)``: the cells of the last gain fit.
    directions
        float64 ``(K, 2)``: each cell's ``(u_y, u_z)``.
    azimuth_reference
        What fixed the azimuth gauge: ``"receivers"`` or ``"doppler"`` (module docstring).
    """

    gain: np.ndarray
    phase_std_deg: np.ndarray
    residual: np.ndarray
    used: np.ndarray
    directions: np.ndarray
    azimuth_reference: str = "receivers"


def _steer(pos: np.ndarray, w: np.ndarray) -> np.ndarray:
    """complex ``(K, C)``: ``exp(−j·pos·w)`` for ``pos`` ``(C, 2)`` [rad per unit sine]: an
    element toward ``+y`` is nearer a target at ``u_y > 0``, its delay and so its phase
    smaller (docs/conventions.md §3; the chain's beams apply the conjugate)."""
    return np.exp(-1j * (w @ pos.T))


class _Beams:
    """FFT beams of a virtual array on whole half-wavelength positions (``ipos``)."""

    def __init__(self, ipos: np.ndarray, rho: float, pad: int = 4) -> None:
        self.ipos = ipos - ipos.min(axis=0)
        self.n_az = int(sfft.next_fast_len(pad * (int(self.ipos[:, 0].max()) + 1)))
        self.n_el = int(sfft.next_fast_len(pad * (int(self.ipos[:, 1].max()) + 1)))
        # FFT bin f of an axis of size n sums y_p·exp(−j2π f p / n), the beam s(w)ᴴy of the
        # steering exp(−jπ·rho·p·w) at w = −2f/(n·rho)
        fy = -np.fft.fftfreq(self.n_az) * 2.0 / rho
        fz = -np.fft.fftfreq(self.n_el) * 2.0 / rho if self.n_el > 1 else np.zeros(1)
        self.uy, self.uz = np.meshgrid(fy, fz, indexing="ij")
        self.visible = self.uy**2 + self.uz**2 <= 1.0

    def peaks(self, y: np.ndarray, use_el: bool, chunk: int = 256) -> np.ndarray:
        """float64 ``(K, 2)``: the strongest visible beam of each row of ``y`` (K, C)."""
        k = y.shape[0]
        vis = (self.visible if use_el else self.visible & (self.uz == 0)).ravel()
        best = np.empty(k, dtype=np.int64)
        for k0 in range(0, k, chunk):
            yk = y[k0:k0 + chunk]
            grid = np.zeros((yk.shape[0], self.n_az, self.n_el), dtype=np.complex64)
            rows = np.arange(yk.shape[0])[:, None]
            np.add.at(grid, (rows, self.ipos[None, :, 0], self.ipos[None, :, 1]), yk)
            p = np.abs(sfft.fft2(grid, axes=(1, 2))).reshape(yk.shape[0], -1)
            best[k0:k0 + chunk] = np.argmax(np.where(vis[None], p, -1.0), axis=1)
        return np.stack([self.uy.ravel()[best], self.uz.ravel()[best]], axis=1)


def _refine(y: np.ndarray, pos: np.ndarray, w: np.ndarray, step: np.ndarray,
            use_el: bool, levels: int = 6) -> np.ndarray:
    """Local search of each row's beam peak from ``w``, halving ``step`` at each level."""
    w = w.copy()
    best = np.abs(np.sum(y * np.conj(_steer(pos, w)), axis=1))
    moves = [(dy, dz) for dy in (-1, 0, 1) for dz in ((-1, 0, 1) if use_el else (0,))
             if dy or dz]
    h = step.copy()
    for _ in range(levels):
        for dy, dz in moves:
            cand = w + np.array([dy * h[0], dz * h[1]])
            p = np.abs(np.sum(y * np.conj(_steer(pos, cand)), axis=1))
            better = (p > best) & (np.sum(cand**2, axis=1) <= 1.0)
            w[better], best[better] = cand[better], p[better]
        h = h * 0.5
    return w


def _slope(z: np.ndarray, x: np.ndarray, coherent: bool = False) -> float:
    """The slope ``b`` in [−π, π] that best fits ``z ≈ exp(j·b·x)`` for unit phasors ``z``:
    the largest ``Re Σ z·exp(−j·b·x)`` (``coherent``: its modulus, any constant phase
    allowed). A grid fine enough for the largest ``|x|``, then a local search."""
    x = np.asarray(x, dtype=np.float64)
    if not np.any(x):
        return 0.0

    def fit(b: np.ndarray) -> np.ndarray:
        v = np.exp(-1j * np.outer(b, x)) @ z
        return np.abs(v) if coherent else v.real

    h = np.pi / (8.0 * np.abs(x).max())
    grid = np.arange(-np.pi, np.pi + h, h)
    b = float(grid[int(np.argmax(fit(grid)))])
    for _ in range(30):
        cand = np.array([b - h, b, b + h])
        b = float(cand[int(np.argmax(fit(cand)))])
        h *= 0.5
    return b


def fix_gauge(gain: np.ndarray, tx_pos: np.ndarray, rx_pos: np.ndarray,
              rho: float) -> np.ndarray:
    """``gain`` ``(tx, rx)`` with the gauge of the module docstring: RX phases without an
    azimuth trend, TX phases without an elevation trend, channel (0, 0) equal to 1."""
    g = np.asarray(gain, dtype=np.complex128)
    rx_z = np.exp(1j * np.angle(np.sum(g * np.conj(g[:, :1]), axis=0)))
    tx_z = np.exp(1j * np.angle(np.sum(g * np.conj(g[:1, :]), axis=1)))
    a = _slope(rx_z, rho * (rx_pos[:, 0] - rx_pos[0, 0]))
    e = _slope(tx_z, rho * (tx_pos[:, 1] - tx_pos[0, 1]))
    vp = tx_pos[:, None, :] + rx_pos[None, :, :]
    g = g * np.exp(-1j * rho * (a * vp[..., 0] + e * vp[..., 1]))
    return g / g[0, 0]


def gauge_aligned_error(estimate: np.ndarray, truth: np.ndarray,
                        tx_pos: np.ndarray, rx_pos: np.ndarray) -> np.ndarray:
    """Per-channel phase error [deg] of ``estimate`` against ``truth`` (both ``(tx, rx)``)
    after the constant phase and the azimuth and elevation ramps that best align them (what
    no self-calibration can tell, module docstring), float64 ``(tx, rx)`` in (−180, 180]."""
    d = np.asarray(estimate) * np.conj(np.asarray(truth))
    vp = (tx_pos[:, None, :] + rx_pos[None, :, :]).reshape(-1, 2)
    z = (d / np.maximum(np.abs(d), 1e-30)).ravel()
    a = e = 0.0
    for _ in range(3):                                  # the two ramps, in turn
        a = _slope(z * np.exp(-1j * e * vp[:, 1]), vp[:, 0], coherent=True)
        e = _slope(z * np.exp(-1j * a * vp[:, 0]), vp[:, 1], coherent=True)
    r = z * np.exp(-1j * (a * vp[:, 0] + e * vp[:, 1]))
    r = r * np.exp(-1j * np.angle(np.sum(r)))
    return np.degrees(np.angle(r)).reshape(np.shape(d))


def self_calibrate(cells: np.ndarray, tx_pos: np.ndarray, rx_pos: np.ndarray, rho: float,
                   settings: PhaseEstimateSettings | None = None,
                   doppler: tuple[np.ndarray, np.ndarray] | None = None) -> SelfCalibration:
    """Per-channel gains of a virtual array from cells that each hold one scatterer.

    Parameters
    ----------
    cells
        complex ``(K, tx, rx)``: each cell's channels (TDM-compensated, unaliased Doppler).
    tx_pos, rx_pos
        float ``(tx, 2)``, ``(rx, 2)``: ``(az, el)`` positions in half wavelengths at the
        antenna's design frequency (whole numbers: the beams are FFTs).
    rho
        Carrier over design frequency: a position ``p`` has the phase ``π·rho·p·w``.
    settings
        :class:`PhaseEstimateSettings` (``keep_fraction``, ``iterations``,
        ``elevation_reference``).
    doppler
        ``(rates, velocities)``: each cell's unaliased range rate [m/s] ``(K,)`` and the
        radar's velocity in its own frame [m/s] ``(K, 3)`` (NaN where unknown). A static
        scatterer has ``rate = −v·u``, which a direction offset breaks: the azimuth gauge is
        then fixed by the Doppler (:func:`doppler_azimuth_offset`) instead of the receivers.

    Returns
    -------
    SelfCalibration
    """
    s = settings or PhaseEstimateSettings()
    x = np.asarray(cells, dtype=np.complex128)
    if x.ndim != 3 or x.shape[0] < 4:
        raise MissingDataError(f"self-calibration needs at least 4 cells of (tx, rx) channels, "
                               f"got shape {x.shape}")
    k, ntx, nrx = x.shape
    x = x.reshape(k, -1)
    x = x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-30)   # equal weights
    vp = (tx_pos[:, None, :] + rx_pos[None, :, :]).reshape(-1, 2)
    pos = np.pi * rho * vp
    beams = _Beams(np.rint(vp).astype(np.int64), rho)
    use_el = bool(np.ptp(vp[:, 1]) > 0)
    step = np.array([2.0 / (beams.n_az * rho), 2.0 / (max(beams.n_el, 2) * rho)])
    g = np.ones(ntx * nrx, dtype=np.complex128)
    ref = np.arange(nrx)                              # the reference TX's channels
    used = np.ones(k, dtype=bool)
    for it in range(s.iterations):
        y = x / g
        if it == 0:
            # Directions from the reference TX alone: no TX error reaches them.
            sub = _Beams(np.rint(vp[ref]).astype(np.int64), rho)
            w = sub.peaks(y[:, ref], use_el=bool(np.ptp(vp[ref, 1]) > 0))
            w = _refine(y[:, ref], pos[ref], w, step, use_el=False)
        else:
            w = _refine(y, pos, beams.peaks(y, use_el), step, use_el)
        sv = _steer(pos, w)                                                   # (K, C)
        a = np.sum(x * np.conj(g * sv), axis=1) / np.sum(np.abs(g) ** 2)
        b = a[:, None] * sv
        resid = np.sum(np.abs(x - g * b) ** 2, axis=1)
        used = resid <= np.quantile(resid, s.keep_fraction)
        bu = b[used]
        g = np.sum(np.conj(bu) * x[used], axis=0) / np.sum(np.abs(bu) ** 2, axis=0)
        g = g / g[0]
    # The gauge once, at the end: fixing it on every pass moves all directions at once, and
    # cells near the edge of the visible region then fall out of it.
    g = fix_gauge(g.reshape(ntx, nrx), tx_pos, rx_pos, rho).ravel()
    # Final fit statistics with the last directions and the gauge-fixed gains.
    y = x / g
    w = _refine(y, pos, beams.peaks(y, use_el), step, use_el)
    reference = "receivers"
    if doppler is not None and receiver_spread(g.reshape(ntx, nrx)) > MATCHED_RX_DEG:
        for _ in range(4):
            # found again after each shift (which wraps them and changes which cells lie in
            # the visible region), until the shift is below a hundredth of an azimuth bin
            dy = doppler_azimuth_offset(w[used], doppler[0][used], doppler[1][used], 1.0 / rho)
            if dy is None:
                break
            g = g * np.exp(-1j * np.pi * rho * vp[:, 0] * dy)   # as below: w moves by −dy
            y = x / g
            w = _refine(y, pos, beams.peaks(y, use_el), step, use_el)
            reference = "doppler"
            if abs(dy) < 0.01 * step[0]:
                break
    if use_el and s.elevation_reference == "scene":
        # x = g ⊙ s(w) = (g·e^{−jπρ·el·δ}) ⊙ s(w − δ ẑ): the scene's median elevation to zero
        delta = float(np.median(w[used, 1]))
        g = g * np.exp(-1j * np.pi * rho * vp[:, 1] * delta)
        y = x / g
        w = _refine(y, pos, beams.peaks(y, use_el), step, use_el)
    sv = _steer(pos, w)
    a = np.sum(x * np.conj(g * sv), axis=1) / np.sum(np.abs(g) ** 2)
    b = a[:, None] * sv
    err = x - g * b
    resid = np.sum(np.abs(err) ** 2, axis=1)
    n_used = max(int(used.sum()), 2)
    sig2 = np.sum(np.abs(err[used]) ** 2, axis=0) / (n_used - 1)
    var = sig2 / np.maximum(np.sum(np.abs(b[used]) ** 2, axis=0), 1e-30)
    std = np.degrees(np.sqrt(var / 2.0) / np.maximum(np.abs(g), 1e-30))
    return SelfCalibration(g.reshape(ntx, nrx), std.reshape(ntx, nrx), resid, used, w,
                           reference)


MATCHED_RX_DEG = 20.0
"""Receivers whose phases (averaged over TX) lie within this rms [deg] of a line are taken as
matched, and fix the azimuth gauge; scattered ones (the cascade's four chips, each with its
own LO path) leave it to the Doppler where the radar's velocity is known."""


def receiver_spread(gain: np.ndarray) -> float:
    """rms [deg] of the RX phases (averaged over TX) about their best line through RX 0's, in
    the order of the channels (the gauge-fixed gains have the line removed already)."""
    g = np.asarray(gain)
    ph = np.angle(np.sum(g * np.conj(g[:, :1]), axis=0))
    return float(np.degrees(np.sqrt(np.mean(ph**2))))


MIN_DOPPLER_CELLS = 50
"""Cells seen from a radar moving at ≥ 0.2 m/s that the Doppler azimuth gauge needs."""


def doppler_azimuth_offset(w: np.ndarray, rates: np.ndarray, velocities: np.ndarray,
                           half_period: float = 1.0) -> float | None:
    """The shift ``δ`` of the direction sine ``u_y`` that best makes ``rate = −v·u(w − δŷ)``
    hold for the cells of a static scene (the median absolute misfit, so that movers do not
    count), or None where fewer than :data:`MIN_DOPPLER_CELLS` cells have a known velocity of
    at least 0.2 m/s. ``w`` ``(K, 2)`` direction sines, ``rates`` ``(K,)`` [m/s],
    ``velocities`` ``(K, 3)`` [m/s] in the radar frame; ``half_period``: an array on whole
    half wavelengths repeats in ``u_y`` every ``2·half_period`` (``1/rho``), so shifted
    sines wrap into ``±half_period`` and ``δ`` is searched over one period."""
    v = np.asarray(velocities, dtype=np.float64)
    ok = np.all(np.isfinite(v), axis=1) & (np.linalg.norm(np.nan_to_num(v), axis=1) >= 0.2)
    if ok.sum() < MIN_DOPPLER_CELLS:
        return None
    w, r, v = w[ok], np.asarray(rates, dtype=np.float64)[ok], v[ok]
    hp = float(half_period)

    def misfit(d: np.ndarray) -> np.ndarray:
        uy = np.mod(w[None, :, 0] - d[:, None] + hp, 2.0 * hp) - hp
        uz = np.broadcast_to(w[None, :, 1], uy.shape)
        ux = np.sqrt(np.clip(1.0 - uy**2 - uz**2, 0.0, None))
        pred = -(v[None, :, 0] * ux + v[None, :, 1] * uy + v[None, :, 2] * uz)
        return np.median(np.abs(r[None, :] - pred), axis=1)

    h = 0.004
    grid = np.arange(-hp, hp, h)
    d = float(grid[int(np.argmin(misfit(grid)))])
    for _ in range(12):
        cand = np.array([d - h, d, d + h])
        d = float(cand[int(np.argmin(misfit(cand)))])
        h *= 0.5
    return d


def frame_cells(proc, adc: np.ndarray, settings: PhaseEstimateSettings
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The strongest single cells of one frame, as the chain calibrates them.

    Parameters
    ----------
    proc
        A :class:`~coloradar.dsp.RadarProcessor` of the radar.
    adc
        complex ``(tx, rx, chirp, sample)``.
    settings
        ``min_snr_db``, ``cells_per_frame``.

    Returns
    -------
    cells : numpy.ndarray
        complex128 ``(K, tx, rx)``, TDM-compensated at each cell's refined folded Doppler.
    snr : numpy.ndarray
        float64 ``(K,)``: detection statistic over CFAR noise.
    rate : numpy.ndarray
        float64 ``(K,)``: folded range rate [m/s], refined between Doppler bins.
    offsets : numpy.ndarray
        float64 ``(K, tx, rx)``: where each channel's range profile peaks, relative to the
        cell's mean over channels [range bins of the cube] (log-parabola over the cell and
        its two range neighbours; NaN at the first and last range bin): a channel's delay.
    """
    cube, det = proc.cube, proc.detector
    nr = proc.num_range_bins
    rd = cube.doppler(cube.range_cube(adc)[..., :nr], compensate=False)
    found = det.cfar.run(rd)
    stat, noise, nd = found.stat, found.noise, rd.shape[2]
    d, r = np.nonzero(found.mask)
    snr = stat[d, r] / noise[d, r]
    near = r < int(np.ceil(det.cfar.settings.min_range / cube.range_bin_width))
    ok = np.flatnonzero(~near & (snr >= 10.0 ** (settings.min_snr_db / 10.0)))
    ok = ok[np.argsort(-snr[ok])][:settings.cells_per_frame]
    d, r, snr = d[ok], r[ok], snr[ok]
    vecs = rd[:, :, d, r].astype(np.complex128)
    d_ref = (refine_peak(np.stack([stat[(d - 1) % nd, r], stat[d, r],
                                   stat[(d + 1) % nd, r]], axis=1), d, nd, wrap=True)
             if d.size else d.astype(np.float64))
    if cube.tdm is not None and d.size:
        vecs = vecs * cube.tdm_at(d) * tdm_phase(rd.shape[0], d_ref - d, nd)[:, None, :]
    rate = (d_ref - nd // 2) * (cube.velocities[1] - cube.velocities[0])
    offsets = np.full(vecs.shape, np.nan)
    inner = (r >= 1) & (r <= nr - 2)
    if inner.any():
        lo, mid, hi = (np.log(np.maximum(np.abs(rd[:, :, d[inner], r[inner] + k]), 1e-30))
                       for k in (-1, 0, 1))
        curv = lo - 2.0 * mid + hi
        peak = np.where(curv < 0, 0.5 * (lo - hi) / np.where(curv < 0, curv, -1.0), np.nan)
        peak = np.clip(peak, -0.5, 0.5)
        n = np.sum(np.isfinite(peak), axis=(0, 1), keepdims=True)
        mean = np.nansum(peak, axis=(0, 1), keepdims=True) / np.maximum(n, 1)
        offsets[:, :, inner] = np.where(n > 0, peak - mean, np.nan)
    return np.moveaxis(vecs, -1, 0), snr, rate, np.moveaxis(offsets, -1, 0)


@dataclass(frozen=True, eq=False)
class PhaseEstimate:
    """A phase calibration measured from frames, and how well they determine it.

    Attributes
    ----------
    calibration
        The radar's calibration with the measured phases (``phase_frequency_calib.txt``):
        the existing one's phases times the measured residual gains (its frequencies kept),
        or, for a radar without one, the measured gains with zero delays.
    fit
        The self-calibration of the residual gains (:class:`SelfCalibration`).
    frames
        Frames that gave cells.
    delay
        float64 ``(tx, rx)``: each channel's measured delay relative to channel (0, 0)
        [range bins of the frame], or None (the calibration's own delays were kept).
    """

    calibration: PhaseFrequencyCalib
    fit: SelfCalibration
    frames: int
    delay: np.ndarray | None = None

    @property
    def cells(self) -> int:
        """Cells the estimate used."""
        return int(self.fit.used.size)

    def tx_phase_deg(self) -> np.ndarray:
        """float64 ``(tx,)``: each TX slot's phase relative to slot 0, averaged over RX [deg]
        (the correction is the opposite)."""
        g = self.fit.gain
        return np.degrees(np.angle(np.sum(g * np.conj(g[:1, :]), axis=1)))


def measured_calibration(calib: RadarCalib, gain: np.ndarray,
                         delay: np.ndarray | None = None) -> PhaseFrequencyCalib:
    """The phase calibration that removes ``gain`` ``(tx, rx)`` (and ``delay``, each channel's
    range offset in the frame's range bins ``c·fs/(2·S·Ns)``) from frames the chain has
    calibrated with ``calib``'s own (or from raw frames when it has none).

    The chain multiplies channel ``(t, r)`` by ``P[0,0]/P[t,r]`` and shifts it by
    ``−(f[t,r] − f[0,0])`` bins scaled to the frame (docs/conventions.md §2), so the residual
    gains multiply the existing ``P`` and the delays add to ``f``; a radar without a
    calibration gets ``P = gain``, ``f = delay`` and no near-field phases.
    """
    g = np.asarray(gain, dtype=np.complex128) / gain[0, 0]
    dly = np.zeros(g.shape) if delay is None else np.asarray(delay, dtype=np.float64)
    w = calib.waveform
    old = calib.phase_frequency
    if old is None:
        return PhaseFrequencyCalib(dly - dly[0, 0], g, w.slope, w.sample_rate,
                                   near_field=False)
    to_cal = (old.slope / w.slope) * (w.sample_rate / old.sample_rate)
    return PhaseFrequencyCalib(old.frequency + (dly - dly[0, 0]) * to_cal, old.phase * g,
                               old.slope, old.sample_rate, near_field=old.near_field)


def _collect(proc, frames: SequenceOf, s: PhaseEstimateSettings,
             velocities: Velocities | None,
             progress: Callable[[int], None] | None) -> tuple[list, list, list, list]:
    """Cells, range rates, velocities and channel range offsets of every frame."""
    parts: list = []
    rates: list = []
    vels: list = []
    offs: list = []
    for i in range(len(frames)):
        adc = frames[i]
        if adc is not None:
            c, _, rate, off = frame_cells(proc, adc, s)
            if len(c):
                parts.append(c)
                rates.append(rate)
                offs.append(off)
                v = (np.full(3, np.nan) if velocities is None
                     else np.asarray(velocities[i], dtype=np.float64))
                vels.append(np.broadcast_to(v, (len(c), 3)))
        if progress is not None:
            progress(1)
    return parts, rates, vels, offs


def estimation_passes(calib: RadarCalib) -> int:
    """Passes over the frames :func:`estimate_phase_calibration` makes: 4 for a radar without
    a calibration (its channels' delays are measured first, then the phases on frames with
    them removed, twice more with the delays corrected on the cells found to hold one
    scatterer), 1 for one whose calibration holds the delays (2 where the channels show none:
    one LO, as on the single chip)."""
    return 1 if calib.phase_frequency is not None else 4


def _median_offsets(offs: list, used: np.ndarray | None) -> np.ndarray | None:
    """Per channel, the median range offset over the cells (``used`` of them) where every
    channel peaks; None with fewer than 4 such cells."""
    if not offs:
        return None
    o = np.concatenate(offs)
    good = np.all(np.isfinite(o), axis=(1, 2))
    if used is not None:
        good &= used
    if good.sum() < 4:
        return None
    return np.median(o[good], axis=0)


def estimate_phase_calibration(frames: SequenceOf, calib: RadarCalib,
                               settings: PhaseEstimateSettings | None = None,
                               progress: Callable[[int], None] | None = None,
                               velocities: Velocities | None = None) -> PhaseEstimate:
    """Measure a radar's per-channel phases and gains (and, without a calibration, delays)
    from its ADC frames.

    Parameters
    ----------
    frames
        ``len`` and indexing: complex ``(tx, rx, chirp, sample)`` ADC frames (None: a frame
        that could not be read, passed over), read once a pass (:func:`estimation_passes`;
        an ``AdcStream`` reads them lazily). Their static scene must move slower than ``v_max``
        relative to the radar (unaliased Doppler; a minority of faster movers is left out by
        the trimmed fit).
    calib
        The radar's calibration; its phase calibration, if any, is applied first and refined.
    settings
        :class:`PhaseEstimateSettings`.
    progress
        Called with the frames done: 1 after each frame of each pass (more at once for the
        passes a board without delays does not need).
    velocities
        ``velocities[i]``: the radar's velocity in its own frame at frame ``i``, float
        ``(3,)`` [m/s] (the ground truth's; NaN where unknown), or None. With them the azimuth
        gauge can come from the static scene's Doppler (:func:`self_calibrate`).

    Returns
    -------
    PhaseEstimate
    """
    from dataclasses import replace

    from .processor import RadarProcessor  # processor imports this layer's stages

    s = settings or PhaseEstimateSettings()
    ant = calib.antenna
    rho = calib.waveform.center_frequency / ant.design_frequency
    tx_pos = np.asarray(ant.tx_positions, dtype=np.float64)
    rx_pos = np.asarray(ant.rx_positions, dtype=np.float64)
    proc = RadarProcessor(calib)
    to_frame = calib.waveform.num_samples / proc.cube.range_fft_size
    delay = None
    base = calib
    if estimation_passes(calib) > 1:
        # A board's channels have their own delays (the cascade's four chips: a few tenths of
        # a range bin); left in, they change each cell's channels differently with where its
        # target lies in the bin, and no constant gain fits. Pass 1: the median over cells of
        # each channel's range peak against the cell's mean (cells where every channel
        # peaks); passes 2 and 3 correct it with the cells their fits found to hold one
        # scatterer (measured on simulated cascade runs: 0.12 → 0.04 → 0.02 → 0.016 bins rms).
        _, _, _, offs = _collect(proc, frames, s, None, progress)
        delay = _median_offsets(offs, None)
        if delay is not None and not np.any(delay):
            # One LO (the single chip): on a single scatterer every channel's range profile is
            # the same, and the median offsets are exactly zero: no delays, one more pass.
            delay = None
            if progress is not None:
                progress(2 * len(frames))             # the passes that are not needed
        if delay is not None:
            delay = delay * to_frame
            base = replace(calib, phase_frequency=measured_calibration(
                calib, np.ones(delay.shape, dtype=np.complex128), delay))
    for last in ((False, False, True) if delay is not None else (True,)):
        parts, rates, vels, offs = _collect(proc if base is calib else RadarProcessor(base),
                                            frames, s, velocities,
                                            progress)
        if sum(len(p) for p in parts) < 4:
            raise MissingDataError(f"{calib.name}: no frame has cells {s.min_snr_db:g} dB "
                                   "above the noise to measure the channel phases on")
        doppler = ((np.concatenate(rates), np.concatenate(vels)) if velocities is not None
                   else None)
        fit = self_calibrate(np.concatenate(parts), tx_pos, rx_pos, rho, s, doppler)
        if last or delay is None:
            break
        more = _median_offsets(offs, fit.used)
        if more is None:
            break
        delay = delay + more * to_frame
        base = replace(calib, phase_frequency=measured_calibration(
            calib, np.ones(delay.shape, dtype=np.complex128), delay))
    return PhaseEstimate(measured_calibration(calib, fit.gain, delay), fit, len(parts), delay)
