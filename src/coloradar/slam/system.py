"""Radar SLAM from one radar's point clouds and the IMU: :func:`slam_from_clouds`.

1. Ego-velocity of every frame; its static points go to a :class:`.submaps.FrameStore`.
2. The radar-inertial filter (:mod:`.frontend`): a pose and covariance at every frame.
3. Keyframes and their submaps (:mod:`.submaps`).
4. Odometry factors between consecutive keyframes; optionally a registration factor beside each
   (``refine_odometry``), kept when it agrees with the odometry.
5. Loop candidates, verified (:mod:`.loops`); for a radar with fewer than 3 elevation rows
   (the single chip) loops constrain x, y and yaw only.
6. The pose graph, optimised with its consistency test (:mod:`.graph`).
7. Every frame's pose: the odometry's, corrected by the keyframes' corrections interpolated in
   time (:func:`correct_frames`); the map from the optimised keyframe poses (:func:`build_slam_map`).
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation, Slerp
from scipy.stats import chi2

from ..calib import Calibration
from ..geometry import SE3, Trajectory, sensor_to_base
from ..odometry.ego_velocity import EgoVelocityConfig
from ..odometry.pipeline import elevation_rows
from ..odometry.rio import RioConfig
from .frontend import (
    FrontEnd,
    FrontEndSettings,
    estimate_track,
    radar_inertial_frontend,
    relative_covariance,
)
from .graph import Edge, PoseGraph, optimize_with_consistency
from .loops import LoopRecord, loop_candidates, verify_loop
from .registration import register
from .settings import SlamSettings
from .submaps import FrameStore, Submap, build_submap, point_accuracy, select_keyframes, static_points

__all__ = ["SlamResult", "build_slam_map", "correct_frames", "slam_from_clouds"]


@dataclass(frozen=True, eq=False)
class SlamResult:
    """What :func:`slam_from_clouds` estimated.

    Attributes
    ----------
    odometry
        The front end's ``world_T_base`` at every radar frame.
    trajectory
        The optimised ``world_T_base`` at the same times.
    keyframes
        int64 ``(K,)``: the keyframes' frame indices.
    keyframe_odometry, keyframe_poses
        ``world_T_base`` of the keyframes before and after optimisation.
    loops
        Every verified candidate (accepted or not).
    map_points
        float32 ``(N, 5)``: ``x y z count intensity``: voxel centroids of the map (world frame),
        the number of keyframes that saw the voxel, their mean intensity.
    frontend
        The front end's output.
    submap_points
        Points in each keyframe's submap.
    timings
        Seconds per stage.
    """

    odometry: Trajectory
    trajectory: Trajectory
    keyframes: np.ndarray
    keyframe_odometry: list[SE3]
    keyframe_poses: list[SE3]
    loops: list[LoopRecord]
    map_points: np.ndarray
    frontend: FrontEnd
    submap_points: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def accepted_loops(self) -> list[LoopRecord]:
        return [lp for lp in self.loops if lp.accepted]


def correct_frames(odometry: Trajectory, keyframes: np.ndarray, before: list[SE3],
                   after: list[SE3]) -> Trajectory:
    """Every frame's pose: the odometry's, times the keyframes' world-side correction
    ``C_k = after_k · before_k⁻¹``, interpolated in time between keyframes (rotation by slerp,
    translation linearly) and held before the first and after the last."""
    t = odometry.timestamps
    if keyframes.size == 0:
        return odometry
    corr = [a @ b.inverse() for a, b in zip(after, before, strict=True)]
    tk = t[keyframes]
    rots = Rotation.concatenate([c.rotation for c in corr])
    trans = np.array([c.translation for c in corr])
    tq = np.clip(t, tk[0], tk[-1])
    if keyframes.size == 1:
        r_c = Rotation.concatenate([rots[0]] * t.size)
        t_c = np.repeat(trans, t.size, axis=0)
    else:
        r_c = Slerp(tk, rots)(tq)
        t_c = np.stack([np.interp(tq, tk, trans[:, i]) for i in range(3)], axis=1)
    new_r = r_c * odometry.rotations
    new_t = r_c.apply(np.array(odometry.translations, dtype=np.float64)) + t_c
    return Trajectory(t, new_t, new_r, name="slam")


def build_slam_map(submaps: list[Submap], poses: list[SE3], voxel: float, min_keyframes: int
                   ) -> np.ndarray:
    """float32 ``(N, 5)`` ``x y z count intensity``: the voxels (edge ``voxel`` [m]) into which
    at least ``min_keyframes`` submaps put a point, their centroid, that count and the mean
    intensity, from the keyframes' ``poses``."""
    xyz, inten, kf = [], [], []
    for n, (s, p) in enumerate(zip(submaps, poses, strict=True)):
        if s.points.shape[0]:
            xyz.append(p.apply(s.points))
            inten.append(s.intensity.astype(np.float64))
            kf.append(np.full(s.points.shape[0], n, dtype=np.int64))
    if not xyz:
        return np.zeros((0, 5), dtype=np.float32)
    pts, it, ks = np.concatenate(xyz), np.concatenate(inten), np.concatenate(kf)
    keys = np.floor(pts / voxel).astype(np.int64)
    _, vox = np.unique(keys, axis=0, return_inverse=True)
    vox = vox.reshape(-1)
    m = int(vox.max()) + 1
    # Distinct keyframes per voxel: count the unique (voxel, keyframe) pairs.
    pair = np.unique(vox * (len(submaps) + 1) + ks)
    seen = np.bincount(pair // (len(submaps) + 1), minlength=m)
    cnt = np.bincount(vox, minlength=m).astype(np.float64)
    cols = [np.bincount(vox, weights=pts[:, i], minlength=m) / cnt for i in range(3)]
    out = np.column_stack([*cols, seen, np.bincount(vox, weights=it, minlength=m) / cnt])
    return out[seen >= min_keyframes].astype(np.float32)


def _odometry_edges(fe: FrontEnd, kfs: np.ndarray, submaps: list[Submap], s: SlamSettings
                    ) -> list[Edge]:
    fl_t, fl_r = s.odometry_floor_translation, np.radians(s.odometry_floor_rotation_deg)
    traj = fe.trajectory
    edges = []
    for n in range(1, kfs.size):
        a, b = int(kfs[n - 1]), int(kfs[n])
        rel = traj[a].inverse() @ traj[b]
        cov = relative_covariance(fe, a, b, fl_t, fl_r)
        edges.append(Edge(n - 1, n, rel, cov, "odometry"))
        if s.refine_odometry:
            reg = register(submaps[n - 1], submaps[n], rel, s)
            if (reg.fitness >= s.min_fitness and np.all(np.isfinite(reg.covariance))):
                d = np.concatenate([(rel.inverse() @ reg.target_T_source).rotation.as_rotvec(),
                                    (rel.inverse() @ reg.target_T_source).translation])
                if float(d @ np.linalg.solve(cov + reg.covariance, d)) < chi2.ppf(s.gate_probability, 6):
                    edges.append(Edge(n - 1, n, reg.target_T_source, reg.covariance,
                                      "registration"))
    return edges


def _loops(fe: FrontEnd, kfs: np.ndarray, submaps: list[Submap], s: SlamSettings,
           planar: bool) -> list[LoopRecord]:
    traj = fe.trajectory
    pos = traj.translations[kfs]
    path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))])
    fl_t, fl_r = s.odometry_floor_translation, np.radians(s.odometry_floor_rotation_deg)
    cov_p = fe.covariance[kfs, :3, :3]
    out = []
    for j in range(kfs.size):
        for c in loop_candidates(j, pos, path, cov_p, submaps, s):
            a, b = int(kfs[c.i]), int(kfs[c.j])
            rel = traj[a].inverse() @ traj[b]
            cov = relative_covariance(fe, a, b, fl_t, fl_r, steps=c.j - c.i)
            out.append(verify_loop(c, submaps, rel, cov, s, planar))
    return out


def slam_from_clouds(clouds: Iterable[np.ndarray], timestamps: np.ndarray, calib: Calibration,
                     imu_timestamps: np.ndarray, imu_data: np.ndarray, *, radar: str,
                     frontend: FrontEndSettings | EgoVelocityConfig,
                     settings: SlamSettings | None = None,
                     groundtruth: Trajectory | None = None) -> SlamResult:
    """Radar SLAM of one radar's point clouds and the IMU.

    Parameters
    ----------
    clouds
        float ``(N_k, 5)`` ``x y z intensity range_rate`` (radar frame), one per timestamp,
        read once (an iterator is fine: only each frame's static points are kept, on disk).
    timestamps
        float64 ``(M,)``: the frames' stamps [s].
    calib
        The rig (``base_T_<radar>``, ``base_T_imu``, the radar's array and waveform).
    imu_timestamps, imu_data
        float64 ``(K,)`` [s], ``(K, 6)``: ``ax ay az`` [m/s²] ``gx gy gz`` [rad/s].
    radar
        ``"single_chip"`` or ``"cascade"``.
    frontend
        :class:`~coloradar.slam.frontend.FrontEndSettings`, or just the ego-velocity settings
        (:func:`coloradar.odometry.ego_velocity_config`; the filter's defaults, seed 0).
    settings
        :class:`SlamSettings` (default values when None).
    groundtruth
        Only for the initial pose (as the odometry's).

    Returns
    -------
    SlamResult
    """
    s = settings or SlamSettings()
    fs = frontend if isinstance(frontend, FrontEndSettings) else FrontEndSettings(frontend)
    ego_config, rio_config = fs.ego_velocity, fs.filter or RioConfig()
    thr = s.static_threshold if s.static_threshold is not None else ego_config.threshold
    tm: dict[str, float] = {}
    t0 = time.perf_counter()
    store = FrameStore()
    try:
        def keep(k, cloud, est):
            v = est.velocity if est.ok else np.full(3, np.nan)
            store.append(static_points(cloud, v, thr, s.min_range, s.max_range))

        track, still = estimate_track(clouds, timestamps, ego_config, seed=fs.seed, frame=radar,
                                      on_frame=keep, zero_velocity=rio_config.zero_velocity)
        tm["ego_velocity"] = time.perf_counter() - t0
        fe = radar_inertial_frontend(track, still, calib, imu_timestamps, imu_data, radar=radar,
                                     groundtruth=groundtruth, config=rio_config)
        tm["filter"] = time.perf_counter() - t0 - sum(tm.values())
        traj = fe.trajectory
        kfs = select_keyframes(traj, fe.ok, s.keyframe_distance, np.radians(s.keyframe_angle_deg))
        acc = point_accuracy(calib.radar(radar), s)
        b_T_r = sensor_to_base(calib, radar)
        submaps = [build_submap(int(k), traj, store, b_T_r, acc, s, fe.frames) for k in kfs]
    finally:
        store.close()
    tm["submaps"] = time.perf_counter() - t0 - sum(tm.values())
    before = [traj[int(k)] for k in kfs]
    if kfs.size == 0:
        return SlamResult(traj, traj, kfs, before, before, [], np.zeros((0, 5), np.float32), fe,
                          np.zeros(0, np.int64), tm)
    edges = _odometry_edges(fe, kfs, submaps, s)
    records = _loops(fe, kfs, submaps, s, elevation_rows(calib.radar(radar)) < 3)
    tm["loops"] = time.perf_counter() - t0 - sum(tm.values())
    loop_edges = [Edge(r.i, r.j, r.measured, r.covariance, "loop") for r in records
                  if r.accepted and r.measured is not None and r.covariance is not None]
    graph = PoseGraph(before, edges + loop_edges, robust_kernel=s.robust_kernel)
    after, active = optimize_with_consistency(graph, s.gate_probability)
    dropped = {(e.i, e.j) for e, a in zip(graph.edges, active, strict=True)
               if e.kind == "loop" and not a}
    records = [LoopRecord(**{**r.__dict__, "accepted": False,
                             "reason": "inconsistent with the other loops and the odometry"})
               if r.accepted and (r.i, r.j) in dropped else r for r in records]
    tm["graph"] = time.perf_counter() - t0 - sum(tm.values())
    out = correct_frames(traj, kfs, before, after)
    m = build_slam_map(submaps, after, s.map_voxel, s.map_min_keyframes)
    tm["map"] = time.perf_counter() - t0 - sum(tm.values())
    return SlamResult(traj, out, kfs, before, after, records, m, fe,
                      np.array([sm.points.shape[0] for sm in submaps], dtype=np.int64), tm)
