"""Probabilistic occupancy maps of radar (and lidar) data: ``coloradar.mapping``.

A sparse, voxel-hashed 3-D log-odds map (:mod:`.voxels`), filled by inverse sensor models of
point clouds (:mod:`.sensor_model`: a return's occupancy spread by its range and angle
uncertainty, free space along its ray) and of 3-D heatmaps (:mod:`.heatmap_model`: every cell
against the heatmap's own noise floor), one frame at a time along any trajectory
(:mod:`.build`), a radar's movers and ghosts left out by the Doppler test of a static world
(:mod:`.static_gate`); a 2-D grid of a height band in the ROS ``map_server`` format (:mod:`.grid2d`);
scores against a reference (:mod:`.quality`). See ``docs/mapping.md``.

Layer: above ``geometry`` (and ``dsp``, for the heatmap cells' placement), below ``sim``;
``slam`` builds its map with it, ``viz`` draws it, ``cli`` runs it.
"""

from .build import (
    MAP_INPUTS,
    OccupancyJob,
    OccupancyResult,
    build_occupancy_map,
    frame_evidence,
    occupancy_from_frames,
)
from .grid2d import OccupancyGrid2D, grid_iou, occupancy_grid, write_map_server
from .heatmap_model import HeatmapModel, heatmap_evidence
from .quality import MapQuality, format_map_quality, map_quality
from .sensor_model import (
    PointSensorModel,
    angle_std_floor,
    lidar_sensor_model,
    point_evidence,
    radar_sensor_model,
)
from .static_gate import StaticGate, StaticTest, static_frames, static_mask
from .voxels import FREE, OCCUPIED, UNKNOWN, OccupancyMap, OccupancySettings

__all__ = [
    "FREE",
    "MAP_INPUTS",
    "OCCUPIED",
    "UNKNOWN",
    "HeatmapModel",
    "MapQuality",
    "OccupancyGrid2D",
    "OccupancyJob",
    "OccupancyMap",
    "OccupancyResult",
    "OccupancySettings",
    "PointSensorModel",
    "StaticGate",
    "StaticTest",
    "angle_std_floor",
    "build_occupancy_map",
    "format_map_quality",
    "frame_evidence",
    "grid_iou",
    "heatmap_evidence",
    "lidar_sensor_model",
    "map_quality",
    "occupancy_from_frames",
    "occupancy_grid",
    "point_evidence",
    "radar_sensor_model",
    "static_frames",
    "static_mask",
    "write_map_server",
]
