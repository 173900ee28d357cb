"""Radar sensor models: what each radar sees of a scene, its raw ADC frames and on-board points.

Per frame (timestamp = start of the frame's first chirp):

1. Scatterers (static structure and moving objects) are moved into the radar frame. Those
   outside the range window (``min_range`` .. ``max_range_fraction`` of the unambiguous range,
   the IF filter's pass band), behind the radar, outside the field of view, facing away
   (one-sided faces) or occluded (a ray from the radar meets another surface first) are culled.
2. Each remaining scatterer gets a complex amplitude ``A·s·g(θ)·P(az, el)·e^{jϕ}``
   (:mod:`.scene`, ``P`` the two-way antenna pattern ``cos^pa(az)·cos^pe(el)``) and its
   velocity relative to the radar.
3. :func:`.radar_if.synthesize_adc` (single precision) forms the IF frame (real TDM timing, free-space
   ``1/R²``); white thermal noise is added *before* the per-channel errors, as in hardware
   (receiver noise enters at the LNA, ahead of the receive chain's gain); the cascade's
   per-channel gain, phase and delay errors are then imposed with
   :func:`.radar_if.apply_channel_errors` (the inverse of the calibration written to
   ``calib/cascade/phase_frequency_calib.txt``). The transmit part of a channel's gain (TX
   power) scales the echo but not the receiver noise, so the noise of TX ``t`` enters scaled by
   ``1/a_t`` (:func:`tx_gains`); after calibration the channels therefore carry unequal noise,
   as real ones do. The static coupling/leakage term (whose range FFT is
   ``coupling_calib.txt``) is added last; the result is rounded and clipped to int16 when
   written.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.fft
from scipy.spatial.transform import Rotation

from ..calib import CouplingCalib, PhaseFrequencyCalib, RadarCalib
from ..calib.waveform import SPEED_OF_LIGHT
from .radar_if import apply_channel_errors, synthesize_adc
from .raycast import RectArrays, cast_rays
from .scene import Scatterers

__all__ = [
    "RADAR_MODELS",
    "PhaseErrors",
    "RadarModel",
    "RadarTargets",
    "make_channel_errors",
    "make_coupling",
    "onboard_pointcloud",
    "planted_coupling",
    "radar_frame",
    "tx_gains",
    "visible_targets",
]


@dataclass(frozen=True)
class RadarModel:
    """Sensor-level parameters of a simulated radar (beyond its calibration).

    Attributes
    ----------
    gain
        ``A``: ADC counts at 1 m of a 1 m² target on boresight.
    noise_std
        Thermal noise per I and per Q component [counts].
    pattern_azimuth, pattern_elevation
        Exponents of the two-way amplitude pattern ``cos^pa(az)·cos^pe(el)``.
    max_azimuth, max_elevation
        Field-of-view limits [rad] beyond which nothing is received.
    min_range
        Nearest scatterer simulated [m].
    max_range_fraction
        Farthest scatterer, as a fraction of the unambiguous range ``c·fs/(2S)`` (the IF
        anti-alias filter suppresses beat frequencies beyond it).
    coupling_ranges
        Equivalent one-way ranges [m] of the TX→RX leakage paths (direct leakage, radome).
    coupling_amplitude
        Typical amplitude of one leakage path per channel [counts].
    detection_threshold_db
        On-board detector: SNR threshold of a range-Doppler cell [dB].
    frame_jitter
        Standard deviation of the frame timestamps about the nominal rate [s].
    """

    gain: float
    noise_std: float
    pattern_azimuth: float = 1.0
    pattern_elevation: float = 4.0
    max_azimuth: float = np.radians(85.0)
    max_elevation: float = np.radians(70.0)
    min_range: float = 0.3
    max_range_fraction: float = 0.95
    coupling_ranges: tuple[float, ...] = (0.02, 0.06, 0.12, 0.25)
    coupling_amplitude: float = 10.0
    detection_threshold_db: float = 15.0
    frame_jitter: float = 1.0e-3


RADAR_MODELS: dict[str, RadarModel] = {
    # Amplitudes follow the real calibration files: a ~3 m corner reflector gives range-FFT
    # peaks of 5e3..3e4 on the cascade (phase_frequency_calib) and the coupling profiles peak
    # near 4e3 (cascade, 256-point FFT) and 1.5e4 (single chip, 128-point FFT).
    "cascade": RadarModel(gain=300.0, noise_std=2.0, coupling_amplitude=8.0),
    "single_chip": RadarModel(gain=500.0, noise_std=3.0, coupling_amplitude=60.0,
                              pattern_elevation=6.0),
}
"""Default models of the two ColoRadar radars."""


@dataclass(frozen=True, eq=False)
class RadarTargets:
    """The scatterers a radar sees in one frame, in its frame at the frame start.

    Attributes
    ----------
    position
        float64 ``(K, 3)`` [m].
    velocity
        float64 ``(K, 3)``: relative to the radar, radar frame [m/s].
    amplitude
        complex128 ``(K,)``: amplitude at 1 m [counts] (pattern and incidence included).
    ident
        int64 ``(K,)``: scene-wide scatterer identifiers.
    """

    position: np.ndarray
    velocity: np.ndarray
    amplitude: np.ndarray
    ident: np.ndarray

    def __len__(self) -> int:
        return int(self.ident.size)

    @property
    def range(self) -> np.ndarray:
        """float64 ``(K,)`` [m]."""
        return np.linalg.norm(self.position, axis=1)

    @property
    def range_rate(self) -> np.ndarray:
        """float64 ``(K,)`` [m/s], > 0 receding."""
        r = self.range
        return np.einsum("ij,ij->i", self.position, self.velocity) / np.where(r > 0, r, 1.0)

    @property
    def received_amplitude(self) -> np.ndarray:
        """float64 ``(K,)``: ``|a|/R²`` per ADC sample [counts]."""
        return np.abs(self.amplitude) / self.range**2


def visible_targets(calib: RadarCalib, model: RadarModel, scatterers: Scatterers,
                    world_R_radar: Rotation, radar_origin: np.ndarray,
                    radar_velocity: np.ndarray, radar_angular_velocity: np.ndarray,
                    rects: RectArrays, occlusion_margin: float = 0.05) -> RadarTargets:
    """Cull and weight the scatterers one radar sees at one instant.

    Parameters
    ----------
    calib, model
        The radar.
    scatterers
        World-frame scatterers at this instant (``(K, …)`` arrays).
    world_R_radar, radar_origin
        The radar's pose [m].
    radar_velocity
        float ``(3,)``: velocity of the radar's origin, world frame [m/s].
    radar_angular_velocity
        float ``(3,)``: angular velocity of the radar, its own frame [rad/s].
    rects
        Surfaces that can hide scatterers (group size 1: this instant).
    occlusion_margin
        A hit this much before the scatterer hides it [m] (scatterers lie on surfaces).

    Returns
    -------
    RadarTargets
    """
    w = calib.waveform
    o = np.asarray(radar_origin, dtype=np.float64)
    rel = scatterers.position - o
    r_inv = world_R_radar.inv()
    p = r_inv.apply(rel) if len(rel) else rel
    rng_ = np.linalg.norm(p, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        az = np.arctan2(p[:, 1], p[:, 0])
        el = np.arcsin(np.clip(p[:, 2] / rng_, -1, 1))
    keep = ((rng_ >= model.min_range) & (rng_ <= model.max_range_fraction * w.max_range)
            & (p[:, 0] > 0) & (np.abs(az) <= model.max_azimuth)
            & (np.abs(el) <= model.max_elevation))
    # Incidence on surfaces; one-sided faces seen from behind are dropped.
    n = scatterers.normal
    has_n = np.any(n != 0, axis=1)
    cos_inc = np.where(has_n, -np.einsum("ij,ij->i", n, rel) / np.where(rng_ > 0, rng_, 1), 1.0)
    keep &= ~(scatterers.one_sided & (cos_inc <= 0))
    idx = np.flatnonzero(keep)
    if idx.size and rects.count:
        dirs = rel[idx] / rng_[idx, None]
        dist, _ = cast_rays(o[None, None, :], dirs[None], rects)
        idx = idx[dist[0] >= rng_[idx] - occlusion_margin]
    p_k = p[idx]
    pattern = (np.cos(az[idx]) ** model.pattern_azimuth
               * np.cos(el[idx]) ** model.pattern_elevation)
    amp = (model.gain * scatterers.strength[idx] * np.abs(cos_inc[idx]) * pattern
           * np.exp(1j * scatterers.phase[idx]))
    # d/dt of R_ws^T (P - o): the scatterer's and the radar's motion, plus the radar's turn.
    v_rel = (r_inv.apply(scatterers.velocity[idx] - radar_velocity) if idx.size
             else np.zeros((0, 3)))
    v_rel = v_rel - np.cross(np.asarray(radar_angular_velocity, float), p_k)
    return RadarTargets(p_k, v_rel, amp, scatterers.ident[idx])


def make_channel_errors(calib: RadarCalib, rng: np.random.Generator,
                        gain_spread: float = 7.0) -> PhaseFrequencyCalib:
    """Random per-channel errors of a cascade board, as its calibration file describes them.

    Frequencies ≈ 51 ± 0.3 range bins (a corner reflector near 3 m seen with slightly different
    delays per channel, as in the real file) and random phases. Amplitudes are a TX gain times
    an RX gain times a small residual (log-normal), scaled so that the largest over the
    smallest is about ``gain_spread`` (the real file's amplitudes, 5.0e3 … 3.4e4, spread 6.8×
    and are nearly rank one); slope and sampling rate are the waveform's. Marked
    ``near_field=False``: the simulator's frames are far-field (:mod:`.radar_if`), so the
    errors it imposes and this calibration removes hold no reflector's near-field phases, and
    processing does not focus (``near_field="auto"``; docs/dsp.md, "Near field").
    """
    w = calib.waveform
    shape = (w.num_tx, w.num_rx)
    freq = 51.15 + rng.uniform(-0.3, 0.3, shape)
    phase = np.exp(1j * rng.uniform(-np.pi, np.pi, shape))
    log_amp = (rng.normal(0.0, 1.0, (w.num_tx, 1)) + 0.8 * rng.normal(0.0, 1.0, (1, w.num_rx))
               + 0.15 * rng.normal(0.0, 1.0, shape))
    if gain_spread > 1.0 and np.ptp(log_amp) > 0:
        log_amp = log_amp * (np.log(gain_spread) / np.ptp(log_amp))
    amp = 1.0e4 * np.exp(log_amp - log_amp.mean())
    return PhaseFrequencyCalib(np.round(freq, 4), amp * phase, w.slope, w.sample_rate,
                               near_field=False)


@dataclass(frozen=True)
class PhaseErrors:
    """Per-TX and per-RX phase and gain errors planted on one simulated radar board (an
    uncalibrated board, as the release's single chip and a user's own board are).

    Attributes
    ----------
    radar
        ``"single_chip"`` or ``"cascade"``.
    tx_phase_deg, rx_phase_deg
        Each TX slot's / RX channel's phase error [deg]: a tuple with one value each, or a
        spread ``s`` from which each is drawn uniformly in ``[−s, s]`` (``board_seed``). TX
        slot 0 and RX 0 are the reference (their errors are relative).
    gain_db
        Spread [dB] of the TX and RX gains, each drawn uniformly in ``[−g, g]``.
    calibration
        What the calib folder holds: ``"none"`` no ``phase_frequency_calib.txt`` (an
        uncalibrated board: the cascade's own channel errors and delays are then unknown
        too); ``"board"`` the board's own calibration without the planted errors (the
        cascade's, or the single chip's unit one: a calibration gone stale, a TX path that
        drifted); ``"all"`` the one that removes everything.
    board
        A ``phase_frequency_calib.txt`` (path) whose channel errors (delays and gains) the
        board carries instead of the simulator's own, the release's cascade file say: how well
        ``coloradar calibrate phase`` recovers a real calibration (docs/calibration.md).
    """

    radar: str = "single_chip"
    tx_phase_deg: tuple[float, ...] | float = 180.0
    rx_phase_deg: tuple[float, ...] | float = 0.0
    gain_db: float = 0.0
    calibration: Literal["none", "board", "all"] = "none"
    board: str | None = None

    def gains(self, num_tx: int, num_rx: int, rng: np.random.Generator) -> np.ndarray:
        """complex128 ``(tx, rx)``: ``x = g · ideal`` per channel, ``g[0, 0] = 1``."""
        def draw(v: tuple[float, ...] | float, n: int, what: str) -> np.ndarray:
            if isinstance(v, (int, float)):
                return rng.uniform(-float(v), float(v), n)
            a = np.asarray(v, dtype=np.float64)
            if a.shape != (n,):
                raise ValueError(f"{what}: expected {n} values, got {a.size}")
            return a
        tx = np.radians(draw(self.tx_phase_deg, num_tx, "tx_phase_deg"))
        rx = np.radians(draw(self.rx_phase_deg, num_rx, "rx_phase_deg"))
        amp = 10.0 ** (rng.uniform(-self.gain_db, self.gain_db, (num_tx, 1)) / 20.0
                       + rng.uniform(-self.gain_db, self.gain_db, (1, num_rx)) / 20.0)
        g = amp * np.exp(1j * (tx[:, None] + rx[None, :]))
        return g / g[0, 0]


def tx_gains(errors: PhaseFrequencyCalib) -> np.ndarray:
    """Transmit part ``a_t`` of the channel gains ``|P[t,r]/P[0,0]|`` (float64 ``(tx,)``).

    The gains are split as ``a_t·b_r·e_tr`` by averaging their logarithms over RX (geometric
    mean), normalised so that ``Π a_t = 1``: receiver noise is scaled by ``b_r`` (and the
    residual) but not by ``a_t``.
    """
    log_g = np.log(np.abs(1.0 / errors.relative_phase()))
    a = log_g.mean(axis=1)
    return np.exp(a - a.mean())


def make_coupling(calib: RadarCalib, model: RadarModel,
                  rng: np.random.Generator) -> tuple[np.ndarray, CouplingCalib]:
    """A static TX→RX leakage term and the calibration that measures it.

    Returns
    -------
    coupling_adc : numpy.ndarray
        complex64 ``(tx, rx, sample)``: added to every chirp of every frame [counts].
    calib : CouplingCalib
        Its unwindowed, unnormalised range FFT (``scipy.fft.fft`` over samples; identical for
        all chirps, so equal to the chirp average), first ``num_range_bins`` bins.
    """
    w = calib.waveform
    ntx, nrx, _, ns = w.frame_shape
    f_fast = w.start_frequency + w.slope * (w.adc_start_time + np.arange(ns) / w.sample_rate)
    tau = 2.0 * np.asarray(model.coupling_ranges) / SPEED_OF_LIGHT                # (L,)
    paths = np.exp(2j * np.pi * tau[:, None] * f_fast[None, :])                   # (L, Ns)
    # Nearer paths are stronger (direct leakage dominates); random per channel.
    scale = model.coupling_amplitude / (1.0 + np.arange(len(tau)))
    amp = (scale * rng.rayleigh(1.0, (ntx, nrx, len(tau)))
           * np.exp(1j * rng.uniform(-np.pi, np.pi, (ntx, nrx, len(tau)))))
    adc = (amp @ paths).astype(np.complex64)                                       # (tx, rx, Ns)
    spectrum = scipy.fft.fft(adc.astype(np.complex128), axis=-1)[..., :calib.heatmap.num_range_bins]
    return adc, CouplingCalib(spectrum.astype(np.complex64), w.num_chirps)


def planted_coupling(calib: RadarCalib, coupling: CouplingCalib,
                     own_adc: np.ndarray) -> np.ndarray:
    """The leakage term of a radar whose calibration carries ``coupling`` (a released file, say)
    instead of the simulator's own.

    For each TX that ``coupling`` holds, the signal whose unwindowed, unnormalised FFT equals
    the file's bins ``0 … K−1`` (and zero on the others); for each TX whose block is all zeros
    (``coupling.missing_tx``: the released single chip's TX 2), ``own_adc``, the simulator's own
    leakage. The frames then carry coupling on every TX, and the calibration says only what the
    file says.

    Returns
    -------
    numpy.ndarray
        complex64 ``(tx, rx, sample)`` [counts], added to every chirp.
    """
    ns = calib.waveform.num_samples
    k = min(coupling.num_range_bins, ns)
    spec = np.zeros((coupling.num_tx, coupling.num_rx, ns), dtype=np.complex128)
    spec[..., :k] = coupling.data[..., :k]
    adc = np.fft.ifft(spec, axis=-1).astype(np.complex64)
    for t in coupling.missing_tx:
        adc[t] = own_adc[t]
    return adc


def radar_frame(calib: RadarCalib, model: RadarModel, targets: RadarTargets, *,
                channel_errors: PhaseFrequencyCalib | None, coupling_adc: np.ndarray | None,
                rng: np.random.Generator) -> np.ndarray:
    """The raw ADC frame (before int16 rounding) of one radar seeing ``targets``.

    Returns
    -------
    numpy.ndarray
        complex64 ``(tx, rx, chirp, sample)`` [counts].
    """
    frame = synthesize_adc(calib, targets.position, targets.velocity, targets.amplitude,
                           precision="single")
    if model.noise_std > 0:
        # Receiver noise enters before the receive chain's gain, after the TX power.
        noise = rng.standard_normal((*frame.shape, 2), dtype=np.float32)
        scale = np.full(frame.shape[0], model.noise_std, dtype=np.float32)
        if channel_errors is not None:
            scale = (model.noise_std / tx_gains(channel_errors)).astype(np.float32)
        frame += scale[:, None, None, None] * noise.view(np.complex64)[..., 0]
    if channel_errors is not None:
        frame = apply_channel_errors(frame, channel_errors)
    if coupling_adc is not None:
        frame += coupling_adc[:, :, None, :]
    return frame


def coherent_snr(calib: RadarCalib, model: RadarModel, targets: RadarTargets) -> np.ndarray:
    """float64 ``(N,)``: each scatterer's SNR after the range, Doppler and virtual-array
    sums, ``|A|²·Ns·Nc·Nv/(2σ²)`` (linear, not dB)."""
    w = calib.waveform
    nv = w.num_tx * w.num_rx
    return (targets.received_amplitude**2 * w.num_samples * w.num_chirps * nv
            / (2.0 * model.noise_std**2))


def onboard_pointcloud(calib: RadarCalib, model: RadarModel, targets: RadarTargets,
                       rng: np.random.Generator) -> np.ndarray:
    """What a TI single-chip radar's on-board detector reports for ``targets``.

    The firmware (TI mmWave SDK out-of-box demo) detects cells of the range–Doppler map by
    CFAR, keeps local peaks (peak grouping) and estimates one angle per cell. Modelled from the
    truth: each scatterer adds its coherent SNR ``|A|²·Ns·Nc·Nv/(2σ²)`` to its (range bin,
    aliased Doppler bin) cell of a map whose noise level is 1; a cell is detected when it is a
    3×3 local maximum and exceeds ``model.detection_threshold_db`` above the larger of the noise
    and the mean of its range neighbours (CA-CFAR: 4 guard, 16 training cells). A detection
    takes the angle of its cell's strongest scatterer, with a noise of standard deviation
    ``(2/N)/(1.6·sqrt(2·SNR))`` in ``sin(angle)`` (N the distinct virtual positions along that
    axis); azimuth is reported on a 64-point angle-FFT grid, range and range rate at their bin
    centres.

    Returns
    -------
    numpy.ndarray
        float32 ``(N, 5)``: x y z [m], intensity (SNR [dB]), range rate [m/s], radar frame.
    """
    from scipy.ndimage import maximum_filter, uniform_filter1d

    w = calib.waveform
    if len(targets) == 0:
        return np.zeros((0, 5), dtype=np.float32)
    r = targets.range
    nc = w.num_chirps
    rbin = np.rint(r / w.range_bin_width).astype(np.int64)
    dbin = np.mod(np.rint(targets.range_rate / w.velocity_bin_width).astype(np.int64), nc)
    snr_k = coherent_snr(calib, model, targets)
    nr = w.num_samples
    keep = rbin < nr
    snr_map = np.zeros((nr, nc))
    np.add.at(snr_map, (rbin[keep], dbin[keep]), snr_k[keep])
    power = snr_map + 1.0                                           # noise level 1
    # CA-CFAR along range: mean of 2x8 training cells beyond 2 guard cells on each side.
    wide = uniform_filter1d(power, 21, axis=0, mode="nearest") * 21
    guard = uniform_filter1d(power, 5, axis=0, mode="nearest") * 5
    clutter = (wide - guard) / 16
    thr = 10 ** (model.detection_threshold_db / 10)
    peak = power >= maximum_filter(power, size=3, mode=("nearest", "wrap"))
    det = peak & (power > thr * np.maximum(clutter, 1.0)) & (snr_map > 0)
    cells_r, cells_d = np.nonzero(det)
    if cells_r.size == 0:
        return np.zeros((0, 5), dtype=np.float32)
    # The strongest scatterer of each detected cell sets its angle.
    cell_of = rbin * nc + dbin
    order = np.lexsort((-snr_k, cell_of))
    uniq, first = np.unique(cell_of[order], return_index=True)
    wanted = cells_r * nc + cells_d
    k = order[first[np.searchsorted(uniq, wanted)]]
    snr = snr_map[cells_r, cells_d]
    ant = calib.antenna
    p = targets.position[k]
    u_az = p[:, 1] / np.linalg.norm(p[:, :2], axis=1)                      # sin(az)
    u_el = p[:, 2] / r[k]                                                   # sin(el)
    n_az = max(2, len(np.unique(ant.virtual.unique_positions[:, 0])))
    n_el = max(2, len(np.unique(ant.virtual.unique_positions[:, 1])))
    sd = 1.0 / (1.6 * np.sqrt(2 * snr))
    u_az = u_az + rng.standard_normal(k.size) * (2.0 / n_az) * sd
    u_az = np.clip(np.rint(u_az * 32) / 32, -0.999, 0.999)
    u_el = np.clip(u_el + rng.standard_normal(k.size) * (2.0 / n_el) * sd, -0.999, 0.999)
    d_signed = (cells_d + nc // 2) % nc - nc // 2
    el = np.arcsin(u_el)
    az = np.arcsin(u_az)
    rng_rep = cells_r * w.range_bin_width
    xyz = rng_rep[:, None] * np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                              np.sin(el)])
    out = np.column_stack([xyz, 10 * np.log10(snr), d_signed * w.velocity_bin_width])
    return out.astype(np.float32)
