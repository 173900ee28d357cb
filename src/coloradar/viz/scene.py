"""Every sensor of a run in one frame at one time: lidar, both radars' points, the trajectory.

:func:`gather_scene` collects the data (no plotting), :func:`draw_scene` draws it into an axes
(bird's-eye or 3-D) and :func:`plot_scene` makes a figure. A sensor frame stamped ``t'`` is put
into the chosen frame at time ``t`` through the ground truth,
``frame_T_world(t) @ world_T_base(t') @ base_T_sensor``, so sensors sampled at different
instants line up while the rig moves; without ground truth covering both times the static
extrinsic is used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from matplotlib.axes import Axes
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from ..calib import RADARS, Calibration
from ..dsp.points import POINT_SOURCES, FramePoints, PointSource, default_point_source
from ..errors import MissingDataError, SettingsError
from ..geometry import SE3, Trajectory, sensor_to_base, trajectory_from_groundtruth
from ._figure import new_figure

if TYPE_CHECKING:
    from mpl_toolkits.mplot3d import Axes3D

__all__ = ["RADAR_STREAMS", "Scene", "draw_scene", "gather_scene", "plot_scene", "radar_points",
           "radar_source", "scene_time"]

RADAR_STREAMS = {r: tuple(f"{r}/{s}" for s in POINT_SOURCES) for r in RADARS}
"""Where a radar's points come from, in order of preference (:data:`coloradar.dsp.POINT_SOURCES`):
the run's point clouds, CFAR detections of its ADC frames, CFAR peaks of its heatmaps, each
turned into points by :class:`coloradar.dsp.FramePoints`."""

REFERENCE_STREAMS = ("cascade/heatmaps", "cascade/adc", "single_chip/pointclouds",
                     "single_chip/heatmaps", "single_chip/adc", "lidar/pointclouds")
"""Default stream whose frame index ``--frame`` counts."""

_MARKERS = {"cascade": "o", "single_chip": "^"}


@dataclass
class Scene:
    """What one picture of a run shows, in one frame.

    Attributes
    ----------
    frame
        ``"base"``, ``"world"`` or a sensor name.
    time
        The picture's time [s].
    lidar
        float32 ``(N, 3)`` or None.
    radars
        Radar name -> float32 ``(M, 4)``: x y z [m], range rate [m/s].
    trajectory
        float64 ``(K, 3)``: ground-truth positions of the base origin in ``frame`` (None
        without ground truth).
    rig
        float64 ``(2, 3)``: the base origin and a point 1 m ahead of it (base +y) in ``frame``.
    sources
        Stream name -> (frame index, timestamp) of the frame each sensor contributed.
    """

    frame: str
    time: float
    lidar: np.ndarray | None = None
    radars: dict[str, np.ndarray] = field(default_factory=dict)
    trajectory: np.ndarray | None = None
    rig: np.ndarray | None = None
    sources: dict[str, tuple[int, float]] = field(default_factory=dict)


def radar_source(seq, radar: str, cache: dict | None = None) -> str | None:
    """The stream a radar's points are taken from (see :data:`RADAR_STREAMS`), or None."""
    radars = getattr(getattr(seq, "layout", None), "radars", RADARS)
    src = default_point_source(seq, radar) if radar in radars else None
    return None if src is None else f"{radar}/{src}"


def radar_points(seq, radar: str, name: str, data: np.ndarray, *, max_points: int = 400,
                 cache: dict | None = None) -> np.ndarray:
    """float32 ``(N, 5)`` points (radar frame) of one frame ``data`` read from stream ``name``
    (:class:`coloradar.dsp.FramePoints`; at most ``max_points``, the strongest)."""
    cache = {} if cache is None else cache
    key = ("points", name, max_points)
    if key not in cache:
        source = cast(PointSource, name.split("/", 1)[1])
        grid = None
        if source == "heatmaps" and hasattr(seq, "radar"):
            grid = seq.radar(radar).heatmap_config      # the grid the heatmaps were made on
        cache[key] = FramePoints(seq.calib.radar(radar), source, heatmap_config=grid,
                                 max_points=max_points)
    return cache[key](data)


def _has(seq, stream: str) -> bool:
    try:
        return stream in seq.available()
    except AttributeError:  # pragma: no cover - duck-typed sequences
        return True


def _stream(seq, name: str):
    return seq.stream(name)


def scene_time(seq, index: int, stream: str | None = None) -> tuple[float, str]:
    """Timestamp of frame ``index`` of ``stream`` (default: the first present of
    :data:`REFERENCE_STREAMS`); returns ``(time, stream)``."""
    if stream is None:
        stream = next((s for s in REFERENCE_STREAMS if _has(seq, s)), None)
        if stream is None:
            raise MissingDataError(f"{seq.name}: no radar or lidar frames to show")
    ts = _stream(seq, stream).timestamps
    if not -len(ts) <= index < len(ts):
        raise MissingDataError(f"{seq.name}: frame {index} out of range ({stream} has "
                               f"{len(ts)} frames)")
    return float(ts[index]), stream


def _latest(ts: np.ndarray, t: float, max_age: float) -> int | None:
    """Index of the newest frame at or before ``t`` (or the first one within ``max_age``
    after it when none precedes), None when nothing is within ``max_age``."""
    i = int(np.searchsorted(ts, t, side="right")) - 1
    if i >= 0 and t - ts[i] <= max_age:
        return i
    if i + 1 < len(ts) and ts[i + 1] - t <= max_age:
        return i + 1
    return None


class _Framer:
    """``frame_T_sensor`` for data stamped ``t'`` shown at time ``t``."""

    def __init__(self, calib: Calibration, frame: str, traj: Trajectory | None, t: float):
        self.calib, self.frame, self.traj, self.t = calib, frame, traj, t
        self.frame_T_base = (SE3.identity() if frame in ("base", "world")
                             else sensor_to_base(calib, frame).inverse())
        self.frame_T_world: SE3 | None = None
        if traj is not None and traj.covers(np.array([t]))[0]:
            w_T_b = traj.at(t)
            self.frame_T_world = (SE3.identity() if frame == "world"
                                  else self.frame_T_base @ w_T_b.inverse())
        elif frame == "world":
            raise MissingDataError(f"no ground truth at t={t:.3f} s to place data in the world")

    def pose(self, sensor: str, t_data: float) -> SE3:
        b_T_s = sensor_to_base(self.calib, sensor)
        if self.frame_T_world is None or self.traj is None:
            return self.frame_T_base @ b_T_s
        if self.traj.covers(np.array([t_data]))[0]:
            return self.frame_T_world @ self.traj.at(t_data) @ b_T_s
        if self.frame == "world":
            return self.frame_T_world @ self.traj.at(self.t) @ b_T_s
        return self.frame_T_base @ b_T_s


def gather_scene(seq, time: float, *, frame: str = "base",
                 sensors: tuple[str, ...] = ("lidar", "cascade", "single_chip"),
                 max_age: float = 0.5, trajectory_window: float = 20.0,
                 max_lidar_points: int = 30000, max_radar_points: int = 400,
                 trajectory: Trajectory | None = None, cache: dict | None = None) -> Scene:
    """Collect the sensors' latest frames at ``time`` in ``frame``.

    Parameters
    ----------
    seq
        A sequence.
    time
        [s], Unix time.
    frame
        ``"base"``, ``"world"`` or a sensor name (a sensor-centric view).
    sensors
        Which of ``lidar``, ``cascade``, ``single_chip`` to include (missing ones are skipped).
    max_age
        A sensor frame older (or newer) than this [s] is not shown.
    trajectory_window
        Show the ground truth within ``±`` this many seconds [s].
    max_lidar_points
        Evenly thin lidar scans to at most this many points.
    max_radar_points
        Points kept per radar frame, the strongest (:class:`coloradar.dsp.FramePoints`).
    trajectory
        ``world_T_base(t)``; default the run's ground truth when present.
    cache
        A dict reused across calls (animation) to avoid re-reading frames.
    """
    if trajectory is None and _has(seq, "groundtruth"):
        trajectory = trajectory_from_groundtruth(seq)
    framer = _Framer(seq.calib, frame, trajectory, time)
    scene = Scene(frame, time)
    cache = {} if cache is None else cache

    def cached(tag: str, i: int, make):
        key = (tag, i)
        if key not in cache:
            for k in [k for k in cache if k[0] == tag]:
                del cache[k]  # keep one frame per stream: animations move forward
            cache[key] = make()
        return cache[key]

    def read(name: str, i: int) -> np.ndarray | None:
        # A bad frame is reported once (DataWarning) and its sensor left out of the picture,
        # so that an animation goes on, as `coloradar process` skips a bad frame.
        return cached(name, i, lambda: _stream(seq, name).read_or_skip(i))

    if "lidar" in sensors and _has(seq, "lidar/pointclouds"):
        ts = _stream(seq, "lidar/pointclouds").timestamps
        i = _latest(ts, time, max_age)
        cloud = None if i is None else read("lidar/pointclouds", i)
        if i is not None and cloud is not None:
            step = max(1, int(np.ceil(len(cloud) / max_lidar_points)))
            pts = cloud[::step, :3]
            pts = pts[np.all(np.isfinite(pts), axis=1) & (np.abs(pts).sum(axis=1) > 0)]
            scene.lidar = framer.pose("lidar", float(ts[i])).apply(pts)
            scene.sources["lidar/pointclouds"] = (i, float(ts[i]))
    for radar in ("cascade", "single_chip"):
        if radar not in sensors:
            continue
        name = radar_source(seq, radar, cache)
        if name is None:
            continue
        ts = _stream(seq, name).timestamps
        i = _latest(ts, time, max_age)
        frame_data = None if i is None else read(name, i)
        if i is None or frame_data is None:
            continue
        data = cached(f"{name}:points", i, lambda name=name, i=i, radar=radar, d=frame_data:
                      radar_points(seq, radar, name, d, max_points=max_radar_points,
                                   cache=cache))
        pose = framer.pose(radar, float(ts[i]))
        scene.radars[radar] = np.column_stack([pose.apply(data[:, :3].astype(np.float32)),
                                               data[:, 4]]).astype(np.float32)
        scene.sources[name] = (i, float(ts[i]))
    if trajectory is not None and framer.frame_T_world is not None:
        keep = np.abs(trajectory.timestamps - time) <= trajectory_window
        scene.trajectory = framer.frame_T_world.apply(trajectory.translations[keep])
        rig = framer.frame_T_world @ trajectory.at(time)
    else:
        rig = framer.frame_T_base
    scene.rig = rig.apply(np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
    return scene


def _bev_axes(calib: Calibration, frame: str) -> tuple[tuple[int, float, str], tuple[int, float,
                                                                                    str]]:
    """Which coordinate (index, sign, label) goes across and which up in a bird's-eye view.

    Base and world: x across, y up. A sensor frame: the sensor axes closest to the rig's right
    (base +x) and forward (base +y), e.g. −y and x for the radars.
    """
    if frame in ("base", "world"):
        return (0, 1.0, f"x [m] ({frame})"), (1, 1.0, f"y [m] ({frame})")
    m = sensor_to_base(calib, frame).rotation.as_matrix()   # columns: sensor axes in base
    i = int(np.argmax(np.abs(m[0])))
    rest = [k for k in range(3) if k != i]
    j = rest[int(np.argmax(np.abs(m[1, rest])))]
    si, sj = float(np.sign(m[0, i])), float(np.sign(m[1, j]))
    name = "xyz"

    def lab(k: int, s: float, what: str) -> str:
        return f"{'−' if s < 0 else ''}{name[k]} [m] ({frame}, rig {what})"

    return (i, si, lab(i, si, "right")), (j, sj, lab(j, sj, "forward"))


def _clip_3d(scene: Scene, centre: np.ndarray, extent: float) -> Scene:
    """A copy of ``scene`` without points outside the 3-D view box (mplot3d draws them)."""
    half = np.array([extent, extent, extent / 4])

    def inside(p: np.ndarray) -> np.ndarray:
        return p[np.all(np.abs(p[:, :3] - centre) <= half, axis=1)]

    def maybe(p: np.ndarray | None) -> np.ndarray | None:
        return None if p is None else inside(p)

    return Scene(scene.frame, scene.time, maybe(scene.lidar),
                 {k: inside(v) for k, v in scene.radars.items()}, maybe(scene.trajectory),
                 scene.rig, scene.sources)


def _rate_norm(seq, scene: Scene, limit: float | None) -> Normalize:
    if limit is None:
        limit = max((seq.calib.radar(r).waveform.max_velocity for r in scene.radars), default=1.0)
    return Normalize(-limit, limit)


def draw_scene(ax: Axes, scene: Scene, calib: Calibration, *, view: str = "bev",
               extent: float | None = 20.0, norm: Normalize | None = None) -> ScalarMappable:
    """Draw ``scene`` into ``ax`` (a 3-D axes for ``view="3d"``).

    Returns the range-rate colour mapping, for a colorbar. ``extent`` [m] is the half-width of
    the view around the rig (None: fit the data).
    """
    norm = norm or Normalize(-1.0, 1.0)
    mappable = ScalarMappable(norm=norm, cmap="coolwarm")
    if view == "bev":
        (i, si, li), (j, sj, lj) = _bev_axes(calib, scene.frame)

        def uv(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return si * p[:, i], sj * p[:, j]
    elif view == "3d":
        li, lj = "x [m]", "y [m]"
        if extent is not None and scene.rig is not None:
            scene = _clip_3d(scene, scene.rig[0], extent)
    else:
        raise SettingsError(f"view must be 'bev' or '3d', got {view!r}")
    if scene.lidar is not None and len(scene.lidar):
        if view == "bev":
            u, v = uv(scene.lidar)
            ax.scatter(u, v, s=0.4, c="0.55", linewidths=0, label="lidar",
                       rasterized=True)
        else:
            x, y, z = scene.lidar[:, :3].T
            cast("Axes3D", ax).scatter(x, y, z, s=0.3, c="0.55", linewidths=0, label="lidar")
    for radar, pts in scene.radars.items():
        if not len(pts):
            continue
        kw: dict[str, Any] = dict(c=pts[:, 3], cmap="coolwarm", norm=norm, s=14,
                                  marker=_MARKERS.get(radar, "o"), edgecolors="k",
                                  linewidths=0.3, label=f"{radar} radar")
        if view == "bev":
            u, v = uv(pts)
            ax.scatter(u, v, **kw)
        else:
            ax.scatter(*pts[:, :3].T, **kw)
    if scene.trajectory is not None and len(scene.trajectory):
        if view == "bev":
            ax.plot(*uv(scene.trajectory), "-", color="tab:green", lw=1.2, label="ground truth")
        else:
            ax.plot(*scene.trajectory.T, "-", color="tab:green", lw=1.2, label="ground truth")
    if scene.rig is not None:
        o, f = scene.rig
        if view == "bev":
            (ou, ov), (fu, fv) = (si * o[i], sj * o[j]), (si * f[i], sj * f[j])
            ax.annotate("", xy=(fu, fv), xytext=(ou, ov),
                        arrowprops=dict(arrowstyle="-|>", color="tab:green", lw=2))
            ax.plot([ou], [ov], "s", color="tab:green", ms=6, label="rig")
        else:
            ax.plot([o[0]], [o[1]], [o[2]], "s", color="tab:green", ms=6, label="rig")
    if view == "bev":
        ax.set_aspect("equal")
        if extent is not None and scene.rig is not None:
            cu, cv = si * scene.rig[0, i], sj * scene.rig[0, j]
            ax.set_xlim(cu - extent, cu + extent)
            ax.set_ylim(cv - extent, cv + extent)
        ax.grid(True, lw=0.3, alpha=0.5)
    else:
        ax3d = cast("Axes3D", ax)  # view="3d" draws into a 3-D axes (see the docstring)
        ax3d.set_zlabel("z [m]")
        if extent is not None and scene.rig is not None:
            c = scene.rig[0]
            ax3d.set_xlim(c[0] - extent, c[0] + extent)
            ax3d.set_ylim(c[1] - extent, c[1] + extent)
            ax3d.set_zlim(c[2] - extent / 4, c[2] + extent / 4)
            ax3d.set_box_aspect((4, 4, 1))
    ax.set_xlabel(li)
    ax.set_ylabel(lj)
    ax.legend(loc="upper right", fontsize="small", markerscale=2)
    return mappable


def plot_scene(seq, time: float | None = None, *, index: int = 0, stream: str | None = None,
               frame: str = "base", view: str = "bev", extent: float | None = 20.0,
               rate_limit: float | None = None, size: tuple[float, float] = (8.0, 7.5),
               **gather) -> Figure:
    """One picture of every sensor of a run at one time.

    Parameters
    ----------
    seq
        A sequence.
    time
        [s]; default the timestamp of frame ``index`` of ``stream`` (:func:`scene_time`).
    frame, view, extent
        See :func:`gather_scene` and :func:`draw_scene`.
    rate_limit
        Colour scale of the radar points' range rate ``±`` [m/s]; default the radars' v_max.
    **gather
        Passed to :func:`gather_scene`.
    """
    label = ""
    if time is None:
        time, ref = scene_time(seq, index, stream)
        label = f", {ref} frame {index}"
    scene = gather_scene(seq, time, frame=frame, **gather)
    fig = new_figure(*size, projection="3d" if view == "3d" else None)
    ax = fig.axes[0]
    mappable = draw_scene(ax, scene, seq.calib, view=view, extent=extent,
                          norm=_rate_norm(seq, scene, rate_limit))
    if scene.radars:
        fig.colorbar(mappable, ax=ax, label="radar range rate [m/s] (+ receding)", shrink=0.8)
    t0 = _run_start(seq)
    ax.set_title(f"{seq.name}\nt = {time - t0:.2f} s{label}, {frame} frame", fontsize="medium")
    return fig


def _run_start(seq) -> float:
    if _has(seq, "groundtruth"):
        return float(seq.groundtruth.timestamps[0])
    starts = [float(_stream(seq, s).timestamps[0]) for s in REFERENCE_STREAMS if _has(seq, s)
              and len(_stream(seq, s).timestamps)]
    return min(starts) if starts else 0.0
