"""Radar ego-velocity, radar–inertial odometry, and trajectory evaluation.

- :func:`estimate_ego_velocity`: the sensor's 3D velocity from one point cloud's range rates
  (RANSAC + least squares, with covariance), robust to moving objects and false alarms.
- :func:`rio_odometry`: the radar-inertial error-state EKF (IMU propagation, radar velocity
  updates, automatic zero-velocity updates, online biases, time offset and extrinsic rotation).
- :func:`radar_inertial_odometry`: the dead-reckoning baseline, ego-velocities integrated with
  gyro (or ground-truth) attitude into the rig's trajectory.
- :func:`run_odometry`, :func:`evaluate_odometry`: the ``coloradar odometry`` and
  ``coloradar evaluate`` commands as functions; :func:`ego_velocity_report` for summaries.
- :func:`absolute_trajectory_error`, :func:`relative_pose_error`, :func:`velocity_errors`,
  :func:`umeyama_alignment`: evaluation against ground truth; TUM files for ``evo``;
  :func:`posyaw_alignment` and :func:`rpg_relative_error`: the radar-inertial literature's
  protocol (rpg_trajectory_evaluation). The
  error records, :class:`Evaluation` among them, live in :mod:`.metrics`, below both
  :mod:`.evaluation` (which computes them) and :mod:`.plot` (which draws them).

See ``docs/odometry.md``.
"""

from .alignment import Alignment, posyaw_alignment, umeyama_alignment
from .dead_reckoning import (
    ORIENTATION_SOURCES,
    cumulative_rotations,
    dead_reckon,
    estimate_gyro_bias,
    integrate_gyro,
    radar_inertial_odometry,
)
from .doppler import DopplerConfig, PointNoise
from .ego_velocity import (
    EgoVelocity,
    EgoVelocityConfig,
    VelocityPrior,
    estimate_ego_velocity,
    static_inlier_threshold,
)
from .evaluation import (
    EVALUATION_FILES,
    Evaluation,
    evaluate_odometry,
    evaluate_trajectory,
    evaluation_dict,
    format_evaluation,
    write_evaluation,
)
from .metrics import (
    RPE_PAIRINGS,
    RPG_LENGTHS,
    ATEResult,
    RPEPairing,
    RPEResult,
    VelocityErrors,
    absolute_trajectory_error,
    apply_alignment,
    associate_trajectories,
    path_length,
    relative_pose_error,
    rpe_pairs,
    rpg_relative_error,
    velocity_errors,
)
from .pipeline import (
    ESTIMATORS,
    SOURCES,
    EgoVelocityJob,
    OdometryJob,
    OdometryOutput,
    default_source,
    ego_velocity_config,
    run_ego_velocity,
    run_odometry,
)
from .report import ego_velocity_report
from .rio import RioConfig, RioResult, rio_odometry, rio_summary
from .tum import format_tum, parse_tum, read_tum, write_tum
from .velocity_track import (
    EgoVelocityTrack,
    estimate_ego_velocities,
    format_velocity_table,
    parse_velocity_table,
    read_velocity_table,
    write_velocity_table,
)

__all__ = [
    "ESTIMATORS",
    "EVALUATION_FILES",
    "ORIENTATION_SOURCES",
    "RPE_PAIRINGS",
    "RPG_LENGTHS",
    "SOURCES",
    "ATEResult",
    "Alignment",
    "DopplerConfig",
    "EgoVelocity",
    "EgoVelocityConfig",
    "EgoVelocityJob",
    "EgoVelocityTrack",
    "Evaluation",
    "OdometryJob",
    "OdometryOutput",
    "PointNoise",
    "RPEPairing",
    "RPEResult",
    "RioConfig",
    "RioResult",
    "VelocityErrors",
    "VelocityPrior",
    "absolute_trajectory_error",
    "apply_alignment",
    "associate_trajectories",
    "cumulative_rotations",
    "dead_reckon",
    "default_source",
    "ego_velocity_config",
    "ego_velocity_report",
    "estimate_ego_velocities",
    "estimate_ego_velocity",
    "estimate_gyro_bias",
    "evaluate_odometry",
    "evaluate_trajectory",
    "evaluation_dict",
    "format_evaluation",
    "format_tum",
    "format_velocity_table",
    "integrate_gyro",
    "parse_tum",
    "parse_velocity_table",
    "path_length",
    "posyaw_alignment",
    "radar_inertial_odometry",
    "read_tum",
    "read_velocity_table",
    "relative_pose_error",
    "rio_odometry",
    "rio_summary",
    "rpe_pairs",
    "rpg_relative_error",
    "run_ego_velocity",
    "run_odometry",
    "static_inlier_threshold",
    "umeyama_alignment",
    "velocity_errors",
    "write_evaluation",
    "write_tum",
    "write_velocity_table",
]
