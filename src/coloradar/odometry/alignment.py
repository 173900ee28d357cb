"""Least-squares alignment of two point sets: SE(3), or Sim(3) with a scale (Umeyama 1991).

Given corresponding points ``x_i`` (source, e.g. estimated positions) and ``y_i`` (target,
e.g. ground truth), the transform minimising ``Σ |y_i − (s R x_i + t)|²`` is, in closed form
(S. Umeyama, "Least-squares estimation of transformation parameters between two point
patterns", IEEE TPAMI 13(4), 1991)::

    μx, μy = means;  σx² = mean |x_i − μx|²;  Σ = mean (y_i − μy)(x_i − μx)ᵀ = U D Vᵀ
    S = diag(1, 1, sign(det U · det V))        (a rotation, never a reflection)
    R = U S Vᵀ;   s = tr(D S) / σx²  (1 without scale);   t = μy − s R μx

The rotation is unique when the points do not lie on one line; for a straight-line trajectory
any rotation about the line fits equally well and one of them is returned.

:func:`posyaw_alignment` is the same fit restricted to a rotation about the world z axis (4
degrees of freedom: position and yaw), the alignment of visual- and radar-inertial odometry,
whose roll and pitch the accelerometer observes (Z. Zhang and D. Scaramuzza, "A Tutorial on
Quantitative Trajectory Evaluation for Visual(-Inertial) Odometry", IROS 2018;
``rpg_trajectory_evaluation``'s ``posyaw``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import ColoradarError, SettingsError

__all__ = ["Alignment", "posyaw_alignment", "umeyama_alignment"]


@dataclass(frozen=True, eq=False)
class Alignment:
    """A similarity transform ``y = s · R x + t``.

    Attributes
    ----------
    rotation
        A single :class:`scipy.spatial.transform.Rotation`.
    translation
        float64 ``(3,)`` [m].
    scale
        ``s`` (1.0 for an SE(3) alignment).
    """

    rotation: Rotation
    translation: np.ndarray
    scale: float = 1.0

    @classmethod
    def identity(cls) -> Alignment:
        """The identity transform."""
        return cls(Rotation.identity(), np.zeros(3), 1.0)

    def matrix(self) -> np.ndarray:
        """float64 ``(4, 4)``: ``[[s R, t], [0, 1]]``."""
        m = np.eye(4)
        m[:3, :3] = self.scale * self.rotation.as_matrix()
        m[:3, 3] = self.translation
        return m

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Map float ``(N, 3)`` or ``(3,)`` points; float64 result."""
        p = np.array(points, dtype=np.float64)
        return self.scale * self.rotation.apply(p) + self.translation


def umeyama_alignment(source: np.ndarray, target: np.ndarray, *,
                      with_scale: bool = False) -> Alignment:
    """The SE(3) (or Sim(3)) transform that best maps ``source`` points onto ``target``.

    Parameters
    ----------
    source, target
        float ``(N, 3)``, corresponding rows [m], N >= 2 (>= 3 off one line for a unique
        rotation).
    with_scale
        Also estimate a scale (Sim(3)), e.g. for monocular or badly scaled estimates.

    Returns
    -------
    Alignment
        Minimises ``Σ |target_i − (s R source_i + t)|²``.
    """
    x, y = _point_sets(source, target)
    mx, my = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mx, y - my
    var_x = float((xc * xc).sum() / x.shape[0])
    cov = yc.T @ xc / x.shape[0]
    u, dvals, vt = np.linalg.svd(cov)
    s = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2] = -1.0
    r = (u * s) @ vt
    scale = float((dvals * s).sum() / var_x) if with_scale and var_x > 0 else 1.0
    rot = Rotation.from_matrix(r)
    return Alignment(rot, my - scale * rot.apply(mx), scale)


def _point_sets(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both point sets as float64 ``(N, 3)``, checked (equal shapes, N >= 2)."""
    x = np.asarray(source, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 3:
        raise SettingsError(f"expected two (N, 3) arrays of equal shape, got {x.shape}, {y.shape}")
    if x.shape[0] < 2:
        raise ColoradarError(f"an alignment needs at least 2 corresponding positions, "
                             f"got {x.shape[0]}")
    return x, y


def posyaw_alignment(source: np.ndarray, target: np.ndarray) -> Alignment:
    """The rotation about world z and the translation that best map ``source`` onto ``target``.

    A visual- or radar-inertial estimate has four unobservable degrees of freedom: position and
    yaw (gravity fixes roll and pitch). Its trajectory is therefore aligned to the reference
    by the rigid transform ``y = R_z(θ) x + t`` that minimises ``Σ |y_i − R_z(θ) x_i − t|²``
    (Z. Zhang and D. Scaramuzza, "A Tutorial on Quantitative Trajectory Evaluation for
    Visual(-Inertial) Odometry", IROS 2018: the 4-DoF alignment of its trajectory-alignment
    section; ``align_umeyama(..., yaw_only=True)`` of ``rpg_trajectory_evaluation``, which
    ``posyaw`` uses with all poses). In closed form, with centred points
    ``x̃_i = x_i − μx``, ``ỹ_i = y_i − μy``::

        θ = atan2(Σ (x̃_x ỹ_y − x̃_y ỹ_x), Σ (x̃_x ỹ_x + x̃_y ỹ_y));   t = μy − R_z(θ) μx

    (the z components do not depend on θ; ``θ`` maximises ``Σ ỹ_iᵀ R_z(θ) x̃_i``).

    Parameters
    ----------
    source, target
        float ``(N, 3)``, corresponding rows [m] in frames whose z axes are both "up"
        (against gravity), N >= 2. When the points have no horizontal spread the yaw is
        undetermined and 0 is returned.

    Returns
    -------
    Alignment
        Scale 1; its rotation never rolls or pitches.
    """
    x, y = _point_sets(source, target)
    mx, my = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mx, y - my
    sin = float(np.sum(xc[:, 0] * yc[:, 1] - xc[:, 1] * yc[:, 0]))
    cos = float(np.sum(xc[:, 0] * yc[:, 0] + xc[:, 1] * yc[:, 1]))
    rot = Rotation.from_rotvec([0.0, 0.0, float(np.arctan2(sin, cos))])
    return Alignment(rot, my - rot.apply(mx), 1.0)
