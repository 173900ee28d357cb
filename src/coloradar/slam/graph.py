"""The pose graph of the keyframes, optimised with GTSAM (batch Levenberg–Marquardt).

Variables: ``world_T_base`` of every keyframe (``Pose3``). Factors: a prior on the first
keyframe (the odometry's initial pose, held tight), one ``BetweenFactorPose3`` per odometry step
with the front end's relative covariance (:func:`.frontend.relative_covariance`), optional
registration steps, and one per accepted loop with its covariance under a robust kernel
(Cauchy by default). After optimisation every loop's residual is tested against the chi-square
quantile of 6 degrees of freedom; the worst loop beyond it is dropped and the graph solved
again, until all loops agree (:func:`optimize_with_consistency`): a loop that the others and the
odometry cannot explain is rejected, whatever its registration fitness.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from ..geometry import SE3
from . import _deps

__all__ = ["Edge", "PoseGraph", "optimize_with_consistency"]


def _pose3(gtsam, t: SE3):
    return gtsam.Pose3(gtsam.Rot3(t.rotation.as_matrix()), np.asarray(t.translation, float))


def _se3(p) -> SE3:
    return SE3.from_matrix(np.asarray(p.matrix()))


@dataclass(frozen=True, eq=False)
class Edge:
    """A relative-pose factor ``T_i⁻¹ T_j = measured``.

    Attributes
    ----------
    i, j
        Keyframe numbers.
    measured
        ``i_T_j``.
    covariance
        float64 ``(6, 6)``: rotation [rad²] then translation [m²], frame ``j`` tangent.
    kind
        ``"odometry"``, ``"registration"`` or ``"loop"``.
    """

    i: int
    j: int
    measured: SE3
    covariance: np.ndarray
    kind: str = "odometry"


@dataclass
class PoseGraph:
    """Keyframe poses and relative-pose factors.

    Attributes
    ----------
    initial
        The keyframes' initial ``world_T_base`` (the odometry's).
    edges
        Every factor but the prior.
    robust_kernel
        ``"cauchy"``, ``"huber"`` or ``"none"`` for loop factors.
    prior_std
        Standard deviation of the prior on the first keyframe (rotation [rad], translation [m]).
    """

    initial: list[SE3]
    edges: list[Edge] = field(default_factory=list)
    robust_kernel: str = "cauchy"
    prior_std: tuple[float, float] = (1e-4, 1e-4)

    def _noise(self, gtsam, e: Edge):
        cov = 0.5 * (e.covariance + e.covariance.T)
        base = gtsam.noiseModel.Gaussian.Covariance(cov)
        if e.kind != "loop" or self.robust_kernel == "none":
            return base
        # Kernel widths in whitened units (standard deviations).
        est = (gtsam.noiseModel.mEstimator.Cauchy.Create(1.0) if self.robust_kernel == "cauchy"
               else gtsam.noiseModel.mEstimator.Huber.Create(1.345))
        return gtsam.noiseModel.Robust.Create(est, base)

    def optimize(self, active: list[bool] | None = None, start: list[SE3] | None = None
                 ) -> list[SE3]:
        """Optimised ``world_T_base`` of every keyframe; ``active[k]`` (default all) says
        whether edge ``k`` is used; ``start``: the initial values (default :attr:`initial`)."""
        gtsam = _deps.gtsam()
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        for k, t in enumerate(start or self.initial):
            values.insert(k, _pose3(gtsam, t))
        sr, st = self.prior_std
        graph.add(gtsam.PriorFactorPose3(0, _pose3(gtsam, self.initial[0]),
                                         gtsam.noiseModel.Diagonal.Sigmas(
                                             np.array([sr] * 3 + [st] * 3))))
        for n, e in enumerate(self.edges):
            if active is None or active[n]:
                graph.add(gtsam.BetweenFactorPose3(e.i, e.j, _pose3(gtsam, e.measured),
                                                   self._noise(gtsam, e)))
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(100)
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        return [_se3(result.atPose3(k)) for k in range(len(self.initial))]

    def chi2_of(self, e: Edge, poses: list[SE3]) -> float:
        """Squared Mahalanobis distance of an edge's residual at ``poses`` (no kernel)."""
        gtsam = _deps.gtsam()
        f = gtsam.BetweenFactorPose3(e.i, e.j, _pose3(gtsam, e.measured),
                                     gtsam.noiseModel.Gaussian.Covariance(
                                         0.5 * (e.covariance + e.covariance.T)))
        v = gtsam.Values()
        v.insert(e.i, _pose3(gtsam, poses[e.i]))
        v.insert(e.j, _pose3(gtsam, poses[e.j]))
        return 2.0 * float(f.error(v))


def optimize_with_consistency(graph: PoseGraph, probability: float
                              ) -> tuple[list[SE3], list[bool]]:
    """Optimise, then drop the worst loop whose residual exceeds the chi-square quantile
    ``probability`` (6 dof) and optimise again, until every remaining loop passes.

    Returns
    -------
    poses
        Optimised keyframe poses.
    active
        Per edge, whether it was kept (odometry edges always are).
    """
    limit = float(chi2.ppf(probability, 6))
    active = [True] * len(graph.edges)
    poses = None
    while True:
        # From the last solution: dropping one loop moves the optimum by little.
        poses = graph.optimize(active, poses)
        worst, worst_chi2 = -1, limit
        for n, e in enumerate(graph.edges):
            if e.kind == "loop" and active[n]:
                c = graph.chi2_of(e, poses)
                if c > worst_chi2:
                    worst, worst_chi2 = n, c
        if worst < 0:
            return poses, active
        active[worst] = False
