"""Sensor extrinsics and moving point clouds between the sensor, base and world frames.

Frames (docs/conventions.md §3):

- ``<sensor>``: each sensor's own frame; the radars' is x boresight, y left, z up.
- ``base``: the rig frame (x right, y forward, z up); ``calib/transforms/base_to_<sensor>.txt``
  is ``base_T_<sensor>``.
- ``world``: fixed at the run's start pose; the ground truth is ``world_T_base(t)``.

A point cloud stamped ``t`` is moved into the world frame with
``world_T_base(t) @ base_T_sensor``, the ground truth interpolated at ``t``.
"""

from __future__ import annotations

import numpy as np

from ..calib import Calibration
from ..errors import MissingDataError
from .se3 import SE3
from .trajectory import Trajectory

__all__ = [
    "cloud_to_base",
    "cloud_to_world",
    "sensor_a_T_sensor_b",
    "sensor_to_base",
    "world_T_sensor",
]


def sensor_to_base(calib: Calibration, sensor: str) -> SE3:
    """``base_T_<sensor>``: maps ``sensor`` coordinates into the base frame.

    Parameters
    ----------
    calib
        The rig calibration (``calib.transforms``).
    sensor
        ``"cascade"``, ``"single_chip"``, ``"lidar"``, ``"imu"``, ``"vicon"`` or ``"base"``
        (identity).

    Raises
    ------
    MissingDataError
        The calibration has no transform for ``sensor``.
    """
    if sensor == "base":
        return SE3.identity()
    ext = calib.transforms.get(sensor)
    if ext is None:
        known = ", ".join(sorted(calib.transforms)) or "none"
        raise MissingDataError(f"calibration {calib.source}: no base_to_{sensor}.txt transform "
                               f"(known sensors: {known})")
    return SE3.from_extrinsic(ext)


def sensor_a_T_sensor_b(calib: Calibration, a: str, b: str) -> SE3:
    """``a_T_b``: maps coordinates in sensor ``b``'s frame to sensor ``a``'s frame.

    ``sensor_a_T_sensor_b(calib, "cascade", "lidar").apply(lidar_xyz)`` gives the lidar's
    points in the cascade radar's frame.
    """
    return sensor_to_base(calib, a).inverse() @ sensor_to_base(calib, b)


def world_T_sensor(trajectory: Trajectory, calib: Calibration, sensor: str,
                   times: np.ndarray, tolerance: float = 0.0) -> Trajectory:
    """Poses of ``sensor`` in the world frame at ``times`` (e.g. a stream's timestamps).

    Parameters
    ----------
    trajectory
        ``world_T_base(t)``, e.g. :func:`~coloradar.geometry.trajectory_from_groundtruth`.
    calib, sensor
        Which extrinsic to append.
    times
        float64 ``(M,)`` [s], strictly increasing.
    tolerance
        See :meth:`Trajectory.interpolate`.
    """
    return trajectory.interpolate(times, tolerance) @ sensor_to_base(calib, sensor)


def cloud_to_base(cloud: np.ndarray, calib: Calibration, sensor: str) -> np.ndarray:
    """A sensor's point cloud ``(N, C)`` (x y z first) in the base frame; other columns kept."""
    return sensor_to_base(calib, sensor).apply_to_cloud(cloud)


def cloud_to_world(cloud: np.ndarray, timestamp: float, trajectory: Trajectory,
                   calib: Calibration, sensor: str, tolerance: float = 0.0) -> np.ndarray:
    """A sensor's point cloud ``(N, C)`` stamped ``timestamp`` [s] in the world frame.

    Raises
    ------
    ExtrapolationError
        ``timestamp`` is outside the trajectory's span (beyond ``tolerance``).
    """
    pose = trajectory.at(timestamp, tolerance) @ sensor_to_base(calib, sensor)
    return pose.apply_to_cloud(cloud)
