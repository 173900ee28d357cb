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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import ColoradarError, SettingsError

__all__ = ["Alignment", "umeyama_alignment"]


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
    x = np.asarray(source, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 3:
        raise SettingsError(f"expected two (N, 3) arrays of equal shape, got {x.shape}, {y.shape}")
    if x.shape[0] < 2:
        raise ColoradarError(f"an alignment needs at least 2 corresponding positions, "
                             f"got {x.shape[0]}")
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
