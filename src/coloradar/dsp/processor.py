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
      → CFAR (Doppler circular, range mirrored) → local maxima → angle per detection = detect(adc)
      → unique virtual elements → 2D angle FFT per cell → peak over Doppler      = heatmap(adc)
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, Literal, get_args

import numpy as np
import scipy.fft as sfft

from ..calib import HeatmapConfig, RadarCalib
from ..calib.waveform import SPEED_OF_LIGHT
from ..errors import FormatError, SettingsError
from .angle import bartlett_spectrum, capon_spectrum, refine_peak
from .array import OVERLAP_MODES, OverlapMode, angle_grid, combine_channels, sines_to_unit
from .cfar import (
    CFAR_KINDS,
    CFAREdge,
    CFARKind,
    cfar,
    cfar_window,
    effective_train_cells,
    power_correlation,
)
from .cube import coupling_signal, phase_frequency_factors, signed_doppler_bins
from .detect import Detections, channel_noise, local_maxima, sidelobe_envelope, sidelobe_mask
from .heatmap import ENGINES, heatmap_from_elements, resolve_engine
from .tdm import alias_hypotheses, alias_phase, overlap_pairs, tdm_phase
from .windows import WINDOWS, WindowName, coherent_window, window

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
        Keep only detections that are local maxima of the range–Doppler power (3×3).
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
    doppler_unwrap: float = 5.0
    heatmap_unwrap: bool = False
    sidelobe_guard: bool = True
    sidelobe_margin_db: float = 6.0
    min_range: float = 0.3
    peak_grouping: bool = True
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
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise SettingsError(f"{name} = {getattr(self, name)!r}; expected one of "
                                    f"{', '.join(map(str, allowed))}")
        if not 0.0 < self.pfa < 1.0:
            raise SettingsError(f"pfa must lie in (0, 1), got {self.pfa!r}")
        if not self.doppler_unwrap >= 0:
            raise SettingsError(f"doppler_unwrap must be >= 0 m/s (0 = off), got "
                                f"{self.doppler_unwrap!r}")
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

    # ------------------------------------------------------------------ cubes
    def _check(self, adc: np.ndarray) -> np.ndarray:
        adc = np.asarray(adc)
        if adc.shape != self.calib.frame_shape or not np.iscomplexobj(adc):
            raise FormatError(f"{self.calib.name} ADC frame: expected complex "
                              f"(tx, rx, chirp, sample) = {self.calib.frame_shape}, got "
                              f"{adc.dtype} {adc.shape}")
        return adc

    def _range_cube(self, adc: np.ndarray) -> np.ndarray:
        """Calibrated range FFT ``(tx, rx, chirp, range)``; chirps carry the Doppler window and
        the ``(−1)^c`` of the Doppler shift."""
        x = self._check(adc)
        if self._engine == "numba":
            return self._range_cube_compiled(x)
        y = x - self._coupling if self._coupling is not None else x.astype(np.complex64)
        if y.dtype != np.complex64:
            y = y.astype(np.complex64)
        if self.settings.dc_removal:
            y -= y.mean(axis=-1, keepdims=True)
        y *= self._mult
        out = sfft.fft(y, n=self.range_fft_size, axis=-1, workers=self.settings.workers,
                       overwrite_x=True)
        return out[..., : self.num_range_bins]

    def _range_cube_compiled(self, x: np.ndarray,
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
        out = out[..., : self.num_range_bins]
        return out.reshape(ntx, nrx, nc, -1) if channels is None else out

    def _doppler(self, rcube: np.ndarray) -> np.ndarray:
        v = sfft.fft(rcube, n=self.doppler_fft_size, axis=2, workers=self.settings.workers)
        if self.doppler_fft_size % 2:
            v = sfft.fftshift(v, axes=2)
        if self._tdm is not None:
            v *= self._tdm
        return v

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
        if self._engine == "numba" and s.overlap == "first" and not s.heatmap_unwrap:
            return self._heatmap_read_channels(adc)
        rd = self.range_doppler(adc)
        return self._heatmap_unwrapped(rd) if s.heatmap_unwrap else self._heatmap(rd)

    def _heatmap_read_channels(self, adc: np.ndarray) -> np.ndarray:
        """:meth:`_heatmap` computing the range–Doppler cube of only the channels it reads
        (the cascade's 134 first pairs of 192 channels): the same values to the bit (FFTs do
        not depend on the batch; TDM is the same multiply as in :meth:`_doppler`, so that
        :meth:`products` gives the same heatmap), less work."""
        if self._read_channels is None:
            nrx = self.calib.frame_shape[1]
            first = self.calib.antenna.virtual.first_pair
            used, element_channel = np.unique(first[:, 0] * nrx + first[:, 1],
                                              return_inverse=True)
            tdm = None if self._tdm is None else self._tdm[used // nrx, 0]   # (K, nd, 1)
            self._read_channels = used, element_channel, tdm
        used, element_channel, tdm = self._read_channels
        rc = self._range_cube_compiled(self._check(adc), used)         # (K, chirp, range)
        v = sfft.fft(rc, n=self.doppler_fft_size, axis=1, workers=self.settings.workers)
        if self.doppler_fft_size % 2:
            v = sfft.fftshift(v, axes=1)
        if tdm is not None:
            v *= tdm
        return heatmap_from_elements(v, self.grid, self.velocities,
                                     workers=self.settings.workers, engine=self._engine,
                                     channels=element_channel)

    def _heatmap(self, rd: np.ndarray) -> np.ndarray:
        if self.settings.overlap == "first":
            # the engine reads each element's channel straight from the cube
            ntx, nrx = rd.shape[:2]
            first = self.calib.antenna.virtual.first_pair
            return heatmap_from_elements(rd.reshape(ntx * nrx, *rd.shape[2:]), self.grid,
                                         self.velocities, workers=self.settings.workers,
                                         engine=self._engine,
                                         channels=first[:, 0] * nrx + first[:, 1])
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
        stat, _, looks = self._detection_map(rd)
        mask, _ = self._cfar_mask(stat, looks)
        d, r = np.nonzero(mask)
        if d.size == 0:
            return self._heatmap(rd)
        nd = rd.shape[2]
        alias, _ = self._choose_alias(rd[:, :, d, r], (d - nd // 2).astype(np.float64))
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
        rcube = self._range_cube(adc)
        return self._detect(rcube, self._doppler(rcube))

    def _detection_map(self, rd: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Detection statistic ``(doppler, range)`` float64, the plain power sum (flat), and
        the looks the CFAR threshold is computed for (``noise_weighting``)."""
        s = self.settings
        ntx, nrx, nd, nr = rd.shape
        mag2 = np.abs(rd).reshape(ntx * nrx, nd * nr)
        np.square(mag2, out=mag2)
        plain = mag2.sum(axis=0)
        if s.noise_weighting == "off":
            return plain.reshape(nd, nr).astype(np.float64), plain, self._looks
        # Inverse-noise weights: each term a unit exponential times the mean noise power, so
        # the sum is a Ntx·Nrx-look chi-square whatever the channel gains.
        sig2 = channel_noise(mag2.reshape(ntx * nrx, nd, nr),
                             int(np.ceil(s.min_range / self.range_bin_width)))
        wts = (sig2.mean() / sig2).astype(np.float32)
        return (wts @ mag2).reshape(nd, nr).astype(np.float64), plain, self._looks

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
        res = cfar(stat[:, r0:], s.cfar_kind, s.cfar_guard, s.cfar_train, s.pfa,
                   rank=s.cfar_rank, looks=looks, mode=cmodes, split_axis=1,
                   cell_factor=self._cell_factor, excise=s.cfar_excision)
        mask = np.zeros(stat.shape, dtype=bool)
        mask[:, r0:] = res.detections
        noise = np.full(stat.shape, np.inf)
        noise[:, r0:] = res.noise
        return mask, noise

    def _detect(self, rcube: np.ndarray, rd: np.ndarray) -> Detections:
        s = self.settings
        stat, plain, looks = self._detection_map(rd)
        modes: tuple[CFAREdge, CFAREdge] = ("wrap", "mirror")   # (Doppler, range)
        mask, noise = self._cfar_mask(stat, looks)
        if s.peak_grouping:
            mask &= local_maxima(stat, modes)
        d, r = np.nonzero(mask)
        if s.sidelobe_guard and d.size > 1:
            # Candidates inside min_range still explain sidelobes, so the cut comes after.
            keep = sidelobe_mask(d, r, stat[d, r], stat[d, r] - noise[d, r], self._env_d,
                                 self._env_r, stat.shape[0], 10.0 ** (s.sidelobe_margin_db / 10))
            d, r = d[keep], r[keep]
        near = r < int(np.ceil(s.min_range / self.range_bin_width))
        d, r = d[~near], r[~near]
        nd, nr = stat.shape
        d_ref = refine_peak(np.stack([stat[(d - 1) % nd, r], stat[d, r],
                                      stat[(d + 1) % nd, r]], axis=1), d, nd, wrap=True)
        r_ref = refine_peak(np.stack([stat[d, np.maximum(r - 1, 0)], stat[d, r],
                                      stat[d, np.minimum(r + 1, nr - 1)]], axis=1),
                            r, nr, wrap=False)
        k_signed = d_ref - nd // 2
        ntx = rd.shape[0]
        vecs = rd[:, :, d, r]                                           # (tx, rx, K)
        if self._tdm is not None:
            # rd holds bin-centre compensation; add the fractional remainder.
            vecs = vecs * tdm_phase(ntx, d_ref - d, nd)[:, None, :]
        alias, spec = self._choose_alias(vecs, k_signed)
        if alias is not None:
            vecs = vecs * alias_phase(ntx, alias)[:, None, :]
        if s.angle_method == "capon" and d.size:
            vectors = combine_channels(vecs, self.calib.antenna.virtual, s.overlap).T
            snaps = rcube[:, :, :, r]                                    # (tx, rx, chirp, K)
            if self._tdm is not None:
                ph = tdm_phase(ntx, k_signed, nd)
                if alias is not None:
                    ph = ph * alias_phase(ntx, alias)
                snaps = snaps * ph[:, None, None, :]
            snaps = combine_channels(snaps, self.calib.antenna.virtual, s.overlap)
            spec = capon_spectrum(self.detection_grid, snaps.transpose(2, 1, 0), vectors,
                                  s.capon_loading, workers=s.workers)
        elif spec is None:
            vectors = combine_channels(vecs, self.calib.antenna.virtual, s.overlap).T
            spec = bartlett_spectrum(self.detection_grid, vectors, workers=s.workers)
        uy, uz, peak = self._peak_directions(spec)
        if s.beam_doppler and d.size:
            d_ref = self._beam_doppler(rd, d, r, alias, uy, uz)
            k_signed = d_ref - nd // 2
        rng = r_ref * self.range_bin_width
        unit = sines_to_unit(uy, uz)
        xyz = rng[:, None] * unit
        k_true = k_signed + (alias * nd if alias is not None else 0)
        flat = plain.reshape(nd, nr)
        return Detections(
            range_bin=r.astype(np.int64), doppler_bin=d.astype(np.int64), range=rng,
            range_rate=k_true * (self.velocities[1] - self.velocities[0]),
            azimuth=np.arctan2(unit[:, 1], unit[:, 0]), elevation=np.arcsin(unit[:, 2]),
            xyz=xyz, intensity=peak, power=flat[d, r].astype(np.float64),
            snr=stat[d, r] / noise[d, r], alias=alias)

    def _choose_alias(self, vecs: np.ndarray, k_signed: np.ndarray
                      ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Best Doppler alias per detection (:mod:`coloradar.dsp.tdm`) and, when it was scored
        by the angle spectrum, the Bartlett spectra of the winners.

        ``vecs``: complex ``(tx, rx, K)`` compensated at the folded Doppler ``k_signed``.
        Returns ``(None, None)`` when the search is off.
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
            spectra = np.empty((k, g.num_el, g.num_az), dtype=np.float32)
            step = 256                                  # bounds the (K·H, el, az) spectra
            for k0 in range(0, k, step):
                ks = slice(k0, min(k, k0 + step))
                kk = ks.stop - k0
                cand = vecs[:, :, ks, None] * ph[:, None, None, :]             # (tx, rx, k, H)
                el = combine_channels(cand, self.calib.antenna.virtual, self.settings.overlap)
                spec = bartlett_spectrum(g, el.reshape(el.shape[0], kk * hyps.size).T,
                                         workers=self.settings.workers)
                vis = np.where(self._visible[None], spec, 0.0)
                sc = vis.reshape(kk, hyps.size, g.num_el * g.num_az).max(axis=2)
                sc = np.where(allowed[ks], sc, -np.inf)
                score[ks] = sc
                spectra[ks] = spec.reshape(kk, hyps.size, g.num_el, g.num_az)[
                    np.arange(kk), np.argmax(sc, axis=1)]
        score = np.where(allowed, score, -np.inf)
        best = np.argmax(score, axis=1) if k else np.zeros(0, dtype=np.int64)
        return hyps[best], spectra

    def _beam_doppler(self, rd: np.ndarray, d: np.ndarray, r: np.ndarray,
                      alias: np.ndarray | None, uy: np.ndarray, uz: np.ndarray) -> np.ndarray:
        """Sub-bin Doppler of each detection from the beam steered at its direction.

        The power map sums all directions, so a cell of an extended surface (floor, wall) mixes
        scatterers of many range rates, and its Doppler peak is pulled off the range rate of
        the direction the angle spectrum found (docs/dsp.md, "Beam-steered Doppler"). The
        beam at that direction keeps only its neighbourhood. Returns float64 ``(K,)``
        refined Doppler bins, as the power-map refinement.
        """
        ntx = rd.shape[0]
        nd = rd.shape[2]
        g = self.detection_grid
        cols = []
        for j in (-1, 0, 1):
            dn = (d + j) % nd
            v = rd[:, :, dn, r]
            if self._tdm is not None:
                # rd holds the compensation of the wrapped bin dn; a neighbour across the
                # edge needs that of d + j, one Doppler period (one alias) away.
                v = v * tdm_phase(ntx, (d + j - dn).astype(np.float64), nd)[:, None, :]
            if alias is not None:
                v = v * alias_phase(ntx, alias)[:, None, :]
            cols.append(combine_channels(v, self.calib.antenna.virtual, self.settings.overlap))
        # The Bartlett beam at the refined sines: the angle grid's FFT evaluated off-grid,
        # Σ_m x_m exp(jπρ(s_az·p_az,m·u_y + s_el·p_el,m·u_z)) over unique elements m.
        phase = np.pi * g.rho * (g.azimuth_sign * g.az_pos[:, None] * uy[None, :]
                                 + g.elevation_sign * g.el_pos[:, None] * uz[None, :])
        steer = np.exp(1j * phase).astype(np.complex64)                    # (M, K)
        p3 = np.stack([np.abs(np.sum(c * steer, axis=0)) ** 2 for c in cols], axis=1)
        return refine_peak(p3, d, nd, wrap=True)

    def _peak_directions(self, spec: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sub-bin peak direction sines and peak value of ``(K, el, az)`` spectra."""
        g = self.detection_grid
        k = spec.shape[0]
        masked = np.where(self._visible[None], spec, 0.0)
        flat = masked.reshape(k, g.num_el * g.num_az).argmax(axis=1) if k else np.zeros(0, int)
        ie, ia = np.divmod(flat, g.num_az)
        kk = np.arange(k)
        ne, na = g.num_el, g.num_az
        fe = refine_peak(np.stack([spec[kk, (ie - 1) % ne, ia], spec[kk, ie, ia],
                                   spec[kk, (ie + 1) % ne, ia]], axis=1), ie, ne, wrap=True)
        fa = refine_peak(np.stack([spec[kk, ie, (ia - 1) % na], spec[kk, ie, ia],
                                   spec[kk, ie, (ia + 1) % na]], axis=1), ia, na, wrap=True)
        uz = 2.0 * (fe - ne // 2) / (ne * g.rho)
        uy = 2.0 * (fa - na // 2) / (na * g.rho)
        return uy, uz, spec[kk, ie, ia].astype(np.float64)

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
        rcube = self._range_cube(adc)
        rd = self._doppler(rcube)
        pts = self._detect(rcube, rd).pointcloud() if pointcloud else None
        if not heatmap:
            return None, pts
        return (self._heatmap_unwrapped(rd) if self.settings.heatmap_unwrap
                else self._heatmap(rd)), pts

    def __repr__(self) -> str:
        changed = {f.name: getattr(self.settings, f.name) for f in fields(self.settings)
                   if getattr(self.settings, f.name) != f.default}
        return f"RadarProcessor({self.calib.name!r}, {changed})"


def _power_sum(cube: np.ndarray) -> np.ndarray:
    mag = np.abs(cube)
    np.square(mag, out=mag)
    return mag.sum(axis=(0, 1))
