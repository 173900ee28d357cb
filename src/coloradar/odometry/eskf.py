"""Error-state extended Kalman filter of an IMU with velocity-type aiding (the RIO core).

**Nominal state** ``x = (p, v, R, b_a, b_g, t_d[r], R_ir[r])``: the IMU origin's position and
velocity in a gravity-aligned world frame (z up) [m, m/s], its attitude ``R = world_R_imu``,
the accelerometer and gyro biases (IMU frame) [m/s², rad/s], and per aiding radar ``r`` its
time offset ``t_d`` [s] (a frame stamped ``t`` shows the motion at IMU time ``t + t_d``) and
extrinsic rotation ``R_ir = imu_R_radar``.

**Error state** ``δx = (δp, δv, δθ, δb_a, δb_g, δt_d[r], δφ[r])`` (15 + 4 per radar),
with the attitude error in the world frame, ``R_true = Exp(δθ) R``, and the extrinsic error in
the radar frame, ``R_ir,true = R_ir Exp(δφ)``. The IMU measures
``f = Rᵀ(a − g) + b_a + n_a`` and ``ω_m = ω + b_g + n_g``; the biases are random walks.

**Propagation** between IMU samples ``k → k+1`` (``Δt``; mid-point rates
``ω̄ = ½(ω_k + ω_{k+1}) − b_g``, ``f̄ = ½(f_k + f_{k+1}) − b_a``)::

    R⁺ = R Exp(ω̄ Δt),   a = R Exp(½ω̄ Δt) f̄ + g,   v⁺ = v + a Δt,   p⁺ = p + v Δt + ½ a Δt²

and ``P⁺ = Φ P Φᵀ + Q`` with the second-order transition of the continuous error dynamics
``δṗ = δv``, ``δv̇ = −[R f̄]× δθ − R δb_a − R n_a``, ``δθ̇ = −R δb_g − R n_g``,
``δḃ = n_b``::

    Φ = I + F Δt + ½ F² Δt²,   Q = diag(0, σ_a² Δt, σ_g² Δt, σ_ba² Δt, σ_bg² Δt, ...)

(σ as noise densities; ``R σ² I Rᵀ = σ² I``). Nothing loops over IMU samples in Python: the
rotation increments, ``Φ_k`` and ``Q_k`` of all samples of an interval are formed at once,
the attitudes by a parallel prefix product (log₂ n batched 3 × 3 products), velocity and
position by cumulative sums, and the interval's ``(Φ, Q)`` by pairwise composition
``(Φ_b Φ_a, Φ_b Q_a Φ_bᵀ + Q_b)`` in log₂ n batched steps.

**Updates** are linear-Gaussian on ``δx`` with Joseph-form covariance, chi-square gating,
injection into the nominal state and the usual first-order reset (ignored: the reset Jacobian
``I − ½[δθ]×`` differs from I by the size of the correction).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ColoradarError, SettingsError

__all__ = ["GRAVITY", "ErrorStateEKF", "ImuNoise", "exp_so3", "skew"]

GRAVITY = np.array([0.0, 0.0, -9.80665])
"""Gravity in the filter's world frame (z up) [m/s²]."""

P, V, TH, BA, BG = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)


def skew(w: np.ndarray) -> np.ndarray:
    """``[w]×`` for ``(3,)`` or ``(N, 3)`` vectors: ``(3, 3)`` or ``(N, 3, 3)``."""
    w = np.asarray(w, dtype=np.float64)
    out = np.zeros((*w.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def exp_so3(phi: np.ndarray) -> np.ndarray:
    """Rodrigues: ``Exp(φ)`` for ``(3,)`` or ``(N, 3)`` rotation vectors [rad]."""
    phi = np.asarray(phi, dtype=np.float64)
    th = np.linalg.norm(phi, axis=-1)[..., None, None]
    k = skew(phi)
    small = th < 1e-8
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th**2 / 6.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    return np.eye(3) + a * k + b * (k @ k)


def _orthonormalize(r: np.ndarray) -> np.ndarray:
    # One Newton step towards the nearest rotation: enough for the round-off of a few dozen
    # products (the error is squared each time it is applied).
    return r @ (1.5 * np.eye(3) - 0.5 * (r.T @ r))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a × b`` of two (3,) vectors (numpy.cross costs ~20x more on single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _prefix_products(m: np.ndarray) -> np.ndarray:
    """Inclusive prefix products ``m_0 m_1 ⋯ m_k`` of a stack ``(n, d, d)``: a Hillis-Steele
    scan, ``ceil(log₂ n)`` batched matrix products instead of n sequential ones."""
    p = m
    s = 1
    while s < p.shape[0]:
        p = np.concatenate([p[:s], p[:-s] @ p[s:]])
        s *= 2
    return p


def _compose_transitions(phi: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The single step equivalent to the steps ``(Φ_k, Q_k)``, k = 0..n−1 in time order:
    ``Φ = Φ_{n−1}⋯Φ_0`` and ``Q = Σ_k Φ_{n−1}⋯Φ_{k+1} Q_k (⋯)ᵀ``, by pairwise (tree)
    reduction: adjacent steps a then b combine to ``(Φ_b Φ_a, Φ_b Q_a Φ_bᵀ + Q_b)``."""
    while phi.shape[0] > 1:
        n2 = phi.shape[0] // 2 * 2
        a, b = phi[0:n2:2], phi[1:n2:2]
        qa, qb = q[0:n2:2], q[1:n2:2]
        nphi = b @ a
        nq = b @ qa @ np.swapaxes(b, 1, 2) + qb
        if n2 < phi.shape[0]:
            nphi = np.concatenate([nphi, phi[n2:]])
            nq = np.concatenate([nq, q[n2:]])
        phi, q = nphi, nq
    return phi[0], q[0]


@dataclass(frozen=True)
class ImuNoise:
    """Continuous-time IMU noise of the filter's process model.

    Attributes
    ----------
    accel_noise_density, gyro_noise_density
        White noise [m/s²/√Hz], [rad/s/√Hz].
    accel_bias_walk, gyro_bias_walk
        Bias random walk [m/s²/√s], [rad/s/√s].
    """

    accel_noise_density: float
    gyro_noise_density: float
    accel_bias_walk: float
    gyro_bias_walk: float


class ErrorStateEKF:
    """The filter: nominal state, error covariance, propagation and updates.

    Parameters
    ----------
    imu_t, imu_f, imu_w
        float64 ``(N,)`` [s], ``(N, 3)`` specific force [m/s²], ``(N, 3)`` rate [rad/s]: the
        whole IMU stream (IMU frame), strictly increasing times.
    noise
        Process noise.
    n_radars
        Radars whose time offset and extrinsic rotation are states.
    """

    def __init__(self, imu_t: np.ndarray, imu_f: np.ndarray, imu_w: np.ndarray,
                 noise: ImuNoise, n_radars: int = 1, *, _stacked: np.ndarray | None = None):
        self.imu_t = np.asarray(imu_t, dtype=np.float64)
        # One (N, 6) array [f | ω] that interpolation reads a row of; f and ω are its views.
        self._imu = (_stacked if _stacked is not None else
                     np.ascontiguousarray(np.hstack([np.asarray(imu_f, dtype=np.float64),
                                                     np.asarray(imu_w, dtype=np.float64)])))
        self.imu_f, self.imu_w = self._imu[:, :3], self._imu[:, 3:]
        if self.imu_t.size < 2 or np.any(np.diff(self.imu_t) <= 0):
            raise ColoradarError("the filter needs at least 2 IMU samples with strictly "
                                 "increasing timestamps")
        self.noise = noise
        self.n_radars = n_radars
        self.dim = 15 + 4 * n_radars
        self.p = np.zeros(3)
        self.v = np.zeros(3)
        self.R = np.eye(3)
        self.ba = np.zeros(3)
        self.bg = np.zeros(3)
        self.td = np.zeros(n_radars)
        self.R_ir = np.tile(np.eye(3), (n_radars, 1, 1))
        self.P = np.zeros((self.dim, self.dim))
        self.t = float(self.imu_t[0])
        q = np.zeros(self.dim)
        q[V] = noise.accel_noise_density**2
        q[TH] = noise.gyro_noise_density**2
        q[BA] = noise.accel_bias_walk**2
        q[BG] = noise.gyro_bias_walk**2
        self._q = q                                   # per second
        self._q_extra = np.zeros(self.dim)            # random walks of t_d, φ (per second)
        self.transition = np.eye(self.dim)            # Φ of the last propagation (smoother)

    @classmethod
    def from_array(cls, imu_t: np.ndarray, imu: np.ndarray, noise: ImuNoise,
                   n_radars: int = 1) -> ErrorStateEKF:
        """The filter on one ``(N, 6)`` array ``[f | ω]`` (units as the constructor's), kept
        as it is when float64 and C-contiguous: a 10-minute 300 Hz stream is 8.6 MB that the
        constructor would copy."""
        arr = np.ascontiguousarray(imu, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != 6:
            raise SettingsError(f"expected IMU data of shape (N, 6), got {arr.shape}")
        return cls(imu_t, arr[:, :3], arr[:, 3:], noise, n_radars, _stacked=arr)

    # -- indices -----------------------------------------------------------------------------

    def td_index(self, r: int) -> int:
        """Error-state index of radar ``r``'s time offset."""
        return 15 + r

    def phi_slice(self, r: int) -> slice:
        """Error-state slice of radar ``r``'s extrinsic rotation."""
        s = 15 + self.n_radars + 3 * r
        return slice(s, s + 3)

    def set_extra_walk(self, index: int | slice, var_per_s: float) -> None:
        """Random-walk variance rate [unit²/s] of a calibration state."""
        self._q_extra[index] = var_per_s

    # -- IMU access --------------------------------------------------------------------------
    def imu_at(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Raw specific force and rate linearly interpolated at ``t`` (clamped to the stream)."""
        tt = np.atleast_1d(np.asarray(t, dtype=np.float64))
        ts = self.imu_t
        i = np.clip(np.searchsorted(ts, tt, side="right") - 1, 0, ts.size - 2)
        a = np.clip((tt - ts[i]) / (ts[i + 1] - ts[i]), 0.0, 1.0)[:, None]
        x = self._imu[i] * (1.0 - a) + self._imu[i + 1] * a
        if np.ndim(t) == 0:
            return x[0, :3], x[0, 3:]
        return x[:, :3], x[:, 3:]

    def angular_state(self, t: float, h: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
        """Bias-corrected angular rate [rad/s] and its derivative [rad/s²] at ``t`` (IMU
        frame); the derivative is a centred difference over ``±h``, averaged over ``2h``."""
        _, w = self.imu_at(np.array([t - h, t, t + h]))
        return w[1] - self.bg, (w[2] - w[0]) / (2 * h)

    # -- propagation -------------------------------------------------------------------------
    def propagate(self, t_end: float) -> None:
        """Propagate the nominal state and covariance from ``self.t`` to ``t_end``; the
        interval's transition ``Φ`` is left in :attr:`transition` (the identity when no time
        passed)."""
        self.transition = np.eye(self.dim)
        if t_end <= self.t:
            return
        i0 = int(np.searchsorted(self.imu_t, self.t, side="right"))
        i1 = int(np.searchsorted(self.imu_t, t_end, side="left"))
        ends = self.imu_at(np.array([self.t, t_end]))
        tg = np.concatenate([[self.t], self.imu_t[i0:i1], [t_end]])
        xg = np.concatenate([np.hstack(ends)[:1], self._imu[i0:i1], np.hstack(ends)[1:]])
        # Samples closer than 1 µs (a knot at an IMU sample) give no step.
        keep = np.concatenate([[True], np.diff(tg) > 1e-6])
        tg, xg = tg[keep], xg[keep]
        if tg.size < 2:
            self.t = t_end
            return
        dt = np.diff(tg)
        mid = 0.5 * (xg[1:] + xg[:-1])
        fb = mid[:, :3] - self.ba
        wb = mid[:, 3:] - self.bg
        d_full = exp_so3(wb * dt[:, None])
        d_half = exp_so3(0.5 * wb * dt[:, None])
        n = dt.size
        rs = np.concatenate([self.R[None], self.R @ _prefix_products(d_full)])
        r_mid = rs[:-1] @ d_half
        a_sf = np.einsum("nij,nj->ni", r_mid, fb)                  # R f̄, world
        acc = a_sf + GRAVITY
        dv = acc * dt[:, None]
        vs = self.v + np.concatenate([np.zeros((1, 3)), np.cumsum(dv, 0)])
        self.p = self.p + np.sum(vs[:-1] * dt[:, None] + 0.5 * dv * dt[:, None], 0)
        self.v = vs[-1]
        self.R = _orthonormalize(rs[-1])
        # Transition matrices and noise of all steps at once, then composed pairwise.
        phi = np.zeros((n, self.dim, self.dim))
        phi[:, np.arange(self.dim), np.arange(self.dim)] = 1.0
        d1 = dt[:, None, None]
        d2 = 0.5 * d1**2
        sk = skew(a_sf)
        eye = np.eye(3)
        phi[:, P, V] = eye * d1
        phi[:, V, TH] = -sk * d1
        phi[:, V, BA] = -r_mid * d1
        phi[:, TH, BG] = -r_mid * d1
        phi[:, P, TH] = -sk * d2
        phi[:, P, BA] = -r_mid * d2
        phi[:, V, BG] = sk @ r_mid * d2
        qd = np.zeros((n, self.dim, self.dim))
        qd[:, np.arange(self.dim), np.arange(self.dim)] = (self._q + self._q_extra) * dt[:, None]
        f, q = _compose_transitions(phi, qd)
        self.transition = f
        pm = f @ self.P @ f.T + q
        self.P = 0.5 * (pm + pm.T)
        self.t = t_end

    # -- updates -----------------------------------------------------------------------------
    def update(self, residual: np.ndarray, H: np.ndarray, Rm: np.ndarray,
               gate: float | None = None) -> tuple[bool, float]:
        """Kalman update with ``residual = z − h(x̂)``, Jacobian ``H`` (m × dim) and
        measurement covariance ``Rm``. Returns (accepted, normalised innovation squared)."""
        S = H @ self.P @ H.T + Rm
        S = 0.5 * (S + S.T)
        try:
            Si = np.linalg.inv(S)
        except np.linalg.LinAlgError:
            return False, float("inf")
        nis = float(residual @ Si @ residual)
        if gate is not None and not nis <= gate:
            return False, nis
        K = self.P @ H.T @ Si
        dx = K @ residual
        ikh = np.eye(self.dim) - K @ H
        pm = ikh @ self.P @ ikh.T + K @ Rm @ K.T
        self.P = 0.5 * (pm + pm.T)
        self.inject(dx)
        return True, nis

    def inject(self, dx: np.ndarray) -> None:
        """Add an error-state correction to the nominal state."""
        self.p = self.p + dx[P]
        self.v = self.v + dx[V]
        self.R = exp_so3(dx[TH]) @ self.R
        self.ba = self.ba + dx[BA]
        self.bg = self.bg + dx[BG]
        for r in range(self.n_radars):
            self.td[r] += dx[self.td_index(r)]
            self.R_ir[r] = self.R_ir[r] @ exp_so3(dx[self.phi_slice(r)])

    # -- measurement models ------------------------------------------------------------------
    def radar_velocity_model(self, r: int, t_ir: np.ndarray
                             ) -> tuple[np.ndarray, np.ndarray]:
        """Predicted radar-origin velocity in the radar frame and its Jacobian ``(3, dim)``.

        ``y = R_irᵀ (Rᵀ v + ω × t_ir)`` at the current filter time; ``t_ir`` is the radar
        origin in the IMU frame [m]. The time-offset column is ``dy/dt``
        (``d(Rᵀv)/dt = −ω × Rᵀv + f − b_a + Rᵀ g``, ``d(ω × t)/dt = α × t``).
        """
        w, alpha = self.angular_state(self.t)
        f, _ = self.imu_at(self.t)
        rt = self.R.T
        vb = rt @ self.v
        u = vb + _cross(w, t_ir)
        rir_t = self.R_ir[r].T
        y = rir_t @ u
        H = np.zeros((3, self.dim))
        H[:, V] = rir_t @ rt
        H[:, TH] = rir_t @ rt @ skew(self.v)
        H[:, BG] = rir_t @ skew(t_ir)
        du = -_cross(w, vb) + (f - self.ba) + rt @ GRAVITY + _cross(alpha, t_ir)
        H[:, self.td_index(r)] = rir_t @ du
        H[:, self.phi_slice(r)] = skew(y)
        return y, H
