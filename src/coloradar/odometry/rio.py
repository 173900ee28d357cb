"""Radar-inertial odometry: the error-state EKF of :mod:`.eskf` driven by radar ego-velocities.

:func:`rio_odometry` runs the whole chain on one run's data:

1. **Zero-velocity detection** (:mod:`.zero_velocity`) at every radar frame, from the radar's
   ego-speed (or, given the points, their range rates against the Doppler noise) and the
   IMU's quietness; nobody says when the rig stands still.
2. **Initialisation** at the first usable radar frame: attitude from gravity
   (:mod:`.gravity`; motion removed with the radar's velocities when the rig already moves),
   gyro bias from the mean rate when that frame is static, velocity from the radar; a moving
   start only from a frame the next one corroborates within what the IMU allows
   (:func:`_consistent`).
3. **Propagation** with every IMU sample (:meth:`.ErrorStateEKF.propagate`).
4. **Updates**, in time order over all radars (the order of the frames' IMU times
   ``stamp + t_d[r]`` under the current offsets): a static frame gives a zero-velocity update
   (``v = 0``, σ ``zupt_std``) and, when that is accepted, an ungated zero-rate update of the
   gyro bias (the mean rate of the IMU samples since the previous one); any other usable frame
   gives a radar velocity update,
   ``z = v_radar`` (RANSAC ego-velocity, :mod:`.ego_velocity`), covariance the RANSAC one
   times ``velocity_noise_scale²`` plus ``velocity_noise_floor²`` (the RANSAC covariance has
   the right shape but leaves out angle and Doppler-bin errors),
   ``h(x) = R_irᵀ (Rᵀ v + ω × t_ir)`` at IMU time ``t + t_d``. Each update is gated by the
   chi-square test of its normalised innovation at ``gate_probability``. A planar ego-velocity
   (``v_z`` fixed at 0) updates ``v_z`` only loosely (``planar_vz_std``).
5. **Output** at the first radar's frames (IMU clock, ``t + t_d``): ``world_T_base``, its 6 × 6
   covariance (position, attitude), biases and time offsets.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from scipy.integrate import trapezoid  # numpy.trapezoid needs numpy >= 2
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from ..calib import Calibration
from ..errors import ColoradarError, DataWarning, SettingsError
from ..geometry import SE3, Trajectory, sensor_to_base
from .anchor import anchor_covariance, smoothed_start
from .doppler import (
    DopplerConfig,
    PointNoise,
    doppler_points_index,
    doppler_update,
    elevation_rows,
    point_noise_for,
)
from .eskf import BA, BG, TH, ErrorStateEKF, ImuNoise, P, V, skew
from .gravity import gravity_alignment
from .noise_estimate import NoiseEstimateConfig, PointNoiseEstimator, VerticalPrior, observer
from .rio_outputs import KeepPose, PoseOutputs, PoseState
from .smoother import RtsSmoother
from .velocity_track import EgoVelocityTrack
from .zero_velocity import ZeroVelocityConfig, imu_quiet, static_frames, still_rates

__all__ = ["UPDATES", "RioConfig", "RioResult", "rio_odometry", "rio_summary"]

EDGE_FRAMES = 5
"""Radar frames left out before the first usable one or beyond the IMU's span that go
unwarned (a frame at each edge of the IMU's span is normal; the summaries count them)."""

UPDATES = ("doppler", "ego-velocity")
"""Radar updates of the filter: every Doppler point a scalar measurement (tightly coupled,
the default, :mod:`.doppler`) or one RANSAC ego-velocity per frame (loosely coupled)."""

_G0 = 9.80665
_DEG = np.pi / 180.0


@dataclass(frozen=True)
class RioConfig:
    """Settings of the radar-inertial filter.

    The IMU defaults are the MicroStrain 3DM-GX5-25 datasheet's (MicroStrain/LORD, "3DM-GX5-25
    Attitude and Heading Reference System", 8400-0093): noise densities 100 µg/√Hz and
    0.005 °/s/√Hz, initial bias ±0.002 g and ±0.04 °/s, bias instability 0.04 mg and 8 °/h
    (turned into random walks as instability / √(100 s)). The regime the filter must survive
    (issue 25) has turn-on biases up to twice the datasheet's and walks of one to ten times the
    derived densities; the filter assumes **three times** the derived walks (the regime's
    geometric middle; the derivation is a convention, not a datasheet figure). Chosen on 48
    tuning runs of ``benchmarks/mc_odometry.py`` (worst single-chip end 1.44 → 0.58 % on the
    32 fresh ones, medians a little better); twice the turn-on biases as well made the
    worst runs without a rest worse (the heading follows a barely observable vertical gyro
    bias): the turn-on uncertainties stay the datasheet's (docs/odometry.md, "Monte Carlo").

    Attributes
    ----------
    accel_noise_density, gyro_noise_density
        [m/s²/√Hz], [rad/s/√Hz].
    accel_bias_walk, gyro_bias_walk
        [m/s²/√s], [rad/s/√s]: three times the datasheet-derived densities (above).
    accel_bias_std, gyro_bias_std
        Initial bias uncertainty [m/s²], [rad/s] (turn-on bias).
    velocity_noise_scale, velocity_noise_floor
        The radar measurement covariance is ``scale² C + floor² I`` with ``C`` the RANSAC
        ego-velocity covariance [-, m/s]. The defaults (2, 5 mm/s) are measured: over nine
        simulated 60 s runs the scale that makes the normalised error of the ego-velocities
        against the truth equal its degrees of freedom was 1.8 (cascade) and 1.4 (single
        chip). An isotropic floor large enough to cover the across-boresight errors (the
        0.05 m/s used before) swamps the boresight axis, whose error is a few mm/s and which
        carries the forward acceleration and so the time offset.
    gate_probability
        Chi-square gate of every update (an innovation beyond this quantile is rejected).
    estimate_time_offset
        Estimate each radar's time offset ``t_d`` online.
    time_offset, time_offset_std
        Its initial value and uncertainty [s].
    time_offset_warmup
        Seconds after the start during which the time offset is held at ``time_offset``
        (default 0: estimated from the first frame). Holding it while the rig starts moving
        (the strongest accelerations, the most informative frames) applies those frames at
        the wrong time, and their error goes into the biases and rotations.
    estimate_extrinsic_rotation
        Estimate each radar's rotation relative to the IMU online (the calibration's as prior).
    extrinsic_warmup
        Seconds after the start during which that rotation is held at the calibration's [s]:
        the start's attitude errors (gravity aligned while moving) would otherwise be taken
        for a mounting error and kept.
    extrinsic_rotation_std
        Prior uncertainty of that rotation [rad].
    extrinsic_rotation_axes
        ``"auto"`` (default): yaw alone for a radar with fewer than 3 elevation rows (the
        single chip), roll, pitch and yaw for the others; ``"all"``: roll, pitch and yaw for
        a radar whose points measure ``v_z``, yaw alone for a planar radar (its
        ego-velocity cannot see the others); ``"yaw"``: yaw alone for every radar. On the
        runs of issue 42 written by another program the single chip's estimated pitch
        converged to +0.75° where the truth was 0 (final error 0.5 → 1.4 %), its coarse
        elevations leaving mounting pitch and body pitch barely apart. A mounting pitch and
        the body's pitch tilt the measured velocity alike, and only the forward
        accelerations tell them apart: on the
        point-level Monte Carlo (no velocity bias) the estimated pitch wanders and ``"yaw"``
        is ahead, on ADC-level runs (the DSP chain's few-cm/s ``v_z`` bias) ``"all"`` is
        (docs/odometry.md, "Online extrinsic rotation").
    zero_velocity
        The zero-velocity detector's settings.
    planar_vz_std
        A planar radar (``v_z`` fixed at 0: the single chip's ego-velocities, and its Doppler
        points with ``--model planar``) updates its own ``v_z`` with this standard deviation
        [m/s]: the planar model's assumption, held loosely, in either update (the Doppler
        points' and the ego-velocity's; since issue 42 the single chip's Doppler points are
        3-D by default and this applies to its ego-velocity updates only). 5 cm/s: on the tuning runs of
        ``benchmarks/mc_odometry.py`` 2, 5 and 10 cm/s gave the Doppler update median final
        errors of 0.18, 0.22 and 0.30 % and 5 cm/s the smaller worst case of the two best;
        the ego-velocity update, which had 10 cm/s, is no worse with it (docs/odometry.md).
    zupt_std
        Standard deviation of a zero-velocity update [m/s].
    align_window
        Seconds of IMU samples around the first frame used for gravity alignment.
    moving_tilt_std
        Roll/pitch uncertainty after aligning while the rig moves [rad] (at rest it follows
        from ``accel_bias_std``).
    anchor_delay
        The attitudes of the output's first ``anchor_delay`` seconds are the one estimated
        then, carried back by the gyro (the first estimates are the least certain), and the
        output is anchored at the first of them [s].
    max_rejected
        After this many consecutive rejected frames per radar, with no update of any radar
        accepted in between, the filter has lost the radars: its velocity restarts from the
        next frame's measurement (counted as ``resets``).
    update
        ``"doppler"`` (default): the tightly coupled update, each Doppler point of a frame a
        scalar residual gated on its own (:mod:`.doppler`), when the frames' points are given
        (``points`` of :func:`rio_odometry`); the frame's RANSAC ego-velocity only when too
        few points pass the gate. ``"ego-velocity"``: one RANSAC ego-velocity per frame
        (loosely coupled, the literature's baseline). Chosen on the tuning runs of
        ``benchmarks/mc_odometry.py`` (docs/odometry.md).
    doppler
        Settings of the Doppler-point update.
    point_noise
        Per radar (in the order of the tracks) the points' noise; None: each radar's default
        (:func:`~coloradar.odometry.doppler.point_noise_for`). Where the noise is measured
        (``noise_estimate``: by default for every radar), the prior of that measurement.
    vertical_prior
        A radar whose points are used in 3-D also updates its ``v_z ≈ 0`` with a standard
        deviation measured from its own frames (:class:`.noise_estimate.VerticalPrior`): the
        rig's vertical motion as a soft prior that a ramp or a pitching rig widens. Off by
        default: on the two runs written by another program it halved the noisy run's
        vertical end error (0.40 → 0.24 %) but doubled both runs' ATE (0.035 → 0.055 %,
        0.10 → 0.23 %).
    noise_estimate
        The points' range-rate and direction noise measured from their residuals while the
        filter runs (:mod:`.noise_estimate`), for the per-point gate and the
        errors-in-variables correction: a constant over-corrects exact directions and
        under-corrects noisy ones (issue 42).
    smooth
        Offline: the poses smoothed with the later measurements too (Rauch–Tung–Striebel,
        :mod:`.smoother`); covariances, velocities and biases stay the filter's. Off by
        default (``coloradar odometry`` is causal); SLAM's front end turns it on.
    """

    accel_noise_density: float = 100e-6 * _G0
    gyro_noise_density: float = 0.005 * _DEG
    accel_bias_walk: float = 3.0 * 0.04e-3 * _G0 / 10.0
    gyro_bias_walk: float = 3.0 * 8.0 * _DEG / 3600.0 / 10.0
    accel_bias_std: float = 0.002 * _G0
    gyro_bias_std: float = 0.04 * _DEG
    velocity_noise_scale: float = 2.0
    velocity_noise_floor: float = 0.005
    gate_probability: float = 0.999
    estimate_time_offset: bool = True
    time_offset: float = 0.0
    time_offset_std: float = 0.05
    time_offset_warmup: float = 0.0
    extrinsic_warmup: float = 0.0
    estimate_extrinsic_rotation: bool = True
    extrinsic_rotation_std: float = 1.0 * _DEG
    extrinsic_rotation_axes: str = "auto"
    zero_velocity: ZeroVelocityConfig = field(default_factory=ZeroVelocityConfig)
    planar_vz_std: float = 0.05
    zupt_std: float = 0.005
    align_window: float = 0.5
    moving_tilt_std: float = 3.0 * _DEG
    max_rejected: int = 5
    anchor_delay: float = 5.0
    update: str = "doppler"
    doppler: DopplerConfig = field(default_factory=DopplerConfig)
    point_noise: tuple[PointNoise, ...] | None = None
    noise_estimate: NoiseEstimateConfig = field(default_factory=NoiseEstimateConfig)
    vertical_prior: bool = False
    smooth: bool = False

    def __post_init__(self) -> None:
        for name in ("accel_noise_density", "gyro_noise_density", "accel_bias_walk",
                     "gyro_bias_walk", "accel_bias_std", "gyro_bias_std",
                     "velocity_noise_floor", "velocity_noise_scale", "time_offset_std",
                     "extrinsic_rotation_std",
                     "planar_vz_std", "zupt_std", "align_window", "time_offset_warmup",
                     "extrinsic_warmup",
                     "anchor_delay", "moving_tilt_std"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise SettingsError(f"RioConfig.{name} must be a finite number >= 0, got {v!r}")
        if self.max_rejected < 1:
            raise SettingsError(f"max_rejected must be >= 1, got {self.max_rejected}")
        if not 0 < self.gate_probability <= 1:
            raise SettingsError(f"gate_probability must be in (0, 1], got {self.gate_probability}")
        if self.extrinsic_rotation_axes not in ("auto", "yaw", "all"):
            raise SettingsError("RioConfig.extrinsic_rotation_axes must be 'auto', 'yaw' or "
                                f"'all', got {self.extrinsic_rotation_axes!r}")
        if self.update not in UPDATES:
            raise SettingsError(f"unknown radar update {self.update!r}; expected one of "
                                f"{', '.join(UPDATES)}")

    @property
    def noise(self) -> ImuNoise:
        """The process noise of the filter."""
        return ImuNoise(self.accel_noise_density, self.gyro_noise_density,
                        self.accel_bias_walk, self.gyro_bias_walk)


@dataclass(frozen=True, eq=False)
class RioResult:
    """What the filter estimated at the first radar's frames (M poses).

    Attributes
    ----------
    trajectory
        ``world_T_base`` at the IMU-clock times ``t + t_d`` of the frames.
    frame_timestamps
        float64 ``(M,)``: the radar stamps of those frames [s].
    covariance
        float64 ``(M, 6, 6)``: covariance of the base position [m²] and attitude (world-frame
        rotation vector) [rad²], in the output's world frame; it includes the tilt error
        of the anchoring first pose, which the re-anchoring imposes on every pose.
    velocity
        float64 ``(M, 3)``: the IMU's velocity, output world frame [m/s].
    accel_bias, gyro_bias
        float64 ``(M, 3)`` [m/s², rad/s] and their standard deviations ``*_std``.
    time_offset, time_offset_std
        float64 ``(M, R)`` [s], one column per radar.
    extrinsic_rotation
        float64 ``(R, 3)``: final rotation-vector correction of each radar's extrinsic
        rotation, radar frame [rad] (0 when not estimated).
    radars
        The radars, in column order.
    static
        bool ``(M,)``: frames found static (zero-velocity update applied).
    stats
        Counts per radar: ``updates``, ``rejected``, ``zupts``, ``failed`` (no ego-velocity),
        ``resets`` (velocity restarted after ``max_rejected`` rejections in a row),
        ``point_updates`` (frames updated point by point), ``points`` and ``points_used``
        (points offered to and passed by the per-point gate).
    velocity_covariance
        float64 ``(M, 3, 3)``: covariance of ``velocity`` [m²/s²], output world frame
        (the anchoring's tilt error included, as for ``covariance``).
    static_points
        Per output pose, bool over the rows of the first radar's cloud: the points the
        per-point gate took as static (None where the frame had no point update, or the
        filter ran without points).
    kept
        None: every field above is given at every pose. Else int64 ``(K,)``: the poses
        (indices into ``trajectory``) at which ``covariance``, ``velocity``, the biases, the
        time offsets, ``velocity_covariance`` and ``static_points`` are given (``K`` rows):
        those a ``keep`` of :func:`rio_odometry` asked for, the anchoring pose and the last.
    filtered
        With ``RioConfig.smooth``: the filter's own poses (causal, as without it), anchored
        alike; ``trajectory`` is then the smoothed one. None otherwise.
    point_noise
        Per radar, the points' noise at the end of the run: measured from the data
        (``RioConfig.noise_estimate``) or the prior (None without points).
    """

    trajectory: Trajectory
    frame_timestamps: np.ndarray
    covariance: np.ndarray
    velocity: np.ndarray
    accel_bias: np.ndarray
    accel_bias_std: np.ndarray
    gyro_bias: np.ndarray
    gyro_bias_std: np.ndarray
    time_offset: np.ndarray
    time_offset_std: np.ndarray
    extrinsic_rotation: np.ndarray
    radars: tuple[str, ...]
    static: np.ndarray
    stats: dict[str, dict[str, int]]
    velocity_covariance: np.ndarray | None = None
    static_points: list[np.ndarray | None] | None = None
    kept: np.ndarray | None = None
    filtered: Trajectory | None = None
    point_noise: tuple[PointNoise, ...] | None = None


def _planar(track: EgoVelocityTrack) -> bool:
    ok = track.ok & np.all(np.isfinite(track.velocity), axis=1)
    return bool(ok.any()) and bool(np.all(track.velocity[ok, 2] == 0.0)
                                   and np.all(track.covariance[ok, 2, :] == 0.0))


def _coarse_elevation(calib: Calibration, radar: str) -> bool:
    """Whether the radar's array has fewer than 3 elevation rows (unknown radars: no)."""
    try:
        return elevation_rows(calib.radar(radar)) < 3
    except (KeyError, ValueError, AttributeError, ColoradarError):
        return False


def _initial_motion(track: EgoVelocityTrack, sel: np.ndarray, ekf: ErrorStateEKF,
                    t_ir: np.ndarray, r_ir: np.ndarray, td: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """IMU-frame velocity at the first selected frame and the mean IMU-frame acceleration
    over the selected frames, from the radar (``a_b = du/dt + ω × u``)."""
    tt = track.timestamps[sel] + td
    _, w = ekf.imu_at(tt)
    u = (r_ir @ track.velocity[sel].T).T - np.cross(w, t_ir)
    if sel.size < 3 or np.ptp(tt) < 0.1:
        return u[0], np.zeros(3)
    slope = np.polyfit(tt - tt[0], u, 1)[0]
    return u[0], slope + np.cross(w.mean(0), u.mean(0))


def _imu_frame_velocity(track: EgoVelocityTrack, k: int, ekf: ErrorStateEKF, t_ir: np.ndarray,
                        r_ir: np.ndarray, td: float) -> np.ndarray:
    """Frame ``k``'s radar velocity as the IMU origin's velocity in the IMU frame."""
    _, w = ekf.imu_at(float(track.timestamps[k] + td))
    return r_ir @ track.velocity[k] - np.cross(w, t_ir)


def _radar_noise(cov: np.ndarray, scale: float, floor: float) -> np.ndarray:
    """Covariance ``(3, 3)`` [m²/s²] of a radar ego-velocity measurement: the RANSAC one
    ``cov`` times ``scale²`` plus ``floor²`` on each axis (:class:`RioConfig`)."""
    return scale**2 * cov + floor**2 * np.eye(3)


def _default_noise(calib: Calibration, radar: str) -> PointNoise:
    """The radar's point noise from its waveform (Doppler bin, ``v_max``) when the
    calibration knows it, else the defaults of :func:`point_noise_for`."""
    try:
        w = calib.radar(radar).waveform
    except (ColoradarError, KeyError, AttributeError):
        return point_noise_for(radar)
    return point_noise_for(radar, float(w.velocity_bin_width), float(w.max_velocity))


class _FramePoints:
    """One radar's clouds as the filter reads them, frame ``k`` → the usable points ``(K, 4)``
    (:func:`.doppler.doppler_points_index`), their rows in the cloud and the cloud's size.

    Computed when asked (the last frame kept), not for the whole run at once: the clouds stay
    wherever the caller keeps them — a list, or SLAM's frame store on disk — and memory does
    not grow with the run's length. The price: the set-up's rest test reads every frame once
    and the filter once more (a pass is 1.4 % of the single chip's filter time: 15 ms of
    1.05 s on a 90 s run)."""

    def __init__(self, clouds: Sequence[np.ndarray], min_range: float) -> None:
        self.clouds, self.min_range = clouds, min_range
        self._last: tuple[int, tuple[np.ndarray, np.ndarray, int]] | None = None

    def __len__(self) -> int:
        return len(self.clouds)

    def __getitem__(self, k: int) -> tuple[np.ndarray, np.ndarray, int]:
        if self._last is None or self._last[0] != k:
            c = self.clouds[k]
            self._last = (k, (*doppler_points_index(c, self.min_range), int(np.shape(c)[0])))
        return self._last[1]

    def __iter__(self) -> Iterator[tuple[np.ndarray, np.ndarray, int]]:
        return (self[k] for k in range(len(self)))


def _prepare_points(points: Sequence[Sequence[np.ndarray]] | None,
                    tracks: Sequence[EgoVelocityTrack], cfg: RioConfig
                    ) -> list[_FramePoints] | None:
    """Per radar, per frame: the usable points ``(K, 4)``, their rows in the cloud and the
    cloud's size (:class:`_FramePoints`); None when the update is loosely coupled."""
    if points is None or cfg.update != "doppler":
        return None
    if len(points) != len(tracks):
        raise SettingsError(f"{len(tracks)} tracks but point clouds of {len(points)} radars")
    out = []
    for tr, clouds in zip(tracks, points, strict=True):
        if len(clouds) != len(tr):
            raise SettingsError(f"{tr.frame}: {len(tr)} frames but {len(clouds)} point clouds")
        out.append(_FramePoints(clouds, cfg.doppler.min_range))
    return out


def _consistent(track: EgoVelocityTrack, k: int, j: int, ekf: ErrorStateEKF, t_ir: np.ndarray,
                r_ir: np.ndarray, td: float, floor: float, gate: float, scale: float = 1.0
                ) -> bool:
    """Whether frames ``k`` and ``j`` of one radar can both be right, whatever the attitude.

    In the IMU frame ``du/dt = f + Rᵀg − ω × u``; ``|Rᵀg| = g`` whatever ``R``, so
    ``u_j − u_k − ∫(f − ω × u_k) dt`` lies within ``g·|t_j − t_k|`` of zero (biases and the
    change of ``ω × u`` are small beside it). Beyond that, plus ``gate`` standard deviations
    of the two measurements, one of them is wrong. A bound from physics, no tuned constant:
    it catches gross errors (a cloud fitted by an alias of the true motion, metres per
    second off), which would otherwise seed the filter's velocity and gravity alignment.
    """
    ta, tb = sorted((float(track.timestamps[k] + td), float(track.timestamps[j] + td)))
    ts = ekf.imu_t
    inner = ts[(ts > ta) & (ts < tb)]
    tg = np.concatenate([[ta], inner, [tb]])
    f, w = ekf.imu_at(tg)
    uk = _imu_frame_velocity(track, k, ekf, t_ir, r_ir, td)
    uj = _imu_frame_velocity(track, j, ekf, t_ir, r_ir, td)
    g = f - np.cross(w, uk)
    sign = 1.0 if j > k else -1.0
    integral = sign * trapezoid(g, tg, axis=0)
    cov = (_radar_noise(track.covariance[k], scale, floor)
           + _radar_noise(track.covariance[j], scale, floor))
    sigma = float(np.sqrt(np.max(np.linalg.eigvalsh(cov))))
    return bool(np.linalg.norm(uj - uk - integral) <= _G0 * (tb - ta) + gate * sigma)


@dataclass(eq=False)
class _Setup:
    """What a run of the filter works with: inputs checked, the filter built (its nominal
    calibration states set), per radar the frames found static and the points prepared."""

    cfg: RioConfig
    tracks: list[EgoVelocityTrack]
    names: tuple[str, ...]
    imu_t: np.ndarray
    imu: np.ndarray
    ekf: ErrorStateEKF
    imu_T_base: SE3
    ext: list[SE3]
    t_ir: list[np.ndarray]
    planar: list[bool]
    pts: list[_FramePoints] | None
    noises: tuple[PointNoise, ...]
    estimators: list[PointNoiseEstimator]
    vertical: list[VerticalPrior]
    dcfg: list[DopplerConfig]
    ext_yaw_only: list[bool]
    static: list[np.ndarray]


def _check_imu(imu_timestamps: np.ndarray, imu_data: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    imu_t = np.asarray(imu_timestamps, dtype=np.float64).reshape(-1)
    imu = np.asarray(imu_data, dtype=np.float64)
    if imu.shape != (imu_t.size, 6):
        raise SettingsError(f"expected IMU data of shape ({imu_t.size}, 6), got {imu.shape}")
    good_imu = np.all(np.isfinite(imu), axis=1) & np.isfinite(imu_t)
    if not good_imu.all():          # a copy only when samples are left out
        imu_t, imu = imu_t[good_imu], imu[good_imu]
    if imu_t.size < 10 or np.any(np.diff(imu_t) <= 0):
        raise ColoradarError("radar-inertial odometry needs an IMU stream of at least 10 "
                             "samples with strictly increasing timestamps")
    return imu_t, imu


def _setup(tracks: EgoVelocityTrack | Sequence[EgoVelocityTrack], calib: Calibration,
           imu: tuple[np.ndarray, np.ndarray], radars: Sequence[str] | None, cfg: RioConfig,
           still: Sequence[np.ndarray] | None, points: Sequence[Sequence[np.ndarray]] | None
           ) -> _Setup:
    """Check the inputs of :func:`rio_odometry` and build what its filter runs on."""
    tr_list = [tracks] if isinstance(tracks, EgoVelocityTrack) else list(tracks)
    if not tr_list:
        raise SettingsError("rio_odometry needs at least one ego-velocity track")
    names = tuple(radars) if radars is not None else tuple(t.frame for t in tr_list)
    if len(names) != len(tr_list):
        raise SettingsError(f"{len(tr_list)} tracks but {len(names)} radar names")
    imu_t, imu_d = _check_imu(*imu)
    n_r = len(tr_list)
    ekf = ErrorStateEKF.from_array(imu_t, imu_d, cfg.noise, n_r)
    base_T_imu = sensor_to_base(calib, "imu")
    ext = [base_T_imu.inverse() @ sensor_to_base(calib, n) for n in names]
    for r, e in enumerate(ext):
        ekf.R_ir[r] = e.rotation.as_matrix()
        ekf.td[r] = cfg.time_offset
    planar = [_planar(t) for t in tr_list]
    pts = _prepare_points(points, tr_list, cfg)
    noises = cfg.point_noise or tuple(_default_noise(calib, n) for n in names)
    if len(noises) != n_r:
        raise SettingsError(f"{n_r} radars but {len(noises)} point noises")
    # Per radar: the points inform v_z unless the radar's model is planar (DopplerConfig).
    dcfg = [replace(cfg.doppler, planar=p if cfg.doppler.planar is None else cfg.doppler.planar)
            for p in planar]
    # Radars whose points observe v_z see the extrinsic's roll and pitch as well (not
    # estimated with extrinsic_rotation_axes "yaw").
    coarse = [cfg.extrinsic_rotation_axes == "auto" and _coarse_elevation(calib, n)
              for n in names]
    ext_yaw_only = [cfg.extrinsic_rotation_axes == "yaw" or c
                    or (p and (pts is None or bool(d.planar)))
                    for p, d, c in zip(planar, dcfg, coarse, strict=True)]
    zv = cfg.zero_velocity
    static = []
    for r, tr in enumerate(tr_list):
        quiet = imu_quiet(imu_t, imu_d[:, :3], imu_d[:, 3:], tr.timestamps + cfg.time_offset, zv)
        st = None if still is None else np.asarray(still[r], dtype=bool)
        if pts is not None:
            # The points' own range rates against the radar's Doppler noise: a sparse cloud's
            # RANSAC speed at rest is often above max_speed, and its rest would go unseen.
            own = np.array([still_rates(p, noises[r].range_rate_std, zv)
                            for p, _, _ in pts[r]], dtype=bool)
            st = own if st is None else st | own
        static.append(static_frames(np.linalg.norm(tr.velocity, axis=1), tr.ok, quiet, zv, st))
    return _Setup(cfg, tr_list, names, imu_t, imu_d, ekf, base_T_imu.inverse(), ext,
                  [e.translation for e in ext], planar, pts, noises,
                  [PointNoiseEstimator(n, cfg.noise_estimate) for n in noises],
                  [VerticalPrior() for _ in noises], dcfg,
                  ext_yaw_only, static)


def _first_frame(s: _Setup) -> tuple[int, np.ndarray, np.ndarray, float]:
    """The first usable frame of the first radar (a moving one only if the next frame
    corroborates it): its index, the frames inside the IMU's span, those measured, and the
    3-dof gate in standard deviations."""
    cfg, prim, ekf = s.cfg, s.tracks[0], s.ekf
    inside = (prim.timestamps + cfg.time_offset >= s.imu_t[0]) & \
             (prim.timestamps + cfg.time_offset <= s.imu_t[-1])
    measured = prim.ok & np.all(np.isfinite(prim.velocity), axis=1)
    usable = np.flatnonzero(inside & (measured | s.static[0]))
    if usable.size == 0:
        raise ColoradarError(f"{prim.frame}: no radar frame with a usable ego-velocity lies "
                             "within the IMU's time span; nothing to filter")
    gate_sigma = float(np.sqrt(chi2.ppf(cfg.gate_probability, 3))) \
        if cfg.gate_probability < 1 else np.inf
    meas = np.flatnonzero(inside & measured)

    def corroborated(k: int) -> bool:
        # A moving start takes the frame's velocity as the filter's: the next measured frame
        # must agree with it as far as the IMU allows (see _consistent). That bound grows by
        # g a second, so the next frame must come within the alignment window: a lone
        # frame seconds before the next (a few points fitted by a wrong motion) says nothing.
        nxt = meas[meas > k]
        if nxt.size and prim.timestamps[nxt[0]] - prim.timestamps[k] > cfg.align_window:
            return bool(s.static[0][k])
        return s.static[0][k] or nxt.size == 0 or _consistent(
            prim, k, int(nxt[0]), ekf, s.t_ir[0], ekf.R_ir[0], cfg.time_offset,
            cfg.velocity_noise_floor, gate_sigma, cfg.velocity_noise_scale)

    k0 = next((int(k) for k in usable if corroborated(int(k))), int(usable[0]))
    dropped = int(k0 + (~inside[k0:]).sum())
    if dropped > EDGE_FRAMES:       # a frame or two at the IMU's edges is normal (summary)
        warnings.warn(f"{prim.frame}: {dropped} of {len(prim)} radar frames lie before the "
                      "first usable one or outside the IMU's time span; left out",
                      DataWarning, stacklevel=4)
    return k0, inside, measured, gate_sigma


def _initialise(s: _Setup) -> tuple[int, float, np.ndarray]:
    """Set the filter's state and covariance at the first usable frame: returns its index,
    its IMU time and the initial variances (the calibration states' kept for their
    warm-up)."""
    cfg, prim, ekf, imu_t = s.cfg, s.tracks[0], s.ekf, s.imu_t
    k0, inside, measured, gate_sigma = _first_frame(s)
    t0 = float(prim.timestamps[k0] + cfg.time_offset)
    half = cfg.align_window / 2
    win = np.flatnonzero((imu_t >= t0 - half) & (imu_t <= t0 + half))
    if win.size < 5:
        win = np.argsort(np.abs(imu_t - t0))[:10]
    f_win, w_win = s.imu[win, :3], s.imu[win, 3:]
    ekf.t = t0
    P0 = np.zeros(ekf.dim)
    if s.static[0][k0]:
        ekf.R = gravity_alignment(f_win)
        ekf.bg = w_win.mean(axis=0)
        ekf.v = np.zeros(3)
        tilt = cfg.accel_bias_std / _G0
        P0[V] = cfg.zupt_std**2
        # The mean of white rate noise over the window, plus a floor for residual motion.
        span = max(float(np.ptp(imu_t[win])), 1e-3)
        P0[BG] = cfg.gyro_noise_density**2 / span + (2e-4) ** 2
    else:
        tt = prim.timestamps + cfg.time_offset
        sel = np.flatnonzero(measured & inside & (tt >= t0) & (tt <= t0 + cfg.align_window))
        sel = np.array([j for j in sel if j == k0 or _consistent(
            prim, k0, int(j), ekf, s.t_ir[0], ekf.R_ir[0], cfg.time_offset,
            cfg.velocity_noise_floor, gate_sigma, cfg.velocity_noise_scale)], dtype=np.int64)
        u0, a_b = _initial_motion(prim, sel, ekf, s.t_ir[0], ekf.R_ir[0], cfg.time_offset)
        ekf.R = gravity_alignment(f_win, a_b)
        ekf.v = ekf.R @ u0
        tilt = cfg.moving_tilt_std
        vstd = np.sqrt(cfg.velocity_noise_scale**2 * np.max(np.diag(prim.covariance[k0]))
                       + cfg.velocity_noise_floor**2)
        P0[V] = vstd**2
        P0[BG] = cfg.gyro_bias_std**2
    P0[P] = 1e-12
    P0[TH] = [tilt**2, tilt**2, (1e-3) ** 2]
    P0[BA] = cfg.accel_bias_std**2
    for r in range(len(s.tracks)):
        if cfg.estimate_extrinsic_rotation:
            # A planar ego-velocity (v_x, v_y only) sees the radar's yaw, not its roll and
            # pitch: those would only wander, so they stay at the calibration's (and for
            # every radar with extrinsic_rotation_axes "yaw").
            sl = ekf.phi_slice(r)
            P0[sl] = [0.0, 0.0, cfg.extrinsic_rotation_std**2] if s.ext_yaw_only[r] \
                else cfg.extrinsic_rotation_std**2
    ekf.P = np.diag(P0)
    for r in range(len(s.tracks)):
        ekf.P[ekf.phi_slice(r), ekf.phi_slice(r)] = 0.0      # until extrinsic_warmup
    return k0, t0, P0


class _Loop:
    """The event loop: every radar frame in time order, its update, the output poses."""

    def __init__(self, s: _Setup, k0: int, t0: float, P0: np.ndarray,
                 keep: KeepPose | None = None, smoother: RtsSmoother | None = None):
        self.s, self.k0, self.t0, self.P0 = s, k0, t0, P0
        n_r = len(s.tracks)
        self.out = PoseOutputs(len(s.tracks[0]) - k0, n_r, keep, s.cfg.anchor_delay)
        self.smoother = smoother
        self.filtered: tuple[np.ndarray, np.ndarray] | None = None   # (p, R) when smoothed
        # Each output pose's state in the smoother's record (RtsSmoother.pose_at).
        self.at = np.zeros(len(s.tracks[0]) - k0 if smoother else 0, dtype=np.int64)
        self.imu_R_base = s.imu_T_base.rotation.as_matrix()   # for the base pose keep is shown
        self.stats = {n: {"updates": 0, "rejected": 0, "zupts": 0, "failed": 0, "resets": 0,
                          "point_updates": 0, "points": 0, "points_used": 0} for n in s.names}
        cfg = s.cfg
        self.gate3 = float(chi2.ppf(cfg.gate_probability, 3)) if cfg.gate_probability < 1 \
            else None
        self.last_zaru = t0
        self.last_out = -np.inf
        self.rejected_run = 0                     # radar frames rejected since any acceptance
        self.td_on = np.zeros(n_r, dtype=bool)
        self.ext_on = np.zeros(n_r, dtype=bool)

    def events(self) -> Iterator[tuple[float, int, int]]:
        """Frames in the order of their IMU times ``stamp + t_d[r]`` under the current
        offsets: the radars' offsets differ, so stamp order is not time order, and a frame
        taken after the filter has passed its time would be evaluated late."""
        s, ekf = self.s, self.s.ekf
        # Frames of the other radars from before the start are old news: left out.
        queues = [np.array([k for k in range(len(tr)) if (
            k >= self.k0 if r == 0 else tr.timestamps[k] + s.cfg.time_offset >= self.t0)],
            dtype=np.int64) for r, tr in enumerate(s.tracks)]
        pos = [0] * len(queues)
        while True:
            cand = [(float(s.tracks[r].timestamps[q[pos[r]]] + ekf.td[r]), r)
                    for r, q in enumerate(queues) if pos[r] < q.size]
            if not cand:
                return
            r = min(cand)[1]
            k = int(queues[r][pos[r]])
            pos[r] += 1
            yield float(s.tracks[r].timestamps[k]), r, k

    def run(self) -> None:
        """Propagate to each frame and update with it; with a smoother, smooth the poses."""
        s, ekf, sm = self.s, self.s.ekf, self.smoother
        for stamp, r, k in self.events():
            want = stamp + ekf.td[r]
            tau = max(want, ekf.t)
            if r == 0 and tau <= self.last_out:
                tau = self.last_out + 1e-6        # poses strictly in time order
            if tau > s.imu_t[-1]:
                break
            if sm is not None:
                sm.before(ekf)
            ekf.propagate(tau)
            released = self._release_calibration(r, tau)
            if sm is not None:
                sm.after(ekf, released)
            st = self.stats[s.names[r]]
            used = None
            # A frame found static whose zero-velocity update the filter rejects (a rig
            # creeping slower than the still test resolves, with a quiet IMU) is not lost: it
            # updates as a moving frame does.
            still = bool(s.static[r][k]) and self._zero_velocity(tau, st)
            if s.pts is not None and not still and s.pts[r][k][0].shape[0]:
                est, vert = s.estimators[r], s.vertical[r]
                vz = s.cfg.planar_vz_std if s.dcfg[r].planar else \
                    (vert.std if s.cfg.vertical_prior else None)
                used = doppler_update(ekf, r, s.t_ir[r], s.pts[r][k][0], est.noise,
                                      s.dcfg[r], min(want - tau, 0.0), vz,
                                      observer(est, vert))
                st["points"] += s.pts[r][k][0].shape[0]
            if still:
                pass                    # the zero-velocity update was this frame's update
            elif used is not None:
                st["updates"] += 1
                st["point_updates"] += 1
                st["points_used"] += int(used.sum())
                self.rejected_run = 0
                self.last_zaru = tau
            elif s.tracks[r].ok[k] and np.all(np.isfinite(s.tracks[r].velocity[k])):
                self._ego_velocity(r, k, want, tau, st)
            else:
                st["failed"] += 1
            if r == 0:
                self._record(k - self.k0, tau, k, used)
        if sm is not None:
            n = int(np.isfinite(self.out.t).sum())
            self.filtered = (self.out.p[:n].copy(), self.out.R[:n].copy())
            self.out.p[:n], self.out.R[:n] = sm.smoothed_poses(ekf, self.at[:n])

    def _release_calibration(self, r: int, tau: float) -> list[int]:
        """Start estimating radar ``r``'s time offset and extrinsic rotation after their
        warm-ups: right after the start, errors of the initial state would be read as them.
        Returns the error-state indices released now."""
        ekf, cfg = self.s.ekf, self.s.cfg
        released: list[int] = []
        if cfg.estimate_time_offset and not self.td_on[r] \
                and tau - self.t0 >= cfg.time_offset_warmup:
            j = ekf.td_index(r)
            ekf.P[j, :] = ekf.P[:, j] = 0.0
            ekf.P[j, j] = cfg.time_offset_std**2
            self.td_on[r] = True
            released.append(j)
        if cfg.estimate_extrinsic_rotation and not self.ext_on[r] \
                and tau - self.t0 >= cfg.extrinsic_warmup:
            sl = ekf.phi_slice(r)
            ekf.P[sl, :] = ekf.P[:, sl] = 0.0
            ekf.P[sl, sl] = np.diag(self.P0[sl])
            self.ext_on[r] = True
            released += list(range(sl.start, sl.stop))
        return released

    def _zero_velocity(self, tau: float, st: dict[str, int]) -> bool:
        """A static frame: zero-velocity update and zero-rate update of the gyro bias; returns
        whether the zero-velocity update was accepted."""
        s, ekf, cfg = self.s, self.s.ekf, self.s.cfg
        H = np.zeros((3, ekf.dim))
        H[:, V] = np.eye(3)
        acc, _ = ekf.update(-ekf.v, H, np.eye(3) * cfg.zupt_std**2, self.gate3)
        self.rejected_run = 0 if acc else self.rejected_run
        sel = (s.imu_t > self.last_zaru) & (s.imu_t <= tau)
        if acc and sel.sum() >= 3:
            Hg = np.zeros((3, ekf.dim))
            Hg[:, BG] = np.eye(3)
            span = max(tau - self.last_zaru, 1e-3)
            z = s.imu[sel, 3:].mean(axis=0)
            # The mean of white rate noise over `span` seconds, plus a floor for the rig's
            # residual motion.
            Rg = np.eye(3) * (cfg.gyro_noise_density**2 / span + (2e-4) ** 2)
            # Not gated: the rest is established (radar still, IMU quiet, the zero-velocity
            # update accepted), and a mean rate many prior σ from the bias estimate is the
            # turn-on bias the prior underrates (up to 2x the datasheet's, issue 25), the
            # one measurement that can correct it; gated, the rest would be thrown away.
            ekf.update(z - ekf.bg, Hg, Rg, None)
        self.last_zaru = tau
        st["zupts" if acc else "rejected"] += 1
        return bool(acc)

    def _ego_velocity(self, r: int, k: int, want: float, tau: float,
                      st: dict[str, int]) -> None:
        """The frame's RANSAC ego-velocity as one 3-D measurement (loosely coupled), and the
        restart of the velocity once every radar's frames have been rejected for a while."""
        s, ekf, cfg = self.s, self.s.ekf, self.s.cfg
        tr = s.tracks[r]
        y, H = ekf.radar_velocity_model(r, s.t_ir[r])
        if want < tau:
            # The frame's time has passed (its offset was corrected since it was queued): the
            # prediction at `want`, to first order (the offset column is dy/dt).
            y = y + (want - tau) * H[:, ekf.td_index(r)]
        C = _radar_noise(tr.covariance[k], cfg.velocity_noise_scale, cfg.velocity_noise_floor)
        if s.planar[r]:
            # v_z is not measured: the planar model's assumption v_z = 0, loosely.
            C[2, :] = C[:, 2] = 0.0
            C[2, 2] = cfg.planar_vz_std**2
        acc, _ = ekf.update(tr.velocity[k] - y, H, C, self.gate3)
        st["updates" if acc else "rejected"] += 1
        self.rejected_run = 0 if acc else self.rejected_run + 1
        if self.rejected_run >= cfg.max_rejected * len(s.tracks):
            # The filter has lost the radars (every frame of every radar for a while is an
            # outlier): restart the velocity from this one, with its uncertainty.
            w, _ = ekf.angular_state(tau)
            u = ekf.R_ir[r] @ tr.velocity[k] - np.cross(w, s.t_ir[r])
            ekf.v = ekf.R @ u
            ekf.P[V, :] = 0.0
            ekf.P[:, V] = 0.0
            ekf.P[V, V] = ekf.R @ (ekf.R_ir[r] @ C @ ekf.R_ir[r].T) @ ekf.R.T \
                + np.eye(3) * cfg.velocity_noise_floor**2
            self.rejected_run = 0
            st["resets"] += 1
        self.last_zaru = tau

    def _record(self, i: int, tau: float, k: int, used: np.ndarray | None) -> None:
        """Output pose ``i`` (the first radar's frame ``k``) from the filter's state."""
        s, ekf = self.s, self.s.ekf
        self.last_out = tau
        if self.smoother is not None:
            self.at[i] = self.smoother.pose_at()
        rb = ekf.R @ s.imu_T_base.translation
        J = np.zeros((6, ekf.dim))
        J[:3, P] = np.eye(3)
        J[:3, TH] = -skew(rb)
        J[3:, TH] = np.eye(3)
        dg = np.diag(ekf.P)
        mask = None
        if used is not None and s.pts is not None:
            mask = np.zeros(s.pts[0][k][2], dtype=bool)
            mask[s.pts[0][k][1][used]] = True
        state = PoseState(ekf.v.copy(), J @ ekf.P @ J.T,
                          np.array([ekf.ba, np.sqrt(dg[BA]), ekf.bg, np.sqrt(dg[BG])]),
                          np.array([ekf.td, [np.sqrt(dg[ekf.td_index(j)])
                                             for j in range(len(s.tracks))]]),
                          ekf.P[V, V].copy(), mask)
        base = None if self.out.keep is None else (ekf.p + rb, ekf.R @ self.imu_R_base)
        self.out.record(i, k, tau, ekf.R, ekf.p, state, base)


def _result(s: _Setup, lp: _Loop, initial_pose: SE3 | Trajectory | None) -> RioResult:
    """The loop's poses re-anchored at the initial pose, as a :class:`RioResult`."""
    out = lp.out
    n = int(np.isfinite(out.t).sum())               # recorded in order: a prefix
    prim = s.tracks[0]
    if n < out.t.size:
        warnings.warn(f"{prim.frame}: {out.t.size - n} radar frames after the IMU's end; "
                      "left out", DataWarning, stacklevel=3)
    out_t, out_R, out_p = out.t[:n], out.R[:n], out.p[:n]
    kept, (out_v, out_cov, out_b, out_td, out_vcov), masks = out.states(n)
    c = min(int(np.searchsorted(out_t, out_t[0] + s.cfg.anchor_delay)), n - 1)
    ci = c if kept is None else int(np.searchsorted(kept, c))
    if isinstance(initial_pose, Trajectory):
        initial_pose = (initial_pose.at(out_t[0]) if initial_pose.covers(out_t[:1])[0]
                        else None)
    if initial_pose is None:
        initial_pose = SE3.identity()
    pose0 = initial_pose

    def anchored(out_p: np.ndarray, out_R: np.ndarray, name: str
                 ) -> tuple[Trajectory, np.ndarray, Rotation]:
        # world_T_base in the filter's frame, then re-anchored at the initial pose.
        rot_imu = Rotation.from_matrix(smoothed_start(s.ekf, s.imu_t, s.cfg.anchor_delay,
                                                      out_t, out_R, out_b[ci, 2]))
        rot_base = rot_imu * s.imu_T_base.rotation
        pos_base = out_p + rot_imu.apply(np.tile(s.imu_T_base.translation, (n, 1)))
        a_rot = pose0.rotation * rot_base[0].inv()
        a_t = pose0.translation - a_rot.apply(pos_base[0])
        return (Trajectory(out_t, a_t + a_rot.apply(pos_base), a_rot * rot_base, name),
                pos_base, a_rot)

    traj, pos_base, a_rot = anchored(out_p, out_R, f"{s.names[0]} radar-inertial "
                                     + ("EKF, smoothed" if lp.filtered is not None else "EKF"))
    filtered = (None if lp.filtered is None else
                anchored(*lp.filtered, f"{s.names[0]} radar-inertial EKF")[0])
    sel = slice(None) if kept is None else kept
    out_cov, out_vcov = anchor_covariance(out_cov[ci], pos_base[0], pos_base[sel],
                                           out_v, out_cov, out_vcov)
    am = a_rot.as_matrix()
    big = np.zeros((6, 6))
    big[:3, :3] = big[3:, 3:] = am
    phi = np.array([Rotation.from_matrix(e.rotation.as_matrix().T @ s.ekf.R_ir[r]).as_rotvec()
                    for r, e in enumerate(s.ext)])
    return RioResult(traj, prim.timestamps[lp.k0:lp.k0 + n].copy(), big @ out_cov @ big.T,
                     a_rot.apply(out_v).reshape(-1, 3), out_b[:, 0], out_b[:, 1], out_b[:, 2],
                     out_b[:, 3], out_td[:, 0], out_td[:, 1], phi, s.names,
                     s.static[0][lp.k0:lp.k0 + n], lp.stats, am @ out_vcov @ am.T,
                     masks if s.pts is not None else None, kept, filtered,
                     tuple(e.noise for e in s.estimators) if s.pts is not None else None)


def rio_odometry(tracks: EgoVelocityTrack | Sequence[EgoVelocityTrack], calib: Calibration,
                 imu_timestamps: np.ndarray, imu_data: np.ndarray, *,
                 radars: Sequence[str] | None = None, config: RioConfig | None = None,
                 initial_pose: SE3 | Trajectory | None = None,
                 still: Sequence[np.ndarray] | None = None,
                 points: Sequence[Sequence[np.ndarray]] | None = None,
                 keep: KeepPose | None = None) -> RioResult:
    """Radar-inertial odometry of a run with the error-state EKF.

    Parameters
    ----------
    tracks
        Ego-velocities of one or more radars (:func:`~coloradar.odometry.run_ego_velocity`);
        the output poses are at the first track's frames.
    calib
        Extrinsics ``base_T_imu`` and ``base_T_<radar>``.
    imu_timestamps, imu_data
        float64 ``(N,)`` [s] and ``(N, 6)`` ``ax ay az [m/s²] gx gy gz [rad/s]``, IMU frame.
    radars
        The radar of each track (default: each track's ``frame``).
    config
        Filter settings (default :class:`RioConfig`).
    initial_pose
        ``world_T_base`` of the first output pose, or a trajectory (the ground truth) that
        gives it at that pose's time (the identity where it does not cover it); default the
        identity. The filter's own world frame is gravity-aligned; the output is its motion
        re-anchored at this pose.
    still
        Per track, bool ``(M_r,)``: whether each frame's cloud shows a still world
        (:func:`~coloradar.odometry.zero_velocity.still_world`); None: judged from the
        ego-velocities only.
    points
        Per track, per frame the radar's point cloud, float ``(N_k, 5)`` ``x y z intensity
        range_rate`` (radar frame): with ``config.update == "doppler"`` (the default) every
        point is a measurement of the filter (:mod:`.doppler`). None: the frames'
        ego-velocities only (loosely coupled).
    keep
        None: the result gives every pose's covariance, velocity, biases and offsets. Else
        called at each pose as the filter runs (:data:`.rio_outputs.KeepPose`): those are
        kept only where it says so (:attr:`RioResult.kept`), and the filter's memory grows
        by about 100 bytes a pose instead of 700 or more.

    Returns
    -------
    RioResult
    """
    cfg = config or RioConfig()
    s = _setup(tracks, calib, (imu_timestamps, imu_data), radars, cfg, still, points)
    k0, t0, P0 = _initialise(s)
    smoother = RtsSmoother(s.ekf) if cfg.smooth else None
    loop = _Loop(s, k0, t0, P0, keep, smoother)
    try:
        loop.run()
    finally:
        if smoother is not None:
            smoother.close()
    return _result(s, loop, initial_pose)


def _floats(a: np.ndarray, digits: int = 9) -> list:
    return np.round(np.asarray(a, dtype=np.float64), digits).tolist()


def rio_summary(result: RioResult, config: RioConfig | None = None) -> dict:
    """The filter's estimates as JSON-ready data (the ``"rio"`` entry of ``odometry.json``).

    Keys: ``config`` (the settings), ``radars``, ``time_offset_s`` and ``time_offset_std_s``
    (final, per radar), ``accel_bias_m_s2``, ``gyro_bias_rad_s`` and their ``*_std`` (final),
    ``extrinsic_rotation_correction_deg`` (per radar, rotation vector in its frame),
    ``static_frames``, ``stats`` (per radar: updates, rejected, zupts, failed) and ``poses``:
    per output pose ``timestamp`` (IMU clock), ``radar_timestamp``, ``covariance_upper``
    (the 21 entries of the upper triangle, row by row, of the 6 × 6 covariance of the base
    position [m²] and attitude [rad²], world frame), ``accel_bias``, ``gyro_bias``,
    ``time_offset`` and ``static``.
    """
    r = result
    iu = np.triu_indices(6)
    out: dict = {
        "radars": list(r.radars),
        "time_offset_s": _floats(r.time_offset[-1]),
        "time_offset_std_s": _floats(r.time_offset_std[-1]),
        "accel_bias_m_s2": _floats(r.accel_bias[-1]),
        "accel_bias_std_m_s2": _floats(r.accel_bias_std[-1]),
        "gyro_bias_rad_s": _floats(r.gyro_bias[-1]),
        "gyro_bias_std_rad_s": _floats(r.gyro_bias_std[-1]),
        "extrinsic_rotation_correction_deg": _floats(np.degrees(r.extrinsic_rotation), 6),
        "static_frames": int(r.static.sum()),
        "stats": r.stats,
        "point_noise": None if r.point_noise is None else [
            {"range_rate_std_m_s": float(n.range_rate_std),
             "azimuth_std_deg": float(np.degrees(n.azimuth_std)),
             "elevation_std_deg": float(np.degrees(n.elevation_std))} for n in r.point_noise],
        "poses": {
            "timestamp": _floats(r.trajectory.timestamps),
            "radar_timestamp": _floats(r.frame_timestamps),
            "covariance_upper": [_floats(c[iu], 12) for c in r.covariance],
            "accel_bias": _floats(r.accel_bias),
            "gyro_bias": _floats(r.gyro_bias, 12),
            "time_offset": _floats(r.time_offset),
            "static": [bool(x) for x in r.static],
        },
    }
    if config is not None:
        out = {"config": asdict(config), **out}
    return out
