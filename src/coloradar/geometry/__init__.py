"""Geometry and time: rigid transforms, extrinsics, pose interpolation, stream association,
rig velocity and point maps.

Naming: ``a_T_b`` maps coordinates in frame ``b`` to frame ``a`` (the pose of ``b`` in ``a``);
``world_T_sensor = world_T_base @ base_T_sensor``. See ``docs/geometry.md``.

:mod:`.se3` is the floor: :mod:`.trajectory` builds on it, and ``SE3 @ Trajectory`` is answered
by ``Trajectory.__rmatmul__``, so that ``se3`` imports nothing above it.
"""

from .cloud_io import (
    default_fields,
    read_pcd,
    read_ply,
    read_point_file,
    write_pcd,
    write_ply,
    write_point_file,
)
from .frames import (
    cloud_to_base,
    cloud_to_world,
    sensor_a_T_sensor_b,
    sensor_to_base,
    world_T_sensor,
)
from .mapping import (
    MAP_SOURCES,
    MapSettings,
    PointMap,
    VoxelAccumulator,
    accumulate_clouds,
    build_map,
    voxel_downsample,
)
from .se3 import SE3, transform_points
from .timesync import associate, nearest_indices, window_indices
from .trajectory import ExtrapolationError, Trajectory, trajectory_from_groundtruth
from .velocity import RigVelocity, rig_velocity, static_range_rate

__all__ = [
    "MAP_SOURCES",
    "SE3",
    "ExtrapolationError",
    "MapSettings",
    "PointMap",
    "RigVelocity",
    "Trajectory",
    "VoxelAccumulator",
    "accumulate_clouds",
    "associate",
    "build_map",
    "cloud_to_base",
    "cloud_to_world",
    "default_fields",
    "nearest_indices",
    "read_pcd",
    "read_ply",
    "read_point_file",
    "rig_velocity",
    "sensor_a_T_sensor_b",
    "sensor_to_base",
    "static_range_rate",
    "trajectory_from_groundtruth",
    "transform_points",
    "voxel_downsample",
    "window_indices",
    "world_T_sensor",
    "write_pcd",
    "write_ply",
    "write_point_file",
]
