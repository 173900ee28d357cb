"""Keyframes, their submaps of static radar points, and the submaps' place descriptors.

- **Static points** of a frame (:func:`static_points`): the points whose range rate is what a
  static point at their place shows under the frame's ego-velocity, ``vr ≈ −d·v``
  (docs/odometry.md): moving objects, multipath ghosts with a wrong Doppler and noise drop out.
- **Frame store** (:class:`.stores.FrameStore`, seen here as :class:`StaticPoints`): each
  frame's cloud and static points, kept in a temporary file (not in memory) until the
  submaps are built, so memory stays flat in the run's length.
- **Keyframes** (:class:`KeyframeSelector`, one pose at a time as the filter runs): every
  ``keyframe_distance`` metres or ``keyframe_angle_deg`` degrees of odometry motion.
- **Submaps** (:func:`build_submap`): the static points of the frames within
  ``submap_window`` seconds of a keyframe, in the keyframe's base frame (with the odometry's
  relative poses), with per-point covariances from range and angle accuracy
  (``R·diag(σ_r², (r σ_az)², (r σ_el)²)·Rᵀ``), voxel-averaged: a summary, not a copy.
- **Descriptor** (:func:`scan_context`): a scan-context grid (Kim and Kim, "Scan Context:
  Egocentric spatial descriptor for place recognition within 3D point cloud map", IROS 2018)
  of the submap seen from above: rings × sectors around the keyframe, each cell the count of
  points (radar points are too sparse for the original's maximum height), normalised per
  column; :func:`descriptor_distance` is the smallest mean cosine distance over the column
  shifts (yaw), and gives that yaw.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ..calib import RadarCalib
from ..geometry import SE3, Trajectory, voxel_downsample
from .settings import SlamSettings

__all__ = ["KeyframeSelector", "PointAccuracy", "StaticPoints", "Submap", "Submaps",
           "build_submap", "descriptor_distance", "point_accuracy", "point_covariances",
           "scan_context",
           "static_mask", "static_points", "surface_covariances"]


@dataclass(frozen=True)
class PointAccuracy:
    """One standard deviation of a radar point in range [m], azimuth and elevation [rad]."""

    range_std: float
    azimuth_std: float
    elevation_std: float


def point_accuracy(radar: RadarCalib, settings: SlamSettings) -> PointAccuracy:
    """The accuracy of the radar's points: the settings' values, else half a range bin and, per
    angle, the array's resolution ``2/N`` in sine (``N`` distinct virtual positions along
    the axis) over ``1.6·√(2·SNR)`` at an SNR of 20 dB (the Cramér–Rao-like accuracy the
    simulator's detector model uses, :func:`coloradar.sim.onboard_pointcloud`), with a floor
    of 0.5°."""
    pos = radar.antenna.virtual.unique_positions
    n_az = max(int(np.unique(pos[:, 0]).size), 1)
    n_el = max(int(np.unique(pos[:, 1]).size), 1)

    def acc(n: int) -> float:
        return max((2.0 / n) / (1.6 * np.sqrt(2.0 * 100.0)), np.radians(0.5))

    return PointAccuracy(
        settings.range_std if settings.range_std is not None
        else 0.5 * float(radar.waveform.range_bin_width),
        np.radians(settings.azimuth_std_deg) if settings.azimuth_std_deg is not None else acc(n_az),
        np.radians(settings.elevation_std_deg) if settings.elevation_std_deg is not None
        else acc(n_el))


def point_covariances(xyz: np.ndarray, acc: PointAccuracy) -> np.ndarray:
    """float64 ``(N, 3, 3)``: covariance of each radar-frame point [m²] from its range and
    angle accuracy (range along the ray, ``r·σ`` across it in azimuth and elevation)."""
    p = np.asarray(xyz, dtype=np.float64)
    r = np.maximum(np.linalg.norm(p, axis=1), 1e-6)
    u = p / r[:, None]
    az = np.arctan2(u[:, 1], u[:, 0])
    el = np.arcsin(np.clip(u[:, 2], -1, 1))
    e_az = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], axis=1)
    e_el = np.stack([-np.sin(el) * np.cos(az), -np.sin(el) * np.sin(az), np.cos(el)], axis=1)
    s = np.stack([np.full_like(r, acc.range_std), r * acc.azimuth_std, r * acc.elevation_std],
                 axis=1)
    basis = np.stack([u, e_az, e_el], axis=2)                       # columns: the three axes
    return np.einsum("nik,nk,njk->nij", basis, s**2, basis)


def static_mask(cloud: np.ndarray, velocity: np.ndarray, threshold: float,
                min_range: float, max_range: float) -> np.ndarray:
    """bool ``(N,)``: the static points of one frame (see :func:`static_points`); all False
    when the cloud is not ``(N, 5)`` or the velocity is unknown."""
    c = np.asarray(cloud, dtype=np.float64)
    if c.ndim != 2 or c.shape[0] == 0 or c.shape[1] < 5 or not np.all(np.isfinite(velocity)):
        return np.zeros(c.shape[0] if c.ndim == 2 else 0, dtype=bool)
    r = np.linalg.norm(c[:, :3], axis=1)
    ok = np.isfinite(r) & (r > min_range) & (r < max_range) & np.isfinite(c[:, 4])
    resid = np.full(c.shape[0], np.inf)
    resid[ok] = c[ok, 4] + (c[ok, :3] / r[ok, None]) @ np.asarray(velocity, dtype=np.float64)
    return np.abs(resid) < threshold


def static_points(cloud: np.ndarray, velocity: np.ndarray, threshold: float,
                  min_range: float, max_range: float) -> np.ndarray:
    """float32 ``(K, 4)``: ``x y z intensity`` of the static points of one frame.

    Parameters
    ----------
    cloud
        float ``(N, 5)``: ``x y z intensity range_rate``, radar frame.
    velocity
        float ``(3,)``: the radar's ego-velocity, radar frame [m/s] (NaN: no point is static).
    threshold
        Largest ``|vr + d·v|`` of a static point [m/s].
    min_range, max_range
        Range limits [m].
    """
    keep = static_mask(cloud, velocity, threshold, min_range, max_range)
    if not keep.any():
        return np.zeros((0, 4), dtype=np.float32)
    return np.asarray(cloud)[keep][:, :4].astype(np.float32)


class KeyframeSelector:
    """The keyframe rule, one pose at a time: the first usable pose, then each usable pose
    ``distance`` [m] or ``angle`` [rad] away from the last keyframe's.

    Called by the radar-inertial filter at each pose it outputs (``keep`` of
    :func:`coloradar.odometry.rio_odometry`), so that SLAM's front end keeps the filter's
    covariance at the keyframes only. It sees the filter's poses before their rigid
    re-anchoring, which changes no distance or relative angle: the keyframes obey the rule
    on the output trajectory too.

    Parameters
    ----------
    usable
        bool ``(M,)`` over the radar frames: those with an ego-velocity.
    distance, angle
        Thresholds [m], [rad].
    """

    def __init__(self, usable: np.ndarray, distance: float, angle: float) -> None:
        self.usable = np.asarray(usable, dtype=bool)
        self.distance, self.angle = float(distance), float(angle)
        self.picked: list[int] = []
        self._last: tuple[np.ndarray, Rotation] | None = None

    def __call__(self, index: int, frame: int, position: np.ndarray,
                 attitude: np.ndarray) -> bool:
        """Whether pose ``index`` (of radar frame ``frame``; ``position`` float ``(3,)`` [m],
        ``attitude`` a rotation matrix ``(3, 3)``) is a keyframe; the keyframes' pose indices
        gather in :attr:`picked`."""
        if not self.usable[frame]:
            return False
        rot = Rotation.from_matrix(attitude)
        pos = np.array(position, dtype=np.float64)
        if self._last is not None:
            p, r = self._last
            if np.linalg.norm(pos - p) < self.distance \
                    and (r.inv() * rot).magnitude() < self.angle:
                return False
        self._last = (pos, rot)
        self.picked.append(int(index))
        return True


@dataclass(frozen=True, eq=False)
class Submap:
    """The static points around one keyframe, in its base frame.

    Attributes
    ----------
    frame
        Index of the keyframe's radar frame.
    points
        float64 ``(N, 3)`` [m], base frame of the keyframe.
    intensity
        float32 ``(N,)``.
    covariances
        float64 ``(N, 3, 3)`` [m²].
    descriptor
        float32 ``(rings, sectors)``: :func:`scan_context`.
    surface
        float64 ``(N, 3, 3)``: :func:`surface_covariances` of the points (None: not computed).
    """

    frame: int
    points: np.ndarray
    intensity: np.ndarray
    covariances: np.ndarray
    descriptor: np.ndarray
    surface: np.ndarray | None = None


class StaticPoints(Protocol):
    """Each frame's static points by frame index (:class:`.stores.FrameStore`)."""

    def read(self, k: int, /) -> np.ndarray: ...


class Submaps(Protocol):
    """The keyframes' submaps by number: a list, or a :class:`.stores.SubmapStore` (on disk)."""

    def __getitem__(self, k: int, /) -> Submap: ...

    def __len__(self) -> int: ...


def surface_covariances(points: np.ndarray, spread: float, k: int = 10) -> np.ndarray:
    """float64 ``(N, 3, 3)``: ``spread²`` in the plane of each point's ``k`` nearest
    neighbours (the normal is the direction of least spread), zero along the normal: a point
    may slide along its surface, not through it (GICP's plane model)."""
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[0]
    if n < 3:
        return np.zeros((n, 3, 3))
    kk = min(k, n)
    _, idx = cKDTree(p).query(p, k=kk)
    nb = p[idx.reshape(n, kk)]
    d = nb - nb.mean(axis=1, keepdims=True)
    _, vec = np.linalg.eigh(np.einsum("nki,nkj->nij", d, d))
    normal = vec[:, :, 0]
    return spread**2 * (np.eye(3) - np.einsum("ni,nj->nij", normal, normal))


def build_submap(k: int, traj: Trajectory, store: StaticPoints, base_T_radar: SE3,
                 acc: PointAccuracy, settings: SlamSettings, frames: np.ndarray | None = None
                 ) -> Submap:
    """The submap of keyframe ``k`` (frames within ``submap_window`` seconds of it); pose
    ``f`` of ``traj`` is frame ``frames[f]`` of the store (default ``f``)."""
    t = traj.timestamps
    lo = int(np.searchsorted(t, t[k] - settings.submap_window, side="left"))
    hi = int(np.searchsorted(t, t[k] + settings.submap_window, side="right"))
    parts = [store.read(int(frames[f]) if frames is not None else f) for f in range(lo, hi)]
    sizes = np.array([p.shape[0] for p in parts])
    if sizes.sum() == 0:
        empty = np.zeros((0, 3))
        return Submap(k, empty, np.zeros(0, np.float32), np.zeros((0, 3, 3)),
                      scan_context(empty, settings))
    pts = np.concatenate(parts).astype(np.float64)
    # k_T_radar for every frame of the window at once, then per point (one matrix product).
    k_T = traj[k].inverse().matrix() @ traj[lo:hi].matrices() @ base_T_radar.matrix()
    per_point = np.repeat(k_T, sizes, axis=0)
    r = per_point[:, :3, :3]
    xyz = np.einsum("nij,nj->ni", r, pts[:, :3]) + per_point[:, :3, 3]
    cov = point_covariances(pts[:, :3], acc)
    cov = np.einsum("nij,njk,nlk->nil", r, cov, r).reshape(-1, 9)
    rows = [np.column_stack([xyz, pts[:, 3], cov])]
    vox = voxel_downsample(np.concatenate(rows), settings.submap_voxel)
    xyz = vox[:, :3]
    return Submap(k, xyz, vox[:, 3].astype(np.float32), vox[:, 4:].reshape(-1, 3, 3),
                  scan_context(xyz, settings), surface_covariances(xyz, settings.inlier_distance))


def scan_context(points: np.ndarray, settings: SlamSettings) -> np.ndarray:
    """float32 ``(rings, sectors)``: point counts per polar cell of the x–y plane (base frame:
    sector 0 starts at +x, counter-clockwise), each column scaled to unit length."""
    nr, ns, rmax = settings.descriptor_rings, settings.descriptor_sectors, settings.descriptor_range
    p = np.asarray(points, dtype=np.float64)
    grid = np.zeros((nr, ns), dtype=np.float32)
    if p.shape[0] == 0:
        return grid
    rho = np.hypot(p[:, 0], p[:, 1])
    keep = rho < rmax
    ring = np.minimum((rho[keep] / rmax * nr).astype(np.int64), nr - 1)
    ang = np.mod(np.arctan2(p[keep, 1], p[keep, 0]), 2 * np.pi)
    sector = np.minimum((ang / (2 * np.pi) * ns).astype(np.int64), ns - 1)
    np.add.at(grid, (ring, sector), 1.0)
    norm = np.linalg.norm(grid, axis=0)
    return np.where(norm > 0, grid / np.where(norm > 0, norm, 1.0), 0.0).astype(np.float32)


def descriptor_distance(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """``(distance, yaw)`` of two :func:`scan_context` grids: the smallest mean cosine distance
    over the columns (sectors occupied in either) over all column shifts, in [0, 1], and the
    yaw [rad] of ``b``'s frame in ``a``'s at that shift (1.0 and 0 when either is empty)."""
    ns = a.shape[1]
    if not np.any(a) or not np.any(b):
        return 1.0, 0.0
    # Column s of b rolled by k lands on column s + k of a: b's frame is turned by k sectors.
    roll = (np.arange(ns)[None, :] - np.arange(ns)[:, None]) % ns          # [k, c] -> c - k
    dots = np.einsum("rc,rkc->kc", a, b[:, roll])
    occ_b = (np.linalg.norm(b, axis=0) > 0)[roll]                           # (ns, ns)
    occupied = (np.linalg.norm(a, axis=0) > 0)[None, :] | occ_b
    dist = np.where(occupied, 1.0 - dots, 0.0).sum(axis=1) / np.maximum(occupied.sum(axis=1), 1)
    k = int(np.argmin(dist))
    return float(dist[k]), float(k * 2 * np.pi / ns)
