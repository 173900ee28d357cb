"""Learning data: time-synchronised radar / lidar samples, image views, lidar targets, metrics.

* :mod:`.samples` — :class:`SyncedSamples`, a map-style dataset over run folders or exported
  ``.h5`` files (one sample per radar frame).
* :mod:`.views` — range–azimuth and bird's-eye images of heatmaps and lidar clouds on one grid.
* :mod:`.targets` — a run's lidar scans fused into a voxel map, cut to each radar frame's view.
* :mod:`.metrics` — Chamfer, modified Hausdorff, F-score, BEV occupancy IoU / precision / recall.
* :mod:`.splits` — run splits by a stable hash; the named splits of published work.
* :mod:`.batching` — numpy and PyTorch collation; :func:`torch_dataset` (torch optional).
* :mod:`.scoring` — a folder of predicted clouds against a run's targets (``coloradar score``).

* :mod:`.h5_file` — :class:`~.h5_file.H5Run`, the reader of the files written by ``coloradar
  export RUN OUT.h5 --format hdf5`` (their writer and layout: :mod:`coloradar.interop.hdf5`,
  which imports this package; nothing here imports ``interop``). See docs/learning.md.
"""

from .batching import VARIABLE_KEYS, collate_numpy, collate_torch, torch_dataset
from .metrics import (
    CloudScores,
    chamfer_distance,
    f_score,
    mean_scores,
    modified_hausdorff,
    nearest_distances,
    occupancy_scores,
    score_clouds,
)
from .samples import PRODUCTS, SampleOptions, SyncedSamples, ViewOptions
from .scoring import ScoreReport, score_folder
from .splits import named_split, named_splits, split_runs
from .targets import MapCut, TargetSettings, VoxelMap, build_voxel_map, frame_target, prepare_cut
from .views import (
    DB_FLOOR,
    LIDAR_CHANNELS,
    BevGrid,
    BevProjector,
    fov_mask,
    lidar_bev,
    lidar_polar,
    point_bins,
    radar_bev,
    radar_polar,
)

__all__ = [
    "DB_FLOOR",
    "LIDAR_CHANNELS",
    "PRODUCTS",
    "VARIABLE_KEYS",
    "BevGrid",
    "BevProjector",
    "CloudScores",
    "MapCut",
    "SampleOptions",
    "ScoreReport",
    "SyncedSamples",
    "TargetSettings",
    "ViewOptions",
    "VoxelMap",
    "build_voxel_map",
    "chamfer_distance",
    "collate_numpy",
    "collate_torch",
    "f_score",
    "fov_mask",
    "frame_target",
    "lidar_bev",
    "lidar_polar",
    "mean_scores",
    "modified_hausdorff",
    "named_split",
    "named_splits",
    "nearest_distances",
    "occupancy_scores",
    "point_bins",
    "prepare_cut",
    "radar_bev",
    "radar_polar",
    "score_clouds",
    "score_folder",
    "split_runs",
    "torch_dataset",
]
