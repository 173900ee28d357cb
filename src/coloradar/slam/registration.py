"""Registration of two submaps (small_gicp GICP) and what it is worth.

:func:`register` aligns a source submap to a target submap from an initial guess with
small_gicp (Koide, "small_gicp: Efficient and parallel algorithms for point cloud
registration", JOSS 2024), whose GICP (Segal et al., RSS 2009) models each point by the
covariance of its neighbours. Its Python binding takes no covariances of ours, so the radar's
own per-point covariances (range and angle accuracy, :func:`.submaps.point_covariances`) enter
the result's uncertainty: each point's covariance is its sensor covariance plus a surface term
(``inlier_distance²`` along the local surface of its 10 nearest neighbours, nothing across it:
a point may slide along a wall but not through it, as in GICP's plane model), and the
Gauss–Newton information ``H = Σ Jᵀ (C_t + R C_s Rᵀ)⁻¹ J`` of the paired points at the
solution, with ``J = [−R [p]ₓ, R]`` the derivative of ``T·p`` under the right perturbation
``T·Exp(ξ)``, ``ξ = (ω, v)`` (GTSAM's ``Pose3`` tangent order), gives the covariance
``scale · H⁻¹``. Along a featureless corridor that covariance is large in the corridor's
direction, as it should be.

Fitness is the share of source points within ``inlier_distance`` of the target after
alignment; overlap is the smaller of that share both ways.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..geometry import SE3
from . import _deps
from .settings import SlamSettings
from .submaps import Submap, surface_covariances

__all__ = ["MIN_POINTS", "Registration", "register", "register_points"]

MIN_POINTS = 20
"""Fewer points than this in either set: not registered (fitness 0)."""


@dataclass(frozen=True, eq=False)
class Registration:
    """The result of registering a source submap to a target.

    Attributes
    ----------
    target_T_source
        The estimated pose of the source in the target's frame.
    fitness
        Share of source points within ``inlier_distance`` of the target.
    overlap
        The smaller of that share from source to target and from target to source.
    rmse
        RMS distance of those inlier pairs [m].
    covariance
        float64 ``(6, 6)``: rotation [rad²] then translation [m²] (right perturbation).
    converged
        small_gicp's own flag.
    pairs
        Inlier pairs used for the covariance.
    """

    target_T_source: SE3
    fitness: float
    overlap: float
    rmse: float
    covariance: np.ndarray
    converged: bool
    pairs: int


def _skew(p: np.ndarray) -> np.ndarray:
    z = np.zeros(p.shape[0])
    return np.stack([np.stack([z, -p[:, 2], p[:, 1]], 1), np.stack([p[:, 2], z, -p[:, 0]], 1),
                     np.stack([-p[:, 1], p[:, 0], z], 1)], axis=1)


def _information(tgt: np.ndarray, tgt_cov: np.ndarray, src: np.ndarray, src_cov: np.ndarray,
                 t: SE3, pairs: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    it, is_ = pairs
    r = t.rotation.as_matrix()
    p = src[is_]
    c = tgt_cov[it] + np.einsum("ij,njk,lk->nil", r, src_cov[is_], r) + 1e-6 * np.eye(3)
    w = np.linalg.inv(c)
    jac = np.concatenate([-np.einsum("ij,njk->nik", r, _skew(p)),
                          np.broadcast_to(r, (p.shape[0], 3, 3))], axis=2)   # (n, 3, 6)
    return np.einsum("nki,nkl,nlj->ij", jac, w, jac)


def register_points(target: np.ndarray, source: np.ndarray, init: SE3, settings: SlamSettings,
                    target_cov: np.ndarray | None = None, source_cov: np.ndarray | None = None,
                    surfaces: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
                    ) -> Registration:
    """Register point sets ``source`` to ``target`` (float ``(N, 3)``, ``(M, 3)`` [m]) from
    ``init`` (the source's pose in the target's frame); per-point covariances ``(N, 3, 3)``
    (default: isotropic (1 cm)²) weight the returned covariance, with the surface terms
    ``surfaces`` (:func:`.submaps.surface_covariances` of target and source; computed when
    None)."""
    sg = _deps.small_gicp()
    tgt = np.ascontiguousarray(target, dtype=np.float64)
    src = np.ascontiguousarray(source, dtype=np.float64)
    nan6 = np.full((6, 6), np.nan)
    if tgt.shape[0] < MIN_POINTS or src.shape[0] < MIN_POINTS:
        return Registration(init, 0.0, 0.0, np.nan, nan6, False, 0)
    res = sg.align(tgt, src, init.matrix(), registration_type=settings.registration,
                   downsampling_resolution=settings.submap_voxel,
                   max_correspondence_distance=settings.max_correspondence, max_iterations=30)
    t = SE3.from_matrix(np.asarray(res.T_target_source))
    moved = t.apply(src)
    d_st, i_st = cKDTree(tgt).query(moved, k=1)
    d_ts = cKDTree(moved).query(tgt, k=1)[0]
    near = d_st <= settings.inlier_distance
    fitness = float(near.mean())
    overlap = min(fitness, float(np.mean(d_ts <= settings.inlier_distance)))
    rmse = float(np.sqrt(np.mean(d_st[near] ** 2))) if near.any() else np.nan
    iso = 0.01**2 * np.eye(3)
    s_t = surfaces[0] if surfaces[0] is not None else surface_covariances(
        tgt, settings.inlier_distance)
    s_s = surfaces[1] if surfaces[1] is not None else surface_covariances(
        src, settings.inlier_distance)
    tc = (target_cov if target_cov is not None else iso) + s_t
    sc = (source_cov if source_cov is not None else iso) + s_s
    cov = nan6
    if near.sum() >= 6:
        info = _information(tgt, tc, src, sc, t, (i_st[near], np.flatnonzero(near)))
        if np.linalg.cond(info) < 1e12:
            cov = settings.registration_cov_scale * np.linalg.inv(info)
    return Registration(t, fitness, overlap, rmse, cov, bool(res.converged), int(near.sum()))


def register(target: Submap, source: Submap, init: SE3, settings: SlamSettings) -> Registration:
    """Register submap ``source`` to ``target`` from ``init`` (:func:`register_points` with the
    submaps' per-point covariances)."""
    return register_points(target.points, source.points, init, settings,
                           target.covariances, source.covariances,
                           (target.surface, source.surface))
