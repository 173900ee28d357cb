"""An occupancy map of a run: its frames placed by a trajectory, one frame at a time.

:func:`build_occupancy_map` reads a sensor's frames (point clouds, the ADC frames' points, or
heatmaps) in time order, places each with ``world_T_base(t) · base_T_sensor`` from any
trajectory (the ground truth, an estimate, SLAM's), and adds its evidence
(:mod:`.sensor_model`, :mod:`.heatmap_model`) to an :class:`~.voxels.OccupancyMap`. Frames are
read and dropped one at a time: memory is the map's.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from ..errors import MissingDataError, SettingsError
from ..geometry import Trajectory, rig_velocity, sensor_to_base
from ..geometry.timesync import window_indices
from .heatmap_model import HeatmapModel, heatmap_evidence
from .sensor_model import PointSensorModel, lidar_sensor_model, point_evidence, radar_sensor_model
from .static_gate import StaticGate, StaticTest
from .voxels import OccupancyMap, OccupancySettings

__all__ = ["MAP_INPUTS", "OccupancyJob", "OccupancyResult", "build_occupancy_map",
           "frame_evidence", "occupancy_from_frames"]

MapInput = Literal["points", "heatmaps"]
MAP_INPUTS: tuple[str, ...] = ("points", "heatmaps")
"""What a map is built from: point clouds (the sensor's own, ``coloradar process``'s, or the
ADC frames' points) or heatmaps (a radar's)."""

_DEG = np.pi / 180.0

Evidence = Callable[..., tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class OccupancyJob:
    """What :func:`build_occupancy_map` maps, and with which sensor model.

    Attributes
    ----------
    sensor
        ``"single_chip"``, ``"cascade"`` or ``"lidar"`` (points only).
    source
        ``"points"`` or ``"heatmaps"`` (a radar's).
    start, duration
        Window in seconds from the trajectory's start (None duration: to its end).
    stride
        Every ``stride``-th frame.
    min_azimuth_std_deg, min_elevation_std_deg
        Floors of a radar return's angle errors [deg] (:class:`~.sensor_model.PointSensorModel`;
        None: the radar's own, :func:`~.sensor_model.angle_std_floor`: 1° and 2° for the
        single chip, 0.53° and 2° for the cascade).
    max_range
        Returns beyond are left out [m] (None: the radar's unambiguous range; a lidar 15 m).
    processing
        Keyword arguments of :class:`coloradar.dsp.RadarProcessor` for points from ADC.
    heatmap
        Keyword arguments of :class:`~.heatmap_model.HeatmapModel` beyond its grid.
    static_gate
        A radar's points, or heatmap returns, whose range rates a static world does not
        explain (movers, ghosts) are left out (:mod:`.static_gate`, the sensor's velocity
        from the trajectory); None: all are mapped. The lidar is not tested.
    """

    sensor: str = "single_chip"
    source: MapInput = "points"
    start: float = 0.0
    duration: float | None = None
    stride: int = 1
    min_azimuth_std_deg: float | None = None
    min_elevation_std_deg: float | None = None
    max_range: float | None = None
    processing: Mapping[str, Any] | None = None
    heatmap: Mapping[str, Any] | None = None
    static_gate: StaticGate | None = field(default_factory=StaticGate)

    def __post_init__(self) -> None:
        if self.sensor not in ("single_chip", "cascade", "lidar"):
            raise SettingsError(f"sensor must be 'single_chip', 'cascade' or 'lidar', got "
                                f"{self.sensor!r}")
        if self.source not in MAP_INPUTS:
            raise SettingsError(f"source must be one of {', '.join(MAP_INPUTS)}, got "
                                f"{self.source!r}")
        if self.sensor == "lidar" and self.source != "points":
            raise SettingsError("the lidar has point clouds only (source 'points')")
        if self.stride < 1:
            raise SettingsError(f"stride must be >= 1, got {self.stride}")


@dataclass(frozen=True, eq=False)
class OccupancyResult:
    """A run's occupancy map and what made it.

    Attributes
    ----------
    map
        The :class:`~.voxels.OccupancyMap` (world frame: the trajectory's).
    job
        The :class:`OccupancyJob`.
    frame_indices, timestamps
        int64 and float64 ``(F,)``: the frames used (stream indices, stamps [s]).
    points_from
        The stream read: ``"pointclouds"``, ``"adc"`` or ``"heatmaps"``.
    static_test
        The static test's counts (:meth:`~.static_gate.StaticTest.summary`) and its warning
        (``"warning"``, or None), or None when no test ran.
    """

    map: OccupancyMap
    job: OccupancyJob
    frame_indices: np.ndarray
    timestamps: np.ndarray
    points_from: str
    static_test: dict[str, Any] | None = None


def occupancy_from_frames(frames: Iterable[np.ndarray | None], rotations: np.ndarray,
                          translations: np.ndarray, evidence: Evidence,
                          settings: OccupancySettings | None = None,
                          progress: Callable[[int, int], None] | None = None,
                          velocities: np.ndarray | None = None) -> OccupancyMap:
    """Integrate frames into a new map.

    Parameters
    ----------
    frames
        One frame per pose (a cloud or a heatmap, sensor frame; None: a frame left out).
    rotations, translations
        float ``(F, 3, 3)`` and ``(F, 3)``: ``world_T_sensor`` of each frame.
    evidence
        ``evidence(frame, R, t) -> (keys, delta)`` (:func:`frame_evidence`), or
        ``evidence(frame, R, t, v)`` when ``velocities`` are given.
    settings
        The map's settings.
    progress
        Called as ``progress(done, total)`` after each frame.
    velocities
        float ``(F, 3)``: the sensor's velocity at each frame [m/s], sensor frame (for a
        heatmap model's static test, :class:`~.heatmap_model.HeatmapModel`; a point model's
        frames are tested before, :class:`~.static_gate.StaticTest`).
    """
    m = OccupancyMap(settings)
    n = len(translations)
    for k, frame in enumerate(frames):
        if k >= n:
            raise SettingsError(f"more frames than poses ({n})")
        if frame is not None:
            m.integrate(*(evidence(frame, rotations[k], translations[k]) if velocities is None
                          else evidence(frame, rotations[k], translations[k], velocities[k])))
        if progress is not None:
            progress(k + 1, n)
    return m


def frame_evidence(model: PointSensorModel | HeatmapModel,
                   settings: OccupancySettings) -> Evidence:
    """The ``evidence`` function of :func:`occupancy_from_frames` for a sensor model."""
    if isinstance(model, HeatmapModel):
        return lambda f, r, t, v=None: heatmap_evidence(f, r, t, model, settings, v)
    # Points are tested before they reach the evidence (a velocity is not needed here).
    return lambda f, r, t, v=None: point_evidence(f, r, t, model, settings)


def _stream(seq, job: OccupancyJob) -> tuple[Any, Callable[[Any], np.ndarray] | None, str,
                                            PointSensorModel | HeatmapModel]:
    """The frames to read, their converter, what they are, and the sensor model."""
    if job.sensor == "lidar":
        if "lidar/pointclouds" not in seq.available():
            raise MissingDataError(f"{seq.location}: no lidar point clouds in this run")
        return (seq.stream("lidar/pointclouds"), None, "pointclouds",
                lidar_sensor_model(job.max_range or 15.0))
    rc = seq.calib.radar(job.sensor)
    if job.source == "heatmaps":
        if f"{job.sensor}/heatmaps" not in seq.available():
            raise MissingDataError(f"{seq.location}: no {job.sensor} heatmaps in this run "
                                   f"(present: {', '.join(seq.available()) or 'nothing'}); "
                                   "'coloradar process RUN --out OUT' computes them from ADC "
                                   "frames, then open the run with products=OUT (--products OUT)")
        radar = seq.radar(job.sensor)
        points = radar_sensor_model(rc, **_floors(job))
        model = HeatmapModel(radar.heatmap_config, points, max_range=job.max_range,
                             **{"static_test": _static_test(seq, job),
                                **dict(job.heatmap or {})})
        return radar.heatmaps, None, "heatmaps", model
    from ..dsp.points import radar_point_stream

    have = seq.available()
    src = "pointclouds" if f"{job.sensor}/pointclouds" in have else "adc"
    if f"{job.sensor}/{src}" not in have:
        raise MissingDataError(f"{seq.location}: the {job.sensor} radar has no point clouds "
                               f"or ADC frames in this run (present: "
                               f"{', '.join(have) or 'nothing'})")
    stream, convert = radar_point_stream(seq, job.sensor, src,  # type: ignore[arg-type]
                                         processing=job.processing)
    pm = radar_sensor_model(rc, max_range=job.max_range, **_floors(job))
    return stream, convert, src, pm


def _floors(job: OccupancyJob) -> dict[str, float | None]:
    """The job's angle floors in radians, None where the radar's own apply."""
    return {"min_azimuth_std": None if job.min_azimuth_std_deg is None
            else job.min_azimuth_std_deg * _DEG,
            "min_elevation_std": None if job.min_elevation_std_deg is None
            else job.min_elevation_std_deg * _DEG}


def _static_test(seq, job: OccupancyJob) -> StaticTest | None:
    """The static test of a radar's frames (None: none asked for, or the lidar)."""
    if job.static_gate is None or job.sensor == "lidar":
        return None
    return StaticTest.for_radar(seq.calib.radar(job.sensor), job.static_gate)


def build_occupancy_map(seq, trajectory: Trajectory, job: OccupancyJob | None = None,
                        settings: OccupancySettings | None = None, *,
                        progress: Callable[[int, int], None] | None = None) -> OccupancyResult:
    """The occupancy map of a run's frames placed by ``trajectory`` (module docstring).

    Parameters
    ----------
    seq
        The run (:func:`coloradar.open_sequence`; open it with ``products=OUT`` to map the
        point clouds or heatmaps ``coloradar process`` wrote).
    trajectory
        ``world_T_base(t)``: the ground truth (:func:`coloradar.geometry.trajectory_from_groundtruth`),
        a TUM file's (:func:`coloradar.odometry.read_tum`) or SLAM's. Frames outside its span are
        left out.
    job
        :class:`OccupancyJob` (default: the single chip's points).
    settings
        :class:`~.voxels.OccupancySettings`.
    progress
        Called as ``progress(done, total)`` after each frame.

    Returns
    -------
    OccupancyResult
    """
    job = job or OccupancyJob()
    stream, convert, src, model = _stream(seq, job)
    settings = settings or OccupancySettings()
    ts = np.asarray(stream.timestamps, dtype=np.float64)
    t0 = trajectory.start + job.start
    idx = window_indices(ts, t0, None if job.duration is None else t0 + job.duration)
    idx = idx[trajectory.covers(ts[idx])][::job.stride]
    if idx.size == 0:
        raise MissingDataError(f"{seq.location}: no {job.sensor} frame lies within the "
                               f"trajectory's span ({trajectory.start:.3f} to "
                               f"{trajectory.end:.3f} s) and the window; are the poses this "
                               "run's?")
    trans, rot = trajectory.interpolate_arrays(ts[idx])
    mount = sensor_to_base(seq.calib, job.sensor).matrix()
    r_ws = rot.as_matrix() @ mount[:3, :3]
    t_ws = trans + rot.apply(mount[:3, 3])
    used = np.ones(idx.size, bool)
    # A heatmap model tests its returns itself (given the velocities); points are tested here.
    heat = isinstance(model, HeatmapModel)
    test = model.static_test if isinstance(model, HeatmapModel) else _static_test(seq, job)
    vel = None
    if test is not None and len(trajectory) >= 2:
        vel = rig_velocity(trajectory, ts[idx], calib=seq.calib, sensor=job.sensor).linear
    point_test = None if heat or vel is None else test

    def frames() -> Iterable[np.ndarray | None]:
        for k, i in enumerate(idx):
            f = stream.read_or_skip(int(i))    # a bad frame is reported and left out
            used[k] = f is not None
            f = f if f is None or convert is None else convert(f)
            if f is not None and point_test is not None and vel is not None:
                f = f[point_test(f, vel[k])]
            yield f

    m = occupancy_from_frames(frames(), r_ws, t_ws, frame_evidence(model, settings), settings,
                              progress, vel if heat else None)
    summary = None if test is None or vel is None else \
        {**test.summary(), "warning": test.warning()}
    return OccupancyResult(m, job, idx[used], ts[idx[used]], src, summary)
