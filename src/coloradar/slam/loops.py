"""Loop candidates and their verification.

A keyframe ``j`` may close a loop with an earlier keyframe ``i`` when

1. the rig has travelled at least ``loop_min_separation`` metres between them (neighbours
   overlap trivially);
2. **Mahalanobis gate** — the odometry does not rule out that they are within
   ``loop_search_radius`` of each other: with ``Δp`` the odometry's displacement and ``Σ`` the
   covariance of the motion from ``i`` to ``j`` (:func:`.frontend.relative_covariance`), the
   excess ``max(0, |Δp| − radius)`` is at most ``loop_gate_sigma`` standard deviations of
   ``Σ`` along ``Δp``;
3. their scan-context descriptors are close (:func:`.submaps.descriptor_distance`); the best
   ``max_loop_candidates`` go on.

Each candidate is **verified**: registered (:func:`.registration.register`) from the odometry's
relative pose, then accepted only with fitness and overlap above their thresholds and a
registered pose consistent with the odometry's (chi-square test of
``Log(T_odo⁻¹ T_reg)`` with the two covariances, 6 dof). In a corridor whose doors repeat every
few metres, registration snaps to the nearest look-alike; the odometry test rejects a
look-alike the odometry cannot have drifted to, and the graph's consistency test
(:func:`.graph.optimize_with_consistency`) what is left.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import chi2

from ..geometry import SE3
from .registration import register
from .settings import SlamSettings
from .submaps import Submaps, descriptor_distance

__all__ = ["Candidate", "LoopRecord", "factor_floor", "loop_candidates", "odometry_chi2",
           "reverse_release", "verify_loop"]


@dataclass(frozen=True)
class Candidate:
    """A keyframe pair worth registering: keyframe numbers ``i < j``, descriptor distance,
    and the gate's standard deviations of excess distance."""

    i: int
    j: int
    descriptor_distance: float
    gate_sigma: float


@dataclass(frozen=True, eq=False)
class LoopRecord:
    """A verified candidate (accepted or not) for ``loops.csv``.

    Attributes
    ----------
    i, j
        Keyframe numbers (``i`` earlier).
    descriptor_distance, gate_sigma
        From the candidate search.
    fitness, overlap, rmse
        From registration (rmse [m]).
    odometry_chi2
        Squared Mahalanobis distance of the registered pose from the odometry's.
    accepted
        Whether it is a factor of the final graph.
    reason
        ``"accepted"`` or why not.
    measured, covariance
        ``i_T_j`` from registration and its factor covariance ``(6, 6)`` (None if not
        registered).
    """

    i: int
    j: int
    descriptor_distance: float
    gate_sigma: float
    fitness: float
    overlap: float
    rmse: float
    odometry_chi2: float
    accepted: bool
    reason: str
    measured: SE3 | None = None
    covariance: np.ndarray | None = None


def loop_candidates(j: int, positions: np.ndarray, path: np.ndarray, position_cov: np.ndarray,
                    descriptor: Callable[[int], np.ndarray], settings: SlamSettings
                    ) -> list[Candidate]:
    """Candidates of keyframe ``j`` among the earlier keyframes.

    Parameters
    ----------
    positions
        float64 ``(K, 3)``: the keyframes' odometry positions (world) [m].
    path
        float64 ``(K,)``: path length at each keyframe [m].
    position_cov
        float64 ``(K, 3, 3)``: the odometry's marginal position covariance at each keyframe
        [m²]; the relative position of ``i`` and ``j`` has ``P_j − P_i`` plus the odometry's
        translation floor per keyframe step.
    descriptor
        ``descriptor(k)``: keyframe ``k``'s :func:`~.submaps.scan_context` (e.g.
        :meth:`.stores.SubmapStore.descriptor`, which reads only that).
    """
    earlier = np.flatnonzero(path[:j] <= path[j] - settings.loop_min_separation)
    if earlier.size == 0:
        return []
    d = positions[j] - positions[earlier]
    dist = np.linalg.norm(d, axis=1)
    reach = settings.loop_search_radius
    u = d / np.maximum(dist, 1e-9)[:, None]
    cov = settings.odometry_cov_scale * (position_cov[j] - position_cov[earlier])
    var = (np.einsum("ni,nij,nj->n", u, cov, u)
           + (j - earlier) * settings.odometry_floor_translation**2)
    gate = np.maximum(dist - reach, 0.0) / np.sqrt(np.maximum(var, 1e-12))
    out = []
    mine = descriptor(j)
    for n in np.flatnonzero(gate <= settings.loop_gate_sigma):
        i = int(earlier[n])
        dd, _ = descriptor_distance(descriptor(i), mine)
        if dd <= settings.max_descriptor_distance:
            out.append(Candidate(i, j, dd, float(gate[n])))
    out.sort(key=lambda c: c.descriptor_distance)
    return out[:settings.max_loop_candidates]


def odometry_chi2(odometry: SE3, odometry_cov: np.ndarray, measured: SE3,
                  measured_cov: np.ndarray) -> float:
    """Squared Mahalanobis distance of a registered relative pose ``measured`` from the
    odometry's, with the two ``(6, 6)`` covariances summed (both in the source frame ``j``,
    GTSAM's ``Pose3`` tangent order): ``Log(T_odo⁻¹ T_reg)`` to first order (rotation
    vector, translation). The test of loops, ``refine_odometry`` and the disjoint-submap
    factors against the odometry."""
    err = odometry.inverse() @ measured
    resid = np.concatenate([err.rotation.as_rotvec(), err.translation])
    return float(resid @ np.linalg.solve(measured_cov + odometry_cov, resid))


PLANAR_RELEASE = (np.radians(10.0), 0.1)
"""Standard deviations [rad], [m] added to a planar loop's tilt and height. Two elevation rows
leave the registration's tilt unusable, and its height coarse but not void. With the planar
front end (before issue 42) 0.2 m was chosen on the single chip's tuning runs (seeds
101–111): it took SLAM's height error down on 10 of 11 runs against 1 m, and 0.05 m did
about as well on average but worse on the corridors. The 3-D front end drifts more in height
on those flat runs, and on the same tuning runs the loops' SLAM ATE went, for 0.2 / 0.1 /
0.05 m, to 0.040–0.044 / 0.030–0.036 / 0.025–0.034 % on the courtyards and stayed at
0.017–0.025 % elsewhere: 0.1 m, the middle, because a loop that joins two heights has only
this coarse registration to say how far apart they are (docs/slam.md, "The 3-D front end")."""


def factor_floor(settings: SlamSettings, planar: bool) -> np.ndarray:
    """float64 ``(6, 6)``: what a registration factor's covariance gets added (loops, and the
    disjoint-submap factors of :mod:`.system`): the floors ``loop_rotation_std_deg`` and
    ``loop_translation_std``; for a ``planar`` radar also :data:`PLANAR_RELEASE` on tilt and
    height (see :func:`verify_loop`)."""
    floor = np.diag([np.radians(settings.loop_rotation_std_deg) ** 2] * 3
                    + [settings.loop_translation_std ** 2] * 3)
    if planar:   # tangent (ω, v) in the base frame: x right, y forward, z up
        floor += np.diag([PLANAR_RELEASE[0] ** 2] * 2 + [0.0] * 3 + [PLANAR_RELEASE[1] ** 2])
    return floor


def reverse_release(yaw_i: float, yaw_j: float, travel_j: np.ndarray, std: float
                    ) -> np.ndarray | None:
    """float64 ``(6, 6)``: what a loop between keyframes ``i`` and ``j`` gets added to its
    covariance when their headings ``yaw_i``, ``yaw_j`` [rad] differ by more than 90°:
    ``std²`` [m²] along ``travel_j``, keyframe ``j``'s unit direction of travel in its own
    frame (GTSAM's ``Pose3`` tangent order, translation last); None otherwise.

    Why: a forward-looking radar sees a place it passes the other way from the other side;
    the two submaps overlap in part, and their registration errs along the path. On the
    single chip's tuning hallways (seeds 103, 106, 109), with the submaps placed by the
    ground truth, such loops were off by +5.4 to +8.2 cm along the path on average (loops
    in the same direction −0.2 to +0.4 cm); held at full weight they left SLAM's trajectory
    2–3 cm behind the truth along the path.
    """
    if std <= 0 or abs(np.angle(np.exp(1j * (yaw_i - yaw_j)))) <= np.pi / 2:
        return None
    u = np.asarray(travel_j, dtype=np.float64)
    out = np.zeros((6, 6))
    out[3:, 3:] = std**2 * np.outer(u, u)
    return out


def verify_loop(c: Candidate, submaps: Submaps, odometry: SE3, odometry_cov: np.ndarray,
                settings: SlamSettings, planar: bool = False,
                release: np.ndarray | None = None) -> LoopRecord:
    """Register candidate ``c`` from the odometry's ``i_T_j`` and test it (module docstring);
    ``odometry_cov`` is the ``(6, 6)`` covariance of that relative pose.

    ``planar``: the radar measures elevation too coarsely for registration to fix roll and
    pitch, and fixes height only coarsely (fewer than 3 elevation rows: the single chip,
    whose odometry is planar for the same reason); the loop then constrains x, y and yaw, and
    height loosely (its tilt and height get the standard deviations :data:`PLANAR_RELEASE`
    added, which the odometry test takes too). ``release``: a further ``(6, 6)`` covariance
    added to the factor of a loop that passed (:func:`reverse_release`): it lowers the
    loop's weight in the graph, not the bar it must pass.
    """
    reg = register(submaps[c.i], submaps[c.j], odometry, settings)
    base: dict[str, Any] = dict(i=c.i, j=c.j, descriptor_distance=c.descriptor_distance,
                                gate_sigma=c.gate_sigma, fitness=reg.fitness,
                                overlap=reg.overlap, rmse=reg.rmse)
    floor = factor_floor(settings, planar)
    cov = (reg.covariance if np.all(np.isfinite(reg.covariance)) else np.full((6, 6), np.nan))
    if reg.fitness < settings.min_fitness:
        return LoopRecord(**base, odometry_chi2=np.nan, accepted=False,
                          reason=f"fitness {reg.fitness:.2f} < {settings.min_fitness:.2f}")
    if reg.overlap < settings.min_overlap:
        return LoopRecord(**base, odometry_chi2=np.nan, accepted=False,
                          reason=f"overlap {reg.overlap:.2f} < {settings.min_overlap:.2f}")
    if not np.all(np.isfinite(cov)):
        return LoopRecord(**base, odometry_chi2=np.nan, accepted=False,
                          reason="registration gave no covariance (degenerate geometry)")
    factor_cov = cov + floor
    m = odometry_chi2(odometry, odometry_cov, reg.target_T_source, factor_cov)
    limit = float(chi2.ppf(settings.gate_probability, 6))
    if m > limit:
        return LoopRecord(**base, odometry_chi2=m, accepted=False,
                          reason=f"inconsistent with the odometry (chi2 {m:.1f} > {limit:.1f})")
    if release is not None:
        factor_cov = factor_cov + release
    return LoopRecord(**base, odometry_chi2=m, accepted=True, reason="accepted",
                      measured=reg.target_T_source, covariance=factor_cov)
