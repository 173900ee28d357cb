"""The front end of radar SLAM: the radar-inertial filter, seen through one small adapter.

SLAM needs from odometry, per radar frame: the pose ``world_T_base`` (smoothed, and the
filter's own for comparison), its uncertainty, and
whether the frame had an ego-velocity (its static points are then known by Doppler). This
module is the only place that reads :class:`coloradar.odometry.rio.RioResult`
(:func:`frontend_from_rio`), so a change of the filter's output changes this file only.

Relative uncertainty between two keyframes. The filter reports the marginal covariance ``P_k``
of each pose (position and world-frame attitude). Position and heading are unobservable to a
radar-inertial filter: their uncertainty only grows, by the (nearly independent) increments of
each step, so the covariance of the motion from keyframe ``i`` to ``j`` is approximated by
``P_j − P_i`` (made positive semi-definite), expressed in keyframe ``i``'s frame, plus a floor
per step (:func:`relative_covariance`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ..calib import Calibration
from ..geometry import Trajectory
from ..odometry.ego_velocity import EgoVelocityConfig
from ..odometry.rio import RioConfig, RioResult, rio_odometry
from ..odometry.velocity_track import EgoVelocityTrack, estimate_ego_velocities
from ..odometry.zero_velocity import ZeroVelocityConfig, still_world

__all__ = ["FrontEnd", "FrontEndSettings", "KeyframeRule", "estimate_track", "frontend_from_rio",
           "radar_inertial_frontend", "relative_covariance"]


@dataclass(frozen=True)
class FrontEndSettings:
    """The front end's settings.

    Attributes
    ----------
    ego_velocity
        Ego-velocity estimator settings (:func:`coloradar.odometry.ego_velocity_config` of the
        radar).
    filter
        The radar-inertial filter's settings (default :class:`~coloradar.odometry.rio.RioConfig`).
    seed
        RANSAC seed (frame ``k`` draws with ``SeedSequence([seed, k])``).
    """

    ego_velocity: EgoVelocityConfig
    filter: RioConfig | None = None
    seed: int = 0


@dataclass(frozen=True, eq=False)
class FrontEnd:
    """What SLAM keeps of the odometry (M radar frames, K keyframes).

    Per frame only the trajectory, the frame index and a flag (about 80 bytes a frame); the
    covariances only at the keyframes: memory grows by little with the run's length.

    Attributes
    ----------
    trajectory
        ``world_T_base`` at the frames (IMU-clock times, :attr:`trajectory.timestamps`): the
        filter's poses smoothed when its settings say so (``RioConfig.smooth``, which SLAM
        turns on: :attr:`~coloradar.slam.SlamSettings.smooth_frontend`), what the odometry
        factors are made of.
    frames
        int64 ``(M,)``: each pose's frame in the input clouds (the filter starts at the first
        usable frame, so the first input frames may have no pose).
    ok
        bool ``(M,)``: frames with an ego-velocity.
    keyframes
        int64 ``(K,)``: the keyframes' pose indices (chosen by the caller's rule, see
        :func:`frontend_from_rio`).
    covariance
        float64 ``(K, 6, 6)``: marginal covariance of position [m²] and world-frame attitude
        (rotation vector) [rad²] at the keyframes.
    summary
        A few figures of the filter for ``slam.json``.
    filtered
        The filter's own (causal) poses, as ``coloradar odometry`` gives them; None when
        ``trajectory`` is not smoothed (it is then the filter's).
    """

    trajectory: Trajectory
    frames: np.ndarray
    ok: np.ndarray
    keyframes: np.ndarray
    covariance: np.ndarray
    summary: dict
    filtered: Trajectory | None = None


class KeyframeRule(Protocol):
    """Chooses keyframes one pose at a time as the filter runs (:class:`.submaps.KeyframeSelector`):
    called as :data:`coloradar.odometry.rio_outputs.KeepPose`, it gathers the keyframes' pose
    indices in ``picked``."""

    picked: list[int]

    def __call__(self, index: int, frame: int, position: np.ndarray,
                 attitude: np.ndarray) -> bool: ...


def estimate_track(clouds: Iterable[np.ndarray], timestamps: np.ndarray, config: EgoVelocityConfig,
                   *, seed: int = 0, frame: str = "radar", on_frame=None,
                   zero_velocity: ZeroVelocityConfig | None = None
                   ) -> tuple[EgoVelocityTrack, np.ndarray]:
    """Ego-velocity of every cloud (:func:`~coloradar.odometry.estimate_ego_velocities`), and
    whether each shows a still world (bool ``(M,)``).

    ``on_frame(k, cloud, estimate)`` is called after each frame, so that a caller can keep what
    it needs of the cloud (the static points) without holding every cloud; neither the cloud
    nor the estimate is kept here.
    """
    zv = zero_velocity or ZeroVelocityConfig()
    still = np.zeros(np.size(timestamps), dtype=bool)

    def each(k: int, cloud: np.ndarray, e) -> None:
        still[k] = still_world(cloud, zv, config.min_range)
        if on_frame is not None:
            on_frame(k, cloud, e)

    track = estimate_ego_velocities(clouds, timestamps, config, seed=seed, frame=frame,
                                    on_frame=each)
    return track, still


def frontend_from_rio(res: RioResult, track: EgoVelocityTrack, keyframes: Sequence[int]
                      ) -> FrontEnd:
    """The :class:`FrontEnd` of a filter result and the ego-velocities that drove it: the
    trajectory and, at the ``keyframes`` (pose indices; the result must give the
    covariance there), the covariance. Nothing else of ``res`` is kept (drop it after this
    call)."""
    summary = {"static_frames": int(np.sum(res.static)),
               "time_offset_s": [float(x) for x in res.time_offset[-1]],
               "gyro_bias_rad_s": [float(x) for x in res.gyro_bias[-1]],
               "accel_bias_m_s2": [float(x) for x in res.accel_bias[-1]],
               "stats": res.stats}
    stamps = np.asarray(res.frame_timestamps, dtype=np.float64)
    frames = np.searchsorted(track.timestamps, stamps).clip(0, len(track) - 1).astype(np.int64)
    kfs = np.asarray(keyframes, dtype=np.int64)
    rows = kfs
    if res.kept is not None:
        rows = np.searchsorted(res.kept, kfs).clip(0, max(res.kept.size - 1, 0))
        if kfs.size and not np.array_equal(res.kept[rows], kfs):
            raise ValueError("the filter's result lacks the covariance of some keyframes")
    return FrontEnd(res.trajectory, frames, track.ok[frames], kfs,
                    np.array(res.covariance[rows], dtype=np.float64).reshape(-1, 6, 6), summary,
                    res.filtered)


def radar_inertial_frontend(track: EgoVelocityTrack, still: np.ndarray, calib: Calibration,
                            imu_timestamps: np.ndarray, imu_data: np.ndarray, *, radar: str,
                            keyframes: KeyframeRule, groundtruth: Trajectory | None = None,
                            config: RioConfig | None = None,
                            points: Sequence[np.ndarray] | None = None) -> FrontEnd:
    """Run the radar-inertial filter (:func:`coloradar.odometry.rio_odometry`) on one radar's
    ego-velocities and the IMU, as ``coloradar odometry`` runs it: with ``points`` (the
    frames' clouds ``(N_k, 5)``, e.g. :meth:`.stores.FrameStore.clouds`) every point updates
    the filter (its default, tightly coupled update). The initial pose is the ground truth's
    when given. ``keyframes`` chooses the keyframes as the filter runs, and the filter keeps
    its covariance there only (``keep`` of :func:`~coloradar.odometry.rio_odometry`); its
    result is reduced to a :class:`FrontEnd` and freed on return."""
    res = rio_odometry(track, calib, imu_timestamps, imu_data, radars=(radar,),
                       config=config or RioConfig(), initial_pose=groundtruth, still=[still],
                       points=None if points is None else [points], keep=keyframes)
    return frontend_from_rio(res, track, keyframes.picked)


def _psd(a: np.ndarray) -> np.ndarray:
    w, v = np.linalg.eigh(0.5 * (a + a.T))
    return (v * np.maximum(w, 0.0)) @ v.T


def relative_covariance(fe: FrontEnd, i: int, j: int, floor_translation: float,
                        floor_rotation: float, steps: int = 1, scale: float = 1.0
                        ) -> np.ndarray:
    """Covariance ``(6, 6)`` of the motion ``T_i⁻¹ T_j`` between keyframes ``i < j``
    (numbers in :attr:`FrontEnd.keyframes`), in GTSAM's ``Pose3`` tangent order (rotation
    [rad²], then translation [m²], both in frame ``j``, as GTSAM's ``BetweenFactorPose3``
    measures its error).

    ``P_j − P_i`` of the marginal position and attitude blocks (see the module docstring),
    rotated into frame ``j``, times ``scale``, plus ``steps`` times the floors' squares.
    """
    r_j = fe.trajectory.rotations[int(fe.keyframes[j])].as_matrix()
    dp = _psd(fe.covariance[j, :3, :3] - fe.covariance[i, :3, :3])
    dr = _psd(fe.covariance[j, 3:, 3:] - fe.covariance[i, 3:, 3:])
    out = np.zeros((6, 6))
    out[:3, :3] = scale * (r_j.T @ dr @ r_j) + steps * floor_rotation**2 * np.eye(3)
    out[3:, 3:] = scale * (r_j.T @ dp @ r_j) + steps * floor_translation**2 * np.eye(3)
    return out
