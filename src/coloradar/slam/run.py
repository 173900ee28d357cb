"""Radar SLAM on a run, written to a folder: :func:`run_slam` (``coloradar slam``).

The output folder holds

- ``trajectory.txt``: TUM, ``world_T_base`` at every radar frame, optimised;
- ``odometry.txt``: TUM, the radar-inertial filter's trajectory, as ``coloradar odometry``
  gives it (causal), for comparison;
- ``keyframes.csv``: per keyframe its frame, time, optimised pose, the front end's position
  before optimisation (``odometry_*``: the filter's, smoothed when ``smooth_frontend``), and
  submap size;
- ``loops.csv``: every verified loop candidate: the pair, descriptor distance, gate, fitness,
  overlap, RMSE, the odometry test, accepted or not and why;
- ``map.ply``: the radar map from the optimised poses. By default (``map_kind``
  ``"occupancy"``) the occupied voxels of an occupancy map of every frame
  (:mod:`coloradar.mapping`): ``x y z probability hits misses``, with ``occupancy.npz`` (the
  whole map) and ``grid.pgm`` + ``grid.yaml`` (the ROS ``map_server`` grid of the trajectory's
  median height ± 0.5 m); with ``map_kind="points"`` the keyframes' points, filtered (a voxel
  kept only when ``map_min_keyframes`` keyframes saw it): ``x y z count intensity``;
- ``slam.json``: the run, settings and a summary (and map scores when asked for);
- ``odometry.json``: the run, radar and source, so that ``coloradar evaluate DIR`` evaluates
  ``trajectory.txt`` as it does an odometry folder;
- ``slam.png`` (with matplotlib): the map from above, the trajectory before and after, loop
  edges and the ground truth when the run has it.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from .. import __version__
from ..dsp.points import POINT_SOURCES, PointSource, default_point_source, radar_point_stream
from ..errors import ColoradarError, MissingDataError, OutputExistsError, SettingsError, WriteError
from ..formats.atomic import atomic_write_text, make_output_dir
from ..geometry import build_map, trajectory_from_groundtruth, write_ply
from ..geometry.cloud_metrics import MapScores, score_map
from ..mapping.output import PLY_FIELDS
from ..odometry.ego_velocity import EgoVelocityConfig
from ..odometry.pipeline import ego_velocity_config, run_path
from ..odometry.tum import write_tum
from .frontend import FrontEndSettings
from .settings import SlamSettings
from .system import SlamResult, slam_from_clouds

__all__ = ["SLAM_FILES", "SlamOutput", "benchmark_method", "reference_lidar_map", "run_slam",
           "slam_summary"]

SLAM_FILES = ("trajectory.txt", "odometry.txt", "keyframes.csv", "loops.csv", "map.ply",
              "slam.json", "odometry.json", "slam.png", "occupancy.npz", "grid.pgm", "grid.yaml")
"""The files :func:`run_slam` writes (``slam.png`` only with matplotlib; the last three only
with the occupancy map)."""

Progress = Callable[[int, int], None]


@dataclass(frozen=True, eq=False)
class SlamOutput:
    """What :func:`run_slam` computed and wrote: the output folder, the result, the summary
    written to ``slam.json``, map scores (or None) and the files."""

    folder: Path
    result: SlamResult
    summary: dict
    map_scores: MapScores | None
    files: list[Path]


def reference_lidar_map(seq, voxel: float = 0.1, stride: int = 5) -> np.ndarray:
    """float32 ``(N, 3)``: the run's lidar scans placed with the ground truth, voxel filtered
    (every ``stride``-th scan): the reference a radar map is scored against."""
    m = build_map(seq, "lidar", voxel_size=voxel, stride=stride, min_range=0.5)
    return np.asarray(m.points[:, :3], dtype=np.float32)


def _path_length(p: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if len(p) > 1 else 0.0


def slam_summary(res: SlamResult) -> dict:
    """Counts, distance, timings and the front end's figures, as written to ``slam.json``."""
    reasons: dict[str, int] = {}
    for lp in res.loops:
        key = lp.reason.split(" (")[0]
        reasons[key] = reasons.get(key, 0) + 1
    return {
        "frames": len(res.trajectory),
        "keyframes": int(res.keyframes.size),
        "distance_m": _path_length(res.trajectory.translations),
        "duration_s": float(res.trajectory.duration),
        "loop_candidates": len(res.loops),
        "loops_accepted": len(res.accepted_loops),
        "loop_outcomes": reasons,
        "map_points": int(res.map_points.shape[0]),
        "submap_points_median": float(np.median(res.submap_points)) if res.submap_points.size
        else 0.0,
        "timings_s": {k: round(v, 3) for k, v in res.timings.items()},
        "frontend": res.frontend.summary,
        "odometry_scale": res.scale.as_dict(),
        "factors": {k: res.factors.get(k, 0) for k in ("odometry", "registration", "loop")},
    }


def _keyframes_csv(res: SlamResult) -> str:
    out = io.StringIO()
    out.write("# keyframe,frame,timestamp,x,y,z,qx,qy,qz,qw,odometry_x,odometry_y,odometry_z,"
              "submap_points\n")
    if res.keyframe_poses is None or res.keyframe_odometry is None:
        return out.getvalue()           # no keyframe: the header only
    for n, k in enumerate(res.keyframes):
        p, o = res.keyframe_poses[n], res.keyframe_odometry[n]
        q = p.rotation.as_quat()
        out.write(f"{n},{int(res.frontend.frames[k])},{res.trajectory.timestamps[k]:.6f},"
                  + ",".join(f"{x:.6f}" for x in (*p.translation, *q, *o.translation))
                  + f",{int(res.submap_points[n])}\n")
    return out.getvalue()


def _loops_csv(res: SlamResult) -> str:
    out = io.StringIO()
    out.write("# keyframe_i,keyframe_j,timestamp_i,timestamp_j,descriptor_distance,gate_sigma,"
              "fitness,overlap,rmse_m,odometry_chi2,accepted,reason\n")
    t = res.trajectory.timestamps
    for lp in res.loops:
        ti, tj = t[res.keyframes[lp.i]], t[res.keyframes[lp.j]]
        reason = lp.reason.replace(",", ";")
        out.write(f"{lp.i},{lp.j},{ti:.6f},{tj:.6f},{lp.descriptor_distance:.4f},"
                  f"{lp.gate_sigma:.3f},{lp.fitness:.4f},{lp.overlap:.4f},{lp.rmse:.4f},"
                  f"{lp.odometry_chi2:.3f},{int(lp.accepted)},{reason}\n")
    return out.getvalue()


def _targets(folder: Path, overwrite: bool) -> dict[str, Path]:
    for q in (folder, *folder.parents):
        if q.exists():
            if not q.is_dir():
                raise WriteError(f"{q}: expected an output folder, found a file")
            break
    targets = {n: folder / n for n in SLAM_FILES}
    existing = [n for n, p in targets.items() if p.exists()]
    if existing and not overwrite:
        raise OutputExistsError(f"{folder}: holds {', '.join(existing)} already; pass "
                                "overwrite=True (--overwrite) to replace them")
    return targets


def _clouds(stream, convert, idx: np.ndarray) -> Iterator[np.ndarray]:
    for k in idx:
        frame = stream.read_or_skip(int(k))  # an unreadable frame is reported and skipped
        yield np.zeros((0, 5), np.float32) if frame is None else convert(frame)


def _occupancy(seq, res: SlamResult, radar: str, src: str, s: SlamSettings,
               targets: dict[str, Path]) -> tuple[np.ndarray, dict, list[Path]]:
    """The occupancy map of every frame placed by SLAM's trajectory: its occupied voxels, a
    summary, and ``occupancy.npz``, ``grid.pgm``, ``grid.yaml`` written."""
    from ..mapping import OccupancyJob, OccupancySettings, build_occupancy_map, occupancy_grid
    from ..mapping.grid2d import write_map_server
    from ..mapping.output import default_band

    job = OccupancyJob(sensor=radar, source="heatmaps" if src == "heatmaps" else "points",
                       max_range=s.max_range)
    out = build_occupancy_map(seq, res.trajectory, job, OccupancySettings(voxel=s.map_voxel))
    m = out.map
    occ = m.occupied()
    band = default_band(res.trajectory)
    grid = occupancy_grid(m, *band)
    files = [m.save(targets["occupancy.npz"]), *write_map_server(grid, targets["grid.yaml"])]
    summary = {"voxels": len(m), "occupied": int(occ.shape[0]), "frames": m.frames,
               "band_m": list(band), "grid": grid.counts()}
    return occ, summary, files


def run_slam(seq, out: str | os.PathLike[str], *, radar: str = "single_chip",
             source: str | None = None, settings: SlamSettings | None = None,
             ego_config: EgoVelocityConfig | None = None, seed: int = 0,
             score_against_lidar: bool = False, plot: bool = True, overwrite: bool = False
             ) -> SlamOutput:
    """Radar SLAM of a run (one radar and the IMU), written to ``out`` (module docstring).

    Parameters
    ----------
    seq
        The run (:func:`coloradar.open_sequence`); needs the IMU and the radar's point clouds,
        ADC frames or heatmaps.
    out
        Output folder (created).
    radar, source
        As for ``coloradar odometry`` (``source`` None: the radar's point clouds when the run
        has them, else ADC, else heatmaps).
    settings
        :class:`SlamSettings`.
    ego_config
        Ego-velocity settings (default :func:`coloradar.odometry.ego_velocity_config`).
    seed
        RANSAC seed.
    score_against_lidar
        Also score the map against the lidar map built with ground truth (the run needs lidar
        and ground truth) and put the scores in ``slam.json``.
    plot
        Write ``slam.png`` (skipped without matplotlib).
    overwrite
        Replace existing output files.
    """
    if radar not in ("single_chip", "cascade"):
        raise SettingsError(f"radar must be 'single_chip' or 'cascade', got {radar!r}")
    s = settings or SlamSettings()
    folder = Path(out)
    targets = _targets(folder, overwrite)
    if "imu" not in seq.available():
        raise MissingDataError(f"{seq.location}: the run has no IMU; radar SLAM's front end "
                               "(the radar-inertial filter) needs it")
    if source is not None and source not in POINT_SOURCES:
        raise SettingsError(f"unknown source {source!r}; expected one of "
                            f"{', '.join(POINT_SOURCES)}")
    src: PointSource | None = source or default_point_source(seq, radar)
    if src is None:
        raise MissingDataError(f"{seq.location}: the {radar} radar has no point clouds, ADC "
                               "frames or heatmaps in this run")
    has_gt = "groundtruth" in seq.available()
    if score_against_lidar and not (has_gt and "lidar/pointclouds" in seq.available()):
        raise MissingDataError(f"{seq.location}: scoring the map needs the run's lidar and "
                               "ground truth")
    stream, convert = radar_point_stream(seq, radar, src)
    idx = np.arange(len(stream.timestamps))
    if idx.size < 10:
        raise ColoradarError(f"{seq.location}: only {idx.size} {radar} frames; SLAM needs more")
    gt = trajectory_from_groundtruth(seq) if has_gt else None
    cfg = ego_config or ego_velocity_config(seq.calib.radar(radar))
    res = slam_from_clouds(_clouds(stream, convert, idx), stream.timestamps[idx], seq.calib,
                           seq.imu.timestamps, seq.imu.data, radar=radar, settings=s,
                           frontend=FrontEndSettings(cfg, seed=seed), groundtruth=gt)
    occupancy = (_occupancy(seq, res, radar, src, s, targets) if s.map_kind == "occupancy"
                 else None)
    map_points = res.map_points if occupancy is None else occupancy[0]
    scores = None
    if score_against_lidar:
        scores = score_map(map_points, reference_lidar_map(seq))
    summary = slam_summary(res)
    if occupancy is not None:
        summary["map_points"] = int(map_points.shape[0])
        summary["occupancy"] = occupancy[1]
    info = {"run": run_path(seq), "run_name": seq.name,
            "calib": str(getattr(seq.calib, "source", "preset")), "radar": radar, "source": src,
            "estimator": "slam", "seed": seed, "settings": asdict(s),
            "ego_velocity_config": asdict(cfg), "summary": summary,
            "map_scores": None if scores is None else scores.to_dict(),
            "initial_pose": "groundtruth" if gt is not None else "identity",
            "coloradar_version": __version__}
    make_output_dir(folder)
    comments = [f"run {seq.name}, {radar} radar, source {src}"]
    written = [
        write_tum(targets["trajectory.txt"], res.trajectory, overwrite=overwrite,
                  comments=[*comments, "world_T_base from radar SLAM (optimised pose graph)"]),
        write_tum(targets["odometry.txt"], res.odometry, overwrite=overwrite,
                  comments=[*comments, "world_T_base from the radar-inertial filter (SLAM's "
                            "front end, before optimisation)"])]
    atomic_write_text(targets["keyframes.csv"], _keyframes_csv(res))
    atomic_write_text(targets["loops.csv"], _loops_csv(res))
    if occupancy is None:
        write_ply(targets["map.ply"], res.map_points, ("x", "y", "z", "count", "intensity"),
                  overwrite=True)
    else:
        write_ply(targets["map.ply"], map_points, PLY_FIELDS, overwrite=True)
        written += occupancy[2]
    atomic_write_text(targets["slam.json"], json.dumps(info, indent=2, default=float) + "\n")
    odo_info = {k: info[k] for k in ("run", "run_name", "calib", "radar", "source", "estimator",
                                     "initial_pose", "coloradar_version")}
    atomic_write_text(targets["odometry.json"], json.dumps(odo_info, indent=2) + "\n")
    written += [targets[n] for n in ("keyframes.csv", "loops.csv", "map.ply", "slam.json",
                                     "odometry.json")]
    if plot:
        try:
            from .plot import plot_slam
        except ImportError:
            pass  # matplotlib is an optional extra; everything else is written
        else:
            written.append(plot_slam(targets["slam.png"], res, gt, title=seq.name))
    return SlamOutput(folder, res, summary, scores, [Path(p) for p in written])


def benchmark_method(run: str | os.PathLike[str], out_dir: str | os.PathLike[str],
                     settings: dict | None = None) -> Path:
    """``coloradar benchmark``'s ``slam`` method: SLAM of one run, its TUM trajectory's path.

    ``settings`` may hold ``radar`` (default ``single_chip``), ``source``, ``calib``, ``seed``,
    ``overwrite`` and any :class:`SlamSettings` field.
    """
    from ..dataset import open_sequence

    opts = dict(settings or {})
    radar = opts.pop("radar", "single_chip")
    source = opts.pop("source", None)
    calib = opts.pop("calib", None)
    seed = int(opts.pop("seed", 0))
    overwrite = bool(opts.pop("overwrite", False))
    known = set(SlamSettings.__dataclass_fields__)
    unknown = sorted(set(opts) - known)
    if unknown:
        raise SettingsError(f"slam benchmark: unknown settings {', '.join(unknown)}")
    seq = open_sequence(run, calib=calib)
    res = run_slam(seq, out_dir, radar=radar, source=source,
                   settings=replace(SlamSettings(), **opts), seed=seed, plot=False,
                   overwrite=overwrite)
    return res.folder / "trajectory.txt"

