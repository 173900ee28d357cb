"""Radar SLAM from one radar's point clouds and the IMU: :func:`slam_from_clouds`.

1. Ego-velocity of every frame; the cloud and which of its points are static go to a
   :class:`.stores.FrameStore` (on disk).
2. The radar-inertial filter (:mod:`.frontend`), as ``coloradar odometry`` runs it (every
   point updates it, read back from the store): a pose and covariance at every frame; the
   poses smoothed with the later frames (``smooth_frontend``, :mod:`coloradar.odometry.smoother`).
3. Keyframes and their submaps (:mod:`.submaps`).
4. The odometry's scale, from registrations of keyframes whose submaps share no frame
   (:mod:`.scale`), and the submaps built again at it (:func:`_scale`); odometry factors
   between consecutive keyframes, their translations so scaled; a registration factor
   beside each (``refine_odometry``, on by default), kept when it agrees with the odometry;
   registration factors between keyframes whose submaps share no frame
   (``disjoint_registration``, :func:`_disjoint_edges`).
5. Loop candidates, verified (:mod:`.loops`); for a radar with fewer than 3 elevation rows
   (the single chip) loops constrain x, y and yaw, and height loosely.
6. The pose graph, optimised with its consistency test (:mod:`.graph`).
7. Every frame's pose: the odometry's, corrected by the keyframes' corrections interpolated in
   time (:func:`correct_frames`); the map from the optimised keyframe poses (:func:`build_slam_map`).
"""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

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
from .loops import (
    LoopRecord,
    factor_floor,
    loop_candidates,
    odometry_chi2,
    reverse_release,
    verify_loop,
)
from .registration import register
from .scale import NOT_ESTIMATED, ScaleEstimate, disjoint_pairs, estimate_scale
from .settings import SlamSettings
from .stores import FrameStore, SubmapStore
from .submaps import KeyframeSelector, Submaps, build_submap, point_accuracy, static_mask

__all__ = ["SlamResult", "build_slam_map", "correct_frames", "keyframe_trajectory", "slam_from_clouds"]


@dataclass(frozen=True, eq=False)
class SlamResult:
    """What :func:`slam_from_clouds` estimated.

    Attributes
    ----------
    odometry
        The radar-inertial filter's ``world_T_base`` at every radar frame, as ``coloradar
        odometry`` gives it (causal: not smoothed; the front end's smoothed poses are
        :attr:`FrontEnd.trajectory <.frontend.FrontEnd.trajectory>`).
    trajectory
        The optimised ``world_T_base`` at the same times.
    keyframes
        int64 ``(K,)``: the keyframes' frame indices.
    keyframe_odometry, keyframe_poses
        ``world_T_base`` of the keyframes before optimisation (the front end's, smoothed when
        ``smooth_frontend``) and after (``K`` poses; index
        ``n`` gives keyframe ``n``'s :class:`~coloradar.geometry.SE3`); None without keyframes.
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
    scale
        The odometry's scale measured by registration and applied to the odometry factors
        (:mod:`.scale`).
    factors
        Factors of the pose graph by kind (``odometry``, ``registration``: the
        disjoint-submap and ``refine_odometry`` factors, ``loop``: the loops kept).
    """

    odometry: Trajectory
    trajectory: Trajectory
    keyframes: np.ndarray
    keyframe_odometry: Trajectory | None
    keyframe_poses: Trajectory | None
    loops: list[LoopRecord]
    map_points: np.ndarray
    frontend: FrontEnd
    submap_points: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)
    scale: ScaleEstimate = NOT_ESTIMATED
    factors: dict[str, int] = field(default_factory=dict)

    @property
    def accepted_loops(self) -> list[LoopRecord]:
        return [lp for lp in self.loops if lp.accepted]


def keyframe_trajectory(times: np.ndarray, poses: list[SE3], name: str) -> Trajectory:
    """The keyframes' poses as one :class:`~coloradar.geometry.Trajectory` (arrays: about
    60 bytes a keyframe, not a Python object per pose)."""
    m = np.array([p.matrix() for p in poses]).reshape(-1, 4, 4)
    return Trajectory(times, m[:, :3, 3], Rotation.from_matrix(m[:, :3, :3]), name=name)


def correct_frames(odometry: Trajectory, keyframes: np.ndarray, before: Trajectory,
                   after: Trajectory, block: int = 4096) -> Trajectory:
    """Every frame's pose: the odometry's, times the keyframes' world-side correction
    ``C_k = after_k · before_k⁻¹``, interpolated in time between keyframes (rotation by slerp,
    translation linearly) and held before the first and after the last (computed ``block``
    frames at a time, so that the temporaries do not grow with the run)."""
    t = odometry.timestamps
    if keyframes.size == 0:
        return odometry
    rots = after.rotations * before.rotations.inv()
    trans = after.translations - rots.apply(np.array(before.translations))
    tk = t[keyframes]
    slerp = Slerp(tk, rots) if keyframes.size > 1 else None
    new_t = np.empty((t.size, 3))
    new_q = np.empty((t.size, 4))
    for lo in range(0, t.size, block):
        sl = slice(lo, min(lo + block, t.size))
        tq = np.clip(t[sl], tk[0], tk[-1])
        if slerp is None:
            r_c = Rotation.concatenate([rots[0]] * tq.size)
            t_c = np.repeat(trans, tq.size, axis=0)
        else:
            r_c = slerp(tq)
            t_c = np.stack([np.interp(tq, tk, trans[:, i]) for i in range(3)], axis=1)
        new_q[sl] = (r_c * odometry.rotations[sl]).as_quat()
        new_t[sl] = r_c.apply(np.array(odometry.translations[sl], dtype=np.float64)) + t_c
    return Trajectory(t, new_t, Rotation.from_quat(new_q), name="slam")


def _voxel_key(pts: np.ndarray, voxel: float) -> np.ndarray:
    """int64 key of each point's voxel (21 bits per axis, ±157 km at 0.15 m), ordered as the
    lexicographic order of the voxel indices."""
    idx = np.floor(pts / voxel).astype(np.int64) + (1 << 20)
    return (idx[:, 0] << 42) | (idx[:, 1] << 21) | idx[:, 2]


def build_slam_map(submaps: Submaps, poses: Trajectory | list[SE3], voxel: float,
                   min_keyframes: int, chunk: int = 32) -> np.ndarray:
    """float32 ``(N, 5)`` ``x y z count intensity``: the voxels (edge ``voxel`` [m]) into which
    at least ``min_keyframes`` submaps put a point, their centroid, that count and the mean
    intensity, from the keyframes' ``poses``.

    The sums are accumulated ``chunk`` submaps at a time, so that memory holds the map's
    voxels (bounded by the area covered, not the run's length) and one chunk.
    """
    keys = np.zeros(0, np.int64)
    sums = np.zeros((0, 6))                   # Σx Σy Σz, points, Σ intensity, keyframes
    for lo in range(0, len(poses), chunk):
        xyz, inten, kf = [], [], []
        for n in range(lo, min(lo + chunk, len(poses))):
            s = submaps[n]
            if s.points.shape[0]:
                xyz.append(poses[n].apply(s.points))
                inten.append(s.intensity.astype(np.float64))
                kf.append(np.full(s.points.shape[0], n, dtype=np.int64))
        if not xyz:
            continue
        pts = np.concatenate(xyz)
        k = _voxel_key(pts, voxel)
        # One row per (voxel, keyframe) pair: each counts one keyframe for its voxel.
        pair_keys, pair = np.unique(np.stack([k, np.concatenate(kf)], axis=1), axis=0,
                                    return_inverse=True)
        pair = pair.reshape(-1)
        rows = np.column_stack([np.bincount(pair, weights=c, minlength=pair_keys.shape[0])
                                for c in (*pts.T, np.ones(pts.shape[0]), np.concatenate(inten))])
        rows = np.column_stack([rows, np.ones(pair_keys.shape[0])])
        keys, inv = np.unique(np.concatenate([keys, pair_keys[:, 0]]), return_inverse=True)
        allrows = np.concatenate([sums, rows])
        sums = np.column_stack([np.bincount(inv.reshape(-1), weights=allrows[:, c],
                                            minlength=keys.size) for c in range(6)])
    if keys.size == 0:
        return np.zeros((0, 5), dtype=np.float32)
    cnt = sums[:, 3]
    out = np.column_stack([sums[:, :3] / cnt[:, None], sums[:, 5], sums[:, 4] / cnt])
    return out[sums[:, 5] >= min_keyframes].astype(np.float32)


def _odometry_edges(fe: FrontEnd, submaps: Submaps, s: SlamSettings, scale: float = 1.0
                    ) -> list[Edge]:
    fl_t, fl_r = s.odometry_floor_translation, np.radians(s.odometry_floor_rotation_deg)
    traj, kfs = fe.trajectory, fe.keyframes
    edges = []
    for n in range(1, kfs.size):
        a, b = int(kfs[n - 1]), int(kfs[n])
        rel = traj[a].inverse() @ traj[b]
        rel = SE3(rel.rotation, rel.translation * scale)
        cov = relative_covariance(fe, n - 1, n, fl_t, fl_r, scale=s.odometry_cov_scale)
        edges.append(Edge(n - 1, n, rel, cov, "odometry"))
        if s.refine_odometry:
            reg = register(submaps[n - 1], submaps[n], rel, s)
            if (reg.fitness >= s.min_fitness and np.all(np.isfinite(reg.covariance))
                    and odometry_chi2(rel, cov, reg.target_T_source, reg.covariance)
                    < chi2.ppf(s.gate_probability, 6)):
                edges.append(Edge(n - 1, n, reg.target_T_source, reg.covariance,
                                  "registration"))
    return edges


def _disjoint_edges(fe: FrontEnd, submaps: Submaps, s: SlamSettings, scale: float,
                    planar: bool) -> list[Edge]:
    """Registration factors between keyframes whose submaps share no frame
    (``disjoint_registration``): each keyframe with the first one ``2 · submap_window`` later
    (:func:`.scale.disjoint_pairs`). Their submaps are built from different frames, so the
    registration measures the motion between them independently of the odometry over those
    seconds, as a loop does between laps; between the laps these factors are what holds the
    odometry's drift (on the cascade most of it in height). Covariance: the registration's
    plus the loop factors' floor (:func:`.loops.factor_floor`, tilt and height released for a
    planar radar). Kept when the fitness is at least half ``min_fitness`` (submaps seen
    seconds apart overlap less than a loop's) and the registered motion passes the chi-square
    test against the odometry's (``gate_probability``, 6 dof)."""
    traj, kfs = fe.trajectory, fe.keyframes
    fl_t, fl_r = s.odometry_floor_translation, np.radians(s.odometry_floor_rotation_deg)
    floor = factor_floor(s, planar)
    limit = float(chi2.ppf(s.gate_probability, 6))
    edges = []
    for a, b in disjoint_pairs(np.asarray(traj.timestamps)[kfs], s.submap_window):
        rel = traj[int(kfs[a])].inverse() @ traj[int(kfs[b])]
        rel = SE3(rel.rotation, rel.translation * scale)
        reg = register(submaps[a], submaps[b], rel, s)
        if reg.fitness < 0.5 * s.min_fitness or not np.all(np.isfinite(reg.covariance)):
            continue
        cov = relative_covariance(fe, a, b, fl_t, fl_r, steps=b - a, scale=s.odometry_cov_scale)
        if odometry_chi2(rel, cov, reg.target_T_source, reg.covariance + floor) < limit:
            edges.append(Edge(a, b, reg.target_T_source, reg.covariance + floor, "registration"))
    return edges


def _loops(fe: FrontEnd, submaps: SubmapStore, s: SlamSettings, planar: bool
           ) -> list[LoopRecord]:
    """Step 5: every keyframe's loop candidates, verified; a loop between keyframes that
    pass the place in opposite directions is held loosely along the path
    (:func:`.loops.reverse_release`)."""
    traj, kfs = fe.trajectory, fe.keyframes
    pos = traj.translations[kfs]
    path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))])
    fl_t, fl_r = s.odometry_floor_translation, np.radians(s.odometry_floor_rotation_deg)
    cov_p = fe.covariance[:, :3, :3]
    if kfs.size < 2:
        return []
    rot = traj.rotations[kfs]
    yaw = rot.as_euler("ZYX")[:, 0]
    step = np.gradient(np.asarray(pos, dtype=np.float64), axis=0)
    travel = rot.inv().apply(step / np.maximum(np.linalg.norm(step, axis=1), 1e-9)[:, None])
    out = []
    for j in range(kfs.size):
        for c in loop_candidates(j, pos, path, cov_p, submaps.descriptor, s):
            a, b = int(kfs[c.i]), int(kfs[c.j])
            rel = traj[a].inverse() @ traj[b]
            cov = relative_covariance(fe, c.i, c.j, fl_t, fl_r, steps=c.j - c.i,
                                      scale=s.odometry_cov_scale)
            release = reverse_release(yaw[c.i], yaw[c.j], travel[c.j], s.loop_reverse_along_std)
            out.append(verify_loop(c, submaps, rel, cov, s, planar, release))
    return out


def _optimise(fe: FrontEnd, submaps: Submaps, s: SlamSettings, records: list[LoopRecord],
              scale: float = 1.0, planar: bool = False
              ) -> tuple[list[LoopRecord], Trajectory, dict[str, int]]:
    """Step 6: the pose graph of the odometry edges (translations times ``scale``), the
    disjoint-submap registrations (:func:`_disjoint_edges`) and the accepted loops, optimised
    with its consistency test; the records of the loops it dropped say so; the count of
    the factors kept, by kind."""
    edges = _odometry_edges(fe, submaps, s, scale)
    if s.disjoint_registration == "always" or (s.disjoint_registration == "elevation"
                                               and not planar):
        edges += _disjoint_edges(fe, submaps, s, scale, planar)
    loop_edges = [Edge(r.i, r.j, r.measured, r.covariance, "loop") for r in records
                  if r.accepted and r.measured is not None and r.covariance is not None]
    kfs = fe.keyframes
    p0 = fe.trajectory[int(kfs[0])].translation
    initial = [SE3(p.rotation, p0 + scale * (p.translation - p0))
               for p in (fe.trajectory[int(k)] for k in kfs)]
    graph = PoseGraph(initial, edges + loop_edges, robust_kernel=s.robust_kernel)
    after, active = optimize_with_consistency(graph, s.gate_probability)
    dropped = {(e.i, e.j) for e, a in zip(graph.edges, active, strict=True)
               if e.kind == "loop" and not a}
    records = [LoopRecord(**{**r.__dict__, "accepted": False,
                             "reason": "inconsistent with the other loops and the odometry"})
               if r.accepted and (r.i, r.j) in dropped else r for r in records]
    counts: dict[str, int] = {}
    for e, a in zip(graph.edges, active, strict=True):
        counts[e.kind] = counts.get(e.kind, 0) + int(a)
    return (records, keyframe_trajectory(fe.trajectory.timestamps[kfs], after, "slam keyframes"),
            counts)


def _frontend(clouds: Iterable[np.ndarray], timestamps: np.ndarray, calib: Calibration,
              imu: tuple[np.ndarray, np.ndarray], radar: str, fs: FrontEndSettings,
              s: SlamSettings, groundtruth: Trajectory | None, store: FrameStore,
              tm: dict[str, float]) -> FrontEnd:
    """Steps 1–2: the front end; each frame's cloud and static points go to ``store`` (on
    disk), and what the filter returns is reduced to a :class:`FrontEnd` at once."""
    ego_config = fs.ego_velocity
    rio_config = replace(fs.filter or RioConfig(), smooth=s.smooth_frontend)
    thr = s.static_threshold if s.static_threshold is not None else ego_config.threshold
    t0 = time.perf_counter()

    def keep(k, cloud, est):
        v = est.velocity if est.ok else np.full(3, np.nan)
        store.append(cloud, static_mask(cloud, v, thr, s.min_range, s.max_range))

    track, still = estimate_track(clouds, timestamps, ego_config, seed=fs.seed, frame=radar,
                                  on_frame=keep, zero_velocity=rio_config.zero_velocity)
    _lap("ego_velocity", t0, tm)
    dist, ang = s.keyframe_distance, np.radians(s.keyframe_angle_deg)
    fe = radar_inertial_frontend(
        track, still, calib, imu[0], imu[1], radar=radar, groundtruth=groundtruth,
        config=rio_config, keyframes=KeyframeSelector(track.ok, dist, ang),
        points=store.clouds())
    _lap("filter", t0, tm)
    return fe


def _submaps(fe: FrontEnd, store: FrameStore, calib: Calibration, radar: str, s: SlamSettings,
             scale: float = 1.0) -> SubmapStore:
    """Step 3: the keyframes' submaps (in a :class:`SubmapStore`), each frame placed by the
    odometry with its translations times ``scale``."""
    traj = fe.trajectory
    if scale != 1.0:
        traj = Trajectory(traj.timestamps, scale * np.asarray(traj.translations),
                          traj.rotations, name=traj.name)
    acc = point_accuracy(calib.radar(radar), s)
    b_T_r = sensor_to_base(calib, radar)
    submaps = SubmapStore((s.descriptor_rings, s.descriptor_sectors))
    try:
        for k in fe.keyframes:
            submaps.append(build_submap(int(k), traj, store, b_T_r, acc, s, fe.frames))
    except BaseException:
        submaps.close()
        raise
    return submaps


def _scale(fe: FrontEnd, store: FrameStore, submaps: SubmapStore, calib: Calibration,
           radar: str, s: SlamSettings) -> tuple[ScaleEstimate, SubmapStore]:
    """Step 4: the odometry's scale, and the submaps to use from here on.

    Each submap is built from ± ``submap_window`` of frames placed by the odometry, so it
    carries the odometry's scale error. When a scale is applied (``scale_rebuild``), the
    submaps are built again with the odometry so scaled, so that the loops register, and the
    map is made of, submaps at the scale the graph uses.

    Measuring the scale again on the rebuilt submaps was tried and is not done: on the
    single chip's tuning corridors it came nearer the truth (1.0061 and 1.0065 against
    1.0053 and 1.0052, truth 1.0083 and 1.0080), but on the hallways it went past it
    (1.0100 against 1.0075, truth 1.0067), and the cascade's worst tuning run got worse
    (SLAM / odometry 0.49 → 0.57).
    """
    kfs = fe.keyframes
    scale = estimate_scale(fe.trajectory[kfs], submaps, s)
    if not (scale.used and s.scale_rebuild):
        return scale, submaps
    rebuilt = _submaps(fe, store, calib, radar, s, scale.scale)
    submaps.close()
    return scale, rebuilt


def _lap(stage: str, t0: float, tm: dict[str, float]) -> None:
    """``tm[stage]``: seconds since ``t0`` not yet in ``tm`` (the stage just ended); with
    ``tracemalloc`` tracing, also ``tm['peak_mb_' + stage]``: the stage's peak of traced
    memory [MB] (what :mod:`benchmarks.bench_slam` reports)."""
    spent = sum(v for k, v in tm.items() if not k.startswith("peak_mb_"))
    tm[stage] = time.perf_counter() - t0 - spent
    if tracemalloc.is_tracing():
        tm["peak_mb_" + stage] = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.reset_peak()


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
        read once (an iterator is fine: each frame is kept on disk, not in memory).
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
    tm: dict[str, float] = {}
    t0 = time.perf_counter()
    store = FrameStore()
    submaps = None
    try:
        fe = _frontend(clouds, timestamps, calib, (imu_timestamps, imu_data), radar, fs, s,
                       groundtruth, store, tm)
        odo = fe.filtered if fe.filtered is not None else fe.trajectory
        kfs = fe.keyframes
        if kfs.size == 0:
            return SlamResult(odo, fe.trajectory, kfs, None, None, [],
                              np.zeros((0, 5), np.float32), fe, np.zeros(0, np.int64), tm)
        submaps = _submaps(fe, store, calib, radar, s)
        _lap("submaps", t0, tm)
        scale, submaps = _scale(fe, store, submaps, calib, radar, s)
        store.close()
        _lap("scale", t0, tm)
        planar = elevation_rows(calib.radar(radar)) < 3
        records = _loops(fe, submaps, s, planar)
        _lap("loops", t0, tm)
        records, after, counts = _optimise(fe, submaps, s, records, scale.scale, planar)
        _lap("graph", t0, tm)
        out = correct_frames(fe.trajectory, kfs, fe.trajectory[kfs], after)
        m = build_slam_map(submaps, after, s.map_voxel, s.map_min_keyframes)
        _lap("map", t0, tm)
        return SlamResult(odo, out, kfs, fe.trajectory[kfs], after, records, m, fe,
                          submaps.sizes(), tm, scale, counts)
    finally:
        store.close()
        if submaps is not None:
            submaps.close()
