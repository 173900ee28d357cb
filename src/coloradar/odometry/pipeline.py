"""Run-level odometry: point clouds of a run -> ego-velocities -> trajectory, written to a folder.

Point clouds come from one of three sources of a run, turned into points by
:class:`coloradar.dsp.FramePoints` (the same converter the viewers use):

- ``pointclouds``: the sensor's own point clouds (single chip as shipped, or ``process`` output);
- ``adc``: raw ADC frames through :class:`coloradar.dsp.RadarProcessor` (either radar);
- ``heatmaps``: heatmaps (shipped or computed) through :func:`coloradar.dsp.heatmap_pointcloud`
  with the calibration's heatmap grid.

The trajectory comes from the radar-inertial EKF (:mod:`.rio`, the default) or from the
dead-reckoning baseline (:mod:`.dead_reckoning`). The output folder holds
``ego_velocity.csv`` (:mod:`.velocity_track`), ``trajectory.txt`` (TUM, ``world_T_base``) and
``odometry.json`` (what was run, on which run, with which settings; for the filter also its
biases, time offsets and per-pose covariance, :func:`~coloradar.odometry.rio.rio_summary`),
which :func:`~coloradar.odometry.evaluation.evaluate_odometry` reads.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..calib import RadarCalib
from ..dsp.points import POINT_SOURCES, default_point_source, radar_point_stream
from ..errors import (
    ColoradarError,
    MissingDataError,
    OutputExistsError,
    SettingsError,
    WriteError,
)
from ..formats.atomic import atomic_write_text, make_output_dir
from ..geometry import Trajectory, trajectory_from_groundtruth, window_indices
from .dead_reckoning import ORIENTATION_SOURCES, estimate_gyro_bias, radar_inertial_odometry
from .doppler import elevation_rows
from .ego_velocity import EgoVelocityConfig, static_inlier_threshold
from .rio import RioConfig, rio_odometry, rio_summary
from .tum import write_tum
from .velocity_track import EgoVelocityTrack, estimate_ego_velocities, write_velocity_table
from .zero_velocity import ZeroVelocityConfig, still_world

__all__ = [
    "ESTIMATORS",
    "INFO_FILE",
    "SOURCES",
    "TRAJECTORY_FILE",
    "VELOCITY_FILE",
    "EgoVelocityJob",
    "OdometryJob",
    "OdometryOutput",
    "default_source",
    "ego_velocity_config",
    "elevation_rows",
    "run_ego_velocity",
    "run_odometry",
    "run_path",
]

SOURCES = POINT_SOURCES
VELOCITY_FILE = "ego_velocity.csv"
TRAJECTORY_FILE = "trajectory.txt"
INFO_FILE = "odometry.json"

ESTIMATORS = ("rio", "dead-reckoning")
"""Estimators of :func:`run_odometry`: the radar-inertial EKF (default) and the baseline."""

Progress = Callable[[int, int], None]


def ego_velocity_config(radar_calib: RadarCalib, **overrides) -> EgoVelocityConfig:
    """Estimator settings suited to a radar.

    The inlier threshold comes from its Doppler resolution (:func:`static_inlier_threshold`),
    aliasing is handled at its ``v_max``, and the model is planar (``v_z = 0``, see
    :attr:`EgoVelocityConfig.planar`) when its virtual array has fewer than 3 elevation rows:
    one frame's few points of a two-row array (the single chip's own clouds: 2–20 points)
    leave ``v_z`` so poorly conditioned that a 3-D RANSAC fit is often far off (0.4–0.6 m/s
    RMSE against 0.02 m/s planar on the simulator's single chip, issue 42). This is the
    per-frame estimate (the ego-velocity table, dead reckoning, the loosely coupled update);
    the filter's Doppler-point update is 3-D for every radar
    (:attr:`~coloradar.odometry.doppler.DopplerConfig.planar`), where the IMU's prediction
    and many frames carry ``v_z``. Keyword arguments override single settings of
    :class:`EgoVelocityConfig`.
    """
    w = radar_calib.waveform
    base = EgoVelocityConfig(threshold=static_inlier_threshold(w.velocity_bin_width),
                             max_velocity=float(w.max_velocity),
                             planar=elevation_rows(radar_calib) < 3)
    return replace(base, **overrides)


def default_source(seq, radar: str) -> str:
    """The source used when none is named: the sensor's own point clouds when the run has them
    (single chip), else ADC, else heatmaps (:func:`coloradar.dsp.default_point_source`)."""
    src = default_point_source(seq, radar)
    if src is None:
        have = seq.available()
        raise MissingDataError(f"{seq.location}: the {radar} radar has no point clouds, ADC "
                               f"frames or heatmaps in this run (present: "
                               f"{', '.join(have) or 'nothing'})")
    return src


def _frames(timestamps: np.ndarray, start: float | None, duration: float | None,
            stride: int, max_frames: int | None) -> np.ndarray:
    if stride < 1:
        raise ColoradarError(f"stride must be >= 1, got {stride}")
    t0 = timestamps[0] if timestamps.size else 0.0
    lo = None if start is None else t0 + start
    hi = None if duration is None else (t0 if lo is None else lo) + duration
    idx = window_indices(timestamps, lo, hi)[::stride]
    return idx if max_frames is None else idx[:max_frames]


@dataclass(frozen=True, eq=False)
class EgoVelocityJob:
    """Options of :func:`run_ego_velocity` (each also a keyword of it).

    Attributes
    ----------
    config
        Estimator settings; default :func:`ego_velocity_config` of the radar.
    processing
        Keyword arguments for :class:`coloradar.dsp.RadarProcessor` (``adc``) or
        :func:`coloradar.dsp.heatmap_pointcloud` (``heatmaps``).
    start, duration
        Window in seconds after the stream's first frame; None = from the start / to the end.
    stride, max_frames
        Use every ``stride``-th frame, at most ``max_frames`` of them.
    seed
        RANSAC seed (:func:`~coloradar.odometry.estimate_ego_velocities`).
    progress
        ``progress(done, total)`` after each frame.
    """

    config: EgoVelocityConfig | None = None
    processing: dict | None = None
    start: float | None = None
    duration: float | None = None
    stride: int = 1
    max_frames: int | None = None
    seed: int = 0
    progress: Progress | None = None

    @classmethod
    def of(cls, job: EgoVelocityJob | None = None, **options: Any) -> EgoVelocityJob:
        """``job`` (default: the defaults) with ``options`` replaced."""
        return _job_of(cls, job, options)


def _job_of(cls: Any, job: Any, options: dict[str, Any]) -> Any:
    names = {f.name for f in fields(cls)}
    bad = sorted(set(options) - names)
    if bad:
        raise SettingsError(f"unknown option(s) {', '.join(bad)}; expected some of "
                            f"{', '.join(sorted(names))}")
    return replace(job or cls(), **options)


def run_ego_velocity(seq, radar: str = "cascade", source: str | None = None, *,
                     job: EgoVelocityJob | None = None, **options: Any) -> EgoVelocityTrack:
    """Ego-velocity of one radar for (a window of) a run.

    Parameters
    ----------
    seq
        A :class:`coloradar.Sequence`.
    radar
        ``"cascade"`` or ``"single_chip"``.
    source
        ``"pointclouds"``, ``"adc"`` or ``"heatmaps"``; None: :func:`default_source`.
    job, **options
        :class:`EgoVelocityJob` (``config``, ``processing``, ``start``, ``duration``,
        ``stride``, ``max_frames``, ``seed``, ``progress``), or its fields as keywords.

    Returns
    -------
    EgoVelocityTrack
    """
    return _ego_velocity(seq, radar, source, EgoVelocityJob.of(job, **options))[0]


def _ego_velocity(seq, radar: str, source: str | None, job: EgoVelocityJob,
                  still_config: ZeroVelocityConfig | None = None
                  ) -> tuple[EgoVelocityTrack, np.ndarray, list[np.ndarray]]:
    """:func:`run_ego_velocity`, per frame whether the radar sees a still world
    (:func:`~coloradar.odometry.zero_velocity.still_world`, computed on the same clouds), and
    the clouds themselves (float32 ``(N_k, 5)``, for the filter's Doppler-point update)."""
    source = source or default_source(seq, radar)
    if source not in SOURCES:
        raise ColoradarError(f"unknown source {source!r}; expected one of {', '.join(SOURCES)}")
    stream, convert = radar_point_stream(seq, radar, source, processing=job.processing)
    idx = _frames(stream.timestamps, job.start, job.duration, job.stride, job.max_frames)
    if idx.size == 0:
        raise ColoradarError(f"{seq.name}: no {radar} {source} frames in the chosen window")
    cfg = job.config or ego_velocity_config(seq.calib.radar(radar))

    skipped: dict[int, str] = {}
    still = np.zeros(idx.size, dtype=bool)
    zv = still_config or ZeroVelocityConfig()
    kept: list[np.ndarray] = []

    def clouds() -> Iterator[np.ndarray]:
        for j, k in enumerate(idx):
            frame = stream.read_or_skip(int(k))  # reported as a DataWarning
            if frame is None:
                # One bad frame gives no estimate for that frame, as `coloradar process`
                # skips it; the track keeps its time so the trajectory bridges the gap.
                skipped[j] = f"unreadable frame: {stream.path(int(k))}"
                kept.append(np.zeros((0, 5), dtype=np.float32))
                yield kept[-1]
            else:
                cloud = convert(frame)
                still[j] = still_world(cloud, zv, cfg.min_range)
                kept.append(np.asarray(cloud, dtype=np.float32))
                yield cloud

    track = estimate_ego_velocities(clouds(), stream.timestamps[idx], cfg, seed=job.seed,
                                    frame=radar, progress=job.progress)
    for j, why in skipped.items():
        track.reasons[j] = why
    return track, still, kept


def run_path(seq) -> str:
    """The folder or zip a sequence was opened from, absolute (to open it again later)."""
    src = seq.source
    p = getattr(src, "root", None) or getattr(src, "archive", None)
    return str(Path(p).resolve()) if p is not None else seq.location


@dataclass(frozen=True, eq=False)
class OdometryOutput:
    """What :func:`run_odometry` computed and wrote.

    Attributes
    ----------
    folder
        The output folder.
    track
        Ego-velocities.
    trajectory
        ``world_T_base`` at the radar frames.
    files
        Paths written.
    """

    folder: Path
    track: EgoVelocityTrack
    trajectory: Trajectory
    files: list[Path]


def _check_output_folder(folder: Path) -> None:
    """Refuse an output folder that is, or lies under, a file before any work is done."""
    for q in (folder, *folder.parents):
        if q.exists():
            if not q.is_dir():
                raise WriteError(f"{q}: expected an output folder, found a file" if q == folder
                                 else f"{folder}: cannot be created, {q} is a file")
            return


@dataclass(frozen=True, eq=False)
class OdometryJob:
    """Options of :func:`run_odometry` (each also a keyword of it).

    Attributes
    ----------
    radar, source, config, processing, start, duration, stride, seed, progress
        See :class:`EgoVelocityJob` (``radar``: ``"cascade"`` or ``"single_chip"``).
    estimator
        ``"rio"`` (default): the error-state EKF of :mod:`.rio` (IMU propagation, radar
        updates, automatic zero-velocity updates, online biases and time offset);
        ``"dead-reckoning"``: the baseline of :mod:`.dead_reckoning` (ego-velocities
        integrated with the gyro or ground-truth attitude).
    orientation
        Dead reckoning only: ``"imu"`` (gyro attitude) or ``"groundtruth"`` (upper bound).
    gyro_bias_window
        Dead reckoning only: seconds at the start of the IMU stream during which the rig is at
        rest; their mean angular rate is subtracted as gyro bias. None: no bias correction.
        (The filter finds rest by itself.)
    overwrite
        Replace existing output files.
    rio_config
        Filter settings (:class:`~coloradar.odometry.rio.RioConfig`).
    fuse
        Further radars whose frames also update the filter (``"rio"`` only), e.g.
        ``("single_chip",)`` beside the cascade, each with its default source and settings;
        ``"auto"`` (default): the other radar when the run has data of it (the filter fuses
        both radars), none for dead reckoning; ``()``: the one radar only. ``processing``
        applies to ``radar`` only; fused radars use their default processing.
    """

    radar: str = "cascade"
    source: str | None = None
    orientation: str = "imu"
    config: EgoVelocityConfig | None = None
    processing: dict | None = None
    start: float | None = None
    duration: float | None = None
    stride: int = 1
    seed: int = 0
    gyro_bias_window: float | None = None
    overwrite: bool = False
    progress: Progress | None = None
    estimator: str = "rio"
    rio_config: RioConfig | None = None
    fuse: Sequence[str] | str = "auto"

    @classmethod
    def of(cls, job: OdometryJob | None = None, **options: Any) -> OdometryJob:
        """``job`` (default: the defaults) with ``options`` replaced."""
        return _job_of(cls, job, options)

    def frames(self, radar: str | None = None) -> EgoVelocityJob:
        """The ego-velocity options of ``radar`` (default: the main radar's; a fused radar
        gets its default source, settings and processing)."""
        main = radar is None or radar == self.radar
        return EgoVelocityJob(self.config if main else None,
                              self.processing if main else None, self.start, self.duration,
                              self.stride, None, self.seed, self.progress if main else None)


def _fused_radars(seq, j: OdometryJob) -> tuple[str, ...]:
    """Check the job's estimator options; the radars fused with ``j.radar``."""
    if j.estimator not in ESTIMATORS:
        raise SettingsError(f"unknown estimator {j.estimator!r}; expected one of "
                            f"{', '.join(ESTIMATORS)}")
    if j.orientation not in ORIENTATION_SOURCES:
        raise ColoradarError(f"unknown orientation source {j.orientation!r}; expected one of "
                             f"{', '.join(ORIENTATION_SOURCES)}")
    fuse = j.fuse
    if isinstance(fuse, str):
        if fuse != "auto":
            raise SettingsError(f"fuse must be 'auto' or a list of radars, got {fuse!r}")
        fuse = tuple(r for r in ("cascade", "single_chip") if r != j.radar
                     and default_point_source(seq, r) is not None) if j.estimator == "rio" \
            else ()
    fuse = tuple(fuse)
    if j.estimator == "rio":
        if j.orientation != "imu":
            raise SettingsError("orientation='groundtruth' is a setting of the dead-reckoning "
                                "baseline (--estimator dead-reckoning); the filter estimates "
                                "its attitude from the IMU")
        if j.gyro_bias_window:
            raise SettingsError("gyro_bias_window (--gyro-bias-window) is a setting of the "
                                "dead-reckoning baseline; the filter finds rest by itself")
        bad = [r for r in fuse if r == j.radar or r not in ("cascade", "single_chip")]
        if bad:
            raise SettingsError(f"fuse: {', '.join(bad)} is not a radar other than {j.radar}")
    elif fuse:
        raise SettingsError("fuse (--fuse) needs the filter (estimator 'rio')")
    return fuse


def _targets(out: str | os.PathLike[str], fuse: tuple[str, ...], overwrite: bool) -> list[Path]:
    """The output files, refused when they exist (unless ``overwrite``)."""
    folder = Path(out)
    _check_output_folder(folder)
    names = [VELOCITY_FILE, TRAJECTORY_FILE, INFO_FILE] + [f"ego_velocity_{r}.csv" for r in fuse]
    targets = [folder / n for n in names]
    existing = [p.name for p in targets if p.exists()]
    if existing and not overwrite:
        raise OutputExistsError(f"{folder}: holds {', '.join(existing)} already; pass "
                                "overwrite=True (--overwrite) to replace them")
    return targets


def _reference_inputs(seq, j: OdometryJob) -> tuple[Trajectory | None, tuple | None]:
    """The run's ground truth (or None) and, for a gyro attitude, ``(imu_t, rates, bias)``."""
    gt = trajectory_from_groundtruth(seq) if "groundtruth" in seq.available() else None
    if j.orientation == "groundtruth" and gt is None:
        raise MissingDataError(f"{seq.location}: orientation from ground truth asked for, but "
                               "the run has no ground truth")
    if j.orientation != "imu":
        return gt, None
    if "imu" not in seq.available():
        hint = ("the filter needs it; --estimator dead-reckoning --orientation groundtruth "
                "works without" if j.estimator == "rio" else
                "use orientation 'groundtruth' (--orientation groundtruth)")
        raise MissingDataError(f"{seq.location}: the run has no IMU; {hint}")
    imu_t, imu_w = seq.imu.timestamps, seq.imu.angular_rates
    bias = estimate_gyro_bias(imu_t, imu_w, imu_t[0], imu_t[0] + j.gyro_bias_window) \
        if j.gyro_bias_window else None
    return gt, (imu_t, imu_w, bias)


def _filter_run(seq, j: OdometryJob, main: tuple, fuse: tuple[str, ...],
                gt: Trajectory | None) -> tuple[Trajectory, list[EgoVelocityTrack], dict]:
    """The filter on the main radar's ``(track, still, clouds)`` and the fused radars':
    the trajectory, the fused radars' tracks and the ``rio`` entry of ``odometry.json``."""
    rcfg = j.rio_config or RioConfig()
    tracks, stills, clouds = [main[0]], [main[1]], [main[2]]
    for r in fuse:
        tr_r, st_r, cl_r = _ego_velocity(seq, r, None, j.frames(r), rcfg.zero_velocity)
        tracks.append(tr_r)
        stills.append(st_r)
        clouds.append(cl_r)
    res = rio_odometry(tracks, seq.calib, seq.imu.timestamps, seq.imu.data,
                       radars=(j.radar, *fuse), config=rcfg, initial_pose=gt, still=stills,
                       points=clouds)
    return res.trajectory, tracks[1:], rio_summary(res, rcfg)


def run_odometry(seq, out: str | os.PathLike[str], *, job: OdometryJob | None = None,
                 **options: Any) -> OdometryOutput:
    """Ego-velocity and radar-inertial odometry for a run, written to ``out``.

    Parameters
    ----------
    seq
        The run.
    out
        Output folder (created); gets ``ego_velocity.csv``, ``trajectory.txt`` (TUM),
        ``odometry.json`` (and ``ego_velocity_<radar>.csv`` for each fused radar).
    job, **options
        :class:`OdometryJob`, or its fields as keywords (``radar``, ``source``,
        ``estimator``, ``orientation``, ``rio_config``, ``fuse``, ``overwrite``…).

    Returns
    -------
    OdometryOutput
        The initial pose is the ground truth's at the first frame when the run has ground
        truth (so that the trajectories are comparable without alignment), else the identity.
    """
    j = OdometryJob.of(job, **options)
    fuse = _fused_radars(seq, j)
    targets = _targets(out, fuse, j.overwrite)
    gt, gyro = _reference_inputs(seq, j)
    source = j.source or default_source(seq, j.radar)
    cfg = j.config or ego_velocity_config(seq.calib.radar(j.radar))
    rcfg = j.rio_config or RioConfig()
    main = _ego_velocity(seq, j.radar, source, replace(j.frames(), config=cfg),
                         rcfg.zero_velocity)
    track = main[0]
    info: dict = {
        "run": run_path(seq), "run_name": seq.name,
        "calib": str(getattr(seq.calib, "source", "preset")),
        "radar": j.radar, "source": source, "estimator": j.estimator,
        "orientation": j.orientation, "frames": len(track), "frames_ok": int(track.ok.sum()),
        "start": j.start, "duration": j.duration, "stride": j.stride, "seed": j.seed,
        "gyro_bias": None if gyro is None or gyro[2] is None else [float(b) for b in gyro[2]],
        "initial_pose": "groundtruth" if gt is not None else "identity",
        "config": asdict(cfg), "processing": j.processing or {},
        "coloradar_version": __version__,
    }
    extra: list[EgoVelocityTrack] = []
    if j.estimator == "rio":
        traj, extra, info["rio"] = _filter_run(seq, j, main, fuse, gt)
        info["fuse"] = list(fuse)
        what = ("radar-inertial EKF (IMU propagation, Doppler-point updates)"
                if rcfg.update == "doppler" else
                "radar-inertial EKF (IMU propagation, radar velocity updates)")
    else:
        imu_t, imu_w, bias = gyro if gyro is not None else (None, None, None)
        traj = radar_inertial_odometry(track, seq.calib,
                                       orientation=j.orientation,  # type: ignore[arg-type]
                                       imu_timestamps=imu_t, imu_rates=imu_w, groundtruth=gt,
                                       gyro_bias=bias, radar=j.radar)
        what = f"radar ego-velocity + {j.orientation} attitude (dead reckoning)"
    comments = [f"run {seq.name}, {j.radar} radar, source {source}"]
    make_output_dir(targets[0].parent)
    write_velocity_table(targets[0], track, comments=comments, overwrite=j.overwrite)
    for r, tr_r, path in zip(fuse, extra, targets[3:], strict=True):
        write_velocity_table(path, tr_r, comments=[f"run {seq.name}, {r} radar (fused)"],
                             overwrite=j.overwrite)
    write_tum(targets[1], traj, overwrite=j.overwrite, comments=[
        *comments, f"world_T_base from {what}"])
    atomic_write_text(targets[2], json.dumps(info, indent=2) + "\n")
    return OdometryOutput(targets[0].parent, track, traj, targets)
