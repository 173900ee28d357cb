"""Physically based simulation of ColoRadar runs (built-in sample data and known-truth tests).

Quick start::

    from coloradar.sim import simulate_run, load_truth
    res = simulate_run("sim_out", scene="corridor", duration=10, seed=0)
    truth = load_truth(res.run_path)          # what every radar frame saw, rig velocities, …

What run to simulate is one :class:`~coloradar.sim.run.SimulationSpec` (scene, duration, seed,
motion, sensors, layout, IMU model…); ``simulate_run(out, spec, seed=3)`` takes it and/or its
fields as keywords, and how to run it (``overwrite``, ``workers``, ``progress``) beside.

See ``docs/simulator.md`` for the models, the scene file format and the truth file.
"""

from .imu import GRAVITY, GX5_25, ImuModel, simulate_imu
from .lidar import LidarModel, column_times, simulate_scan
from .paths import EllipsePath, LinePath, Sinusoids, path_from_dict
from .radar import (
    RADAR_MODELS,
    PhaseErrors,
    RadarModel,
    RadarTargets,
    make_channel_errors,
    make_coupling,
    onboard_pointcloud,
    radar_frame,
    tx_gains,
    visible_targets,
)
from .radar_if import apply_channel_errors, slow_times, synthesize_adc
from .rest import RestStart
from .run import (
    RATES,
    SENSOR_CHOICES,
    SimResult,
    Simulation,
    SimulationSpec,
    open_simulation,
    resolve_scene,
    run_name,
    simulate_run,
    simulated_calibration,
)
from .scene import Box, MovingObject, Rect, Reflector, Scatterers, Scene, load_scene, scene_from_dict
from .scenes import SCENES, builtin_scene, builtin_scene_dict
from .trajectory import MOTION_PROFILES, RigState, RigTrajectory, make_trajectory
from .truth import SimTruth, load_truth, match_detections

__all__ = [
    "GRAVITY",
    "GX5_25",
    "MOTION_PROFILES",
    "RADAR_MODELS",
    "RATES",
    "SCENES",
    "SENSOR_CHOICES",
    "Box",
    "EllipsePath",
    "ImuModel",
    "LidarModel",
    "LinePath",
    "MovingObject",
    "PhaseErrors",
    "RadarModel",
    "RadarTargets",
    "Rect",
    "Reflector",
    "RestStart",
    "RigState",
    "RigTrajectory",
    "Scatterers",
    "Scene",
    "SimResult",
    "SimTruth",
    "Simulation",
    "SimulationSpec",
    "Sinusoids",
    "apply_channel_errors",
    "builtin_scene",
    "builtin_scene_dict",
    "column_times",
    "load_scene",
    "load_truth",
    "make_channel_errors",
    "make_coupling",
    "make_trajectory",
    "match_detections",
    "onboard_pointcloud",
    "open_simulation",
    "path_from_dict",
    "radar_frame",
    "resolve_scene",
    "run_name",
    "scene_from_dict",
    "simulate_imu",
    "simulate_run",
    "simulate_scan",
    "simulated_calibration",
    "slow_times",
    "synthesize_adc",
    "tx_gains",
    "visible_targets",
]
