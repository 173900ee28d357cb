"""The Rauch–Tung–Striebel smoother of the radar-inertial filter (:mod:`coloradar.odometry.smoother`).

References: for a linear-Gaussian model the smoothed states are the batch least-squares
solution over the whole run (normal equations, solved here by brute force); on the
simulator's analytic rig motion the smoothed poses must be closer to the truth than the
filter's, and the last pose must be the filter's own (nothing comes after it).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from coloradar.odometry import RioConfig, rio_odometry
from coloradar.odometry.smoother import RtsSmoother, rts_gain
from test_odometry_rio import PRESET, _relative_truth, _synthetic


class _LinearFilter:
    """A Kalman filter of a 3-D constant-velocity model with the error-state filter's
    attributes (19 states, one radar): only position and velocity move; the rest is held
    fixed (zero variance), as a calibration state is before its release."""

    def __init__(self, dt: float, q: tuple[float, float], p0: np.ndarray) -> None:
        self.dim, self.n_radars = 19, 1
        self.p, self.v = np.zeros(3), np.zeros(3)
        self.R, self.R_ir = np.eye(3), np.eye(3)[None].copy()
        self.ba, self.bg, self.td = np.zeros(3), np.zeros(3), np.zeros(1)
        self.P = np.zeros((19, 19))
        self.P[:6, :6] = p0
        self.F = np.eye(19)
        self.F[:3, 3:6] = dt * np.eye(3)
        self.Q = np.zeros((19, 19))
        self.Q[:3, :3] = q[0] ** 2 * np.eye(3)
        self.Q[3:6, 3:6] = q[1] ** 2 * np.eye(3)
        self.transition = np.eye(19)

    def td_index(self, r: int) -> int:
        return 15 + r

    def phi_slice(self, r: int) -> slice:
        return slice(16 + 3 * r, 19 + 3 * r)

    def propagate(self) -> None:
        self.p, self.v = self.p + self.F[0, 3] * self.v, self.v.copy()
        self.P = self.F @ self.P @ self.F.T + self.Q
        self.transition = self.F

    def update(self, z: np.ndarray, sigma: float) -> None:
        H = np.zeros((3, 19))
        H[:, :3] = np.eye(3)
        S = H @ self.P @ H.T + sigma**2 * np.eye(3)
        K = self.P @ H.T @ np.linalg.inv(S)
        dx = K @ (z - self.p)
        self.p, self.v = self.p + dx[:3], self.v + dx[3:6]
        self.P = (np.eye(19) - K @ H) @ self.P


def _batch_positions(zs: np.ndarray, dt: float, q: tuple[float, float], p0: np.ndarray,
                     sigma: float) -> np.ndarray:
    """Least squares over all states ``x_k = (p_k, v_k)`` at once: the prior on ``x_0``
    (zero mean), ``x_{k+1} − F x_k ~ N(0, Q)`` and ``z_k − p_k ~ N(0, σ² I)``."""
    n = len(zs)
    F = np.eye(6)
    F[:3, 3:] = dt * np.eye(3)
    Qi = np.linalg.inv(np.diag([q[0] ** 2] * 3 + [q[1] ** 2] * 3))
    A = np.zeros((6 * n, 6 * n))
    b = np.zeros(6 * n)
    A[:6, :6] += np.linalg.inv(p0)
    for k in range(n - 1):
        J = np.zeros((6, 6 * n))
        J[:, 6 * k:6 * k + 6] = -F
        J[:, 6 * k + 6:6 * k + 12] = np.eye(6)
        A += J.T @ Qi @ J
    for k in range(n):
        A[6 * k:6 * k + 3, 6 * k:6 * k + 3] += np.eye(3) / sigma**2
        b[6 * k:6 * k + 3] += zs[k] / sigma**2
    return np.linalg.solve(A, b).reshape(n, 6)[:, :3]


def test_smoothed_states_are_the_batch_least_squares_solution():
    rng = np.random.default_rng(4)
    dt, q, sigma, n = 0.1, (0.01, 0.2), 0.3, 40
    p0 = np.diag([1.0] * 3 + [0.5] * 3)
    truth = np.cumsum(rng.normal(0, 0.1, (n, 3)), axis=0)
    zs = truth + rng.normal(0, sigma, (n, 3))
    f = _LinearFilter(dt, q, p0)
    f.update(zs[0], sigma)
    with RtsSmoother(f) as sm:                       # type: ignore[arg-type]
        at = [sm.pose_at()]
        filtered = [f.p.copy()]
        for k in range(1, n):
            sm.before(f)                             # type: ignore[arg-type]
            f.propagate()
            sm.after(f)                              # type: ignore[arg-type]
            f.update(zs[k], sigma)
            at.append(sm.pose_at())
            filtered.append(f.p.copy())
        # asked in any order, the same answer
        order = rng.permutation(n)
        pos, att = sm.smoothed_poses(f, np.asarray(at)[order])  # type: ignore[arg-type]
    pos[order] = pos.copy()
    ref = _batch_positions(zs, dt, q, p0, sigma)
    np.testing.assert_allclose(pos, ref, atol=1e-9)
    np.testing.assert_allclose(att, np.tile(np.eye(3), (n, 1, 1)), atol=1e-12)
    np.testing.assert_allclose(pos[-1], filtered[-1], atol=1e-12)
    # and smoothing helps: closer to the truth than the filter on this run
    assert np.sqrt(np.mean((pos - truth) ** 2)) < np.sqrt(np.mean((np.array(filtered) - truth) ** 2))


def test_a_released_state_has_no_correlation_with_the_past():
    P = np.array([[2.0, 0.5], [0.5, 1.0]])
    F = np.eye(2)
    Pp = np.array([[2.0, 0.0], [0.0, 4.0]])          # state 1 set afresh after the step
    g = rts_gain(P, F, Pp, released=[1])
    np.testing.assert_allclose(g, [[1.0, 0.0], [0.25, 0.0]])
    held = rts_gain(P, F, np.diag([2.0, 0.0]))       # state 1 held fixed: no gain from it
    np.testing.assert_allclose(held[:, 1], 0.0)


def _rpe(positions: np.ndarray, rotations: Rotation, truth_p: np.ndarray,
         truth_r: Rotation, lag: int) -> float:
    """RMS error of the relative translation over ``lag`` frames, in the first frame's axes."""
    d_est = rotations[:-lag].inv().apply(positions[lag:] - positions[:-lag])
    d_true = truth_r[:-lag].inv().apply(truth_p[lag:] - truth_p[:-lag])
    return float(np.sqrt(np.mean(np.sum((d_est - d_true) ** 2, axis=1))))


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_smoothed_motion_is_closer_to_the_truth(seed):
    """A 30 s handheld run (simulated IMU, noisy radar ego-velocities): the smoothed relative
    motion over 1 s and 3 s is better than the filter's."""
    imu_t, data, track, traj, *_ = _synthetic(30.0, seed, profile="handheld", speed=1.0,
                                              vel_sigma=0.05)
    filt = rio_odometry(track, PRESET, imu_t, data)
    smooth = rio_odometry(track, PRESET, imu_t, data, config=RioConfig(smooth=True))
    t = filt.trajectory.timestamps
    np.testing.assert_array_equal(t, smooth.trajectory.timestamps)
    tp, tr = _relative_truth(traj, t)
    for lag in (10, 30):
        e_f = _rpe(filt.trajectory.translations, filt.trajectory.rotations, tp, tr, lag)
        e_s = _rpe(smooth.trajectory.translations, smooth.trajectory.rotations, tp, tr, lag)
        assert e_s < 0.85 * e_f, (lag, e_s, e_f)


def test_two_radars_with_their_own_clocks_are_smoothed_too():
    """Two radars, each with its own time offset (released at the start): the frames of both
    are steps of the smoother; the smoothed motion over 1 s is better than the filter's, and
    ``filtered`` is the filter's own output, bit for bit."""
    kw = dict(profile="handheld", speed=1.5, radar_rate=10.0, vel_sigma=0.05)
    imu_t, data, casc, traj, *_ = _synthetic(20.0, 5, td=0.025, **kw)
    _, _, sc, *_ = _synthetic(20.0, 5, td=0.060, radar="single_chip", first_frame=0.08, **kw)
    filt = rio_odometry([casc, sc], PRESET, imu_t, data)
    smooth = rio_odometry([casc, sc], PRESET, imu_t, data, config=RioConfig(smooth=True))
    assert filt.filtered is None
    np.testing.assert_array_equal(smooth.filtered.translations, filt.trajectory.translations)
    tp, tr = _relative_truth(traj, filt.trajectory.timestamps)
    e_f = _rpe(filt.trajectory.translations, filt.trajectory.rotations, tp, tr, 10)
    e_s = _rpe(smooth.trajectory.translations, smooth.trajectory.rotations, tp, tr, 10)
    assert e_s < 0.85 * e_f, (e_s, e_f)


def test_the_smoothers_record_leaves_nothing_behind(tmp_path, monkeypatch):
    """The record is a scratch file in the temporary folder, unlinked from the start: during
    and after a smoothed run the folder holds no file."""
    import tempfile

    from coloradar.formats.atomic import scratch_file

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    with scratch_file("probe_") as f:
        f.write(b"x" * 100)
        f.seek(0)
        assert f.read() == b"x" * 100
        assert list(tmp_path.iterdir()) == []
    imu_t, data, track, *_ = _synthetic(6.0, 3, profile="handheld", speed=1.0)
    res = rio_odometry(track, PRESET, imu_t, data, config=RioConfig(smooth=True))
    assert res.filtered is not None and len(res.trajectory) > 40
    assert list(tmp_path.iterdir()) == []
