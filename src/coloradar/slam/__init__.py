"""Radar SLAM: keyframe submaps, loop closures and a pose graph, from one radar and the IMU.

The radar-inertial filter of :mod:`coloradar.odometry` is the front end (:mod:`.frontend`);
keyframe submaps of static radar points (:mod:`.submaps`) are registered with small_gicp
(:mod:`.registration`); loop candidates come from a scan-context descriptor within the
odometry's uncertainty and are verified (:mod:`.loops`); GTSAM optimises the pose graph with
robust loop factors and a consistency test (:mod:`.graph`); :mod:`.system` runs it all
(:func:`slam_from_clouds`), :mod:`.run` on a run and to an output folder (:func:`run_slam`).

GTSAM and small_gicp are the optional extra ``[slam]``; without them the calls that need them
raise :class:`~coloradar.errors.MissingDependencyError` naming it. See ``docs/slam.md``.
"""

from .settings import SlamSettings
from .system import SlamResult, build_slam_map, correct_frames, slam_from_clouds

__all__ = ["SlamResult", "SlamSettings", "build_slam_map", "correct_frames", "slam_from_clouds"]
