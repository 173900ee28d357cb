"""Trajectory and velocity error metrics: ATE, RPE over fixed distances, ego-velocity error.

Conventions follow the KITTI odometry benchmark (Geiger et al., CVPR 2012) and ``evo``
(M. Grupp, 2017):

- **Association.** The reference (ground truth) is interpolated at the estimate's timestamps
  (linear translation, SLERP rotation); estimate poses outside the reference's span, or within
  a reference gap longer than ``max_gap``, are left out.
- **ATE** (absolute trajectory error, Sturm et al., IROS 2012): after aligning the estimate's
  positions to the reference's (SE(3) Umeyama by default, :mod:`.alignment`), the RMSE (and
  mean, median, max) of ``|p_ref,i − T p_est,i|``. The rotation part is the angle of
  ``R_ref,iᵀ R_a R_est,i`` where ``R_a`` is the chordal mean of ``R_ref,i R_est,iᵀ`` (the
  rotation that best aligns the orientations): the positions of a nearly straight corridor
  walk leave the roll about the path undetermined, and Umeyama's rotation would then show up
  as a large, meaningless attitude error. With ``posyaw`` (position and yaw, the 4-DoF
  alignment of visual/radar-inertial odometry: :func:`~.alignment.posyaw_alignment`),
  ``origin`` or ``none`` alignment ``R_a`` is that alignment's rotation.
- **RPE** over distance ``d``: the error of the relative motion of a pose pair ``(i, j)`` is
  ``E = (ref_i⁻¹ ref_j)⁻¹ (est_i⁻¹ est_j)``. Translation error in percent is ``100 · |t_E| / d``
  and rotation error ``angle(E) / d`` in deg/m, averaged over the pairs (the KITTI devkit's
  numbers; it uses d = 100…800 m for cars, 1, 2, 5 m suit a hand-held rig indoors). RPE needs
  no alignment. The pairs (``pairing``), chosen by the path length ``L`` along the reference
  (``every_pose``) or, as evo does unless given ``--pairs_from_reference``, along the estimate
  (``evo``, ``evo_all_pairs``; ``pairs_from`` overrides):

  * ``"every_pose"`` (default): every pose ``i`` starts a pair; ``j`` is the first pose with
    ``L_j − L_i ≥ d`` (KITTI's rule, with a start at every pose instead of every 10th).
  * ``"evo"``: what ``evo_rpe -d D -u m`` uses: consecutive, non-overlapping segments. The
    first pose is the first segment end; each next segment ends at the first pose whose path
    length from the previous end reaches ``d``; consecutive ends are the pairs, so the first
    pair starts at pose 0 (evo's ``filter_pairs_by_path``, checked against evo 1.38.1).
  * ``"evo_all_pairs"``: ``evo_rpe … --all_pairs``: every pose ``i`` whose best partner ``j``
    (``L_j − L_i`` nearest to ``d``, the earlier pose on a tie) lies within the relative
    tolerance: ``|L_j − L_i − d| ≤ tolerance · d`` (evo's default tolerance is 0.1).
  * ``"rpg"``: ``rpg_trajectory_evaluation``'s rule (``compute_comparison_indices_length``,
    Zhang & Scaramuzza, IROS 2018): the same nearest partner along the *reference*, kept when
    ``|L_j − L_i − d| < tolerance · d`` with its tolerance 0.2 (``max_dist_diff``); with fewer
    than two such pairs a length gives none ("too few samples").
- **RPE yaw error** (every pairing; :attr:`RPEResult.yaw_errors`): rpg's ``rel_yaw``,
  ``|yaw|`` (the z angle of a z-y-x Euler decomposition) of the error rotation expressed in
  world axes through the estimate's attitude at the pair's end, ``R_est,j R_E R_est,jᵀ``.
- **The RIO literature's protocol** (:func:`rpg_relative_error`): RPE with ``"rpg"`` pairs over
  :data:`RPG_LENGTHS` (25, 50, 75, 100 m), ``100 |t_E| / d`` [%] and the yaw error [deg],
  summarised by :meth:`RPEResult.statistics`, beside the ``posyaw`` ATE.
- **Drift** (:func:`trajectory_drift`): RPE with ``every_pose`` pairs over several lengths
  (:data:`DRIFT_LENGTHS`), ``|t_E|/L`` and ``angle(E)/L`` averaged over all segments of all
  lengths together, as the KITTI devkit averages.
- **Final position error** (:func:`final_position_error`): the end-point error after ``origin``
  alignment, in metres and percent of the distance travelled.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np
from scipy.spatial.transform import Rotation

from ..calib import Calibration
from ..errors import ColoradarError, SettingsError
from ..geometry import Trajectory, rig_velocity
from .alignment import Alignment, posyaw_alignment, umeyama_alignment
from .velocity_track import EgoVelocityTrack

__all__ = [
    "DRIFT_LENGTHS",
    "RPE_PAIRINGS",
    "RPG_LENGTHS",
    "ATEResult",
    "DriftResult",
    "Evaluation",
    "FinalError",
    "RPEPairing",
    "RPEResult",
    "VelocityErrors",
    "absolute_trajectory_error",
    "apply_alignment",
    "associate_trajectories",
    "final_position_error",
    "path_length",
    "relative_pose_error",
    "rpe_pairs",
    "rpg_relative_error",
    "trajectory_drift",
    "velocity_errors",
]

Align = Literal["se3", "sim3", "posyaw", "origin", "none"]
ALIGNMENTS: tuple[Align, ...] = get_args(Align)

RPEPairing = Literal["every_pose", "evo", "evo_all_pairs", "rpg"]
"""How :func:`relative_pose_error` pairs poses (see the module docstring)."""
RPE_PAIRINGS: tuple[RPEPairing, ...] = get_args(RPEPairing)


def path_length(positions: np.ndarray) -> np.ndarray:
    """Cumulative distance along a path: float64 ``(N,)`` [m], starting at 0."""
    p = np.asarray(positions, dtype=np.float64)
    if p.shape[0] == 0:
        return np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def associate_trajectories(estimate: Trajectory, reference: Trajectory,
                           max_gap: float | None = 1.0) -> tuple[Trajectory, Trajectory]:
    """The estimate's poses that the reference covers, and the reference at their times.

    Parameters
    ----------
    estimate, reference
        Trajectories in any time order relation (both strictly increasing).
    max_gap
        Leave out estimate times that fall between two reference poses more than this many
        seconds apart [s] (interpolation across a ground-truth dropout would be a guess).
        None: no limit.

    Returns
    -------
    (Trajectory, Trajectory)
        The kept estimate poses and the interpolated reference, same timestamps.

    Raises
    ------
    ColoradarError
        Fewer than two estimate poses lie within the reference.
    """
    t = estimate.timestamps
    keep = reference.covers(t)
    if max_gap is not None and len(reference) > 1:
        k = reference.timestamps
        i = np.clip(np.searchsorted(k, t, side="right") - 1, 0, len(k) - 2)
        keep &= (k[i + 1] - k[i]) <= max_gap
    if keep.sum() < 2:
        raise ColoradarError(
            f"{estimate.name}: only {int(keep.sum())} of {t.size} poses lie within the "
            f"reference {reference.name} (span {reference.start:.3f}..{reference.end:.3f} s, "
            f"estimate {t[0]:.3f}..{t[-1]:.3f} s); are they from the same run?")
    est = estimate[np.flatnonzero(keep)]
    return est, reference.interpolate(est.timestamps)


def apply_alignment(trajectory: Trajectory, alignment: Alignment) -> Trajectory:
    """``T · pose`` for every pose: positions ``s R p + t``, rotations ``R · R_i``."""
    return Trajectory(trajectory.timestamps, alignment.apply(trajectory.translations),
                      alignment.rotation * trajectory.rotations, trajectory.name)


def _stats(e: np.ndarray) -> dict[str, float]:
    return {"rmse": float(np.sqrt(np.mean(e * e))), "mean": float(np.mean(e)),
            "median": float(np.median(e)), "std": float(np.std(e)), "max": float(np.max(e))}


@dataclass(frozen=True, eq=False)
class ATEResult:
    """Absolute trajectory error.

    Attributes
    ----------
    timestamps
        float64 ``(M,)`` [s]: the associated poses.
    errors
        float64 ``(M,)`` [m]: position error after alignment.
    rotation_errors
        float64 ``(M,)`` [deg].
    alignment
        The transform applied to the estimate.
    aligned
        The aligned estimate (associated poses only).
    reference
        The reference at ``timestamps``.
    rmse, mean, median, std, max
        Of ``errors`` [m].
    rotation_rmse
        [deg].
    path_length
        Distance travelled along the reference over the associated span [m].
    """

    timestamps: np.ndarray
    errors: np.ndarray
    rotation_errors: np.ndarray
    alignment: Alignment
    aligned: Trajectory
    reference: Trajectory
    rmse: float
    mean: float
    median: float
    std: float
    max: float
    rotation_rmse: float
    path_length: float

    @property
    def rmse_percent(self) -> float:
        """ATE RMSE as a percentage of the distance travelled (NaN for no motion)."""
        return 100.0 * self.rmse / self.path_length if self.path_length > 0 else float("nan")


def absolute_trajectory_error(estimate: Trajectory, reference: Trajectory, *,
                              align: Align = "se3", max_gap: float | None = 1.0) -> ATEResult:
    """ATE of ``estimate`` against ``reference`` (e.g. the ground truth).

    Parameters
    ----------
    estimate, reference
        ``world_T_body(t)`` of the same body (e.g. both the rig's base frame).
    align
        ``"se3"`` (Umeyama rotation + translation, the default), ``"sim3"`` (with scale),
        ``"posyaw"`` (a rotation about world z + translation, the 4-DoF alignment of
        visual/radar-inertial odometry, :func:`~.alignment.posyaw_alignment`), ``"origin"``
        (make the first associated poses coincide, evo's ``--align_origin``), or ``"none"``.
    max_gap
        See :func:`associate_trajectories`.

    Returns
    -------
    ATEResult
    """
    if align not in ALIGNMENTS:
        raise SettingsError(f"align must be one of {', '.join(ALIGNMENTS)}, got {align!r}")
    est, ref = associate_trajectories(estimate, reference, max_gap)
    if align in ("se3", "sim3"):
        al = umeyama_alignment(est.translations, ref.translations, with_scale=align == "sim3")
    elif align == "posyaw":
        al = posyaw_alignment(est.translations, ref.translations)
    elif align == "origin":
        rot = ref.rotations[0] * est.rotations[0].inv()
        # A copy: Trajectory arrays are read-only, and SciPy's Rotation.apply (Cython memory
        # view) refuses a read-only buffer.
        first = np.array(est.translations[0], dtype=np.float64)
        al = Alignment(rot, ref.translations[0] - rot.apply(first))
    else:
        al = Alignment.identity()
    aligned = apply_alignment(est, al)
    e = np.linalg.norm(aligned.translations - ref.translations, axis=1)
    if align in ("se3", "sim3"):
        # Positions of a nearly straight path do not fix the roll about it, so the rotation
        # errors use the rotation that best aligns the orientations themselves.
        rot_al = (ref.rotations * est.rotations.inv()).mean()
        re = np.degrees((ref.rotations.inv() * rot_al * est.rotations).magnitude())
    else:
        re = np.degrees((ref.rotations.inv() * aligned.rotations).magnitude())
    st = _stats(e)
    return ATEResult(est.timestamps, e, re, al, aligned, ref, st["rmse"], st["mean"],
                     st["median"], st["std"], st["max"], float(np.sqrt(np.mean(re * re))),
                     float(path_length(ref.translations)[-1]))


@dataclass(frozen=True, eq=False)
class RPEResult:
    """Relative pose error over one segment length.

    Attributes
    ----------
    distance
        Segment length ``d`` [m].
    start_times, end_times
        float64 ``(K,)`` [s]: first and second pose of each pair.
    translation_errors
        float64 ``(K,)`` [m]: ``|t_E|``.
    rotation_errors
        float64 ``(K,)`` [deg]: ``angle(E)``.
    pairing
        How the pairs were chosen (:data:`RPEPairing`).
    yaw_errors
        float64 ``(K,)`` [deg]: ``|yaw|`` of ``E`` in world axes (rpg_trajectory_evaluation's
        ``rel_yaw``, see the module docstring); None when not computed.
    """

    distance: float
    start_times: np.ndarray
    end_times: np.ndarray
    translation_errors: np.ndarray
    rotation_errors: np.ndarray
    pairing: RPEPairing = "every_pose"
    yaw_errors: np.ndarray | None = None

    @property
    def pairs(self) -> int:
        """Number of pose pairs ``K``."""
        return int(self.translation_errors.size)

    @property
    def translation_percent(self) -> float:
        """Mean ``100·|t_E|/d`` (KITTI's translation error) [%]; NaN without pairs."""
        return float(100.0 * np.mean(self.translation_errors) / self.distance) if self.pairs \
            else float("nan")

    @property
    def rotation_deg_per_m(self) -> float:
        """Mean ``angle(E)/d`` [deg/m]; NaN without pairs."""
        return float(np.mean(self.rotation_errors) / self.distance) if self.pairs \
            else float("nan")

    @property
    def translation_rmse(self) -> float:
        """RMSE of ``|t_E|`` [m]."""
        e = self.translation_errors
        return float(np.sqrt(np.mean(e * e))) if self.pairs else float("nan")

    @property
    def rotation_rmse(self) -> float:
        """RMSE of ``angle(E)`` [deg]."""
        e = self.rotation_errors
        return float(np.sqrt(np.mean(e * e))) if self.pairs else float("nan")

    def statistics(self) -> dict[str, dict[str, float]]:
        """rpg_trajectory_evaluation's statistics of this length's errors.

        Returns
        -------
        dict
            ``"translation_percent"`` (``100 |t_E| / d`` [%], rpg's ``rel_trans_perc``) and
            ``"yaw_deg"`` (:attr:`yaw_errors` [deg], rpg's ``rel_yaw``), each a dict of
            ``rmse``, ``mean``, ``median``, ``std``, ``min``, ``max`` over the pairs (rpg's
            ``compute_statistics``); NaN without pairs (or without yaw errors).
        """
        yaw = self.yaw_errors if self.yaw_errors is not None else np.zeros(0)
        return {"translation_percent": _stats_or_nan(100.0 * self.translation_errors
                                                     / self.distance),
                "yaw_deg": _stats_or_nan(yaw)}


def _stats_or_nan(e: np.ndarray) -> dict[str, float]:
    """:func:`_stats` and the minimum; NaN for every figure of an empty array."""
    if not e.size:
        return dict.fromkeys(("rmse", "mean", "median", "std", "min", "max"), float("nan"))
    return {**_stats(e), "min": float(np.min(e))}


def _relative(traj: Trajectory, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, Rotation]:
    """``traj_i⁻¹ traj_j`` for index pairs: translations ``(K, 3)`` and rotations."""
    ri_inv = traj.rotations[i].inv()
    return ri_inv.apply(traj.translations[j] - traj.translations[i]), ri_inv * traj.rotations[j]


def rpe_pairs(path: np.ndarray, distance: float, pairing: RPEPairing = "every_pose", *,
              tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(i, j)`` of poses about ``distance`` apart along a path.

    Parameters
    ----------
    path
        float64 ``(N,)`` [m]: cumulative path length of the reference (:func:`path_length`),
        non-decreasing.
    distance
        ``d`` [m], positive.
    pairing
        ``"every_pose"``, ``"evo"``, ``"evo_all_pairs"`` or ``"rpg"`` (see the module
        docstring).
    tolerance
        Relative tolerance of ``"evo_all_pairs"`` (default 0.1, evo's) and ``"rpg"`` (default
        0.2, rpg_trajectory_evaluation's).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        int64 ``(K,)`` each: first and second pose of each pair, ``i < j``.
    """
    dist = np.asarray(path, dtype=np.float64)
    d = float(distance)
    if not d > 0:
        raise SettingsError(f"RPE distances must be positive, got {distance}")
    if pairing not in RPE_PAIRINGS:
        raise SettingsError(f"pairing must be one of {', '.join(RPE_PAIRINGS)}, got {pairing!r}")
    n = dist.size
    # A hair of slack so that exact multiples of the pose spacing are not pushed one pose
    # further by rounding of the cumulative sum.
    slack = 1e-9 * max(1.0, d)
    if pairing == "every_pose":
        # First j with dist[j] >= dist[i] + d.
        j = np.searchsorted(dist, dist + d - slack, side="left")
        i = np.flatnonzero(j < n)
        return i.astype(np.int64), j[i].astype(np.int64)
    if pairing == "evo":
        # Segment ends: pose 0, then each next pose at least d further along the path than
        # the previous end (evo >= 1.x restarts its path sum from 0 at each end; the searches on
        # the cumulative path give the same poses up to rounding, which ``slack`` covers). One
        # search per segment, not per pose.
        ends: list[int] = []
        k = 0
        while k < n:
            ends.append(k)
            k = int(np.searchsorted(dist, dist[k] + d - slack, side="left"))
        e = np.asarray(ends, dtype=np.int64)
        return e[:-1], e[1:]
    tol = (0.2 if pairing == "rpg" else 0.1) if tolerance is None else float(tolerance)
    if not 0 <= tol < 1:
        raise SettingsError(f"tolerance must lie in [0, 1), got {tolerance!r}")
    none = np.zeros(0, np.int64), np.zeros(0, np.int64)
    if n == 0:
        return none
    target = dist + d
    above = np.minimum(np.searchsorted(dist, target, side="left"), n - 1)  # first >= target
    below = np.maximum(above - 1, 0)
    j = np.where(np.abs(dist[above] - target) < np.abs(dist[below] - target), above, below)
    # On a standstill (equal path lengths) the earliest pose of the run of equals.
    j = np.searchsorted(dist, dist[j], side="left")
    off = np.abs(dist[j] - target)
    # evo keeps |…| <= tol·d, rpg |…| < tol·d.
    near = off <= tol * d + slack if pairing == "evo_all_pairs" else off < tol * d
    i = np.flatnonzero(near & (j > np.arange(n)))
    if pairing == "rpg" and i.size < 2:
        return none      # rpg: "Too few samples! Will not compute."
    return i.astype(np.int64), j[i].astype(np.int64)


def relative_pose_error(estimate: Trajectory, reference: Trajectory,
                        distances: tuple[float, ...] | list[float] = (1.0, 2.0, 5.0), *,
                        max_gap: float | None = 1.0, pairing: RPEPairing = "every_pose",
                        tolerance: float | None = None,
                        pairs_from: Literal["reference", "estimate"] | None = None
                        ) -> list[RPEResult]:
    """RPE over fixed travelled distances (KITTI / evo convention, see the module docstring).

    Parameters
    ----------
    estimate, reference
        ``world_T_body(t)`` of the same body.
    distances
        Segment lengths [m].
    max_gap
        See :func:`associate_trajectories`.
    pairing
        ``"every_pose"`` (default), ``"evo"`` (the pairs of ``evo_rpe -d D -u m``),
        ``"evo_all_pairs"`` (``evo_rpe -d D -u m --all_pairs``) or ``"rpg"``
        (rpg_trajectory_evaluation's); see :func:`rpe_pairs`.
    tolerance
        Relative path-length tolerance of ``"evo_all_pairs"`` (None: evo's 0.1) and ``"rpg"``
        (None: rpg's 0.2).
    pairs_from
        Whose path length picks the pairs; None: the reference for ``"every_pose"`` and
        ``"rpg"``, the estimate for the evo pairings (evo's default; ``"reference"`` is evo's
        ``--pairs_from_reference``).

    Returns
    -------
    list[RPEResult]
        One per distance (with no pairs where the run is shorter than it).
    """
    est, ref = associate_trajectories(estimate, reference, max_gap)
    if pairs_from is None:
        pairs_from = "reference" if pairing in ("every_pose", "rpg") else "estimate"
    if pairs_from not in ("reference", "estimate"):
        raise SettingsError(f"pairs_from must be 'reference' or 'estimate', got {pairs_from!r}")
    dist = path_length((ref if pairs_from == "reference" else est).translations)
    out = []
    for d in distances:
        i, j = rpe_pairs(dist, d, pairing, tolerance=tolerance)
        if i.size:
            te, re = _relative(est, i, j)
            tr, rr = _relative(ref, i, j)
            rr_inv = rr.inv()
            err_t = np.linalg.norm(rr_inv.apply(te - tr), axis=1)
            err = rr_inv * re
            err_r = np.degrees(err.magnitude())
            # rpg: the error in world axes through the estimate's attitude at j; its z-y-x
            # Euler yaw is atan2(m10, m00).
            m = (est.rotations[j] * err * est.rotations[j].inv()).as_matrix()
            err_yaw = np.degrees(np.abs(np.arctan2(m[:, 1, 0], m[:, 0, 0])))
        else:   # no pair (a run shorter than d); SciPy 1.11 cannot make an empty Rotation
            err_t = err_r = err_yaw = np.zeros(0)
        out.append(RPEResult(float(d), est.timestamps[i], est.timestamps[j], err_t, err_r,
                             pairing, err_yaw))
    return out


RPG_LENGTHS: tuple[float, ...] = (25.0, 50.0, 75.0, 100.0)
"""Segment lengths [m] of :func:`rpg_relative_error`: those radar-inertial odometry papers
report (x_rio, DeRO, 4DRadarSLAM, with rpg_trajectory_evaluation)."""


def rpg_relative_error(estimate: Trajectory, reference: Trajectory,
                       lengths: tuple[float, ...] | list[float] = RPG_LENGTHS, *,
                       max_gap: float | None = 1.0) -> list[RPEResult]:
    """Relative error over travelled distances as rpg_trajectory_evaluation computes it.

    The protocol of Zhang & Scaramuzza (IROS 2018) that radar-inertial odometry papers use:
    for every pose ``i``, the pose ``j`` whose distance along the reference from ``i`` is
    nearest to ``d``, kept within 20 % of ``d`` (``pairing="rpg"`` of :func:`rpe_pairs`);
    ``E = (ref_i⁻¹ ref_j)⁻¹ (est_i⁻¹ est_j)``; the translation error ``100 |t_E| / d`` [%]
    and the yaw error (:attr:`RPEResult.yaw_errors`) [deg], whose statistics
    :meth:`RPEResult.statistics` gives. Relative errors need no alignment (rpg applies only the
    alignment's scale, 1 for ``posyaw`` and ``se3``).

    Parameters
    ----------
    estimate, reference
        ``world_T_body(t)`` of the same body, z up in both worlds.
    lengths
        Segment lengths [m]; default :data:`RPG_LENGTHS`.
    max_gap
        See :func:`associate_trajectories`.

    Returns
    -------
    list[RPEResult]
        One per length; a length with fewer than two pairs (a run shorter than about 0.8
        of it) has none.
    """
    return relative_pose_error(estimate, reference, lengths, max_gap=max_gap, pairing="rpg")


DRIFT_LENGTHS: tuple[float, ...] = (2.0, 4.0, 6.0, 8.0, 10.0)
"""Segment lengths [m] of :func:`trajectory_drift`: KITTI's eight equally spaced lengths
(100…800 m, for cars) scaled to a hand-held rig indoors, where a ColoRadar run covers 20–150 m."""


@dataclass(frozen=True, eq=False)
class DriftResult:
    """KITTI-style drift: RPE pooled over every segment of several lengths.

    Attributes
    ----------
    segments
        One :class:`RPEResult` per length (``every_pose`` pairing: every pose starts a segment
        of each length, ending at the first pose at least that far along the reference's path).
    """

    segments: list[RPEResult]

    @property
    def lengths(self) -> tuple[float, ...]:
        """The segment lengths [m]."""
        return tuple(r.distance for r in self.segments)

    @property
    def translation_ratios(self) -> np.ndarray:
        """float64 ``(K,)``: ``|t_E| / L`` of every segment of every length [m/m]."""
        parts = [r.translation_errors / r.distance for r in self.segments]
        return np.concatenate(parts) if parts else np.zeros(0)

    @property
    def rotation_ratios(self) -> np.ndarray:
        """float64 ``(K,)``: ``angle(E) / L`` of every segment of every length [deg/m]."""
        parts = [r.rotation_errors / r.distance for r in self.segments]
        return np.concatenate(parts) if parts else np.zeros(0)

    @property
    def pairs(self) -> int:
        """Segments over all lengths."""
        return int(sum(r.pairs for r in self.segments))

    @property
    def translation_percent(self) -> float:
        """Mean of ``100 |t_E| / L`` over every segment of every length [%]; NaN without one."""
        r = self.translation_ratios
        return float(100.0 * r.mean()) if r.size else float("nan")

    @property
    def rotation_deg_per_m(self) -> float:
        """Mean of ``angle(E) / L`` over every segment of every length [deg/m]."""
        r = self.rotation_ratios
        return float(r.mean()) if r.size else float("nan")


def trajectory_drift(estimate: Trajectory, reference: Trajectory,
                     lengths: tuple[float, ...] | list[float] = DRIFT_LENGTHS, *,
                     max_gap: float | None = 1.0) -> DriftResult:
    """Translation drift [%] and rotation drift [deg/m] averaged the KITTI way.

    The KITTI odometry devkit (Geiger et al., CVPR 2012) takes segments of each length ``L``
    starting at every 10th frame, ending at the first frame at least ``L`` further along the
    ground truth's path, and averages ``|t_E| / L`` and ``angle(E) / L`` over *all* segments of
    all lengths together (so a length with more segments weighs more). Here every pose starts a
    segment (``pairing="every_pose"`` of :func:`relative_pose_error`); ``E`` as there.

    Parameters
    ----------
    estimate, reference
        ``world_T_body(t)`` of the same body.
    lengths
        Segment lengths [m]; default :data:`DRIFT_LENGTHS`.
    max_gap
        See :func:`associate_trajectories`.

    Returns
    -------
    DriftResult
    """
    return DriftResult(relative_pose_error(estimate, reference, lengths, max_gap=max_gap,
                                           pairing="every_pose"))


@dataclass(frozen=True, eq=False)
class FinalError:
    """Position error at the end of a trajectory whose first pose is put on the reference's.

    Attributes
    ----------
    error
        ``|p_ref − p_est|`` at the last associated pose after ``origin`` alignment [m].
    path_length
        Distance travelled along the reference over the associated span [m].
    """

    error: float
    path_length: float

    @property
    def percent(self) -> float:
        """``100 · error / path_length`` [%] (NaN for no motion)."""
        return 100.0 * self.error / self.path_length if self.path_length > 0 else float("nan")


def final_position_error(estimate: Trajectory, reference: Trajectory, *,
                         max_gap: float | None = 1.0) -> FinalError:
    """Where the estimate ends against where the reference ends, from the same start.

    The estimate is moved so that its first associated pose coincides with the reference's
    there (position and attitude: evo's ``--align_origin``); no later pose is used to align,
    so this is the drift a user of the estimate would see at the end of the run.

    Parameters
    ----------
    estimate, reference
        ``world_T_body(t)`` of the same body.
    max_gap
        See :func:`associate_trajectories`.
    """
    ate = absolute_trajectory_error(estimate, reference, align="origin", max_gap=max_gap)
    return FinalError(float(ate.errors[-1]), ate.path_length)


@dataclass(frozen=True, eq=False)
class VelocityErrors:
    """Ego-velocity estimates against the ground-truth rig velocity in the radar frame.

    Attributes
    ----------
    timestamps
        float64 ``(K,)`` [s]: frames compared (ok and within the ground truth).
    estimate, reference
        float64 ``(K, 3)`` [m/s], radar frame.
    frames_total
        Frames in the track.
    frames_failed
        Frames whose estimate was not ok.
    """

    timestamps: np.ndarray
    estimate: np.ndarray
    reference: np.ndarray
    frames_total: int
    frames_failed: int

    @property
    def errors(self) -> np.ndarray:
        """float64 ``(K, 3)``: estimate − reference [m/s]."""
        return self.estimate - self.reference

    @property
    def rmse(self) -> float:
        """RMSE of the error vector's norm [m/s]."""
        e = self.errors
        return float(np.sqrt(np.mean(np.sum(e * e, axis=1)))) if e.size else float("nan")

    @property
    def rmse_axes(self) -> np.ndarray:
        """float64 ``(3,)``: RMSE of each component [m/s]."""
        e = self.errors
        return np.sqrt(np.mean(e * e, axis=0)) if e.size else np.full(3, np.nan)

    @property
    def mean_speed(self) -> float:
        """Mean reference speed over the compared frames [m/s]."""
        return float(np.mean(np.linalg.norm(self.reference, axis=1))) if self.reference.size \
            else float("nan")


def velocity_errors(track: EgoVelocityTrack, reference: Trajectory, calib: Calibration,
                    sensor: str | None = None) -> VelocityErrors:
    """Compare ego-velocities with the ground truth's velocity of the radar origin.

    Parameters
    ----------
    track
        Estimated ego-velocities (radar frame).
    reference
        ``world_T_base(t)`` (ground truth).
    calib
        For ``base_T_<sensor>`` (the lever arm and the axes of the radar).
    sensor
        The radar; default ``track.frame``.

    Returns
    -------
    VelocityErrors
        Only frames whose estimate is ok and whose time the ground truth covers.
    """
    sensor = sensor or track.frame
    use = track.ok & reference.covers(track.timestamps)
    t = track.timestamps[use]
    if t.size:
        ref = rig_velocity(reference, t, calib=calib, sensor=sensor).linear
    else:
        ref = np.zeros((0, 3))
    return VelocityErrors(t, track.velocity[use], ref, len(track), int((~track.ok).sum()))


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Errors of one odometry estimate.

    Attributes
    ----------
    estimate, reference
        The full estimated trajectory and the ground truth (``world_T_base``).
    ate
        Absolute trajectory error.
    rpe
        Relative pose errors, one per distance.
    velocity
        Ego-velocity errors, or None without an ego-velocity track.
    track
        The ego-velocity track, if any.
    info
        What was evaluated (run, radar, source, alignment…), JSON-compatible.
    drift
        KITTI-style drift over :data:`~coloradar.odometry.metrics.DRIFT_LENGTHS` (or the
        lengths asked for).
    final
        Position error at the end, from the same start (``origin`` alignment).
    ate_posyaw
        ATE after ``posyaw`` alignment (the RIO literature's, beside ``ate``).
    rpg_relative
        Relative errors over :data:`RPG_LENGTHS` (or the lengths asked for) as
        rpg_trajectory_evaluation computes them (:func:`rpg_relative_error`).
    """

    estimate: Trajectory
    reference: Trajectory
    ate: ATEResult
    rpe: list[RPEResult]
    velocity: VelocityErrors | None = None
    track: EgoVelocityTrack | None = None
    info: dict = field(default_factory=dict)
    drift: DriftResult | None = None
    final: FinalError | None = None
    ate_posyaw: ATEResult | None = None
    rpg_relative: list[RPEResult] | None = None
