"""The odometry's scale, measured by registering keyframes whose submaps share no frame.

A loop closure cannot see a scale error: a closed path shrunk by 0.5 % still closes. The
single chip's on-board detections make the radar-inertial odometry 0.3–0.8 % short on the
simulated runs (each detection's range rate is its Doppler bin's centre, its direction the
cell's strongest scatterer's; docs/slam.md), and that error is most of what is left after loop
closure. Registering two submaps built from disjoint sets of frames measures the distance
between them from the scene itself; the odometry's distance between the same keyframes,
compared along the direction of travel, gives one measurement of the scale per pair:

``s_k = (t_reg · d) / L``, ``L = |t_odo|``, ``d = t_odo / L``, variance ``dᵀ Σ_t d / L²``

with ``t_reg`` and ``Σ_t`` the registration's translation and its covariance (along a
featureless corridor ``Σ_t`` is large along the corridor, and the pair weighs little). Only
the parts of the two submaps within ``scale_common_radius`` of each other are registered (on
the single chip's courtyard runs that made more pairs agree). Each pair is registered twice,
from the odometry's relative pose with its translation shortened and lengthened by
``scale_probe``; a pair whose two results differ by more than ``scale_agreement`` (the
registration stayed where it started, not where the scene put it) is not used. The scale
is the weighted mean of the pairs left after a median/MAD outlier cut; it is used only when
at least ``scale_min_pairs`` pairs agree on it to within ``scale_max_std`` (standard error:
the larger of the weights' and the pairs' own scatter over √n).

Measured on the single chip's tuning runs (docs/slam.md): within 0.1 % of the scale of the
odometry's Sim(3) alignment to the ground truth on hallway runs, and nearer 1 than it on the
corridor and courtyard runs (under-corrected by 0.1–0.6 %); on the cascade, whose odometry
has no scale error to speak of, within 0.1 % of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..geometry import SE3, Trajectory
from .registration import register
from .settings import SlamSettings
from .submaps import Submap, Submaps

__all__ = ["NOT_ESTIMATED", "ScaleEstimate", "disjoint_pairs", "estimate_scale", "pair_scales"]


@dataclass(frozen=True)
class ScaleEstimate:
    """The odometry's scale (true distance / odometry's distance).

    Attributes
    ----------
    scale
        Applied to the odometry factors' translations (1 when not used).
    measured
        The weighted mean of the pairs, applied or not (NaN without pairs).
    std
        Its standard error (NaN without pairs).
    pairs
        Pairs that measured it (after the agreement test and the outlier cut).
    used
        Whether the measured scale was applied (enough pairs, a small enough standard
        error).
    """

    scale: float
    measured: float
    std: float
    pairs: int
    used: bool

    def as_dict(self) -> dict:
        return {"scale": self.scale, "measured": self.measured, "std": self.std,
                "pairs": self.pairs, "used": self.used}


def disjoint_pairs(times: np.ndarray, window: float) -> list[tuple[int, int]]:
    """Keyframe pairs ``(a, b)``: for each keyframe ``a`` the first ``b`` at least ``2 ·
    window`` seconds later (submaps of ± ``window`` seconds then share no frame)."""
    b = np.searchsorted(times, times + 2.0 * window, side="left")
    return [(a, int(j)) for a, j in enumerate(b) if j < times.size]


def _crop(m: Submap, keep: np.ndarray) -> Submap:
    return Submap(m.frame, m.points[keep], m.intensity[keep], m.covariances[keep], m.descriptor,
                  None if m.surface is None else m.surface[keep])


def _common(target: Submap, source: Submap, init: SE3, radius: float) -> tuple[Submap, Submap]:
    """The parts of two submaps within ``radius`` of the other (``source`` placed by
    ``init``): only the shared region can say where one submap lies against the other, and
    on the single chip's courtyard tuning runs registering it alone made more pairs agree."""
    moved = init.apply(source.points)
    near_t = cKDTree(moved).query(target.points, k=1, distance_upper_bound=radius)[0] <= radius
    near_s = cKDTree(target.points).query(moved, k=1, distance_upper_bound=radius)[0] <= radius
    return _crop(target, near_t), _crop(source, near_s)


def pair_scales(poses: Trajectory, submaps: Submaps, s: SlamSettings) -> np.ndarray:
    """float64 ``(n, 2)``: each usable pair's scale measurement ``s_k`` and its variance.

    Parameters
    ----------
    poses
        The keyframes' odometry ``world_T_base`` (``K`` poses, in time order).
    submaps
        The keyframes' submaps (``submaps[n]`` of keyframe ``n``, ± ``s.submap_window``).
    s
        Settings: ``submap_window``, ``scale_common_radius``, ``scale_probe``,
        ``scale_agreement``, ``min_fitness`` (halved here: submaps ``2 · submap_window`` apart
        overlap less than a loop's) and the registration's.
    """
    out = []
    for a, b in disjoint_pairs(np.asarray(poses.timestamps), s.submap_window):
        rel = poses[a].inverse() @ poses[b]
        length = float(np.linalg.norm(rel.translation))
        if length < s.keyframe_distance:
            continue
        d = rel.translation / length
        tgt, src = _common(submaps[a], submaps[b], rel, s.scale_common_radius)
        regs = [register(tgt, src, SE3(rel.rotation, rel.translation * f), s)
                for f in (1.0 - s.scale_probe, 1.0 + s.scale_probe)]
        if any(r.fitness < 0.5 * s.min_fitness or not np.all(np.isfinite(r.covariance))
               for r in regs):
            continue
        lo, hi = (float(r.target_T_source.translation @ d) / length for r in regs)
        if abs(hi - lo) > s.scale_agreement:
            continue
        # The covariance is of a right perturbation T·Exp(ξ): its translation part is in the
        # source's axes, turned into the target's (where d is) by the registered rotation.
        rot = regs[0].target_T_source.rotation.as_matrix()
        var = float(d @ rot @ regs[0].covariance[3:, 3:] @ rot.T @ d) / length**2
        out.append((0.5 * (lo + hi), var))
    return np.array(out, dtype=np.float64).reshape(-1, 2)


NOT_ESTIMATED = ScaleEstimate(1.0, float("nan"), float("nan"), 0, False)
"""What :func:`estimate_scale` returns when it does not estimate (and a result's default)."""


def estimate_scale(poses: Trajectory, submaps: Submaps, s: SlamSettings) -> ScaleEstimate:
    """The odometry's scale from :func:`pair_scales` (module docstring); ``scale`` 1 and
    ``used`` False when ``s.estimate_scale`` is off or the pairs do not pin it down."""
    if not s.estimate_scale or len(poses) < 2:
        return NOT_ESTIMATED
    m = pair_scales(poses, submaps, s)
    if m.shape[0] == 0:
        return NOT_ESTIMATED
    med = float(np.median(m[:, 0]))
    mad = 1.4826 * float(np.median(np.abs(m[:, 0] - med)))
    keep = np.abs(m[:, 0] - med) <= 3.0 * max(mad, 1e-6)
    sk, w = m[keep, 0], 1.0 / np.maximum(m[keep, 1], 1e-12)
    n = int(sk.size)
    est = float(np.sum(w * sk) / np.sum(w))
    std = float(max(1.0 / np.sqrt(np.sum(w)), np.std(sk) / np.sqrt(n)))
    used = n >= s.scale_min_pairs and std <= s.scale_max_std
    return ScaleEstimate(est if used else 1.0, est, std, n, used)
