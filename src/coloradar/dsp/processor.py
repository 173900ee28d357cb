"""The radar processor: one object per radar that turns ADC frames into heatmaps, range–Doppler
maps, detections and point clouds, with everything that depends only on the calibration
(windows, calibration factors, coupling, TDM phases, angle grids, CFAR scale) computed once.

Chain (each step a stage of :mod:`coloradar.dsp`)::

    adc (tx, rx, chirp, sample) complex64
      − coupling signal            (cube.coupling_signal: subtracting it = subtracting the file's
                                    unwindowed range FFT)
      − mean per chirp             (DC removal, optional)
      × G[t, r, n]                 (cascade phase/frequency calibration, docs/conventions.md §2)
      × range window × Doppler window × (−1)^c    (unit coherent gain; (−1)^c = fftshift)
      → range FFT, keep the first num_range_bins → Doppler FFT
      × exp(−j2π k t/(n·Ntx))      (TDM-MIMO compensation)            = range_doppler(adc)
      → Σ|·|² over channels        (non-coherent)                     = range_doppler_power(adc)
      → CFAR (Doppler circular, range truncated) → peaks → every significant angle peak of
        each cell → beam grouping, sidelobe guard → points from the array's phase centre
                                                                        = detect(adc)
      → unique virtual elements → 2D angle FFT per cell → peak over Doppler      = heatmap(adc)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import Any, Literal, get_args

import numpy as np
import scipy.fft as sfft
from scipy.stats import f as f_dist

from ..calib import HeatmapConfig, RadarCalib
from ..calib.waveform import SPEED_OF_LIGHT
from ..errors import FormatError, SettingsError
from .angle import (
    NearField,
    azimuth_peaks,
    capon_spectrum,
    newton_refine,
    refine_peak,
    row_profile,
    steering,
)
from .array import (
    OVERLAP_MODES,
    OverlapMode,
    angle_grid,
    combine_channels,
    pair_antennas,
    phase_centre,
    sines_to_unit,
)
from .cfar import (
    CFAR_KINDS,
    CFARConfig,
    CFAREdge,
    CFARKind,
    cfar_window,
    effective_train_cells,
    power_correlation,
    run_cfar,
)
from .cube import coupling_signal, phase_frequency_factors, signed_doppler_bins
from .detect import (
    Detections,
    channel_noise,
    sidelobe_envelope,
    sidelobe_pairs,
    source_fit_residuals,
)
from .heatmap import ENGINES, heatmap_from_elements, resolve_engine
from .tdm import alias_hypotheses, alias_phase, overlap_pairs, tdm_phase
from .windows import WINDOWS, WindowName, coherent_window, window

MAX_SOURCES = 4
"""Most angle peaks examined per range–Doppler cell (strongest first)."""
STRONG_NEIGHBOUR = 10.0
"""A 2D peak this many times its CFAR noise (10 dB) has its neighbours examined too."""

__all__ = ["ANGLE_METHODS", "COUPLING_DOMAINS", "NOISE_WEIGHTINGS", "AngleMethod", "CouplingDomain",
           "NoiseWeighting", "ProcessingSettings", "RadarProcessor"]

CouplingDomain = Literal["raw", "calibrated"]
"""What the coupling file is the range FFT of: uncalibrated or calibrated samples."""
COUPLING_DOMAINS: tuple[CouplingDomain, ...] = get_args(CouplingDomain)
AngleMethod = Literal["fft", "capon"]
"""Detection angles by Bartlett (FFT) or Capon (MVDR) beamforming."""
ANGLE_METHODS: tuple[AngleMethod, ...] = get_args(AngleMethod)
NoiseWeighting = Literal["whiten", "off"]
"""How channels are summed for detection (:attr:`ProcessingSettings.noise_weighting`)."""
NOISE_WEIGHTINGS: tuple[NoiseWeighting, ...] = get_args(NoiseWeighting)


@dataclass(frozen=True)
class ProcessingSettings:
    """Settings of a :class:`RadarProcessor` (all keyword arguments of its constructor).

    Attributes
    ----------
    range_window, doppler_window
        ``"hann"``, ``"blackman"`` or ``"none"``.
    range_fft_size, doppler_fft_size
        FFT lengths (≥ samples / chirp loops; larger = zero padding); None = no padding.
    num_range_bins
        Range bins kept (heatmap and detection); None = the heatmap_cfg's range span
        (its bin count times the zero-padding factor).
    dc_removal
        Subtract each chirp's mean before anything else.
    phase_frequency_calibration
        Apply the cascade phase/frequency calibration when the calibration has one.
    coupling_subtraction
        Subtract the coupling calibration when the calibration has one.
    coupling_domain
        ``"raw"``: the coupling file is the FFT of uncalibrated samples (subtracted before the
        phase/frequency calibration); ``"calibrated"``: of calibrated samples.
    tdm_compensation
        Compensate the TDM-MIMO Doppler phase before angle processing.
    overlap
        Virtual pairs sharing a position: ``"first"`` (TX-major first pair) or ``"average"``.
    azimuth_sign, elevation_sign
        +1 when the antenna file's az (el) axis grows toward +y (+z) (docs/conventions.md §3); −1 mirrors.
    cfar_kind, cfar_guard, cfar_train, pfa, cfar_rank
        CFAR on the range–Doppler power map; guard/train are (Doppler, range) half-widths;
        ``pfa`` the false-alarm probability per cell for noise (the map sums Ntx·Nrx channels,
        and the threshold accounts for it and for the windows' correlation of neighbouring
        cells); ``cfar_rank`` the OS rank fraction.
    cfar_excision
        CA/GO/SO: a second CFAR pass with the first pass's detections replaced by their noise
        estimate, so that a strong target does not mask weaker ones within its training
        window (:func:`coloradar.dsp.cfar.cfar`).
    noise_weighting
        How the channels are summed for detection. ``"whiten"``: each channel weighted by the
        inverse of its noise power, estimated from the frame (median cell power beyond
        ``min_range``), so that noise in the sum is a proper Ntx·Nrx-look chi-square whatever
        the channel gains and calibration; ``"off"``: plain sum, all channels assumed
        equally noisy (the chain before issue 10; false alarms grow with the gain spread).
    doppler_unwrap
        Largest ``|range rate|`` [m/s] searched beyond ±v_max: each detection tests the TDM
        alias hypotheses whose range rate stays within it (at most Ntx of them) and keeps the
        best (:mod:`coloradar.dsp.tdm`); 0 switches the search off (folded range rates, and
        angles compensated for the folded Doppler).
    alias_margin_db
        Radars without overlapping virtual pairs (the single chip) choose the Doppler alias
        by a model selection on the filled row (one or two sources under each hypothesis,
        :meth:`RadarProcessor._choose_alias`); another hypothesis must explain this margin
        [dB] more power than the folded one.
    heatmap_unwrap
        Heatmaps with disambiguated Doppler: cells that pass the CFAR are compensated for
        their best alias hypothesis before the angle FFT, and channel 1 carries the unwrapped
        range rate (see :meth:`RadarProcessor.heatmap`).
    sidelobe_guard, sidelobe_margin_db
        Drop detections that a stronger one's window sidelobes explain: a candidate ``Δd``
        Doppler and ``Δr`` range bins from a stronger one of power ``P`` is dropped when its
        power above the CFAR noise is below ``P·E_d(Δd)·E_r(Δr)`` times the margin, ``E`` the
        windows' worst-case sidelobe envelopes.
    beam_doppler
        Refine each detection's Doppler on the beam steered at its refined direction (three
        dot products per detection) instead of on the channel-summed power: on extended
        surfaces the summed power mixes the range rates of all directions of a cell, and the
        range rate would not belong to the direction reported (docs/dsp.md).
    min_range
        Detections closer than this [m] are dropped (coupling residue lives there).
    peak_grouping
        Group the cells of one target into one point: CFAR cells that peak along Doppler or
        along range are examined, and a point is kept only where its cell's beam, steered at
        the point's direction, is not smaller than that of any of the 8 neighbouring
        range–Doppler cells (so a target one bin from a stronger one in another direction
        stays). False: every CFAR cell makes points.
    multi_peak
        Every significant peak of a cell's azimuth profile becomes a point (two scatterers
        at one range and range rate, as a wall on each side of a corridor): a secondary peak
        counts when, with the strongest source's response (its sidelobes) removed, what is
        left in its direction is above the beam noise at ``angle_pfa`` and within
        ``angle_dynamic_range_db`` of the strongest, and, once the cell's sources are fitted
        jointly, it stands out of what that fit leaves (an F-test at ``angle_pfa`` with the
        residual as the noise: model error of extended surfaces counts as noise there).
        False: one point per cell.
    angle_pfa
        Probability that noise alone makes a secondary angle peak in a cell.
    angle_dynamic_range_db
        A secondary angle peak of a cell counts only within this many dB of the cell's
        strongest source, after that source's response is removed (model errors of real
        arrays: calibration residue, mutual coupling).
    near_field
        Focus beams at the detection's range (:class:`~coloradar.dsp.angle.NearField`): the
        cascade's aperture is in its near field over the whole processed range. ``"auto"``
        (default): where the calibration focuses the channels at its reflector's range
        (:attr:`~coloradar.calib.RadarCalib.near_field_reference`: the release's cascade
        file, ≈ 3.0 m), focus relative to it, ``exp(−jk(q(ρ) − q(R0)))``; where it does not
        (no phase calibration, or one marked far-field as the simulator's), no focusing.
        True: always focus (relative to the calibration's reflector when it has one,
        absolute when not: spherical-wave frames without a near-field calibration). False:
        plane-wave beams (docs/dsp.md, "Near field").
    phase_centre
        Points from the virtual array's phase centre (True: the physics of a real array, whose
        range FFT and beams measure range and direction from it; the point is that position
        in the radar frame). False: range and direction taken as seen from the radar origin,
        as the simulator's narrowband far-field model (:mod:`coloradar.sim.radar_if`) makes
        them (docs/dsp.md, "Where a point is").
    angle_refine
        Refine each direction off the grid by Newton steps on the Bartlett beam power
        (``angle_method="fft"``), after the log-parabola on the grid.
    angle_method
        ``"fft"`` (Bartlett) or ``"capon"`` (MVDR per detection, see :mod:`coloradar.dsp.angle`).
    angle_oversample
        Detection angle grid = heatmap grid × this, before sub-bin refinement.
    capon_loading
        Capon diagonal loading relative to the mean eigenvalue.
    workers
        Threads per scipy.fft call. The default 1 is fastest for one frame on few cores (the
        heatmap's FFTs come in cache-sized chunks too small to split); parallelism across
        frames belongs to the batch layer (one process per core).
    engine
        ``"auto"`` (numba when installed, else numpy), ``"numba"`` or ``"numpy"``: whether
        the heatmap's elevation transform, power and Doppler maximum, and the range stage's
        coupling/DC/calibration/window pass, run as compiled kernels
        (:mod:`coloradar.dsp.heatmap`, ``pip install coloradar[accel]``); the results agree
        to float32 rounding.
    """

    range_window: WindowName = "hann"
    doppler_window: WindowName = "hann"
    range_fft_size: int | None = None
    doppler_fft_size: int | None = None
    num_range_bins: int | None = None
    dc_removal: bool = True
    phase_frequency_calibration: bool = True
    coupling_subtraction: bool = True
    coupling_domain: CouplingDomain = "raw"
    tdm_compensation: bool = True
    overlap: OverlapMode = "first"
    azimuth_sign: int = 1
    elevation_sign: int = 1
    beam_doppler: bool = True
    cfar_kind: CFARKind = "ca"
    cfar_guard: tuple[int, int] = (1, 2)
    cfar_train: tuple[int, int] = (2, 8)
    pfa: float = 1e-4
    cfar_rank: float = 0.75
    cfar_excision: bool = True
    noise_weighting: NoiseWeighting = "whiten"
    doppler_unwrap: float = 10.0
    alias_margin_db: float = 0.0
    heatmap_unwrap: bool = False
    sidelobe_guard: bool = True
    sidelobe_margin_db: float = 6.0
    min_range: float = 0.3
    peak_grouping: bool = True
    multi_peak: bool = True
    angle_pfa: float = 1e-3
    angle_refine: bool = True
    angle_dynamic_range_db: float = 20.0
    near_field: bool | Literal["auto"] = "auto"
    phase_centre: bool = True
    angle_method: AngleMethod = "fft"
    angle_oversample: int = 2
    capon_loading: float = 0.05
    workers: int = 1
    engine: str = "auto"

    def __post_init__(self) -> None:
        choices = {"range_window": WINDOWS, "doppler_window": WINDOWS,
                   "coupling_domain": COUPLING_DOMAINS, "overlap": OVERLAP_MODES,
                   "cfar_kind": CFAR_KINDS, "angle_method": ANGLE_METHODS,
                   "noise_weighting": NOISE_WEIGHTINGS,
                   "azimuth_sign": (1, -1), "elevation_sign": (1, -1), "engine": ENGINES}
        choices["near_field"] = (True, False, "auto")
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise SettingsError(f"{name} = {getattr(self, name)!r}; expected one of "
                                    f"{', '.join(map(str, allowed))}")
        if not 0.0 < self.pfa < 1.0:
            raise SettingsError(f"pfa must lie in (0, 1), got {self.pfa!r}")
        if not self.doppler_unwrap >= 0:
            raise SettingsError(f"doppler_unwrap must be >= 0 m/s (0 = off), got "
                                f"{self.doppler_unwrap!r}")
        if not 0.0 < self.angle_pfa < 1.0:
            raise SettingsError(f"angle_pfa must lie in (0, 1), got {self.angle_pfa!r}")
        if self.angle_oversample < 1 or self.capon_loading <= 0:
            raise SettingsError("angle_oversample must be >= 1 and capon_loading > 0")
        for name in ("cfar_guard", "cfar_train"):
            object.__setattr__(self, name, _range_doppler_pair(name, getattr(self, name)))

    def replace(self, **changes) -> ProcessingSettings:
        """A copy with some settings changed (unknown names raise ``TypeError``)."""
        return replace(self, **changes)

    @classmethod
    def parse_setting(cls, text: str) -> tuple[str, object]:
        """``NAME=VALUE`` (as given on a command line) as a field name and a typed value.

        The value is read as the type of the field's default: ``true``/``false`` for flags,
        comma-separated integers for tuples (``2,8``), ``none`` where the default is None.
        ``workers`` is not settable this way (executors decide it).

        Raises
        ------
        ValueError
            Unknown name, missing ``=``, or a value of the wrong type.
        """
        names = [f.name for f in fields(cls) if f.name != "workers"]
        defaults = {f.name: f.default for f in fields(cls)}
        name, sep, value = text.partition("=")
        name, value = name.strip(), value.strip()
        if not sep or name not in names:
            raise SettingsError(f"expected NAME=VALUE with NAME one of {', '.join(names)}; "
                                f"got {text!r}")
        default = defaults[name]
        try:
            if name == "near_field":                     # a flag or "auto"
                if value.lower() == "auto":
                    return name, "auto"
                if value.lower() not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError
                return name, value.lower() in ("true", "1", "yes")
            if value.lower() == "none" and default is None:
                return name, None
            if isinstance(default, bool):
                if value.lower() not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError
                return name, value.lower() in ("true", "1", "yes")
            if isinstance(default, tuple):
                return name, tuple(int(v) for v in value.split(","))
            if isinstance(default, int) or default is None:
                return name, int(value)
            if isinstance(default, float):
                return name, float(value)
            return name, value
        except ValueError:
            raise SettingsError(f"{name}: cannot use {value!r} (default {default!r})") from None


def _range_doppler_pair(name: str, value: Any) -> tuple[int, int]:
    """A CFAR window size as ``(range, Doppler)`` cells: one number stands for both axes."""
    try:
        t = tuple(int(v) for v in value) if isinstance(value, (tuple, list)) else (int(value),)
    except (TypeError, ValueError):
        raise SettingsError(f"{name} = {value!r}; expected cells along range and Doppler, "
                            "e.g. (1, 2), or one number for both") from None
    if len(t) == 1:
        t = (t[0], t[0])
    if len(t) != 2 or min(t) < 0:
        raise SettingsError(f"{name} = {value!r}; expected two non-negative cell counts "
                            "(range, Doppler), or one for both")
    return (t[0], t[1])


class RadarProcessor:
    """ADC frames of one radar → range–Doppler cubes, heatmaps, detections, point clouds.

    Parameters
    ----------
    calib
        The radar's calibration (``seq.calib.cascade`` or ``seq.calib.single_chip``).
    settings
        A :class:`ProcessingSettings`; keyword arguments override single settings.

    Examples
    --------
    >>> proc = RadarProcessor(seq.calib.cascade, angle_method="capon")   # doctest: +SKIP
    >>> hm = proc.heatmap(seq.cascade.adc[0])         # (el, az, range, 2) float32
    >>> pts = proc.pointcloud(seq.cascade.adc[0])     # (N, 5) float32
    """

    def __init__(self, calib: RadarCalib, settings: ProcessingSettings | None = None,
                 **overrides) -> None:
        s = (settings or ProcessingSettings()).replace(**overrides)
        self.calib = calib
        self.settings = s
        w, hm = calib.waveform, calib.heatmap
        ntx, nrx, nc, ns = w.frame_shape
        self.range_fft_size = int(s.range_fft_size or ns)
        self.doppler_fft_size = int(s.doppler_fft_size or nc)
        # Default: the heatmap grid's range span, whatever the zero padding (padding refines
        # the bins, it must not shorten the range covered).
        self.num_range_bins = int(s.num_range_bins
                                  or -(-hm.num_range_bins * self.range_fft_size // ns))
        if self.range_fft_size < ns or self.doppler_fft_size < nc:
            raise SettingsError(f"FFT sizes must be at least {ns} samples and {nc} chirp loops")
        if not 0 < self.num_range_bins <= self.range_fft_size:
            raise SettingsError(f"num_range_bins must lie in 1..{self.range_fft_size}")
        nd = self.doppler_fft_size
        self.range_bin_width = SPEED_OF_LIGHT * w.sample_rate / (2.0 * w.slope
                                                                 * self.range_fft_size)
        self.velocities = signed_doppler_bins(nd) * (w.wavelength / (2.0 * nd * w.tdm_period))
        """float64 ``(doppler,)``: range rate of each Doppler bin [m/s]."""

        # Per-sample and per-chirp factors, fused into one (tx, rx, chirp, sample) multiplier.
        cal = np.ones((ntx, nrx, ns), dtype=np.complex128)
        if s.phase_frequency_calibration and calib.phase_frequency is not None:
            cal = phase_frequency_factors(calib.phase_frequency, w)
        wd = coherent_window(s.doppler_window, nc)
        if nd % 2 == 0:
            wd = wd * np.where(np.arange(nc) % 2 == 0, 1.0, -1.0)
        self._mult = (cal[:, :, None, :] * coherent_window(s.range_window, ns)
                      * wd[None, None, :, None]).astype(np.complex64)
        # The same factors for the compiled range pass: per channel × per chirp.
        self._gain = (cal * coherent_window(s.range_window, ns)).astype(np.complex64)
        self._chirp_weight = wd.astype(np.float32)
        self._engine = resolve_engine(s.engine)
        self._read_channels: tuple | None = None      # see _heatmap_read_channels
        self._coupling = None
        if s.coupling_subtraction and calib.coupling is not None:
            c = coupling_signal(calib.coupling, ns)
            if s.coupling_domain == "calibrated":
                c = c / cal
            self._coupling = c[:, :, None, :].astype(np.complex64)
        self._tdm = None
        if s.tdm_compensation:
            self._tdm = tdm_phase(ntx, signed_doppler_bins(nd), nd)[:, None, :, None]
            self._tdm_table = np.ascontiguousarray(self._tdm[:, 0, :, 0])         # (tx, doppler)

        self.grid = angle_grid(calib.antenna, w.center_frequency, hm.num_elevation_bins,
                               hm.num_azimuth_bins, s.azimuth_sign, s.elevation_sign)
        """:class:`~coloradar.dsp.array.AngleGrid` of the heatmap."""
        os_ = s.angle_oversample
        self.detection_grid = angle_grid(calib.antenna, w.center_frequency,
                                         os_ * hm.num_elevation_bins, os_ * hm.num_azimuth_bins,
                                         s.azimuth_sign, s.elevation_sign)
        dg = self.detection_grid
        self._visible = (dg.az_sines[None, :] ** 2 + dg.el_sines[:, None] ** 2) <= 1.0
        self._init_detection()

    def _init_detection(self) -> None:
        """What detection needs beyond the cube: CFAR counts, alias hypotheses, envelopes."""
        s, w = self.settings, self.calib.waveform
        ntx, nrx, nc, ns = w.frame_shape
        nd = self.doppler_fft_size
        # The map sums ntx·nrx channels of independent noise: that many exponential looks
        # (with "whiten"; "looks" replaces it per frame by the effective number).
        self._looks = ntx * nrx
        # Windowed FFT bins are correlated: the training mean counts as fewer independent
        # cells (cfar.effective_train_cells).
        h = [g + t for g, t in zip(s.cfar_guard, s.cfar_train, strict=True)]
        corr = (power_correlation(window(s.doppler_window, nc), nd, 2 * h[0]),
                power_correlation(window(s.range_window, ns), self.range_fft_size, 2 * h[1]))
        n_all, n_half = cfar_window(s.cfar_guard, s.cfar_train, split_axis=1)
        n_half = max(n_half, 1)
        e_all, e_half = effective_train_cells(s.cfar_guard, s.cfar_train, corr, split_axis=1,
                                              wrap=(nd, None))
        self._cell_factor = {"ca": e_all / n_all, "go": e_half / n_half,
                             "so": e_half / n_half, "os": 1.0}[s.cfar_kind]
        # Doppler disambiguation (coloradar.dsp.tdm).
        limit = s.doppler_unwrap if (s.tdm_compensation and ntx > 1) else 0.0
        vmax = 0.5 * nd * (self.velocities[1] - self.velocities[0])
        self._aliases = alias_hypotheses(ntx, vmax, limit)
        pairs = overlap_pairs(self.calib.antenna.virtual)
        self._pairs = pairs if pairs.resolves(self._aliases) else None
        # Range bins notched by DC removal: the window's half-width in bins, zero padding
        # included (periodic Hann: 3 taps, Blackman: 5).
        taps = {"none": 0, "hann": 1, "blackman": 2}[s.range_window]
        self._notch_bins = (int(np.ceil((taps + 1) * self.range_fft_size / ns))
                            if s.dc_removal else 0)
        # Sidelobe envelopes (Doppler wraps: lags up to nd//2).
        self._env_d = sidelobe_envelope(window(s.doppler_window, nc), nd, nd // 2 + 1)
        self._env_r = sidelobe_envelope(window(s.range_window, ns), self.range_fft_size,
                                        self.num_range_bins)
        # Channels whose coupling the file does not hold (the single chip's all-zero TX 2
        # block): their leakage stays in the zero-Doppler bin at every range, so that bin's
        # detection statistic leaves them out (scaled to the same noise mean).
        self._uncoupled = None
        cpl = self.calib.coupling
        if s.coupling_subtraction and cpl is not None and cpl.missing_tx:
            miss = np.zeros((ntx, nrx), dtype=bool)
            miss[list(cpl.missing_tx)] = True
            self._uncoupled = miss.ravel()
        # Where a point is: range and direction are measured from the virtual array's phase
        # centre; the Doppler shift within a chirp moves the beat frequency (f_c·v/S of range).
        self._centre = (phase_centre(self.calib.antenna, s.azimuth_sign, s.elevation_sign)
                        if s.phase_centre else np.zeros(3))
        self._range_doppler = float(w.center_frequency / w.slope)
        # Secondary angle peaks: above the array's sidelobes and above the beam noise
        # (exponential beam power; about one independent beam per unique element).
        dg = self.detection_grid
        self._angle_floor = float(np.log(dg.num_elements / s.angle_pfa))
        # F(2, 2ν) quantiles at angle_pfa/M for ν = 0..M complex degrees of freedom left
        # (index 0 unused): the residual test of _residual_floor.
        nu = np.arange(dg.num_elements + 1)
        self._f_threshold = np.r_[np.inf, f_dist.isf(s.angle_pfa / dg.num_elements, 2,
                                                     2 * nu[1:])]
        self._angle_dynamic = 10.0 ** (-s.angle_dynamic_range_db / 10)
        self._alias_margin = 10.0 ** (-s.alias_margin_db / 10)
        self._visible_az = np.abs(dg.az_sines) <= 1.0
        rows_el, row_idx = np.unique(dg.el_pos, return_inverse=True)
        self._row_of = np.eye(rows_el.size, dtype=np.complex64)[row_idx]         # (M, rows)
        self._row_steer = np.exp(1j * np.pi * dg.rho * dg.elevation_sign * rows_el[:, None]
                                 * dg.el_sines[None, :]).astype(np.complex64)
        _, counts = np.unique(dg.el_pos, return_counts=True)
        self._row_noise = float(dg.num_elements / counts.max())
        # Doppler alias search without overlapping pairs: one- and two-source fits of the
        # filled row under each hypothesis (_choose_alias); a second source must explain
        # more than noise reaches in the best of the row's ~M_row beams at angle_pfa.
        self._row_sel = dg.el_pos == rows_el[np.argmax(counts)]
        self._row_bins = dg.az_read[self._visible_az]                  # the row beam's grid
        self._alias_penalty = float(np.log(self._row_sel.sum() / s.angle_pfa))
        tx, rx = pair_antennas(self.calib.antenna, s.azimuth_sign, s.elevation_sign)
        c_true = phase_centre(self.calib.antenna, s.azimuth_sign, s.elevation_sign)
        # Near field: relative to the range at which the calibration focused the channels.
        ref = self.calib.near_field_reference
        self._focus = (ref is not None if s.near_field == "auto" else bool(s.near_field))
        self._near = NearField(tx - c_true, rx - c_true,
                               2.0 * np.pi * w.center_frequency / SPEED_OF_LIGHT,
                               reference=ref if s.phase_frequency_calibration else None)
        # The last processed range bin: a tone within half a bin of it gives at most this
        # power ratio to the bin before (window main lobe); beyond it, more.
        self._edge_ratio = _edge_ratio(window(s.range_window, ns), self.range_fft_size)
        self._beam_kernels = self._init_beam_kernels()
        # (focusing phase as a quadratic in the sines, for the secondary peaks' bound)
        self._near_terms = self._near.planar_terms() if self._focus else None
        # (its per-TX and per-RX factors: cyy = t_y² + r_y², one phase per TX and one per RX)
        self._near_factors = (
            np.unique(self._near.tx[:, 1] ** 2, return_inverse=True)
            + np.unique(self._near.rx[:, 1] ** 2, return_inverse=True)
            if self._near_terms is not None else None)
        self._focus_tables = self._planar_focus_tables() if self._near_terms is not None else None

    def _planar_focus_tables(self) -> tuple[np.ndarray, ...]:
        """The focusing phases' per-position tables for :func:`~._kernels.focus_multiply`:
        the unique TX and RX positions ``(y, z)`` with their ``|·|²`` and each element's
        index into them, and ``exp(j·ref_m)`` (the calibration reflector's phases, 1 without
        a reference)."""
        def positions(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            yz, idx = np.unique(p[:, 1:], axis=0, return_inverse=True)
            return (np.ascontiguousarray(yz, dtype=np.float64), (yz**2).sum(axis=1),
                    idx.reshape(-1).astype(np.int64))
        assert self._near_terms is not None
        ref = self._near_terms[4]
        return (*positions(self._near.tx), *positions(self._near.rx),
                np.exp(1j * ref))

    def _init_beam_kernels(self) -> dict[str, Any] | None:
        """Tables of the compiled per-detection beam kernels (:mod:`coloradar.dsp._kernels`):
        used with the numba engine; near-field focusing multiplies their inputs and outputs
        (a phase per element and detection), as on the numpy path."""
        dg = self.detection_grid
        if self._engine != "numba":
            return None
        from . import _kernels
        nrx = self.calib.frame_shape[1]
        first = self.calib.antenna.virtual.first_pair
        _, row = np.unique(dg.el_pos, return_inverse=True)
        return {"k": _kernels,
                "ca": float(np.pi * dg.rho * dg.azimuth_sign),
                "cb": float(np.pi * dg.rho * dg.elevation_sign),
                "az": np.ascontiguousarray(dg.az_pos, dtype=np.int64),
                "el": np.ascontiguousarray(dg.el_pos, dtype=np.int64),
                "row": np.ascontiguousarray(row, dtype=np.int64),
                "row_steer": np.ascontiguousarray(self._row_steer),
                "el_sines": np.ascontiguousarray(dg.el_sines, dtype=np.float64),
                "chan": np.ascontiguousarray(first[:, 0] * nrx + first[:, 1], dtype=np.int64),
                "tx": np.ascontiguousarray(first[:, 0], dtype=np.int64)}

    # ------------------------------------------------------------------ cubes
    def _check(self, adc: np.ndarray) -> np.ndarray:
        adc = np.asarray(adc)
        if adc.shape != self.calib.frame_shape or not np.iscomplexobj(adc):
            raise FormatError(f"{self.calib.name} ADC frame: expected complex "
                              f"(tx, rx, chirp, sample) = {self.calib.frame_shape}, got "
                              f"{adc.dtype} {adc.shape}")
        return adc

    def _range_cube(self, adc: np.ndarray, extra: bool = False) -> np.ndarray:
        """Calibrated range FFT ``(tx, rx, chirp, range)``; chirps carry the Doppler window and
        the ``(−1)^c`` of the Doppler shift. ``extra``: one range bin more than
        ``num_range_bins`` where the FFT has it (detection looks one bin beyond the last)."""
        x = self._check(adc)
        keep = min(self.num_range_bins + int(extra), self.range_fft_size)
        if self._engine == "numba":
            return self._range_cube_compiled(x, keep)
        y = x - self._coupling if self._coupling is not None else x.astype(np.complex64)
        if y.dtype != np.complex64:
            y = y.astype(np.complex64)
        if self.settings.dc_removal:
            y -= y.mean(axis=-1, keepdims=True)
        y *= self._mult
        out = sfft.fft(y, n=self.range_fft_size, axis=-1, workers=self.settings.workers,
                       overwrite_x=True)
        return out[..., :keep]

    def _range_cube_compiled(self, x: np.ndarray, keep: int,
                             channels: np.ndarray | None = None) -> np.ndarray:
        """:meth:`_range_cube` with coupling, DC removal, calibration and windows in one
        compiled pass (same result to float32 rounding). With ``channels`` (flat
        ``tx·num_rx + rx`` indices) only those, as ``(K, chirp, range)``."""
        from ._kernels import prepare_chirps
        nfft, (ntx, nrx, nc, ns) = self.range_fft_size, x.shape
        chans = np.arange(ntx * nrx) if channels is None else np.asarray(channels)
        x = np.ascontiguousarray(x, dtype=np.complex64)
        y = np.empty((chans.size, nc, nfft), dtype=np.complex64)
        if nfft > ns:
            y[..., ns:] = 0.0
        coupling = (np.ascontiguousarray(self._coupling[:, :, 0, :]).view(np.float32)
                    if self._coupling is not None else np.empty((0, 0, 0), dtype=np.float32))
        prepare_chirps(x.view(np.float32), chans.astype(np.int64), coupling,
                       self._gain.view(np.float32), self._chirp_weight,
                       bool(self.settings.dc_removal), y.view(np.float32))
        out = sfft.fft(y, axis=-1, workers=self.settings.workers, overwrite_x=True)
        out = out[..., :keep]
        return out.reshape(ntx, nrx, nc, -1) if channels is None else out

    def _doppler(self, rcube: np.ndarray, compensate: bool = True) -> np.ndarray:
        """Doppler FFT of a range cube; ``compensate=False`` leaves out the TDM phases
        (detection applies them to the few cells it reads, :meth:`_tdm_at`)."""
        v = sfft.fft(rcube, n=self.doppler_fft_size, axis=2, workers=self.settings.workers)
        if self.doppler_fft_size % 2:
            v = sfft.fftshift(v, axes=2)
        if compensate and self._tdm is not None:
            v *= self._tdm
        return v

    def _tdm_at(self, d: np.ndarray) -> np.ndarray | None:
        """Bin-centre TDM phases of Doppler bins ``d``, complex64 ``(tx, 1, K)`` (the factors
        :meth:`_doppler` multiplies the cube by), or None without TDM compensation."""
        return None if self._tdm is None else self._tdm_table[:, d][:, None, :]

    def range_doppler(self, adc: np.ndarray) -> np.ndarray:
        """Calibrated, TDM-compensated range–Doppler cube.

        Parameters
        ----------
        adc
            complex ``(tx, rx, chirp, sample)`` ADC frame.

        Returns
        -------
        numpy.ndarray
            complex64 ``(tx, rx, doppler, range)``; Doppler index ``i`` ↔ range rate
            ``velocities[i]``, range index ``r`` ↔ ``r · range_bin_width``. Unit coherent gain:
            a target of amplitude ``a`` (counts) at bin centres gives ``a`` in its cell.
        """
        return self._doppler(self._range_cube(adc))

    def range_doppler_power(self, adc: np.ndarray) -> np.ndarray:
        """Non-coherent range–Doppler power, float32 ``(doppler, range)``: ``Σ_{tx,rx} |·|²``."""
        return _power_sum(self.range_doppler(adc))

    # ---------------------------------------------------------------- heatmap
    def heatmap(self, adc: np.ndarray) -> np.ndarray:
        """Heatmap in the dataset's format.

        Returns
        -------
        numpy.ndarray
            float32 ``(el, az, range, 2)`` on :meth:`heatmap_config`'s grid: channel 0 the peak
            over Doppler of the angle spectrum's power (a target of amplitude ``a`` per channel
            gives ``|a|²``), channel 1 the range rate of that peak [m/s]: the centre of the
            peak's Doppler bin, *folded* into ``[−v_max, v_max)``, with the angle spectrum
            TDM-compensated for that folded bin. With ``heatmap_unwrap`` the cells that pass
            the CFAR are compensated for their best Doppler alias and channel 1 carries the
            unwrapped rate (:meth:`_heatmap_unwrapped`).
        """
        s = self.settings
        if self._reads_channels():
            return self._heatmap_read_channels(adc)
        rd = self.range_doppler(adc)
        return self._heatmap_unwrapped(rd) if s.heatmap_unwrap else self._heatmap(rd)

    def _reads_channels(self) -> bool:
        """Whether :meth:`heatmap` takes :meth:`_heatmap_read_channels` (the compiled engine
        reading the first pair's channels, the TDM compensation applied in its gather)."""
        s = self.settings
        return self._engine == "numba" and s.overlap == "first" and not s.heatmap_unwrap

    def _heatmap_read_channels(self, adc: np.ndarray) -> np.ndarray:
        """:meth:`_heatmap` computing the range–Doppler cube of only the channels it reads
        (the cascade's 134 first pairs of 192 channels), less work. The values are those of
        :meth:`_heatmap` with ``tdm_applied=False`` on the full cube to the bit (FFTs do not
        depend on the batch; the kernel multiplies each channel by the same TDM factors), so
        that :meth:`products` gives the same heatmap."""
        if self._read_channels is None:
            nrx = self.calib.frame_shape[1]
            first = self.calib.antenna.virtual.first_pair
            used, element_channel = np.unique(first[:, 0] * nrx + first[:, 1],
                                              return_inverse=True)
            tdm = None if self._tdm is None else self._tdm_table[used // nrx]   # (K, nd)
            self._read_channels = used, element_channel, tdm
        used, element_channel, tdm = self._read_channels
        rc = self._range_cube_compiled(self._check(adc), self.num_range_bins, used)  # (K, chirp, range)
        v = sfft.fft(rc, n=self.doppler_fft_size, axis=1, workers=self.settings.workers)
        if self.doppler_fft_size % 2:
            v = sfft.fftshift(v, axes=1)
        # the TDM factors go to the kernel, which applies them while gathering (a pass over
        # the cube less than v *= tdm)
        return heatmap_from_elements(v, self.grid, self.velocities,
                                     workers=self.settings.workers, engine=self._engine,
                                     channels=element_channel, doppler_phase=tdm)

    def _heatmap(self, rd: np.ndarray, tdm_applied: bool = True) -> np.ndarray:
        """Heatmap of a range–Doppler cube; ``tdm_applied=False``: ``rd`` lacks the TDM
        compensation, which the engine then applies (``overlap="first"`` only)."""
        if self.settings.overlap == "first":
            # the engine reads each element's channel straight from the cube
            ntx, nrx = rd.shape[:2]
            first = self.calib.antenna.virtual.first_pair
            phase = None
            if not tdm_applied and self._tdm is not None:
                phase = self._tdm_table[np.arange(ntx * nrx) // nrx]            # (C, nd)
            return heatmap_from_elements(rd.reshape(ntx * nrx, *rd.shape[2:]), self.grid,
                                         self.velocities, workers=self.settings.workers,
                                         engine=self._engine,
                                         channels=first[:, 0] * nrx + first[:, 1],
                                         doppler_phase=phase)
        if not tdm_applied and self._tdm is not None:
            rd = rd * self._tdm
        elements = combine_channels(rd, self.calib.antenna.virtual, self.settings.overlap)
        return heatmap_from_elements(elements, self.grid, self.velocities,
                                     workers=self.settings.workers, engine=self._engine)

    def _heatmap_unwrapped(self, rd: np.ndarray) -> np.ndarray:
        """Heatmap with disambiguated Doppler (``heatmap_unwrap``), through the same kernel.

        Cells of the range–Doppler map that pass the CFAR get their best alias hypothesis
        (as detections do, at the bin centre); their channels are compensated for it before
        the kernel forms the peak-over-Doppler heatmap, and channel 1 of every output cell
        whose peak came from such a cell carries ``folded rate + 2m·v_max``. Cells below
        the CFAR keep the folded compensation and rate (noise has no Doppler to unwrap).
        """
        hyps = self._aliases
        if hyps.size < 2:
            return self._heatmap(rd)
        stat, _, looks, sig2 = self._detection_map(rd)
        mask, noise = self._cfar_mask(stat, looks)
        d, r = np.nonzero(mask)
        if d.size == 0:
            return self._heatmap(rd)
        nd = rd.shape[2]
        elem_noise = (noise[d, r] * self._beam_noise_factor(sig2)
                      * self.detection_grid.num_elements)
        alias, _ = self._choose_alias(rd[:, :, d, r], (d - nd // 2).astype(np.float64),
                                      elem_noise)
        assert alias is not None
        moved = alias != 0
        d, r, alias = d[moved], r[moved], alias[moved]
        if d.size == 0:
            return self._heatmap(rd)
        rd = rd.copy()
        rd[:, :, d, r] *= alias_phase(rd.shape[0], alias)[:, None, :]
        out = self._heatmap(rd)
        m_map = np.zeros(stat.shape, dtype=np.int64)
        m_map[d, r] = alias
        dv = self.velocities[1] - self.velocities[0]
        di = np.clip(np.rint(out[..., 1] / dv).astype(np.int64) + nd // 2, 0, nd - 1)
        ri = np.arange(out.shape[2])[None, None, :]
        out[..., 1] += (m_map[di, ri] * (nd * dv)).astype(np.float32)
        return out

    def heatmap_config(self) -> HeatmapConfig:
        """The grid of :meth:`heatmap` with the true angles of its bins (for heatmap_cfg.txt).

        Elevation bins are ``asin(u_z)``; azimuth bins ``asin(u_y)``, exact in the ``el = 0``
        plane (off it the azimuth axis measures ``cos(el)·sin(az)``; see
        :meth:`~coloradar.dsp.array.AngleGrid.directions`).
        """
        g = self.grid
        return HeatmapConfig(self.num_range_bins, g.num_el, g.num_az, self.range_bin_width,
                             g.azimuth_angles, g.elevation_angles)

    # ------------------------------------------------------------- detection
    def detect(self, adc: np.ndarray) -> Detections:
        """CFAR detections on the range–Doppler power map, each with its direction.

        Returns
        -------
        Detections
        """
        rcube = self._range_cube(adc, extra=True)
        nr = self.num_range_bins
        return self._detect(rcube[..., :nr], self._doppler(rcube[..., :nr], compensate=False),
                            self._doppler(rcube[..., nr:], compensate=False))

    def _detection_map(self, rd: np.ndarray
                       ) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray], int,
                                  np.ndarray | None]:
        """Detection statistic ``(doppler, range)`` float64, the plain power sum (float32)
        at given flat ``doppler·nr + range`` cells, the looks the CFAR threshold is computed
        for (``noise_weighting``), and the channels' noise powers (float64 ``(tx·rx,)``;
        None without whitening)."""
        s = self.settings
        ntx, nrx, nd, nr = rd.shape
        if self._beam_kernels is not None:
            mag2 = np.empty((ntx * nrx, nd * nr), dtype=np.float32)
            self._beam_kernels["k"].power(_c64(rd).reshape(-1).view(np.float32),
                                          mag2.reshape(-1))
        else:
            mag2 = np.abs(rd).reshape(ntx * nrx, nd * nr)
            np.square(mag2, out=mag2)
        if s.noise_weighting == "off":
            plain = mag2.sum(axis=0)
            return (plain.reshape(nd, nr).astype(np.float64), plain.__getitem__, self._looks,
                    None)
        # Inverse-noise weights: each term a unit exponential times the mean noise power, so
        # the sum is a Ntx·Nrx-look chi-square whatever the channel gains.
        sig2 = channel_noise(mag2.reshape(ntx * nrx, nd, nr),
                             int(np.ceil(s.min_range / self.range_bin_width)),
                             engine=self._engine)
        wts = (sig2.mean() / sig2).astype(np.float32)
        stat = (wts @ mag2).reshape(nd, nr).astype(np.float64)
        if self._uncoupled is not None:
            z = nd // 2
            keep = ~self._uncoupled
            row = wts[keep] @ mag2.reshape(ntx * nrx, nd, nr)[keep, z, :]
            stat[z] = row * (wts.sum() / wts[keep].sum())
        # The plain sum is read at the few points' cells only: summed there, channel after
        # channel as numpy sums the whole map along axis 0 (cumsum's last row: the same
        # float32 values), instead of a pass over the map.
        return stat, lambda i: np.cumsum(mag2[:, i], axis=0)[-1], self._looks, sig2

    def _exclude_row(self, weighted: np.ndarray, nd: int) -> np.ndarray:
        """Detection statistic ``(doppler,)`` of one range bin from weighted channel powers
        ``(channels, doppler)``, the zero-Doppler bin without the channels of unknown
        coupling (as :meth:`_detection_map`)."""
        out = weighted.sum(axis=0).astype(np.float64)
        if self._uncoupled is not None:
            keep = ~self._uncoupled
            out[nd // 2] = weighted[keep, nd // 2].sum() * (weighted.shape[0] / keep.sum())
        return out

    def _cfar_mask(self, stat: np.ndarray, looks: int) -> tuple[np.ndarray, np.ndarray]:
        """CFAR on the detection statistic: bool mask and noise estimate, ``(doppler, range)``
        (cells the CFAR does not test: False and +inf)."""
        s = self.settings
        # Range edges: training cells beyond the map are left out ("truncate"), not mirrored
        # (mirrored copies made the edge cells fire ~5x too often). OS needs a full window.
        cmodes: tuple[CFAREdge, CFAREdge] = ("wrap", "mirror" if s.cfar_kind == "os" else "truncate")
        # DC removal notches the first range bins (the window spreads the notch): they would
        # lower the noise estimate of their neighbours, so the CFAR map starts after them.
        r0 = max(0, min(self._notch_bins, stat.shape[1] - s.cfar_guard[1] - s.cfar_train[1] - 1))
        res = run_cfar(stat[:, r0:], CFARConfig(s.cfar_kind, s.cfar_guard, s.cfar_train, s.pfa,
                                                s.cfar_rank, looks, cmodes, 1, self._cell_factor,
                                                s.cfar_excision))
        mask = np.zeros(stat.shape, dtype=bool)
        mask[:, r0:] = res.detections
        noise = np.full(stat.shape, np.inf)
        noise[:, r0:] = res.noise
        return mask, noise

    def _detect(self, rcube: np.ndarray, rd: np.ndarray, rd_next: np.ndarray | None = None
                ) -> Detections:
        """Detections of a range–Doppler cube ``rd`` *without* its TDM phases
        (``_doppler(…, compensate=False)``: the power map does not need them, and the cells
        read get them from :meth:`_tdm_at`); ``rd_next`` (tx, rx, doppler, 1 or 0), the same
        for the range bin after the last one, when computed (a return beyond the processed
        range then makes no local maximum at the last bin)."""
        s = self.settings
        stat, plain_at, looks, sig2 = self._detection_map(rd)
        nxt = None
        if rd_next is not None and rd_next.shape[-1]:
            m2 = np.square(np.abs(rd_next[..., 0])).reshape(-1, rd_next.shape[2])
            wts = (np.ones(m2.shape[0]) if sig2 is None else sig2.mean() / sig2)
            nxt = self._exclude_row(wts[:, None] * m2, rd_next.shape[2])
        mask, noise = self._cfar_mask(stat, looks)
        nd, nr = stat.shape
        if s.peak_grouping:
            # Cells that peak along Doppler or along range: a target one bin from a stronger
            # one (in the other axis) is no 2D maximum of the summed power, but it is one of
            # its own beam; the beam test below decides (docs/dsp.md, "Grouping").
            if self._beam_kernels is not None:
                grouped = np.empty(stat.shape, dtype=bool)
                self._beam_kernels["k"].group_peaks(
                    np.ascontiguousarray(stat), np.ascontiguousarray(mask),
                    np.ascontiguousarray(noise), _f64(nxt if nxt is not None else np.zeros(0)),
                    float(STRONG_NEIGHBOUR), grouped)
                mask = grouped
            else:
                mask = _group_peaks(stat, mask, noise, nxt)
        d, r = np.nonzero(mask)
        near = r < int(np.ceil(s.min_range / self.range_bin_width))
        # Cells inside min_range still explain sidelobes (guard below); they make no points.
        exp_d, exp_r = d, r
        exp_pow, exp_excess = stat[d, r], stat[d, r] - noise[d, r]
        d, r = d[~near], r[~near]
        d_ref = refine_peak(np.stack([stat[(d - 1) % nd, r], stat[d, r],
                                      stat[(d + 1) % nd, r]], axis=1), d, nd, wrap=True)
        k_signed = d_ref - nd // 2
        ntx = rd.shape[0]
        vecs = rd[:, :, d, r]                                           # (tx, rx, K)
        if self._tdm is not None:
            # bin-centre compensation, then the fractional remainder
            vecs = vecs * self._tdm_at(d)
            vecs = vecs * tdm_phase(ntx, d_ref - d, nd)[:, None, :]
        # Beam noise per cell: the CFAR noise of the statistic, per channel, on the beam of the
        # unique elements (|aᴴn|²/M² has mean Σ_m σ_m²/M²).
        beam_noise = noise[d, r] * self._beam_noise_factor(sig2)
        alias, spec = self._choose_alias(vecs, k_signed,
                                         beam_noise * self.detection_grid.num_elements)
        if alias is not None:
            vecs = vecs * alias_phase(ntx, alias)[:, None, :]
        vectors = combine_channels(vecs, self.calib.antenna.virtual, s.overlap).T  # (K, M)
        if s.angle_method == "capon" and d.size:
            snaps = rcube[:, :, :, r]                                    # (tx, rx, chirp, K)
            if self._tdm is not None:
                ph = tdm_phase(ntx, k_signed, nd)
                if alias is not None:
                    ph = ph * alias_phase(ntx, alias)
                snaps = snaps * ph[:, None, None, :]
            snaps = combine_channels(snaps, self.calib.antenna.virtual, s.overlap)
            spec = capon_spectrum(self.detection_grid, snaps.transpose(2, 1, 0), vectors,
                                  s.capon_loading, workers=s.workers)
        floor = self._angle_floor * beam_noise
        rho_cell = np.maximum(r, 1) * self.range_bin_width
        rel = self._angle_dynamic if s.multi_peak else np.inf
        if s.angle_method == "fft":
            # Sources and their azimuths from the filled row (the noise floor of a row beam
            # is M/M_row times that of the full beam), each elevation from the rows' sums.
            prof = row_profile(self.detection_grid, vectors, workers=s.workers,
                               row=self._row_sel)
            prof = np.where(self._visible_az[None], prof, 0.0)
            ci, ia = self._azimuth_peaks(prof, rel, floor * self._row_noise if s.multi_peak
                                         else np.full(d.size, np.inf))
            na = self.detection_grid.num_az
            fa = refine_peak(np.stack([prof[ci, (ia - 1) % na], prof[ci, ia],
                                       prof[ci, (ia + 1) % na]], axis=1), ia, na, wrap=True)
            uy = 2.0 * (fa - na // 2) / (na * self.detection_grid.rho)
            if self._beam_kernels is not None and (not self._focus
                                                   or self._near_terms is not None):
                # Secondary peaks get their elevation in _resolve_peaks once their cell's
                # strongest source is known (most are its sidelobes and need none): NaN here.
                lead = _firsts(ci) if ci.size else np.zeros(0, dtype=bool)
                uz, peak = np.full(ci.size, np.nan), np.zeros(ci.size)
                uz[lead], peak[lead] = self._elevation_search(vectors[ci[lead]], uy[lead],
                                                              rho_cell[ci[lead]])
            else:
                uz, peak = self._elevation_search(vectors[ci], uy, rho_cell[ci])
        else:
            if spec is None:
                g = self.detection_grid
                spec = np.zeros((0, g.num_el, g.num_az))
            masked = np.where(self._visible[None], spec, 0.0)
            ci, ia = azimuth_peaks(masked.max(axis=1), rel, floor if s.multi_peak
                                   else np.full(d.size, np.inf))
            ie = masked[ci, :, ia].argmax(axis=1)
            uy, uz, peak = self._peak_directions(spec, ci, ie, ia)
        rho = rho_cell[ci]
        x = vectors[ci]                                                 # (P, M)
        uy, uz, peak, steer, ci = self._resolve_peaks(x, ci, uy, uz, peak, rho, floor)
        pd, pr = d[ci], r[ci]
        palias = alias[ci] if alias is not None else None
        # Beam of the 3×3 range–Doppler neighbourhood at each point's direction.
        nb = self._beam_neighbourhood(rd, pd, pr, palias, steer, rd_next)  # (P, 3, 3)
        keep = np.ones(ci.size, dtype=bool)
        if s.peak_grouping and ci.size:
            # A point is a maximum of its own beam over its neighbours: a target one bin from
            # a stronger one in another direction stays, the skirt of one target goes.
            centre = nb[:, 1, 1]
            keep &= np.all(nb.reshape(-1, 9) <= centre[:, None] * (1 + 1e-6), axis=1)
        if nr > 1 and ci.size and nxt is None:
            # A return beyond the last processed bin leaks into it with a slope no target
            # inside (within half a bin of it) can make.
            last = pr == nr - 1
            keep &= ~(last & (nb[:, 1, 1] > self._edge_ratio * nb[:, 1, 0]))
        if s.sidelobe_guard and ci.size and exp_d.size > 1:
            # (beam power above the level a noise peak reaches: the direction is a maximum)
            keep &= self._guard(rd, pd, pr, palias, steer, nb[:, 1, 1] - floor[ci], floor[ci],
                                stat[pd, pr] - noise[pd, pr], exp_d, exp_r, exp_pow,
                                exp_excess, stat[pd, pr])
        ci, pd, pr, uy, uz, peak, nb = ci[keep], pd[keep], pr[keep], uy[keep], uz[keep], \
            peak[keep], nb[keep]
        steer = steer[:, keep]
        palias = palias[keep] if palias is not None else None
        r_ref = refine_peak(nb[:, 1, :], pr, nr, wrap=False)
        if s.beam_doppler:
            dref = refine_peak(nb[:, :, 1], pd, nd, wrap=True)
        else:
            dref = d_ref[ci]
        k_true = dref - nd // 2 + (palias * nd if palias is not None else 0)
        rate = k_true * (self.velocities[1] - self.velocities[0])
        # Range–Doppler coupling: the Doppler shift within a chirp raises the beat frequency
        # by 2·f_c·v/c, which the range FFT reads as f_c·v/S of range.
        rng_c = r_ref * self.range_bin_width - rate * self._range_doppler
        unit = sines_to_unit(uy, uz)
        # Range and direction are measured from the virtual array's phase centre.
        xyz = self._centre[None, :] + rng_c[:, None] * unit
        rng = np.linalg.norm(xyz, axis=1)
        return Detections(
            range_bin=pr.astype(np.int64), doppler_bin=pd.astype(np.int64), range=rng,
            range_rate=rate, azimuth=np.arctan2(xyz[:, 1], xyz[:, 0]),
            elevation=np.arcsin(np.clip(xyz[:, 2] / np.maximum(rng, 1e-12), -1.0, 1.0)),
            xyz=xyz, intensity=peak, power=plain_at(pd * nr + pr).astype(np.float64),
            snr=stat[pd, pr] / noise[pd, pr], alias=palias)

    def _steer(self, uy: np.ndarray, uz: np.ndarray, rho: np.ndarray) -> np.ndarray:
        """Beam weights ``(M, P)`` complex64 at direction sines ``(u_y, u_z)``, focused at range
        ``rho`` from the phase centre: ``B(u) = Σ_m x_m w_m / M`` is ``s`` for a source
        ``s`` at ``(rho, u)``."""
        kb = self._beam_kernels
        if kb is not None:
            w = np.empty((self.detection_grid.num_elements, np.size(uy)), dtype=np.complex64)
            kb["k"].steer_columns(kb["ca"], kb["cb"], kb["az"], kb["el"], _f64(uy), _f64(uz), w)
            if self._focus:
                w = self._focused(w, uy, uz, rho, rows=False, copy=False)
            return w
        w = steering(self.detection_grid, uy, uz)
        if self._focus:
            w = w * self._near.focus_sines(uy, uz, rho)
        return w

    _COMPILED_JOINT = True
    """Whether the numba engine refines cells with several sources with the compiled keep
    tests (:func:`~._kernels.joint_round`); False runs the numpy loop (the tests compare
    them)."""

    def _azimuth_peaks(self, prof: np.ndarray, rel: float, floor: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~coloradar.dsp.angle.azimuth_peaks`, compiled with the numba engine."""
        kb = self._beam_kernels
        if kb is None or prof.dtype != np.float32:
            return azimuth_peaks(prof, rel, floor)
        ci, ia = np.empty((2, prof.size), dtype=np.int64)
        n = kb["k"].azimuth_peaks(np.ascontiguousarray(prof), float(rel), _f64(floor), ci, ia)
        return ci[:n], ia[:n]

    def _focused(self, x: np.ndarray, uy: np.ndarray, uz: np.ndarray, rho: np.ndarray,
                 rows: bool = True, copy: bool = True) -> np.ndarray:
        """``x`` times the near-field focusing phases (:meth:`NearField.focus_sines`) at sines
        ``(uy, uz)`` and ranges ``rho`` (``(K,)`` each); ``x`` complex ``(K, M)`` with
        ``rows``, else ``(M, K)``; ``copy=False`` may multiply ``x`` (complex64) in place.
        Compiled where the array is planar (the cascade), numpy otherwise."""
        kb, tables = self._beam_kernels, self._focus_tables
        if kb is None or tables is None:
            f = self._near.focus_sines(uy, uz, rho, transpose=rows)
            if copy:
                return x * f
            x *= f
            return x
        out = np.array(x, dtype=np.complex64, order="C", copy=True) if copy else x
        kb["k"].focus_multiply(out, _f64(uy), _f64(uz), _f64(rho), *tables,
                               self._near.wavenumber, rows)
        return out

    def _resolve_peaks(self, x: np.ndarray, ci: np.ndarray, uy: np.ndarray, uz: np.ndarray,
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
            :meth:`_steer`.
        """
        s = self.settings
        g = self.detection_grid
        m = float(g.num_elements)
        step = (2.0 / (g.num_az * g.rho), 2.0 / (g.num_el * g.rho))
        refine = s.angle_refine and s.angle_method == "fft"

        def newton(xv: np.ndarray, uy0: np.ndarray, uz0: np.ndarray, rr: np.ndarray):
            kb = self._beam_kernels
            if kb is not None:
                if self._focus:
                    xv = self._focused(xv, uy0, uz0, rr)
                out = np.empty((3, np.size(uy0)))
                kb["k"].newton_refine(_c64(xv), kb["ca"], kb["cb"], kb["az"], kb["el"],
                                      _f64(uy0), _f64(uz0), step[0], step[1], 2, True, out[0],
                                      out[1], out[2])
                return out[0], out[1], out[2]
            if self._focus:
                xv = self._focused(xv, uy0, uz0, rr)
            return newton_refine(g, xv, uy0, uz0, step)

        primary = np.ones(ci.size, dtype=bool)
        primary[1:] = ci[1:] != ci[:-1]
        if refine and primary.any():
            uy[primary], uz[primary], peak[primary] = newton(x[primary], uy[primary],
                                                             uz[primary], rho[primary])
        wp = None
        if self._beam_kernels is not None:
            deferred = np.isnan(uz) & ~primary     # secondaries without their elevation yet
            if deferred.any():
                uy, uz, peak, ci, x, rho, primary, wp = self._screen_secondaries(
                    x, ci, uy, uz, peak, rho, floor, primary, deferred)
        if wp is None:
            w = self._steer(uy, uz, rho)                                # (M, P)
        else:
            # the primaries' weights were made for the screening (each column depends on
            # its own peak only: the same values); only the secondaries' are new
            w = np.empty((wp.shape[0], ci.size), dtype=wp.dtype)
            w[:, primary] = wp
            if not primary.all():
                sec = ~primary
                w[:, sec] = self._steer(uy[sec], uz[sec], rho[sec])
        if primary.all():
            return uy, uz, peak, w, ci
        # amplitude of each cell's strongest source and its response in the other directions
        first = np.flatnonzero(primary)[np.cumsum(primary) - 1]        # primary peak of each
        sec = ~primary
        kb = self._beam_kernels
        if kb is not None:
            resid, top = np.empty((2, ci.size))
            kb["k"].secondary_residual(_c64(x), _c64(w), first.astype(np.int64), resid, top)
            resid, top = resid[sec], top[sec]
        else:
            amp = np.einsum("pm,mp->p", x, w) / m
            cross = np.einsum("mp,mp->p", np.conj(w[:, first[sec]]), w[:, sec]) / m
            resid = np.abs(amp[sec] - amp[first[sec]] * cross) ** 2
            top = np.abs(amp[first[sec]]) ** 2
        ok = np.ones(ci.size, dtype=bool)
        ok[sec] = (resid >= floor[ci[sec]]) & (resid >= top * self._angle_dynamic)
        uy, uz, peak, w, ci, x, rho = (uy[ok], uz[ok], peak[ok], w[:, ok], ci[ok], x[ok],
                                       rho[ok])
        # Joint least-squares amplitudes of each cell's remaining sources (sidelobes of a
        # second source get little of it), then each source refined on its cell's vector
        # less the others' fit; all batched over cells (at most MAX_SOURCES per cell).
        cell_of, count = _groups(ci)
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
        if (kb is not None and self._COMPILED_JOINT
                and (not self._focus or self._focus_tables is not None)):
            # the loop below with its numpy glue compiled: the keep tests and the vectors
            # less the other sources' fit in kernels, the refinement steps by the same
            # kernels as the loop's (called from here: linked into one compiled loop they
            # cost seconds more of compiling on the first frame)
            starts = np.flatnonzero(_firsts(ci, end=True))
            alive = np.ones(ci.size, dtype=bool)
            count = np.empty(starts.size - 1, dtype=np.int64)
            amps = np.empty(ci.size, dtype=np.complex128)
            xc, w = _c64(x), np.ascontiguousarray(w, dtype=np.complex64)
            floor_p = _f64(floor[ci])
            for it in range(3):
                multi_left = kb["k"].joint_round(xc, w, starts, alive, floor_p,
                                                 float(self._angle_dynamic), self._f_threshold,
                                                 it > 0, amps, count)
                if not multi_left or it == 2:
                    break
                xp = np.empty(xc.shape, dtype=np.complex64)
                j = np.empty(ci.size, dtype=np.int64)
                k = kb["k"].joint_residuals(xc, w, starts, alive, count, xp, j)
                xp, j = xp[:k], j[:k]
                # elevation afresh on what is left (two sources fool the sparse rows)
                uz[j], _ = self._elevation_search(xp, uy[j], rho[j])
                if refine:
                    uy[j], uz[j], _ = newton(xp, uy[j], uz[j], rho[j])
                w[:, j] = self._steer(uy[j], uz[j], rho[j])
            kb["k"].joint_powers(xc, w, starts, alive, count, peak)
            uy, uz, peak, w, ci = uy[alive], uz[alive], peak[alive], w[:, alive], ci[alive]
            return self._join_lone(lone, uy, uz, peak, w, ci)
        if lone is not None:
            cell_of = _groups(ci)[0]
        for it in range(3):
            amps = self._joint_amplitudes(x, w, cell_of, rank)
            pw = np.abs(amps) ** 2
            starts = np.flatnonzero(_firsts(cell_of))
            top = np.maximum.reduceat(pw, starts)
            ok = (pw >= floor[ci]) & (pw >= top[cell_of] * self._angle_dynamic)
            if it > 0:
                # once the directions are refined jointly, against what the fit leaves
                ok &= pw >= self._residual_floor(x, w, amps, cell_of, starts)
            ok[rank == 0] = True
            uy, uz, peak, w, ci, x, rho, amps = (uy[ok], uz[ok], peak[ok], w[:, ok], ci[ok],
                                                 x[ok], rho[ok], amps[ok])
            cell_of, count = _groups(ci)
            rank = np.arange(ci.size) - np.concatenate([[0], np.cumsum(count)[:-1]])[cell_of]
            multi = count[cell_of] > 1
            if not multi.any() or it == 2:
                break
            amps = self._joint_amplitudes(x, w, cell_of, rank)
            model = np.conj(w) * amps[None, :]                          # (M, P) fitted sources
            starts = np.flatnonzero(_firsts(cell_of))
            total = np.add.reduceat(model.T, starts, axis=0)            # peaks grouped by cell
            xp = (x - total[cell_of] + model.T)[multi]                  # vector less the others
            j = np.flatnonzero(multi)
            # elevation afresh on what is left (two sources fool the sparse rows)
            uz[j], _ = self._elevation_search(xp, uy[j], rho[j])
            if refine:
                uy[j], uz[j], _ = newton(xp, uy[j], uz[j], rho[j])
            w[:, j] = self._steer(uy[j], uz[j], rho[j])
        amps = self._joint_amplitudes(x, w, cell_of, rank)
        multi = count[cell_of] > 1
        peak[multi] = np.abs(amps[multi]) ** 2
        return self._join_lone(lone, uy, uz, peak, w, ci)

    @staticmethod
    def _join_lone(lone: tuple[np.ndarray, ...] | None, uy: np.ndarray, uz: np.ndarray,
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
        and the primaries' weights ``(M, primaries)`` (as :meth:`_steer`)."""
        kb = self._beam_kernels
        assert kb is not None
        lead = np.cumsum(primary) - 1                   # each peak's primary, among primaries
        wp = self._steer(uy[primary], uz[primary], rho[primary])
        bound, top = np.empty((2, ci.size))
        n_rows = int(kb["row"].max()) + 1
        if not self._focus:
            kb["k"].secondary_bound(_c64(x), wp, lead.astype(np.int64), _f64(uy), kb["ca"],
                                    kb["az"], kb["row"], n_rows, bound, top)
        else:
            # focused beams: each element's phase changes with the elevation within a row;
            # the bound adds what that change can contribute over the elevations searched
            assert self._near_terms is not None
            g = self.detection_grid
            ne = g.num_el
            half = 1.0 / (ne * g.rho)                   # half an elevation bin (sine)
            u_grid = 2.0 * half * max(ne // 2 + 0.5, ne - 0.5 - ne // 2)
            sq, cyy, cyz, czz, ref = self._near_terms
            # (cyy = t_y² + r_y²: one phase factor per TX and one per RX, not per element)
            assert self._near_factors is not None
            ty2, it, ry2, ir = self._near_factors
            # (only the deferred peaks: the primaries' bound is not used)
            bound[:], top[:] = np.inf, 0.0
            j = np.flatnonzero(deferred)
            bj, tj = np.empty((2, j.size))
            kb["k"].secondary_bound_focused(
                _c64(x[j]), wp, lead[j].astype(np.int64), _f64(uy[j]), _f64(rho[j]),
                _f64(floor[ci[j]]), float(self._angle_dynamic), kb["ca"], kb["az"],
                kb["row"], n_rows, sq, cyy, cyz, czz, ref, ty2, it.astype(np.int64), ry2,
                ir.astype(np.int64), self._near.wavenumber, u_grid, half, bj, tj)
            bound[j], top[j] = bj, tj
        hopeless = deferred & ((bound < floor[ci]) | (bound < top * self._angle_dynamic))
        keep = ~hopeless
        uy, uz, peak, ci, x, rho, primary, deferred = (
            uy[keep], uz[keep], peak[keep], ci[keep], x[keep], rho[keep], primary[keep],
            deferred[keep])
        if deferred.any():
            uz[deferred], peak[deferred] = self._elevation_search(x[deferred], uy[deferred],
                                                                  rho[deferred])
        return uy, uz, peak, ci, x, rho, primary, wp

    def _residual_floor(self, x: np.ndarray, w: np.ndarray, amps: np.ndarray,
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
        return (self._f_threshold[nu] * rss / nu / m)[cell_of]

    def _elevation_search(self, x: np.ndarray, uy: np.ndarray, rho: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
        """Elevation sine of the strongest beam of each vector ``x`` ``(P, M)`` along its
        azimuth ``uy``, and that beam's power: the elements are steered in azimuth and summed
        per elevation row, then the few rows are beamformed over the detection grid's
        elevation bins; the peak is refined by a log-parabola (Newton steps follow)."""
        g = self.detection_grid
        if x.shape[0] == 0:
            return np.zeros(0), np.zeros(0)
        kb = self._beam_kernels
        if kb is not None:
            if self._focus:
                # focused at elevation 0, as the numpy path's azimuth steering below
                x = self._focused(x, uy, np.zeros(uy.size), rho)
            out = np.empty((2, uy.size))
            kb["k"].elevation_search(_c64(x), kb["ca"], kb["az"], kb["row"], kb["row_steer"],
                                     kb["el_sines"], _f64(uy), float(g.rho), out[0], out[1])
            return out[0], out[1]
        wa = self._steer(uy, np.zeros(uy.size), rho)                   # (M, P)
        # (einsum, not BLAS: threaded BLAS sums in an order that varies between runs, and
        # batch processing promises the bytes of serial processing)
        rows = np.einsum("pm,pm,mr->pr", x, wa.T, self._row_of)          # (P, rows)
        bz = np.abs(np.einsum("pr,re->pe", rows, self._row_steer)) ** 2  # (P, n_el)
        vis = uy[:, None] ** 2 + g.el_sines[None, :] ** 2 <= 1.0
        bz = np.where(vis, bz, 0.0)
        ie = np.argmax(bz, axis=1)
        ne = g.num_el
        k = np.arange(ie.size)
        fe = refine_peak(np.stack([bz[k, (ie - 1) % ne], bz[k, ie], bz[k, (ie + 1) % ne]],
                                  axis=1), ie, ne, wrap=True)
        uz = 2.0 * (fe - ne // 2) / (ne * g.rho)
        return uz, bz[k, ie] / float(g.num_elements) ** 2

    def _joint_amplitudes(self, x: np.ndarray, w: np.ndarray, cell_of: np.ndarray,
                          rank: np.ndarray) -> np.ndarray:
        """Least-squares amplitudes of every cell's sources, batched: the sources of a cell
        are the columns ``conj(w)`` of its peaks; ``x`` the cell's vector per peak. A cell
        with one source gets its beam value; only cells with several are solved."""
        kb = self._beam_kernels
        if kb is not None and cell_of.size and np.all(np.diff(cell_of) >= 0):
            # (the peaks of a cell are consecutive, as _resolve_peaks keeps them)
            starts = np.flatnonzero(_firsts(cell_of, end=True))
            amps = np.empty(cell_of.size, dtype=np.complex128)
            kb["k"].joint_amplitudes(_c64(x), _c64(w), starts.astype(np.int64), amps)
            return amps
        out = np.einsum("pm,mp->p", x, w) / float(w.shape[0])
        counts = np.bincount(cell_of)
        multi = counts[cell_of] > 1
        if not multi.any():
            return out
        x, w, rank = x[multi], w[:, multi], rank[multi]
        cell_of = _groups(cell_of[multi])[0]
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

    def _beam_noise_factor(self, sig2: np.ndarray | None) -> float:
        """Mean beam noise (heatmap units) per unit of the detection statistic's noise."""
        m = self.detection_grid.num_elements
        if sig2 is None:
            return 1.0 / (m * self._looks)
        first = self.calib.antenna.virtual.first_pair
        nrx = self.calib.antenna.num_rx
        used = sig2[first[:, 0] * nrx + first[:, 1]]
        return float(used.sum() / (m * m * sig2.sum()))

    def _beam_neighbourhood(self, rd: np.ndarray, d: np.ndarray, r: np.ndarray,
                            alias: np.ndarray | None, steer: np.ndarray,
                            rd_next: np.ndarray | None = None) -> np.ndarray:
        """Bartlett beam power at each point's direction in the 3 × 3 range–Doppler cells
        around its cell: float64 ``(P, 3, 3)`` [Doppler offset −1..1, range offset −1..1].

        ``rd`` and ``rd_next`` without TDM phases (as :meth:`_detect`). Each Doppler bin gets
        its own TDM compensation (across the Doppler edge that of the unwrapped neighbour)
        and the point's alias; range neighbours beyond the map repeat the edge cell.
        """
        ntx, nrx, nd, nr = rd.shape
        p = d.size
        out = np.zeros((p, 3, 3))
        if p == 0:
            return out
        kb = self._beam_kernels
        if kb is not None and self.settings.overlap == "first":
            nxt = (rd_next[..., 0].reshape(ntx * nrx, nd)
                   if rd_next is not None and rd_next.shape[-1] else np.zeros((0, 0)))
            kb["k"].beam_neighbourhood(
                _c64(rd.reshape(ntx * nrx, nd, nr)), _c64(nxt), kb["chan"], kb["tx"], ntx,
                np.ascontiguousarray(d, dtype=np.int64), np.ascontiguousarray(r, dtype=np.int64),
                _f64(np.zeros(p) if alias is None else alias), self._tdm is not None,
                _c64(steer), out)
            return out
        m2 = float(self.detection_grid.num_elements) ** 2
        for i, j in enumerate((-1, 0, 1)):
            dn = (d + j) % nd
            ph = None
            if self._tdm is not None:
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
                if self._tdm is not None:
                    v = v * self._tdm_at(dn)
                if ph is not None:
                    v = v * ph[:, None, :]
                el = combine_channels(v, self.calib.antenna.virtual, self.settings.overlap)
                out[:, i, k] = np.abs(np.einsum("mp,mp->p", el, steer)) ** 2 / m2
        return out

    def _guard(self, rd: np.ndarray, d: np.ndarray, r: np.ndarray, alias: np.ndarray | None,
               steer: np.ndarray, beam_excess: np.ndarray, beam_floor: np.ndarray,
               cell_excess: np.ndarray, exp_d: np.ndarray, exp_r: np.ndarray,
               exp_pow: np.ndarray, exp_excess: np.ndarray, cell_pow: np.ndarray
               ) -> np.ndarray:
        """Sidelobe guard on points: True = keep.

        First on the summed power (:func:`~coloradar.dsp.detect.sidelobe_pairs`): which
        stronger cells, two or more bins away, could explain a point's cell by the windows'
        worst-case leakage. Then per such pair in the point's own direction: leakage of cell
        ``j`` into the point's cell is ``E_d·E_r`` times ``j``'s beam, so the point stays
        when its beam power above the noise exceeds the margin times ``E_d·E_r·B_j(u)``;
        a weaker target in another direction is then kept beside a strong one.
        """
        s = self.settings
        margin = 10.0 ** (s.sidelobe_margin_db / 10)
        pi, pj, leak = sidelobe_pairs(d, r, cell_pow, cell_excess, exp_d, exp_r, exp_pow,
                                      self._env_d, self._env_r, rd.shape[2], margin)
        keep = np.ones(d.size, dtype=bool)
        if pi.size == 0:
            return keep
        ntx = rd.shape[0]
        jd, jr = exp_d[pj], exp_r[pj]
        v = rd[:, :, jd, jr]
        if self._tdm is not None:
            v = v * self._tdm_at(jd)
        if alias is not None:
            v = v * alias_phase(ntx, alias[pi])[:, None, :]
        el = combine_channels(v, self.calib.antenna.virtual, s.overlap)
        bj = np.abs(np.einsum("mp,mp->p", el, steer[:, pi])) ** 2 / float(
            self.detection_grid.num_elements) ** 2
        # Only a point outside cell j's main lobe is rescued by its direction (there the beam
        # of j has fallen below half its peak, which is at most j's mean element power).
        peak_j = np.mean(np.abs(el) ** 2, axis=0)
        # and only when it stands clear of the noise (twice the level a noise peak reaches)
        explained = ((beam_excess[pi] < margin * leak * bj) | (bj >= 0.5 * peak_j)
                     | (beam_excess[pi] < beam_floor[pi]))
        keep[pi[explained]] = False
        return keep

    def _choose_alias(self, vecs: np.ndarray, k_signed: np.ndarray,
                      noise: np.ndarray | None = None
                      ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Best Doppler alias per detection (:mod:`coloradar.dsp.tdm`); the second value is
        None (kept for callers).

        ``vecs``: complex ``(tx, rx, K)`` compensated at the folded Doppler ``k_signed``;
        ``noise``: float ``(K,)``, the mean noise power per virtual element of each
        detection (None: radars without overlapping pairs score by the row beam's peak).
        Returns ``(None, None)`` when the search is off.

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
        hyps = self._aliases
        if hyps.size < 2:
            return None, None
        ntx, nrx, k = vecs.shape
        nd = self.doppler_fft_size
        dv = self.velocities[1] - self.velocities[0]
        rates = (k_signed[:, None] + hyps[None, :] * nd) * dv                  # (K, H)
        allowed = (np.abs(rates) <= self.settings.doppler_unwrap) | (hyps[None, :] == 0)
        spectra = None
        if self._pairs is not None:
            score = self._pairs.scores(vecs.reshape(ntx * nrx, k).T, hyps)
        else:
            g = self.detection_grid
            ph = alias_phase(ntx, hyps)                                        # (tx, H)
            score = np.empty((k, hyps.size))
            step = 1024
            for k0 in range(0, k, step):
                ks = slice(k0, min(k, k0 + step))
                kk = ks.stop - k0
                cand = vecs[:, :, ks, None] * ph[:, None, None, :]             # (tx, rx, k, H)
                el = combine_channels(cand, self.calib.antenna.virtual, self.settings.overlap)
                # The filled azimuth row: a wrong hypothesis puts a phase step between the TX
                # blocks along it and defocuses it (no elevation ghosts).
                if noise is not None:
                    row = el[self._row_sel].reshape(-1, kk * hyps.size).T       # (k·H, M_row)
                    pen = np.repeat(self._alias_penalty * noise[ks], hyps.size)
                    ok = allowed[ks].reshape(-1)

                    def need(rss1: np.ndarray, kk: int = kk, pen: np.ndarray = pen,
                             ok: np.ndarray = ok) -> np.ndarray:
                        # Where the best one-source fit leaves no more than a second source
                        # is charged, no two-source fit can win: those detections skip it, as
                        # do the hypotheses out of the unwrap range (their score is -inf).
                        lowest = rss1.reshape(kk, hyps.size).min(axis=1)
                        return np.repeat(lowest > pen[::hyps.size], hyps.size) & ok

                    kern = (self._beam_kernels["k"].source_pairs
                            if self._beam_kernels is not None else None)
                    rss1, rss2 = source_fit_residuals(row, g.az_pos[self._row_sel], g.n_az,
                                                      self._row_bins, fit=need, kernel=kern)
                    left = np.minimum(rss1, rss2 + pen)
                    # power explained by the hypothesis' better model (same |x|² for all)
                    sc = (np.sum(np.abs(row) ** 2, axis=1) - left).reshape(kk, hyps.size)
                else:
                    prof = row_profile(g, el.reshape(el.shape[0], kk * hyps.size).T,
                                       workers=self.settings.workers)
                    prof = np.where(self._visible_az[None], prof, 0.0)
                    sc = prof.reshape(kk, hyps.size, g.num_az).max(axis=2)
                # (optional margin for the folded hypothesis, alias_margin_db)
                sc = np.where(hyps[None, :] == 0, sc, sc * self._alias_margin)
                sc = np.where(allowed[ks], sc, -np.inf)
                score[ks] = sc
        score = np.where(allowed, score, -np.inf)
        best = np.argmax(score, axis=1) if k else np.zeros(0, dtype=np.int64)
        return hyps[best], spectra

    def _peak_directions(self, spec: np.ndarray, k: np.ndarray, ie: np.ndarray, ia: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Direction sines of spectrum peaks ``(k, ie, ia)`` refined by log-parabolas along
        both axes of the ``(K, el, az)`` spectra, and the peak values."""
        g = self.detection_grid
        ne, na = g.num_el, g.num_az
        fe = refine_peak(np.stack([spec[k, (ie - 1) % ne, ia], spec[k, ie, ia],
                                   spec[k, (ie + 1) % ne, ia]], axis=1), ie, ne, wrap=True)
        fa = refine_peak(np.stack([spec[k, ie, (ia - 1) % na], spec[k, ie, ia],
                                   spec[k, ie, (ia + 1) % na]], axis=1), ia, na, wrap=True)
        uz = 2.0 * (fe - ne // 2) / (ne * g.rho)
        uy = 2.0 * (fa - na // 2) / (na * g.rho)
        return uy, uz, spec[k, ie, ia].astype(np.float64)

    def pointcloud(self, adc: np.ndarray) -> np.ndarray:
        """Point cloud of one frame, float32 ``(N, 5)``: ``x y z intensity range_rate``."""
        return self.detect(adc).pointcloud()

    def products(self, adc: np.ndarray, heatmap: bool = True, pointcloud: bool = True
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Heatmap and/or point cloud of one frame from one range–Doppler computation.

        Returns
        -------
        tuple
            ``(heatmap or None, pointcloud or None)`` as :meth:`heatmap` and :meth:`pointcloud`.
        """
        nr = self.num_range_bins
        in_kernel = heatmap and self._reads_channels()    # TDM applied as heatmap() does
        rcube = self._range_cube(adc, extra=pointcloud)
        rd = self._doppler(rcube[..., :nr], compensate=not (pointcloud or in_kernel))
        pts = None
        if pointcloud:
            pts = self._detect(rcube[..., :nr], rd,
                               self._doppler(rcube[..., nr:], compensate=False)).pointcloud()
            if heatmap and not in_kernel and self._tdm is not None:
                rd *= self._tdm                      # as _doppler: the heatmap's bits
        if not heatmap:
            return None, pts
        if in_kernel:
            return self._heatmap(rd, tdm_applied=False), pts
        return (self._heatmap_unwrapped(rd) if self.settings.heatmap_unwrap
                else self._heatmap(rd)), pts

    def __repr__(self) -> str:
        changed = {f.name: getattr(self.settings, f.name) for f in fields(self.settings)
                   if getattr(self.settings, f.name) != f.default}
        return f"RadarProcessor({self.calib.name!r}, {changed})"


def _group_peaks(stat: np.ndarray, mask: np.ndarray, noise: np.ndarray,
                 nxt: np.ndarray | None) -> np.ndarray:
    """The detection mask after peak grouping (numpy; :func:`~._kernels.group_peaks` is the
    compiled one): CFAR cells ``mask`` that are maxima of their 3 × 3 neighbourhood of
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


def _groups(ci: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(ci, return_inverse=True, return_counts=True)[1:]`` without the sort where
    ``ci`` is already non-decreasing (the peaks' cells always are: :func:`~coloradar.dsp.
    angle.azimuth_peaks` returns them by cell, and only masks follow)."""
    ci = np.asarray(ci)
    if ci.size == 0 or np.any(ci[1:] < ci[:-1]):
        _, inv, cnt = np.unique(ci, return_inverse=True, return_counts=True)
        return inv.reshape(-1), cnt
    new = _firsts(ci)
    cell_of = np.cumsum(new) - 1
    return cell_of, np.diff(np.append(np.flatnonzero(new), ci.size))


def _firsts(ci: np.ndarray, end: bool = False) -> np.ndarray:
    """bool ``(N,)`` (``end``: ``(N + 1,)``, True last): True where ``ci`` starts a run of
    equal values (``np.r_[True, ci[1:] != ci[:-1]]``, without ``np.r_``'s parsing cost,
    which counts at a few dozen peaks per frame)."""
    ci = np.asarray(ci)
    n = max(ci.size, 1)                                 # (as np.r_: [True] when empty)
    out = np.empty(n + int(end), dtype=bool)
    out[0] = True
    np.not_equal(ci[1:], ci[:-1], out=out[1:n])
    if end:
        out[-1] = True
    return out


def _f64(a: Any) -> np.ndarray:
    """Contiguous float64 (the dtype and layout the compiled kernels are built for)."""
    return np.ascontiguousarray(a, dtype=np.float64)


def _c64(a: Any) -> np.ndarray:
    """Contiguous complex64 (the dtype and layout the compiled kernels are built for)."""
    return np.ascontiguousarray(a, dtype=np.complex64)


def _power_sum(cube: np.ndarray) -> np.ndarray:
    mag = np.abs(cube)
    np.square(mag, out=mag)
    return mag.sum(axis=(0, 1))


def _edge_ratio(win: np.ndarray, fft_size: int) -> float:
    """``|W(½)|² / |W(1½)|²``: power of a tone's cell over the next cell when it lies half a
    bin beyond the cell centre (``W`` the window's DTFT in FFT bins, zero padding included)."""
    w = np.asarray(win, dtype=np.float64)
    k = np.arange(w.size)

    def resp(nu: float) -> float:
        return float(np.abs(np.sum(w * np.exp(-2j * np.pi * nu * k / fft_size))) ** 2)

    return resp(0.5) / max(resp(1.5), 1e-300)
