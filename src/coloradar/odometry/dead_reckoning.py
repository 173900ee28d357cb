"""Radar–inertial dead reckoning: radar ego-velocity + gyro attitude -> trajectory.

The baseline, deliberately simple (no filter, no accelerometer):

1. **Attitude from the gyro.** The body rates ``ω_k`` of the IMU (its own frame, rad/s) are
   integrated as ``R_{k+1} = R_k · Exp(½(ω_k + ω_{k+1}) Δt_k)`` (trapezoidal rate, exact
   for a constant rate), optionally after subtracting a gyro bias. The products are formed by a
   parallel prefix scan over :class:`scipy.spatial.transform.Rotation` arrays (log₂ N
   vectorised compositions, no loop over samples). The attitude at the radar timestamps is the
   SLERP of the integrated one.
2. **Rig attitude.** ``world_R_base(t) = world_R_imu(t) · imu_R_base`` with the extrinsics
   ``base_T_imu``; the first radar frame's attitude is the initial pose's (by default the
   identity: the dataset's ground truth starts at the identity).
3. **Velocity into the world.** The radar measures its own origin's velocity in its own frame,
   ``v_r``; in the world it is ``world_R_base · base_R_radar · v_r``. Frames without a usable
   estimate get the world velocity linearly interpolated from their neighbours.
4. **Position.** The radar origin's position is integrated at the radar timestamps with the
   trapezoidal rule, ``p_{k+1} = p_k + ½(v_k + v_{k+1}) Δt_k``; the rig's pose follows as
   ``world_T_base = world_T_radar · radar_T_base`` (so the lever arm between radar and base is
   accounted for exactly).

With ``orientation="groundtruth"`` step 1-2 use the ground-truth attitude instead: the
velocity-only error, an upper bound on what better attitude could give.
"""

from __future__ import annotations

import warnings
from typing import Literal, get_args

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from ..calib import Calibration
from ..errors import ColoradarError, DataWarning, SettingsError
from ..geometry import SE3, Trajectory, sensor_to_base
from .velocity_track import EgoVelocityTrack

__all__ = [
    "ORIENTATION_SOURCES",
    "OrientationSource",
    "cumulative_rotations",
    "dead_reckon",
    "estimate_gyro_bias",
    "integrate_gyro",
    "radar_inertial_odometry",
]

OrientationSource = Literal["imu", "groundtruth"]
"""Where the attitude comes from: integrated gyro, or the ground truth (an upper bound)."""
ORIENTATION_SOURCES: tuple[OrientationSource, ...] = get_args(OrientationSource)


def cumulative_rotations(deltas: Rotation) -> Rotation:
    """Inclusive prefix products ``P_k = d_0 · d_1 ⋯ d_k`` of a Rotation array.

    A Hillis–Steele scan: ``ceil(log₂ N)`` vectorised compositions instead of N sequential ones.
    """
    p = deltas
    n = len(p)
    s = 1
    while s < n:
        p = Rotation.concatenate([p[:s], p[:-s] * p[s:]])
        s *= 2
    return p


def integrate_gyro(timestamps: np.ndarray, angular_rates: np.ndarray, *,
                   initial: Rotation | None = None,
                   bias: np.ndarray | None = None) -> Rotation:
    """Attitude of the IMU at its sample times from its body angular rates.

    Parameters
    ----------
    timestamps
        float64 ``(N,)`` [s], strictly increasing.
    angular_rates
        float ``(N, 3)`` [rad/s], IMU frame (``ImuData.angular_rates``).
    initial
        ``frame_R_imu`` at the first sample (default identity).
    bias
        float ``(3,)`` [rad/s] subtracted from every sample.

    Returns
    -------
    scipy.spatial.transform.Rotation
        N rotations ``frame_R_imu(t_k)``.
    """
    t = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    w = np.asarray(angular_rates, dtype=np.float64)
    if w.shape != (t.size, 3):
        raise SettingsError(f"expected ({t.size}, 3) angular rates, got {w.shape}")
    if t.size == 0:
        raise ColoradarError("integrate_gyro: no IMU samples")
    if np.any(np.diff(t) <= 0):
        raise ColoradarError("integrate_gyro: IMU timestamps must be strictly increasing")
    if bias is not None:
        w = w - np.asarray(bias, dtype=np.float64).reshape(1, 3)
    r0 = Rotation.identity() if initial is None else initial
    if t.size == 1:
        return Rotation.concatenate([r0])
    steps = Rotation.from_rotvec(0.5 * (w[1:] + w[:-1]) * np.diff(t)[:, None])
    return Rotation.concatenate([r0, r0 * cumulative_rotations(steps)])


def estimate_gyro_bias(timestamps: np.ndarray, angular_rates: np.ndarray,
                       start: float, end: float) -> np.ndarray:
    """Mean angular rate over ``[start, end)`` [s], a window in which the rig is at rest.

    Returns float64 ``(3,)`` [rad/s], to pass as ``bias`` to :func:`integrate_gyro`.
    """
    t = np.asarray(timestamps, dtype=np.float64)
    sel = (t >= start) & (t < end)
    if sel.sum() < 2:
        raise ColoradarError(f"no IMU samples in the bias window [{start:.3f}, {end:.3f}) s")
    return np.asarray(angular_rates, dtype=np.float64)[sel].mean(axis=0)


def dead_reckon(track: EgoVelocityTrack, world_R_base: Rotation, base_T_radar: SE3, *,
                initial_position: np.ndarray | None = None,
                name: str = "radar odometry") -> Trajectory:
    """Integrate ego-velocities with a given rig attitude at every radar frame.

    Parameters
    ----------
    track
        Ego-velocities of the radar (its own frame), M frames; at least one ok.
    world_R_base
        M rotations: the rig's attitude at the track's timestamps.
    base_T_radar
        The radar's extrinsic.
    initial_position
        float ``(3,)``: the base origin at the first frame [m] (default 0).
    name
        Name of the returned trajectory.

    Returns
    -------
    Trajectory
        ``world_T_base`` at the track's timestamps.
    """
    m = len(track)
    if len(world_R_base) != m:
        raise SettingsError(f"{m} frames but {len(world_R_base)} attitudes")
    good = track.ok & np.all(np.isfinite(track.velocity), axis=1)
    if not good.any():
        raise ColoradarError(f"{track.frame}: no frame has a usable ego-velocity "
                             f"({m} frames); nothing to integrate")
    world_R_radar = world_R_base * base_T_radar.rotation
    v = np.zeros((m, 3))
    v[good] = world_R_radar[np.flatnonzero(good)].apply(track.velocity[good])
    if not good.all():
        t_good = track.timestamps[good]
        for ax in range(3):
            v[~good, ax] = np.interp(track.timestamps[~good], t_good, v[good, ax])
    dt = np.diff(track.timestamps)
    steps = 0.5 * (v[1:] + v[:-1]) * dt[:, None]
    p0 = np.zeros(3) if initial_position is None else np.asarray(initial_position, float)
    lever = world_R_base.apply(np.tile(base_T_radar.translation, (m, 1)))
    radar_pos = p0 + lever[0] + np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
    return Trajectory(track.timestamps, radar_pos - lever, world_R_base, name)


def _attitude_from_gyro(times: np.ndarray, imu_t: np.ndarray, imu_rates: np.ndarray,
                        base_R_imu: Rotation, world_R_base0: Rotation,
                        bias: np.ndarray | None) -> Rotation:
    q = integrate_gyro(imu_t, imu_rates, bias=bias)                 # imu0_R_imu(t_k)
    q_at = Slerp(imu_t - imu_t[0], q)(times - imu_t[0])
    world_R_imu0 = world_R_base0 * base_R_imu * q_at[0].inv()
    return world_R_imu0 * q_at * base_R_imu.inv()


def radar_inertial_odometry(track: EgoVelocityTrack, calib: Calibration, *,
                            orientation: OrientationSource = "imu",
                            imu_timestamps: np.ndarray | None = None,
                            imu_rates: np.ndarray | None = None,
                            groundtruth: Trajectory | None = None,
                            initial_pose: SE3 | None = None,
                            gyro_bias: np.ndarray | None = None,
                            radar: str | None = None) -> Trajectory:
    """The rig's trajectory from radar ego-velocities and gyro (or ground-truth) attitude.

    Parameters
    ----------
    track
        Ego-velocities of one radar (:func:`~coloradar.odometry.estimate_ego_velocities`).
    calib
        Extrinsics ``base_T_<radar>`` and ``base_T_imu``.
    orientation
        ``"imu"``: integrate the gyro (needs ``imu_timestamps`` and ``imu_rates``);
        ``"groundtruth"``: the ground-truth attitude (needs ``groundtruth``), an upper bound.
    imu_timestamps, imu_rates
        float64 ``(N,)`` [s] and ``(N, 3)`` [rad/s] gyro samples in the IMU frame.
    groundtruth
        ``world_T_base(t)``; also used for the initial pose when ``initial_pose`` is None.
    initial_pose
        ``world_T_base`` at the first usable radar frame; default: the ground truth there,
        or the identity without ground truth.
    gyro_bias
        float ``(3,)`` [rad/s] subtracted from the gyro.
    radar
        The radar whose extrinsic to use; default ``track.frame``.

    Returns
    -------
    Trajectory
        ``world_T_base`` at the radar frames within the attitude source's time span (frames
        outside it are dropped with a :class:`~coloradar.DataWarning`).
    """
    if orientation not in ORIENTATION_SOURCES:
        raise SettingsError(f"orientation must be one of {', '.join(ORIENTATION_SOURCES)}, "
                            f"got {orientation!r}")
    radar = radar or track.frame
    base_T_radar = sensor_to_base(calib, radar)
    t = track.timestamps
    if orientation == "imu":
        if imu_timestamps is None or imu_rates is None:
            raise ColoradarError("radar-inertial odometry needs IMU samples (imu_timestamps, "
                                 "imu_rates); use orientation='groundtruth' without an IMU")
        imu_t = np.asarray(imu_timestamps, dtype=np.float64)
        inside = (t >= imu_t[0]) & (t <= imu_t[-1])
    else:
        if groundtruth is None:
            raise ColoradarError("orientation='groundtruth' needs the ground truth")
        inside = groundtruth.covers(t)
    if not inside.all():
        warnings.warn(f"{track.frame}: {int((~inside).sum())} of {t.size} radar frames lie "
                      f"outside the {orientation} time span; left out", DataWarning, stacklevel=2)
    sel = np.flatnonzero(inside)
    if sel.size == 0:
        raise ColoradarError(f"{track.frame}: no radar frame lies within the {orientation} "
                             "time span; are the radar and IMU from the same run?")
    sub = _subset(track, sel)
    if initial_pose is None:
        initial_pose = (groundtruth.at(sub.timestamps[0]) if groundtruth is not None
                        and groundtruth.covers(sub.timestamps[:1])[0] else SE3.identity())
    if orientation == "imu":
        base_R_imu = sensor_to_base(calib, "imu").rotation
        att = _attitude_from_gyro(sub.timestamps, imu_t, np.asarray(imu_rates, float),
                                  base_R_imu, initial_pose.rotation, gyro_bias)
    else:
        assert groundtruth is not None  # checked above for this orientation
        att = groundtruth.interpolate_arrays(sub.timestamps)[1]
    return dead_reckon(sub, att, base_T_radar, initial_position=initial_pose.translation,
                       name=f"{radar} radar + {orientation} odometry")


def _subset(track: EgoVelocityTrack, idx: np.ndarray) -> EgoVelocityTrack:
    return EgoVelocityTrack(track.timestamps[idx], track.velocity[idx], track.covariance[idx],
                            track.num_points[idx], track.num_inliers[idx], track.sigma[idx],
                            track.ok[idx], [track.reasons[i] for i in idx], track.frame)
