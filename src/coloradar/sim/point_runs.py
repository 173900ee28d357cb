"""Simulated runs at the point-cloud level, in memory: radar detections, IMU and truth.

:func:`simulate_run` writes a complete run (ADC frames and all), which costs seconds per second
of run on a loaded machine. SLAM and odometry experiments over many seeds need only what the
estimators read: each radar frame's detections (the on-board detector model
:func:`.radar.onboard_pointcloud`, for either radar), the IMU samples, the ground truth, and a
reference lidar map. :func:`simulate_point_run` makes those from the same scene, trajectory and
sensor models as :func:`simulate_run` (same generators keyed by seed, stream and frame), without
synthesising ADC samples, and :func:`laps_duration` gives the run length that closes ``N`` laps
of a scene's closed path (so that the rig comes back to where it started).

The cascade has no on-board detector: its clouds come from its ADC through ``coloradar.dsp``
(range, Doppler and angle FFTs, CFAR, Doppler unwrapping), which resolves angle as well as range
and Doppler. Its point-level frames here use :func:`array_pointcloud`, a model of such a chain
(not the chain itself): one detection per occupied range × Doppler × azimuth × elevation
resolution cell above the detection threshold, at the cell's strongest scatterer with noise of
the cell's size, unaliased range rate. The single chip keeps its on-board detector model
(:func:`coloradar.sim.onboard_pointcloud`: one angle per range–Doppler cell).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..calib import Calibration, write_calibration
from ..errors import OutputExistsError, SettingsError
from ..formats import write_imu, write_poses, write_radar_pointcloud, write_timestamps
from ..formats.layout import COLORADAR
from ..geometry import Trajectory
from ..geometry.mapping import voxel_downsample
from .imu import GX5_25, simulate_imu
from .lidar import LidarModel, simulate_scan
from .paths import EllipsePath
from .radar import RADAR_MODELS, coherent_snr, onboard_pointcloud, visible_targets
from .rest import RestStart
from .run import DEFAULT_START_TIME, RATES, resolve_scene, simulated_calibration
from .scene import Scene
from .trajectory import RigTrajectory, make_trajectory

__all__ = ["PointRun", "array_pointcloud", "laps_duration", "simulate_point_run", "write_point_run"]

# The stream keys of :mod:`.run` (a run's random draws depend on (seed, stream, frame) only).
_KEYS = {"cascade": 1, "single_chip": 2, "lidar": 3, "imu": 4, "trajectory": 8}


@dataclass(frozen=True, eq=False)
class PointRun:
    """One simulated run at the point-cloud level.

    Attributes
    ----------
    radar
        ``"single_chip"`` or ``"cascade"``.
    timestamps
        float64 ``(M,)``: radar frame stamps [s, Unix-like, ``start_time`` + run time].
    clouds
        M float32 ``(N_i, 5)`` arrays: ``x y z intensity range_rate``, radar frame.
    imu_timestamps, imu_data
        float64 ``(K,)`` [s] and ``(K, 6)``: ``ax ay az`` [m/s²] ``gx gy gz`` [rad/s], IMU frame.
    groundtruth
        ``world_T_base`` at 10 Hz (world = the scene frame).
    calib
        The simulated rig's calibration.
    reference_map
        float32 ``(L, 3)``: the lidar's points in the world frame from true poses, voxel
        filtered (the reference a radar map is scored against), or ``(0, 3)``.
    trajectory
        The rig's analytic trajectory (run time).
    scene
        The scene.
    """

    radar: str
    timestamps: np.ndarray
    clouds: list[np.ndarray]
    imu_timestamps: np.ndarray
    imu_data: np.ndarray
    groundtruth: Trajectory
    calib: Calibration
    reference_map: np.ndarray
    trajectory: RigTrajectory
    scene: Scene


def laps_duration(scene: str | os.PathLike[str] | Scene, laps: float, *, speed: float | None = None,
                  rest: float = 0.0) -> float:
    """Seconds the rig needs to go ``laps`` times round a scene's closed (elliptic) path.

    The path parameter is ``θ(t) = θ0 + ω·s(t)`` with ``ω = speed / a`` and the start-up warp
    ``s(t) = t − τ(1 − e^{−t/τ})`` (:class:`~coloradar.sim.paths.EllipsePath`); a lap is
    ``Δθ = 2π``, so ``s(T) = 2π·laps/ω`` is solved for ``T`` (Newton, ``s`` is monotonic).
    Motion-profile perturbations move the rig by centimetres about the path and do not change
    ``θ``. ``speed`` replaces the path's speed as in :func:`simulate_run`; ``rest`` seconds of
    standing still at the start are added, and half the rest's 1 s ease-in ramp
    (:class:`~coloradar.sim.rest.RestStart`, whose warp lags the motion by that much).
    """
    sc = resolve_scene(scene)
    path = sc.rig_path
    if not isinstance(path, EllipsePath):
        raise SettingsError(f"scene {sc.name!r}: laps need a closed (ellipse) rig path, it has "
                            f"a {type(path).__name__}")
    if not (np.isfinite(laps) and laps > 0):
        raise SettingsError(f"laps must be a positive number, got {laps}")
    v = path.speed if speed is None else float(speed)
    if not v > 0:
        raise SettingsError(f"scene {sc.name!r}: the rig path has no speed")
    target = 2.0 * np.pi * laps * path.radii[0] / v
    tau = path.ramp
    t = target + tau
    for _ in range(50):
        if tau <= 0:
            break
        e = np.exp(-t / tau)
        t -= (t - tau * (1 - e) - target) / (1 - e)
    return float(t + (rest + 0.5 if rest > 0 else 0.0))


def array_pointcloud(calib, model, targets, rng: np.random.Generator) -> np.ndarray:
    """Detections of a radar that resolves range, Doppler, azimuth and elevation (a model of
    ADC frames processed by ``coloradar.dsp``; see the module docstring).

    A scatterer's coherent SNR is that of :func:`~coloradar.sim.onboard_pointcloud`
    (``|A|²·Ns·Nc·Nv/(2σ²)``); scatterers sharing a cell (range bin, Doppler bin, and
    ``2/N`` in the sine of each angle, ``N`` the distinct virtual positions along it) add up;
    a cell whose SNR exceeds ``model.detection_threshold_db`` is one detection at its strongest
    scatterer, with Gaussian noise of one cell's width over ``√12`` in range and range rate and
    ``(2/N)/(1.6·√(2·SNR))`` in each sine.

    Returns
    -------
    numpy.ndarray
        float32 ``(N, 5)``: x y z [m], intensity (SNR [dB]), range rate [m/s], radar frame.
    """
    w = calib.waveform
    if len(targets) == 0:
        return np.zeros((0, 5), dtype=np.float32)
    pos = targets.position
    r = targets.range
    snr_k = coherent_snr(calib, model, targets)
    vpos = calib.antenna.virtual.unique_positions
    n_az = max(2, len(np.unique(vpos[:, 0])))
    n_el = max(2, len(np.unique(vpos[:, 1])))
    s_az = pos[:, 1] / np.maximum(np.linalg.norm(pos[:, :2], axis=1), 1e-9)
    s_el = pos[:, 2] / np.maximum(r, 1e-9)
    rr = targets.range_rate
    cells = np.stack([np.rint(r / w.range_bin_width), np.floor(rr / w.velocity_bin_width),
                      np.floor(s_az * n_az / 2), np.floor(s_el * n_el / 2)], axis=1).astype(np.int64)
    _, cell, = np.unique(cells, axis=0, return_inverse=True)[:2]
    cell = cell.reshape(-1)
    total = np.bincount(cell, weights=snr_k)
    order = np.lexsort((-snr_k, cell))
    first = order[np.unique(cell[order], return_index=True)[1]]          # strongest per cell
    snr = total[cell[first]]
    keep = (snr > 10 ** (model.detection_threshold_db / 10)) & (r[first] < w.max_range)
    k, snr = first[keep], snr[keep]
    sd = 1.0 / (1.6 * np.sqrt(2 * snr))
    u_az = np.clip(s_az[k] + rng.standard_normal(k.size) * (2.0 / n_az) * sd, -0.999, 0.999)
    u_el = np.clip(s_el[k] + rng.standard_normal(k.size) * (2.0 / n_el) * sd, -0.999, 0.999)
    rng_m = r[k] + rng.standard_normal(k.size) * w.range_bin_width / np.sqrt(12)
    rate = rr[k] + rng.standard_normal(k.size) * w.velocity_bin_width / np.sqrt(12)
    el, az = np.arcsin(u_el), np.arcsin(u_az)
    xyz = rng_m[:, None] * np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                            np.sin(el)])
    return np.column_stack([xyz, 10 * np.log10(snr), rate]).astype(np.float32)


def _radar_clouds(scene: Scene, traj: RigTrajectory, calib: Calibration, radar: str,
                  times: np.ndarray, seed: int) -> list[np.ndarray]:
    """On-board detections of ``radar`` at run times ``times`` (radar frame, float32 (N, 5))."""
    rc = calib.radar(radar)
    model = RADAR_MODELS[radar]
    b_T_s = calib.transforms[radar].matrix()
    r_bs = Rotation.from_matrix(b_T_s[:3, :3])
    t_bs = b_T_s[:3, 3]
    st = traj.state(times)
    out = []
    for i, t in enumerate(times):
        r_wb, w_b = st.rotation[i], st.angular_velocity[i]
        origin = st.position[i] + r_wb.apply(t_bs)
        vel = st.velocity[i] + r_wb.apply(np.cross(w_b, t_bs))
        scat = scene.static_scatterers
        objs = scene.object_scatterers(float(t))
        if len(objs):
            from .run import _concat  # the run's own merge of static and moving scatterers
            scat = _concat(scat, objs)
        targets = visible_targets(rc, model, scat, r_wb * r_bs, origin, vel,
                                  r_bs.inv().apply(w_b), scene.rect_arrays(np.array([t])))
        rng = np.random.default_rng([seed, _KEYS[radar], i])
        detect = onboard_pointcloud if radar == "single_chip" else array_pointcloud
        out.append(detect(rc, model, targets, rng))
    return out


def _reference_map(scene: Scene, traj: RigTrajectory, calib: Calibration, times: np.ndarray,
                   seed: int, voxel: float) -> np.ndarray:
    b_T_l = calib.transforms["lidar"].matrix()
    parts = []
    for i, t in enumerate(times):
        pts = simulate_scan(scene, traj, b_T_l, float(t), LidarModel(),
                            np.random.default_rng([seed, _KEYS["lidar"], i]))
        xyz = pts[:, :3].astype(np.float64)
        xyz = xyz[np.linalg.norm(xyz, axis=1) > 0.5]
        st = traj.state(np.array([t]))
        r = st.rotation[0] * Rotation.from_matrix(b_T_l[:3, :3])
        o = st.position[0] + st.rotation[0].apply(b_T_l[:3, 3])
        parts.append(voxel_downsample(r.apply(xyz) + o, voxel).astype(np.float32))
    if not parts:
        return np.zeros((0, 3), dtype=np.float32)
    return voxel_downsample(np.concatenate(parts), voxel).astype(np.float32)


def simulate_point_run(scene: str | os.PathLike[str] | Scene = "corridor", duration: float = 20.0,
                       seed: int = 0, *, radar: str = "single_chip", motion: str = "smooth",
                       speed: float | None = None, rest: float = 2.0,
                       lidar_every: float | None = 2.0, map_voxel: float = 0.1) -> PointRun:
    """Simulate a run's radar detections, IMU and ground truth in memory.

    Parameters
    ----------
    scene, duration, seed, motion, speed, rest
        As for :func:`~coloradar.sim.simulate_run` (``rest`` [s]: the rig stands still first).
    radar
        The radar whose on-board detections are simulated, at its rate (:data:`RATES`).
    lidar_every
        Seconds between the lidar scans of the reference map (None: no map).
    map_voxel
        Voxel size of the reference map [m].

    Returns
    -------
    PointRun
    """
    if radar not in ("single_chip", "cascade"):
        raise SettingsError(f"radar must be 'single_chip' or 'cascade', got {radar!r}")
    if not (np.isfinite(duration) and duration > 1.0):
        raise SettingsError(f"duration must be more than 1 s, got {duration}")
    sc = resolve_scene(scene)
    traj = make_trajectory(sc.rig_path, motion, [seed, _KEYS["trajectory"]], speed=speed)
    if rest:
        traj = RestStart(traj, float(rest))  # type: ignore[assignment]
    calib, _ = simulated_calibration(true_angles=False)
    rate = RATES[radar]
    rng = np.random.default_rng([seed, 99])
    times = rng.uniform(0.1, 1.0) / rate + np.arange(0.0, duration - 0.2, 1.0 / rate)
    clouds = _radar_clouds(sc, traj, calib, radar, times, seed)
    imu_t = np.arange(0.0, duration, 1.0 / RATES["imu"])
    imu, _, _ = simulate_imu(traj, calib.transforms["imu"].matrix(), imu_t, GX5_25,
                             np.random.default_rng([seed, _KEYS["imu"]]))
    gt_t = np.arange(0.0, duration, 1.0 / RATES["groundtruth"])
    st = traj.state(gt_t)
    t0 = DEFAULT_START_TIME
    gt = Trajectory(t0 + gt_t, st.position, st.rotation, name="groundtruth")
    ref = (np.zeros((0, 3), dtype=np.float32) if lidar_every is None else
           _reference_map(sc, traj, calib, np.arange(0.05, duration - 0.2, lidar_every), seed,
                          map_voxel))
    return PointRun(radar, t0 + times, clouds, t0 + imu_t, imu, gt, calib, ref, traj, sc)


def write_point_run(run: PointRun, root: str | os.PathLike[str], name: str) -> Path:
    """Write a single-chip :class:`PointRun` as a dataset run ``root/name`` (its point clouds,
    IMU and ground truth relative to the first pose, as the dataset gives it) with the
    calibration in ``root/calib``; refuses an existing run folder. Returns the run folder."""
    if run.radar != "single_chip":
        raise SettingsError("only the single chip has a point-cloud stream in the dataset "
                            "layout; write cascade runs with simulate_run")
    folder = Path(root) / name
    if folder.exists():
        raise OutputExistsError(f"{folder}: exists; choose another name or folder")
    lay = COLORADAR
    pcs = lay.frame("single_chip/pointclouds")
    for i, c in enumerate(run.clouds):
        write_radar_pointcloud(folder / pcs.frame_path(lay.first_frame + i), c)
    write_timestamps(folder / pcs.timestamps_path, run.timestamps)
    imu = lay.tables["imu"]
    write_timestamps(folder / imu.timestamps_path, run.imu_timestamps)
    write_imu(folder / imu.path, run.imu_data)
    gt = run.groundtruth
    inv = gt.rotations[0].inv()
    poses = np.hstack([inv.apply(gt.translations - gt.translations[0]),
                       (inv * gt.rotations).as_quat()])
    tab = lay.tables["groundtruth"]
    write_timestamps(folder / tab.timestamps_path, gt.timestamps)
    write_poses(folder / tab.path, poses)
    if not (Path(root) / "calib").exists():
        write_calibration(run.calib, Path(root) / "calib")
    return folder
