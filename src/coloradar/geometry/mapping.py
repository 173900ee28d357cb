"""Accumulating a map: point clouds of a time window in the world frame, voxel down-sampled."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import MissingDataError, SettingsError
from ..formats.layout import LAYOUTS
from .frames import sensor_to_base
from .se3 import SE3
from .timesync import window_indices
from .trajectory import Trajectory, trajectory_from_groundtruth

__all__ = ["MAP_SOURCES", "MapSettings", "PointMap", "VoxelAccumulator", "accumulate_clouds",
           "build_map", "voxel_downsample"]

MAP_SOURCES = {s.sensor: s.name for lay in LAYOUTS.values() for s in lay.frames.values()
               if s.kind in ("lidar_points", "radar_points")}
"""Sensor name -> its point-cloud stream (:mod:`coloradar.formats.layout`): ``lidar``,
``cascade``, ``single_chip``."""


def voxel_downsample(points: np.ndarray, voxel_size: float,
                     reduce: str = "mean") -> np.ndarray:
    """Keep one point per occupied voxel of a regular grid.

    Parameters
    ----------
    points
        float ``(N, C)``, x y z first [m].
    voxel_size
        Edge of a cubic voxel [m]; voxel ``k`` covers ``[k·size, (k+1)·size)`` on each axis.
    reduce
        ``"mean"``: every column averaged over the voxel's points (the centroid, and mean
        intensity); ``"first"``: the first point (in input order) of each voxel.

    Returns
    -------
    numpy.ndarray
        ``(M, C)``, same dtype, ordered by voxel key.
    """
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] < 3:
        raise SettingsError(f"expected points of shape (N, C>=3), got {p.shape}")
    if not voxel_size > 0:
        raise SettingsError(f"voxel_size must be positive, got {voxel_size}")
    finite = np.all(np.isfinite(p[:, :3]), axis=1)
    p = p[finite]
    if p.shape[0] == 0:
        return p.copy()
    keys = np.floor(p[:, :3].astype(np.float64) / voxel_size).astype(np.int64)
    keys -= keys.min(axis=0)
    dims = keys.max(axis=0) + 1
    if np.prod(dims.astype(np.float64)) < 2.0**62:
        flat = np.ravel_multi_index(keys.T, dims)
        _, first, inverse = np.unique(flat, return_index=True, return_inverse=True)
    else:  # astronomically sparse extents: fall back to row-wise unique
        _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    if reduce == "first":
        return p[first].copy()
    if reduce != "mean":
        raise SettingsError(f"reduce must be 'mean' or 'first', got {reduce!r}")
    m = first.size
    counts = np.bincount(inverse, minlength=m).astype(np.float64)
    out = np.empty((m, p.shape[1]), dtype=p.dtype)
    for j in range(p.shape[1]):  # a handful of columns, each one vectorised bincount
        out[:, j] = np.bincount(inverse, weights=p[:, j], minlength=m) / counts
    return out


_KEY_BITS = 21                    # per axis: ±2^20 voxels (±10 km at 1 cm) in one int64
_KEY_OFFSET = 1 << (_KEY_BITS - 1)


class VoxelAccumulator:
    """A voxel map built one cloud at a time, holding only the occupied voxels.

    Each added cloud is reduced to its per-voxel centroids (:func:`voxel_downsample`), which
    are summed into the map's voxels; :meth:`points` is, per voxel, the mean of the centroids
    of the clouds that saw it (every cloud counting once, however many of its points fell in
    the voxel), and :meth:`counts` the number of those clouds. Memory is that of the occupied
    voxels (``C + 1`` float64 and one int64 key each), whatever the number of clouds: a map of
    a long run costs what its extent costs.

    Parameters
    ----------
    voxel_size
        Edge of a cubic voxel [m]; voxel ``k`` covers ``[k·size, (k+1)·size)`` on each axis.
    flush_every
        Clouds' voxels wait in a batch and are merged into the map (one sort) once more are
        waiting than the larger of this and the map's own size: the merge costs O(log M) per
        voxel added, and the waiting voxels never outnumber the map's by much.
    """

    def __init__(self, voxel_size: float, flush_every: int = 1 << 16):
        if not voxel_size > 0:
            raise SettingsError(f"voxel_size must be positive, got {voxel_size}")
        self.voxel_size = float(voxel_size)
        self.clouds = 0
        self._keys = np.zeros(0, dtype=np.int64)        # sorted, one per occupied voxel
        self._sums: np.ndarray | None = None            # float64 (M, C)
        self._counts = np.zeros(0, dtype=np.int64)
        self._dtype: np.dtype = np.dtype(np.float32)
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []
        self._pending_n = 0
        self._flush_every = max(1, int(flush_every))

    def __len__(self) -> int:
        self._flush()
        return int(self._keys.size)

    def _key(self, xyz: np.ndarray) -> np.ndarray:
        v = np.floor(xyz.astype(np.float64) / self.voxel_size).astype(np.int64) + _KEY_OFFSET
        if v.size and (v.min() < 0 or v.max() >= 1 << _KEY_BITS):
            raise SettingsError(f"a point lies more than {_KEY_OFFSET:,} voxels "
                                f"({_KEY_OFFSET * self.voxel_size:g} m) from the origin; use a "
                                "larger voxel size")
        return (v[:, 0] << (2 * _KEY_BITS)) | (v[:, 1] << _KEY_BITS) | v[:, 2]

    def add(self, points: np.ndarray) -> None:
        """Add one cloud, float ``(N, C)`` x y z first [m] (non-finite points are dropped)."""
        self.clouds += 1
        cen = voxel_downsample(np.asarray(points), self.voxel_size)
        if cen.shape[0] == 0:
            return
        if self._sums is None:
            self._sums = np.zeros((0, cen.shape[1]))
            self._dtype = cen.dtype
        elif cen.shape[1] != self._sums.shape[1]:
            raise SettingsError(f"a cloud of {cen.shape[1]} columns added to a map of "
                                f"{self._sums.shape[1]}")
        # One key per voxel of this cloud (unique already); the voxel is keyed by the cloud's
        # centroid, which lies inside it.
        self._pending.append((self._key(cen[:, :3]), cen.astype(np.float64)))
        self._pending_n += cen.shape[0]
        if self._pending_n > max(self._keys.size, self._flush_every):
            self._flush()

    def _flush(self) -> None:
        if not self._pending or self._sums is None:
            return
        keys = np.concatenate([self._keys, *(k for k, _ in self._pending)])
        sums = np.concatenate([self._sums, *(c for _, c in self._pending)])
        counts = np.concatenate([self._counts,
                                 *(np.ones(k.size, dtype=np.int64) for k, _ in self._pending)])
        self._pending, self._pending_n = [], 0
        self._keys, inv = np.unique(keys, return_inverse=True)
        inv = np.asarray(inv).reshape(-1)
        m = self._keys.size
        # bincount adds in array order: the map's sum first, then each cloud in turn.
        self._sums = np.stack([np.bincount(inv, weights=sums[:, j], minlength=m)
                               for j in range(sums.shape[1])], axis=1)
        self._counts = np.bincount(inv, weights=counts, minlength=m).astype(np.int64)

    def points(self) -> np.ndarray:
        """``(M, C)`` one point per occupied voxel (the mean of its clouds' centroids), in
        the dtype of the clouds added, ordered by voxel (x, then y, then z)."""
        self._flush()
        if self._sums is None:
            return np.zeros((0, 3), dtype=np.float32)
        return (self._sums / self._counts[:, None]).astype(self._dtype)

    def counts(self) -> np.ndarray:
        """int64 ``(M,)``: the number of clouds that put a point in each voxel (order of
        :meth:`points`)."""
        self._flush()
        return self._counts.copy()

    def voxel_indices(self) -> np.ndarray:
        """int64 ``(M, 3)``: voxel ``(i, j, k)`` of each occupied voxel (order of
        :meth:`points`); its centre is ``(ijk + ½)·voxel_size``."""
        self._flush()
        mask = (1 << _KEY_BITS) - 1
        k = self._keys
        return np.stack([(k >> (2 * _KEY_BITS)) & mask, (k >> _KEY_BITS) & mask, k & mask],
                        axis=1) - _KEY_OFFSET


def accumulate_clouds(clouds: Iterable[np.ndarray | None], poses: Iterable[SE3],
                      voxel_size: float | None = None, max_range: float | None = None,
                      min_range: float = 0.0) -> np.ndarray:
    """Move each cloud with its pose and stack them, optionally down-sampling.

    Parameters
    ----------
    clouds
        Iterable of float ``(N_i, C)`` clouds, sensor frame (None: a frame left out).
    poses
        ``world_T_sensor`` of each cloud.
    voxel_size
        Down-sample into a :class:`VoxelAccumulator`, one cloud at a time, so that memory is
        that of the occupied voxels however long the window: a voxel's point is the mean of
        the per-frame centroids, every frame that saw the voxel counting once. None: every
        point is kept.
    max_range, min_range
        Keep points whose distance from the sensor is in ``[min_range, max_range]`` [m] (lidars
        see the rig itself; radars are noisy far out).

    Returns
    -------
    numpy.ndarray
        float32 ``(M, C)``, world frame.
    """
    acc = VoxelAccumulator(voxel_size) if voxel_size else None
    parts = []
    for cloud, pose in zip(clouds, poses, strict=True):
        if cloud is None:  # a frame that could not be read (reported where it was read)
            continue
        c = np.asarray(cloud, dtype=np.float32)
        r = np.linalg.norm(c[:, :3], axis=1)
        keep = r >= min_range
        if max_range is not None:
            keep &= r <= max_range
        w = pose.apply_to_cloud(c[keep])
        if acc is not None:
            acc.add(w)
        else:
            parts.append(w)
    if acc is not None:
        return acc.points()
    if not parts:
        return np.zeros((0, 3), dtype=np.float32)
    return np.concatenate(parts, axis=0)


@dataclass(frozen=True, eq=False)
class PointMap:
    """A point map of a run in the world frame.

    Attributes
    ----------
    points
        float32 ``(M, C)``.
    fields
        Column names (``x y z intensity`` or ``x y z intensity range_rate``).
    sensor
        Which sensor's clouds.
    frame_indices
        int64: the stream indices used.
    timestamps
        float64: their timestamps [s].
    points_from
        The stream the points came from: ``"pointclouds"`` (the sensor's own, or those
        ``coloradar process`` wrote) or ``"adc"`` (computed from the raw ADC frames).
    """

    points: np.ndarray
    fields: tuple[str, ...]
    sensor: str
    frame_indices: np.ndarray
    timestamps: np.ndarray
    points_from: str = "pointclouds"


@dataclass(frozen=True)
class MapSettings:
    """What part of a run :func:`build_map` accumulates, and how (each field is also one of its
    keywords, documented there)."""

    start: float = 0.0
    duration: float | None = None
    voxel_size: float | None = None
    stride: int = 1
    max_range: float | None = None
    min_range: float = 0.0
    processing: Mapping[str, Any] | None = None


def build_map(seq, sensor: str = "lidar", settings: MapSettings | None = None, *,
              trajectory: Trajectory | None = None,
              progress: Callable[[int, int], None] | None = None, **fields: Any) -> PointMap:
    """Accumulate a run's point clouds into a world-frame map.

    Parameters
    ----------
    seq
        A sequence (:func:`coloradar.open_sequence`).
    sensor
        ``"lidar"``, ``"single_chip"`` or ``"cascade"``. A radar's points are its point-cloud
        stream when the sequence has one (the single chip's own, or those of
        ``open_sequence(run, products=OUT)``), else computed from its ADC frames with
        :class:`coloradar.dsp.RadarProcessor` (as ``coloradar odometry`` and ``export`` do).
    settings
        A :class:`MapSettings` (its fields are listed below); keyword arguments named like its
        fields replace them, so ``build_map(seq, "lidar", start=1.0, voxel_size=0.1)`` works.
    trajectory
        ``world_T_base(t)``; default: the run's ground truth.
    progress
        Called as ``progress(done, total)`` after each frame.

    Other Parameters
    ----------------
    start, duration
        Window in seconds from the start of the ground truth; None duration = to the end.
        Frames outside the ground truth's span are left out.
    voxel_size
        Down-sample to one point per voxel of this size [m].
    stride
        Use every ``stride``-th frame of the window.
    max_range, min_range
        Range gate per point, in the sensor frame [m].
    processing
        Keyword arguments of :class:`coloradar.dsp.RadarProcessor` when the points are
        computed from ADC frames.
    """
    opts = replace(settings or MapSettings(), **fields)
    start, duration, stride = opts.start, opts.duration, opts.stride
    if sensor not in MAP_SOURCES:
        raise MissingDataError(f"no point clouds for {sensor!r}; expected one of "
                               f"{', '.join(MAP_SOURCES)}")
    name = MAP_SOURCES[sensor]
    have = seq.available()
    convert: Callable[[np.ndarray], np.ndarray] | None = None
    points_from = "pointclouds"
    if name not in have and sensor != "lidar" and f"{sensor}/adc" in have:
        from ..dsp import RadarProcessor  # only for a radar without point clouds

        proc = RadarProcessor(seq.calib.radar(sensor), **dict(opts.processing or {}))
        convert, name, points_from = proc.pointcloud, f"{sensor}/adc", "adc"
    if name not in have:
        hint = (" (radar point clouds that coloradar process wrote are read with "
                "open_sequence(run, products=OUT), --products OUT)"
                if sensor != "lidar" else "")
        raise MissingDataError(f"{getattr(seq, 'name', 'run')}: no {name} stream and no "
                               f"{sensor}/adc in this run "
                               f"(present: {', '.join(have) or 'nothing'}){hint}"
                               if sensor != "lidar" else
                               f"{getattr(seq, 'name', 'run')}: no {name} stream in this run "
                               f"(present: {', '.join(have) or 'nothing'})")
    stream = seq.stream(name)
    traj = trajectory if trajectory is not None else trajectory_from_groundtruth(seq)
    t0 = traj.start + start
    t1 = None if duration is None else t0 + duration
    ts = np.asarray(stream.timestamps, dtype=np.float64)
    idx = window_indices(ts, t0, t1)
    idx = idx[traj.covers(ts[idx])][::max(1, int(stride))]
    if idx.size == 0:
        until = "the end" if duration is None else f"{start + duration:g} s"
        raise MissingDataError(f"{getattr(seq, 'name', 'run')}: no {sensor} frames between "
                               f"{start:g} s and {until} of the ground truth")
    mount = sensor_to_base(seq.calib, sensor)
    poses = traj.interpolate_arrays(ts[idx])
    world = [SE3(poses[1][k], poses[0][k]) @ mount for k in range(idx.size)]

    used = np.ones(idx.size, dtype=bool)

    def clouds():
        for k, i in enumerate(idx):
            # A bad frame is reported (DataWarning) and left out, like `coloradar process` does.
            cloud = stream.read_or_skip(int(i))
            used[k] = cloud is not None
            yield cloud if cloud is None or convert is None else convert(cloud)
            if progress is not None:
                progress(k + 1, idx.size)

    pts = accumulate_clouds(clouds(), world, opts.voxel_size, opts.max_range, opts.min_range)
    from .cloud_io import default_fields

    return PointMap(pts, default_fields(pts.shape[1]), sensor, idx[used], ts[idx[used]],
                    points_from)
