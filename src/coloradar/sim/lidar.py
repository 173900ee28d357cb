"""An Ouster OS1-64-like spinning lidar, ray-cast against the scene.

Scan layout (what :func:`simulate_scan` returns): ``beams × columns`` points in row-major order,
index ``beam·columns + column``; beam 0 is the top one (elevations evenly spaced from
``+fov/2`` down to ``−fov/2``); column j fires at ``t_scan + j·period/columns`` pointing at
azimuth ``−2π·j/columns`` in the lidar frame (clockwise seen from above, column 0 along +x).
Each point is expressed in the lidar frame *at its own firing time* — the raw driver output,
with the motion distortion of a real spinning sensor. Rays that hit nothing within range, or
closer than the minimum range, are kept as all-zero rows, so every scan has exactly
``beams·columns`` = 65,536 rows, as the ColoRadar files do.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .raycast import RectArrays, cast_rays
from .scene import Scene
from .trajectory import RigTrajectory

__all__ = ["LidarModel", "column_times", "simulate_scan"]


@dataclass(frozen=True)
class LidarModel:
    """OS1-64 parameters.

    Attributes
    ----------
    beams, columns
        64 beams, 1024 columns per revolution.
    vertical_fov
        Total vertical field of view [rad] (33.2° for the OS1-64 gen 1).
    rate
        Revolutions per second [Hz].
    min_range, max_range
        Valid return window [m].
    range_noise
        Standard deviation of the range noise [m].
    intensity_scale
        Intensity of a reflectivity-1 surface hit head-on at 1 m (arbitrary units).
    jitter
        Standard deviation of the scan timestamps [s].
    """

    beams: int = 64
    columns: int = 1024
    vertical_fov: float = np.radians(33.2)
    rate: float = 10.0
    min_range: float = 0.8
    max_range: float = 120.0
    range_noise: float = 0.015
    intensity_scale: float = 1000.0
    jitter: float = 2.0e-4

    @property
    def period(self) -> float:
        return 1.0 / self.rate

    def beam_elevations(self) -> np.ndarray:
        """float64 ``(beams,)`` [rad], top beam first."""
        return np.linspace(self.vertical_fov / 2, -self.vertical_fov / 2, self.beams)

    def column_azimuths(self) -> np.ndarray:
        """float64 ``(columns,)`` [rad] in the lidar frame."""
        return -2.0 * np.pi * np.arange(self.columns) / self.columns

    def directions(self) -> np.ndarray:
        """float64 ``(beams, columns, 3)`` unit ray directions in the lidar frame."""
        el = self.beam_elevations()[:, None]
        az = self.column_azimuths()[None, :]
        return np.stack(np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                            np.sin(el)), axis=-1)


def column_times(model: LidarModel, t_scan: float) -> np.ndarray:
    """float64 ``(columns,)``: firing time of every column of the scan starting at ``t_scan``."""
    return t_scan + np.arange(model.columns) * (model.period / model.columns)


def simulate_scan(scene: Scene, trajectory: RigTrajectory, base_T_lidar: np.ndarray,
                  t_scan: float, model: LidarModel | None = None,
                  rng: np.random.Generator | None = None) -> np.ndarray:
    """One lidar scan.

    Parameters
    ----------
    scene, trajectory
        What is seen, and how the rig moves (times relative to the run start [s]).
    base_T_lidar
        float ``(4, 4)``: the lidar's extrinsic.
    t_scan
        Time of the scan's first column [s, run time].
    model
        The lidar (default :class:`LidarModel`).
    rng
        Random generator for the range noise (None: no noise).

    Returns
    -------
    numpy.ndarray
        float32 ``(beams·columns, 4)``: x y z [m] intensity, lidar frame (see module doc).
    """
    model = model or LidarModel()
    tc = column_times(model, t_scan)
    st = trajectory.state(tc)
    r_bl = base_T_lidar[:3, :3]
    world_r_lidar = st.rotation.as_matrix() @ r_bl                                 # (C, 3, 3)
    origin = st.position + st.rotation.apply(base_T_lidar[:3, 3])                  # (C, 3)
    d_lidar = model.directions()                                                   # (B, C, 3)
    d_world = np.einsum("cij,bcj->cbi", world_r_lidar, d_lidar)                     # (C, B, 3)
    # Static structure (fast sector casting) and moving objects (box per column) separately.
    static = scene.static_rect_arrays
    dist, idx = cast_rays(origin[:, None, :], d_world, static)                      # (C, B)
    normal = np.zeros(d_world.shape)
    refl = np.zeros(dist.shape)
    if static.count:
        normal = static.normal[0][np.maximum(idx, 0)]                              # (C, B, 3)
        refl = static.lidar_reflectivity[np.maximum(idx, 0)]
    if scene.objects:
        moving = RectArrays.concatenate([o.rects(tc, i) for i, o in enumerate(scene.objects)])
        d_o, i_o = cast_rays(origin[:, None, :], d_world, moving)
        nearer = d_o < dist
        cols = np.broadcast_to(np.arange(model.columns)[:, None], i_o.shape)
        normal = np.where(nearer[..., None], moving.normal[cols, np.maximum(i_o, 0)], normal)
        refl = np.where(nearer, moving.lidar_reflectivity[np.maximum(i_o, 0)], refl)
        dist = np.where(nearer, d_o, dist)
    dist, normal, refl = dist.T, np.swapaxes(normal, 0, 1), refl.T                 # (B, C)
    valid = np.isfinite(dist) & (dist >= model.min_range) & (dist <= model.max_range)
    # Intensity: reflectivity × cos(incidence) / R², like a lidar's returned signal.
    cos_inc = np.abs(np.einsum("bck,bck->bc", normal, np.swapaxes(d_world, 0, 1)))
    intensity = (model.intensity_scale * refl * cos_inc / np.maximum(dist, 1.0) ** 2)
    measured = dist
    if rng is not None and model.range_noise > 0:
        measured = dist + rng.standard_normal(dist.shape) * model.range_noise
    pts = np.zeros((model.beams, model.columns, 4), dtype=np.float32)
    xyz = d_lidar * np.where(valid, measured, 0.0)[..., None]
    pts[..., :3] = xyz
    pts[..., 3] = np.where(valid, intensity, 0.0)
    return pts.reshape(-1, 4)
