"""Lidar targets per radar frame: a run's lidar scans fused into a voxel map with the ground-truth
poses, then cut, for every radar frame, to that radar's field of view and range in its frame.

The map holds only occupied voxels, as a sorted array of packed voxel indices (a hash of the
integer voxel coordinates, 21 bits per axis) with a hit count and an intensity sum each. Scans
are streamed: each one is reduced to its own voxels and merged in batches, so memory grows with
the number of occupied voxels, never with the number of scans (a 20 m × 3 m × 3 m corridor at
0.1 m holds at most a few hundred thousand). A voxel counts as occupied when ``min_hits`` scans
or more put a point in it.

There is no free-space carving and no visibility test: the target is every occupied voxel
inside the field of view and range, including surfaces hidden behind others. Moving objects
leave a trail in the map (the map is a union over the run).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..calib import HeatmapConfig
from ..errors import MissingDataError, SettingsError
from ..geometry import SE3, Trajectory, VoxelAccumulator, sensor_to_base, trajectory_from_groundtruth
from .views import fov_mask

__all__ = ["MapCut", "TargetSettings", "VoxelMap", "build_voxel_map", "frame_target", "prepare_cut"]


@dataclass(frozen=True)
class TargetSettings:
    """How lidar targets are made.

    Attributes
    ----------
    voxel_size
        Edge of a map voxel [m]; a target point is a voxel centre.
    min_hits
        Scans that must hit a voxel for it to count (2 or more removes single-scan noise and
        most of a moving object's trail).
    lidar_min_range, lidar_max_range
        Range gate of the lidar points fused [m] (the rig and its operator are close).
    stride
        Fuse every ``stride``-th lidar scan.
    target_min_range
        Leave out target points closer to the radar than this [m].
    """

    voxel_size: float = 0.1
    min_hits: int = 1
    lidar_min_range: float = 1.0
    lidar_max_range: float = 60.0
    stride: int = 1
    target_min_range: float = 0.0

    def __post_init__(self) -> None:
        if not (self.voxel_size > 0 and self.min_hits >= 1 and self.stride >= 1
                and 0 <= self.lidar_min_range < self.lidar_max_range
                and self.target_min_range >= 0):
            raise SettingsError(f"TargetSettings: out of range values {asdict(self)}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class VoxelMap:
    """Occupied voxels of a world-frame map, streamed in scan by scan: a
    :class:`coloradar.geometry.VoxelAccumulator` (which holds only the occupied voxels) read as
    hit counts and intensities.

    Parameters
    ----------
    voxel_size
        Voxel edge [m]; voxel ``(i, j, k)`` covers ``[i·s, (i+1)·s) × …`` and its centre is
        ``((i + ½)·s, …)``. Coordinates must lie within ±``2^20·s`` (±105 km at 0.1 m).
    flush_every
        Scans' voxels are merged into the map once this many are pending (or the map's own
        size, if larger): bounds the pending memory.
    """

    def __init__(self, voxel_size: float = 0.1, flush_every: int = 1 << 16):
        self._acc = VoxelAccumulator(voxel_size, flush_every)
        self.voxel_size = self._acc.voxel_size

    @property
    def scans(self) -> int:
        """Scans added so far."""
        return self._acc.clouds

    def add(self, points: np.ndarray) -> None:
        """Add one scan (world frame, float ``(N, ≥3)``; column 3 is intensity when present).

        A voxel's hit count grows by one per scan that puts at least one point in it.
        """
        p = np.asarray(points)
        if p.ndim != 2 or p.shape[1] < 3:
            raise SettingsError(f"expected points of shape (N, >=3), got {p.shape}")
        inten = p[:, 3] if p.shape[1] > 3 else np.zeros(p.shape[0])
        # x y z and intensity only: a voxel's 4th column is the mean over scans of each
        # scan's mean intensity in it.
        self._acc.add(np.column_stack([p[:, :3], inten]).astype(np.float64))

    def __len__(self) -> int:
        return len(self._acc)

    def voxels(self, min_hits: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centres, hit counts and mean intensities of voxels hit ``min_hits`` times or more.

        Returns
        -------
        centres : numpy.ndarray
            float64 ``(M, 3)`` world frame [m], in key order.
        hits : numpy.ndarray
            int64 ``(M,)``: scans that hit each voxel.
        intensity : numpy.ndarray
            float64 ``(M,)``: mean over those scans of the scan's mean intensity in the voxel.
        """
        hits = self._acc.counts()
        keep = hits >= min_hits
        if not len(self._acc):
            return np.zeros((0, 3)), hits, np.zeros(0)
        centres = (self._acc.voxel_indices()[keep] + 0.5) * self.voxel_size
        return centres, hits[keep], self._acc.points()[keep, 3].astype(np.float64)


@dataclass
class MapCut:
    """A voxel map ready for per-frame cuts: occupied centres (world frame, float64 ``(M, 3)``),
    their mean intensities and a KD-tree over them (None for an empty map)."""

    centres: np.ndarray
    intensity: np.ndarray
    tree: Any


def build_voxel_map(seq: Any, settings: TargetSettings | None = None, *,
                    trajectory: Trajectory | None = None, pose_source: str = "groundtruth",
                    progress: Callable[[int, int], None] | None = None) -> VoxelMap:
    """Fuse a run's lidar scans into a :class:`VoxelMap` with its ground-truth poses.

    Every scan inside the trajectory's span is moved into the world frame by
    ``world_T_base(t_scan) @ base_T_lidar`` (no per-point deskewing: the scan's time stamps
    the whole scan) and added. Unreadable scans are reported (``DataWarning``) and left out.

    Parameters
    ----------
    seq
        A :class:`~coloradar.Sequence` with lidar scans and ground truth.
    settings
        Voxel size, range gate, stride.
    trajectory
        ``world_T_base(t)``; default the run's ``pose_source`` poses.
    progress
        ``progress(done, total)`` after each scan.
    """
    st = settings or TargetSettings()
    if "lidar/pointclouds" not in seq.available():
        raise MissingDataError(f"{seq.location}: no lidar scans in this run; lidar targets need "
                               f"them (present: {', '.join(seq.available()) or 'nothing'})")
    traj = trajectory if trajectory is not None else trajectory_from_groundtruth(seq, pose_source)
    stream = seq.lidar.pointclouds
    ts = np.asarray(stream.timestamps, dtype=np.float64)
    idx = np.flatnonzero(traj.covers(ts))[::st.stride]
    mount = sensor_to_base(seq.calib, "lidar")
    trans, rot = traj.interpolate_arrays(ts[idx])
    vmap = VoxelMap(st.voxel_size)
    for n, i in enumerate(idx):
        cloud = stream.read_or_skip(int(i))
        if cloud is not None:
            r = np.linalg.norm(cloud[:, :3], axis=1)
            c = cloud[(r >= st.lidar_min_range) & (r <= st.lidar_max_range)]
            m = (SE3(rot[n], trans[n]) @ mount).matrix()
            world = np.empty((c.shape[0], 4))
            world[:, :3] = c[:, :3].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
            world[:, 3] = c[:, 3] if c.shape[1] > 3 else 0.0
            vmap.add(world)
        if progress is not None:
            progress(n + 1, idx.size)
    return vmap


def prepare_cut(vmap: VoxelMap, min_hits: int = 1) -> MapCut:
    """The occupied voxels of ``vmap`` with a KD-tree for :func:`frame_target`."""
    centres, _, inten = vmap.voxels(min_hits)
    return MapCut(centres, inten, cKDTree(centres) if centres.shape[0] else None)


def frame_target(cut: MapCut | VoxelMap, world_T_radar: np.ndarray | SE3, config: HeatmapConfig,
                 min_range: float = 0.0, min_hits: int = 1) -> np.ndarray:
    """The occupied voxels a radar sees: inside its field of view and range, in its frame.

    Parameters
    ----------
    cut
        A prepared map (:func:`prepare_cut`, reused over frames) or a :class:`VoxelMap`.
    world_T_radar
        The radar's pose at the frame's time (``(4, 4)`` or :class:`SE3`).
    config
        The radar's heatmap grid: a voxel centre counts when it falls in one of its bins
        (:func:`coloradar.learning.views.point_bins`).
    min_range
        Leave out centres closer than this [m].
    min_hits
        With a :class:`VoxelMap`: scans that must hit a voxel.

    Returns
    -------
    numpy.ndarray
        float32 ``(N, 4)``: x y z of voxel centres in the radar frame [m], mean lidar
        intensity; ordered by voxel key.
    """
    c = prepare_cut(cut, min_hits) if isinstance(cut, VoxelMap) else cut
    if c.tree is None:
        return np.zeros((0, 4), dtype=np.float32)
    m = world_T_radar.matrix() if isinstance(world_T_radar, SE3) else np.asarray(world_T_radar)
    reach = (config.num_range_bins - 0.5) * config.range_bin_width
    idx = np.sort(np.asarray(c.tree.query_ball_point(m[:3, 3], reach), dtype=np.int64))
    local = (c.centres[idx] - m[:3, 3]) @ m[:3, :3]    # R^T (p - t): world -> radar
    keep = fov_mask(local, config, min_range)
    out = np.empty((int(keep.sum()), 4), dtype=np.float32)
    out[:, :3] = local[keep]
    out[:, 3] = c.intensity[idx[keep]]
    return out
