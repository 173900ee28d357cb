"""Anchoring the filter's output at the initial pose: the start's attitudes smoothed by the
gyro, and the anchor's tilt error carried into every pose's covariance."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .dead_reckoning import integrate_gyro
from .eskf import ErrorStateEKF, skew

__all__ = ["anchor_covariance", "smoothed_start"]


def smoothed_start(ekf: ErrorStateEKF, imu_t: np.ndarray, anchor_delay: float, out_t: np.ndarray,
                   out_R: np.ndarray, bg_c: np.ndarray) -> np.ndarray:
    """The attitudes ``world_R_imu`` of the poses with the first ``anchor_delay`` seconds'
    replaced by the attitude at ``anchor_delay`` carried back by the gyro, corrected by the
    bias ``bg_c`` estimated there.

    The first attitude estimates are the least certain (gravity aligned, possibly while
    moving); the filter's attitude a few seconds later, carried back, is better (a fixed-lag
    smoothing of the start). Without it a start-up tilt error of the first pose tilts the
    whole trajectory once the first poses are put on the truth's."""
    c = int(np.searchsorted(out_t, out_t[0] + anchor_delay))
    c = min(c, len(out_t) - 1)
    if c == 0:
        return out_R
    sel = (imu_t > out_t[0]) & (imu_t < out_t[c])
    tg, inv = np.unique(np.concatenate([out_t[:c + 1], imu_t[sel]]), return_inverse=True)
    _, wg = ekf.imu_at(tg)
    cum = integrate_gyro(tg, wg, bias=bg_c)             # imu(t_0)_R_imu(t)
    pos = inv[:c + 1]
    back = cum[pos].inv() * cum[pos[-1]]                # imu(t_i)_R_imu(t_c)
    out = out_R.copy()
    out[:c] = (Rotation.from_matrix(out_R[c]) * back[:c].inv()).as_matrix()
    return out


def anchor_covariance(cov_c: np.ndarray, p0: np.ndarray, pos: np.ndarray, vel: np.ndarray,
                       cov: np.ndarray, vcov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The output's pose and velocity covariances with the anchor's tilt error added.

    The output is rotated so that its first pose lies on the initial pose, and that first
    attitude is the filter's at pose ``c`` carried back (:func:`smoothed_start`): its tilt
    error ``δθ₀`` (world x, y; the filter's own estimate at ``c``) is imposed on every pose.
    To first order pose ``i`` then errs by ``δθ₀`` in attitude, ``δθ₀ × (p_i − p_0)`` in
    position and ``δθ₀ × v_i`` in velocity on top of the filter's own error (the tilt is
    observable, so the filter's later tilt error soon decorrelates from ``δθ₀``; its yaw
    error does not, and already includes the anchor's, so yaw is left out).

    Parameters
    ----------
    cov_c
        float64 ``(6, 6)``: the covariance at the anchoring pose ``c``.
    p0
        float64 ``(3,)``: the first pose's position [m].
    pos, vel
        float64 ``(M, 3)``: positions [m] and velocities [m/s] of the poses whose covariances
        are given, filter world frame.
    cov, vcov
        float64 ``(M, 6, 6)`` (position, attitude) and ``(M, 3, 3)``, filter world frame.

    Returns
    -------
    cov, vcov
        The same shapes, with the anchor's tilt error added.
    """
    p_tilt = cov_c[3:, 3:].copy()
    p_tilt[2, :] = 0.0
    p_tilt[:, 2] = 0.0
    m = len(pos)
    g = np.zeros((m, 6, 3))
    g[:, :3] = -skew(pos - p0)
    g[:, 3:] = np.eye(3)
    sv = skew(vel)
    cov = cov + g @ p_tilt @ g.transpose(0, 2, 1)
    vcov = vcov + sv @ p_tilt @ sv.transpose(0, 2, 1)
    return cov, vcov
