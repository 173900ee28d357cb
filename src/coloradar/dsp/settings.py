"""Settings of the radar processor: one flat, frozen :class:`ProcessingSettings` (the keywords of
:class:`~coloradar.dsp.RadarProcessor` and ``--set NAME=VALUE``), read by each stage of the chain
as its own group (:class:`CubeSettings`, :class:`ArraySettings`, :class:`CFARSettings`,
:class:`AngleSettings`, :class:`AliasSettings`, :class:`GuardSettings`, :class:`PointSettings`),
so that a stage's code names the few settings it depends on.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from difflib import get_close_matches
from typing import Any, Literal, TypeVar, get_args

from ..errors import SettingsError
from .array import OVERLAP_MODES, OverlapMode
from .cfar import CFAR_KINDS, CFARKind
from .heatmap import ENGINES
from .windows import WINDOWS, WindowName

__all__ = [
    "ANGLE_METHODS",
    "CFAR_LOOKS",
    "COUPLING_DOMAINS",
    "NOISE_WEIGHTINGS",
    "UNCALIBRATED_ALIAS",
    "AliasSettings",
    "AngleMethod",
    "AngleSettings",
    "ArraySettings",
    "CFARLooks",
    "CFARSettings",
    "CouplingDomain",
    "CubeSettings",
    "GuardSettings",
    "NoiseWeighting",
    "PointSettings",
    "ProcessingSettings",
    "UncalibratedAlias",
]

CouplingDomain = Literal["raw", "calibrated"]
"""What the coupling file is the range FFT of: uncalibrated or calibrated samples."""
COUPLING_DOMAINS: tuple[CouplingDomain, ...] = get_args(CouplingDomain)
UncalibratedAlias = Literal["fold", "search"]
"""What the Doppler alias choice does on an array without a phase calibration: keep the folded
rate (``"fold"``) or search as on a calibrated array (``"search"``)."""
UNCALIBRATED_ALIAS: tuple[UncalibratedAlias, ...] = get_args(UncalibratedAlias)
AngleMethod = Literal["fft", "capon"]
"""Detection angles by Bartlett (FFT) or Capon (MVDR) beamforming."""
ANGLE_METHODS: tuple[AngleMethod, ...] = get_args(AngleMethod)
NoiseWeighting = Literal["whiten", "off"]
"""How channels are summed for detection (:attr:`ProcessingSettings.noise_weighting`)."""
NOISE_WEIGHTINGS: tuple[NoiseWeighting, ...] = get_args(NoiseWeighting)
CFARLooks = Literal["auto", "channels"]
"""Looks the CFAR threshold assumes (:attr:`ProcessingSettings.cfar_looks`)."""
CFAR_LOOKS: tuple[CFARLooks, ...] = get_args(CFARLooks)


@dataclass(frozen=True)
class CubeSettings:
    """The cube stage (:mod:`coloradar.dsp.cube_stage`): calibration, windows, range and Doppler FFTs,
    TDM compensation, and the engine and threads of every stage.

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
    workers: int = 1
    engine: str = "auto"


@dataclass(frozen=True)
class ArraySettings:
    """The virtual array and the heatmap stage (:mod:`coloradar.dsp.heatmap_stage`).

    Attributes
    ----------
    overlap
        Virtual pairs sharing a position: ``"first"`` (TX-major first pair) or ``"average"``.
    azimuth_sign, elevation_sign
        +1 when the antenna file's az (el) axis grows toward +y (+z) (docs/conventions.md §3); −1 mirrors.
    heatmap_unwrap
        Heatmaps with disambiguated Doppler: cells that pass the CFAR are compensated for
        their best alias hypothesis before the angle FFT, and channel 1 carries the unwrapped
        range rate (see :meth:`RadarProcessor.heatmap`).
    """

    overlap: OverlapMode = "first"
    azimuth_sign: int = 1
    elevation_sign: int = 1
    heatmap_unwrap: bool = False


@dataclass(frozen=True)
class CFARSettings:
    """The CFAR stage of detection (:mod:`coloradar.dsp.detection.cfar_stage`): detection statistic,
    CFAR, peak grouping.

    Attributes
    ----------
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
    cfar_looks
        Looks of the summed power the threshold is computed for. ``"channels"`` (default):
        Ntx·Nrx, exact for independent receiver noise; scene content the channels share
        (clutter, phase-noise skirts, weak returns) then crosses it more often than ``pfa``.
        ``"auto"``: measured in every frame (:func:`coloradar.dsp.cfar.effective_looks`,
        between 1 and Ntx·Nrx): holds ``pfa`` within 2x on planted common-mode noise and
        comes out as Ntx·Nrx on independent noise, but treats dense weak returns as noise
        too (the demo's corridor: a third to two thirds fewer points, docs/dsp.md).
    cfar_range_floor
        Flatten the noise floor along range before the CFAR: every range bin's statistic is
        divided by its floor (the lower quartile over Doppler, median-filtered along range:
        :func:`coloradar.dsp.cfar.range_floor`) and the CFAR's noise estimate multiplied
        back. The receiver's noise is not flat in range — the IF high-pass rises over the
        first bins and the anti-alias filter rolls off over the last — and a training window
        that straddles such a step lowers the threshold of the cells on its high side
        (OpenRadar's real frame: 4x the requested rate at 1e-2 and 10x at 1e-3 on the cells
        before the roll-off, docs/capture.md). A quantile over Doppler ignores the returns of
        a range bin unless they fill three quarters of it. False: the CFAR sees the statistic
        as it is (the chain before issue 29).
    min_range
        Detections closer than this [m] are dropped (coupling residue lives there).
    peak_grouping
        Group the cells of one target into one point: CFAR cells that peak along Doppler or
        along range are examined, and a point is kept only where its cell's beam, steered at
        the point's direction, is not smaller than that of any of the 8 neighbouring
        range–Doppler cells (so a target one bin from a stronger one in another direction
        stays). False: every CFAR cell makes points.
    """

    cfar_kind: CFARKind = "ca"
    cfar_guard: tuple[int, int] = (1, 2)
    cfar_train: tuple[int, int] = (2, 8)
    pfa: float = 1e-4
    cfar_rank: float = 0.75
    cfar_excision: bool = True
    noise_weighting: NoiseWeighting = "whiten"
    cfar_looks: CFARLooks = "channels"
    cfar_range_floor: bool = True
    min_range: float = 0.3
    peak_grouping: bool = True


@dataclass(frozen=True)
class AngleSettings:
    """The angle stages of detection: peaks (:mod:`coloradar.dsp.detection.peaks`) and several-source
    resolution (:mod:`coloradar.dsp.detection.resolve`).

    Attributes
    ----------
    angle_method
        ``"fft"`` (Bartlett) or ``"capon"`` (MVDR per detection, see :mod:`coloradar.dsp.angle`).
    angle_oversample
        Detection angle grid = heatmap grid × this, before sub-bin refinement.
    capon_loading
        Capon diagonal loading relative to the mean eigenvalue.
    angle_refine
        Refine each direction off the grid by Newton steps on the Bartlett beam power
        (``angle_method="fft"``), after the log-parabola on the grid.
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
    """

    angle_method: AngleMethod = "fft"
    angle_oversample: int = 2
    capon_loading: float = 0.05
    angle_refine: bool = True
    near_field: bool | Literal["auto"] = "auto"
    multi_peak: bool = True
    angle_pfa: float = 1e-3
    angle_dynamic_range_db: float = 20.0


@dataclass(frozen=True)
class AliasSettings:
    """The Doppler alias choice of detection (:mod:`coloradar.dsp.detection.alias`).

    Attributes
    ----------
    doppler_unwrap
        Largest ``|range rate|`` [m/s] searched beyond ±v_max: each detection tests the TDM
        alias hypotheses whose range rate stays within it (at most Ntx of them) and keeps the
        best (:mod:`coloradar.dsp.tdm`); 0 switches the search off (folded range rates, and
        angles compensated for the folded Doppler).
    alias_margin_db
        Radars without overlapping virtual pairs (the single chip) choose the Doppler alias
        by a model selection on the filled row (one or two sources under each hypothesis,
        :meth:`~coloradar.dsp.detection.alias.AliasStage.choose`); another hypothesis must explain this margin
        [dB] more power than the folded one.
    alias_min_confidence
        A hypothesis other than the folded one is taken only where its probability
        (:meth:`~coloradar.dsp.detection.alias.AliasStage.confidence`, which treats what no
        model explains as noise) reaches this; elsewhere the folded rate is kept.
    uncalibrated_alias
        What the choice does when the radar's calibration has no phase calibration (or
        ``phase_frequency_calibration`` is off). An alias hypothesis is a phase per TX slot,
        and so is an uncalibrated board's TX phase error: on such an array no test of the
        hypotheses can tell the two apart. ``"fold"`` (default) keeps every detection's
        folded range rate and reports, as its alias confidence, how likely the folded
        hypothesis is under the nominal (uncalibrated) phases, so that a low value flags a
        point that could be aliased; ``"search"`` trusts the nominal phases (a board known to
        be matched, or a simulated one). ``coloradar calibrate phase`` measures the
        calibration from a run's own data (docs/dsp.md, "Doppler beyond ±v_max").
    """

    doppler_unwrap: float = 10.0
    alias_margin_db: float = 0.0
    alias_min_confidence: float = 0.9
    uncalibrated_alias: UncalibratedAlias = "fold"


@dataclass(frozen=True)
class GuardSettings:
    """The sidelobe guard of detection (:mod:`coloradar.dsp.detection.guard`).

    Attributes
    ----------
    sidelobe_guard, sidelobe_margin_db
        Drop detections that a stronger one's window sidelobes explain: a candidate ``Δd``
        Doppler and ``Δr`` range bins from a stronger one of power ``P`` is dropped when its
        power above the CFAR noise is below ``P·E_d(Δd)·E_r(Δr)`` times the margin, ``E`` the
        windows' worst-case sidelobe envelopes.
    """

    sidelobe_guard: bool = True
    sidelobe_margin_db: float = 6.0


@dataclass(frozen=True)
class PointSettings:
    """Where a detection's point is (:mod:`coloradar.dsp.detection.points`).

    Attributes
    ----------
    phase_centre
        Points from the virtual array's phase centre (True: the physics of a real array, whose
        range FFT and beams measure range and direction from it; the point is that position
        in the radar frame). False: range and direction taken as seen from the radar origin,
        as the simulator's narrowband far-field model (:mod:`coloradar.sim.radar_if`) makes
        them (docs/dsp.md, "Where a point is").
    beam_doppler
        Refine each detection's Doppler on the beam steered at its refined direction (three
        dot products per detection) instead of on the channel-summed power: on extended
        surfaces the summed power mixes the range rates of all directions of a cell, and the
        range rate would not belong to the direction reported (docs/dsp.md).
    """

    phase_centre: bool = True
    beam_doppler: bool = True


@dataclass(frozen=True)
class ProcessingSettings:
    """Settings of a :class:`RadarProcessor` (all keyword arguments of its constructor).

    The settings are flat (``ProcessingSettings(pfa=1e-5)``, ``--set pfa=1e-5``); each stage
    of the chain reads its own group of them, documented there:

    ===================  ==================================================================
    :attr:`cube`         :class:`CubeSettings`: windows, FFT sizes, calibration, coupling,
                         TDM, engine, threads
    :attr:`array`        :class:`ArraySettings`: virtual array, sign conventions, the
                         disambiguated heatmap
    :attr:`cfar`         :class:`CFARSettings`: detection statistic, CFAR, peak grouping
    :attr:`angle`        :class:`AngleSettings`: angle peaks and several-source resolution
    :attr:`alias`        :class:`AliasSettings`: Doppler alias choice
    :attr:`guard`        :class:`GuardSettings`: sidelobe guard
    :attr:`points`       :class:`PointSettings`: where a point is, its range rate
    ===================  ==================================================================
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
    cfar_looks: CFARLooks = "channels"
    cfar_range_floor: bool = True
    doppler_unwrap: float = 10.0
    alias_margin_db: float = 0.0
    alias_min_confidence: float = 0.9
    uncalibrated_alias: UncalibratedAlias = "fold"
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
                   "noise_weighting": NOISE_WEIGHTINGS, "cfar_looks": CFAR_LOOKS,
                   "uncalibrated_alias": UNCALIBRATED_ALIAS,
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
        if not 0.0 <= self.alias_min_confidence <= 1.0:
            raise SettingsError(f"alias_min_confidence must lie in [0, 1], got "
                                f"{self.alias_min_confidence!r}")
        if not 0.0 < self.angle_pfa < 1.0:
            raise SettingsError(f"angle_pfa must lie in (0, 1), got {self.angle_pfa!r}")
        if self.angle_oversample < 1 or self.capon_loading <= 0:
            raise SettingsError("angle_oversample must be >= 1 and capon_loading > 0")
        for name in ("cfar_guard", "cfar_train"):
            object.__setattr__(self, name, _range_doppler_pair(name, getattr(self, name)))

    @property
    def cube(self) -> CubeSettings:
        """The cube stage's settings."""
        return _group(CubeSettings, self)

    @property
    def array(self) -> ArraySettings:
        """The virtual array's and the heatmap stage's settings."""
        return _group(ArraySettings, self)

    @property
    def cfar(self) -> CFARSettings:
        """The CFAR stage's settings."""
        return _group(CFARSettings, self)

    @property
    def angle(self) -> AngleSettings:
        """The angle stages' settings (peaks, several-source resolution)."""
        return _group(AngleSettings, self)

    @property
    def alias(self) -> AliasSettings:
        """The alias choice's settings."""
        return _group(AliasSettings, self)

    @property
    def guard(self) -> GuardSettings:
        """The sidelobe guard's settings."""
        return _group(GuardSettings, self)

    @property
    def points(self) -> PointSettings:
        """The point placement's settings."""
        return _group(PointSettings, self)

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
            close = get_close_matches(name, names, n=3) if sep else []
            hint = f"; did you mean {' or '.join(close)}?" if close else ""
            raise SettingsError(f"expected NAME=VALUE with NAME one of {', '.join(names)}; "
                                f"got {text!r}{hint}")
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


_G = TypeVar("_G")


def _group(cls: type[_G], s: ProcessingSettings) -> _G:
    """The settings group ``cls`` of ``s`` (its fields are named as the flat settings)."""
    return cls(**{f.name: getattr(s, f.name) for f in fields(cls)})  # type: ignore[arg-type]
