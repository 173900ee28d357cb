"""Log a run to a Rerun ``.rrd`` recording for interactive 3-D viewing (``rerun run.rrd``).

Optional: needs ``pip install 'coloradar[rerun]'`` (``rerun-sdk``). The entity tree mirrors
the rig::

    world                      z up
    world/groundtruth          the whole trajectory (a line strip)
    world/base                 world_T_base(t): ground truth, interpolated at every frame time
    world/base/<sensor>        base_T_<sensor> (static extrinsic)
    world/base/lidar/points    each scan, lidar frame
    world/base/<radar>/points  radar points (point clouds, ADC detections, or a heatmap's
                               strongest cells), coloured by range rate
    world/map                  an occupancy map's occupied voxels (static), as boxes
                               shaded by their probability (``occupancy=``, or
                               :func:`log_map_rrd` for a map alone)

so Rerun composes the transforms and every point lands in the world frame at its own time.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import MissingDependencyError
from ..formats.atomic import atomic_output, new_output_path
from ..geometry import sensor_to_base, trajectory_from_groundtruth, window_indices
from .scene import RADAR_STREAMS, _has, _run_start, _stream, radar_points, radar_source

__all__ = ["log_map_rrd", "log_run_rrd", "require_rerun"]


def _rate_colors(rate: np.ndarray, limit: float) -> np.ndarray:
    from matplotlib import colormaps

    x = np.clip((np.asarray(rate, dtype=np.float64) / limit + 1.0) / 2.0, 0.0, 1.0)
    return (colormaps["coolwarm"](x)[:, :3] * 255).astype(np.uint8)


def require_rerun():
    try:
        import rerun as rr
    except ImportError:
        raise MissingDependencyError("logging to .rrd needs rerun: "
                                     "pip install 'coloradar[rerun]'") from None
    return rr


def _log_map(rec, rr, occupancy: tuple[np.ndarray, float]) -> None:
    """``world/map``: occupied voxels ``x y z probability …`` as boxes of the voxel's edge,
    darker the surer."""
    occ, voxel = occupancy
    occ = np.asarray(occ)
    p = np.clip((occ[:, 3] - 0.5) * 2.0, 0.0, 1.0) if occ.shape[1] > 3 else np.ones(len(occ))
    grey = (200 - 170 * p).astype(np.uint8)
    rec.log("world/map", rr.Boxes3D(centers=occ[:, :3], half_sizes=[[voxel / 2] * 3],
                                    colors=np.stack([grey, grey, grey], axis=1)), static=True)


def log_map_rrd(out: str | os.PathLike[str], occupied: np.ndarray, voxel: float,
                trajectory=None, *, overwrite: bool = False) -> Path:
    """Write an occupancy map (and the trajectory that made it) to a ``.rrd`` file.

    Parameters
    ----------
    out
        The ``.rrd`` file (written to a temporary name, then renamed).
    occupied
        float ``(N, ≥4)``: ``x y z probability …`` of the occupied voxels (``map.ply``) [m].
    voxel
        Voxel edge [m].
    trajectory
        A :class:`~coloradar.geometry.Trajectory` drawn as ``world/trajectory``, or None.
    overwrite
        Replace an existing ``out``.
    """
    rr = require_rerun()
    out = new_output_path(out, overwrite)
    rec = rr.RecordingStream("coloradar", recording_id=Path(out).stem)
    with atomic_output(out, ".rrd") as tmp_path:
        rec.save(str(tmp_path))
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        _log_map(rec, rr, (occupied, voxel))
        if trajectory is not None:
            rec.log("world/trajectory", rr.LineStrips3D([np.asarray(trajectory.translations)],
                                                        colors=[[200, 40, 40]]), static=True)
        rec.flush()
        rec.disconnect()
    return out


def log_run_rrd(seq, out: str | os.PathLike[str], *, start: float = 0.0,
                duration: float | None = None, max_lidar_points: int = 30000,
                max_radar_points: int = 400, overwrite: bool = False,
                progress: Callable[[int, int], None] | None = None,
                occupancy: tuple[np.ndarray, float] | None = None) -> Path:
    """Write the run's lidar, radar points and ground truth to a ``.rrd`` file.

    Parameters
    ----------
    seq
        A sequence with ground truth.
    out
        The ``.rrd`` file (written to a temporary name, then renamed).
    start, duration
        Window in seconds from the run's start (first ground-truth pose); None = to the end.
    max_lidar_points
        Evenly thin each lidar scan to at most this many points.
    max_radar_points
        Cells kept per radar heatmap when a radar has neither point clouds nor ADC frames.
    overwrite
        Replace an existing ``out``.
    progress
        ``progress(done, total)`` after each logged frame.
    occupancy
        ``(occupied, voxel)``: an occupancy map's occupied voxels ``x y z probability …``
        (``map.ply`` of ``coloradar map``) and their edge [m], logged as ``world/map``.
    """
    rr = require_rerun()
    out = new_output_path(out, overwrite)
    traj = trajectory_from_groundtruth(seq)
    t0 = _run_start(seq) + start
    t1 = None if duration is None else t0 + duration
    streams = []
    if _has(seq, "lidar/pointclouds"):
        streams.append(("lidar", "lidar/pointclouds"))
    cache: dict = {}
    for radar in RADAR_STREAMS:
        name = radar_source(seq, radar, cache)
        if name is not None:
            streams.append((radar, name))
    frames = []  # (time, sensor, stream, index)
    for sensor, name in streams:
        ts = _stream(seq, name).timestamps
        idx = window_indices(ts, t0, t1)
        idx = idx[traj.covers(ts[idx])]
        frames += [(float(ts[i]), sensor, name, int(i)) for i in idx]
    frames.sort()

    rec = rr.RecordingStream("coloradar", recording_id=seq.name)
    # Renamed to out only when complete, with the mode a plain open gives (not mkstemp's 0600).
    with atomic_output(out, ".rrd") as tmp_path:
        tmp = str(tmp_path)
        rec.save(tmp)
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        gt_keep = window_indices(traj.timestamps, t0, t1)
        rec.log("world/groundtruth", rr.LineStrips3D([traj.translations[gt_keep]],
                                                     colors=[[40, 160, 40]]), static=True)
        if occupancy is not None:
            _log_map(rec, rr, occupancy)
        for sensor in {s for s, _ in streams}:
            b_T_s = sensor_to_base(seq.calib, sensor)
            rec.log(f"world/base/{sensor}", rr.Transform3D(
                translation=np.array(b_T_s.translation),
                quaternion=rr.Quaternion(xyzw=b_T_s.rotation.as_quat())), static=True)
        limit = max((seq.calib.radar(r).waveform.max_velocity for r in RADAR_STREAMS), default=1)
        for k, (t, sensor, name, i) in enumerate(frames):
            rec.set_time("time", timestamp=t)
            pose = traj.at(t)
            rec.log("world/base", rr.Transform3D(
                translation=np.array(pose.translation),
                quaternion=rr.Quaternion(xyzw=pose.rotation.as_quat())))
            data = _stream(seq, name)[i]
            if sensor == "lidar":
                step = max(1, int(np.ceil(len(data) / max_lidar_points)))
                rec.log("world/base/lidar/points",
                        rr.Points3D(data[::step, :3], radii=0.02, colors=[[150, 150, 150]]))
            else:
                data = radar_points(seq, sensor, name, data, max_points=max_radar_points,
                                    cache=cache)
                rec.log(f"world/base/{sensor}/points",
                        rr.Points3D(data[:, :3], radii=0.06,
                                    colors=_rate_colors(data[:, 4], limit)))
            if progress is not None:
                progress(k + 1, len(frames))
        rec.flush()
        rec.disconnect()
    return out
