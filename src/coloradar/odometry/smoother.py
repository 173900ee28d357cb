"""Rauch–Tung–Striebel smoothing of the radar-inertial filter's run (offline, for SLAM).

The filter (:mod:`.rio`) estimates each pose from the measurements up to it. Offline, every
pose can use the later ones too. The fixed-interval smoother of Rauch, Tung and Striebel
(AIAA Journal 3(8), 1965) does that with one backward pass over what the filter recorded at
each step ``j`` (one propagation, then that event's updates):

- ``x_j``, ``P_j``: the posterior before the propagation (the previous event's result);
- ``x⁻_{j+1}``, ``P⁻_{j+1}``: the prediction after it; ``Φ_j`` its transition.

With the gain ``G_j = P_j Φ_jᵀ (P⁻_{j+1})⁻¹`` the smoothed states are, backwards from the
last (which is the filter's)::

    x^s_j = x_j ⊞ G_j (x^s_{j+1} ⊟ x⁻_{j+1})

``⊞``/``⊟`` are the filter's error-state composition (:mod:`.eskf`: position, velocity and
biases additive, the attitude error in the world frame, the extrinsic rotation's in the radar
frame). This is the error-state form of the smoother used for inertial navigation; it
linearises at the filter's estimates, as the filter itself does.

Two of the filter's steps are not a plain prediction, and are written so that the recursion
stays exact for them: a calibration state released after its warm-up (its variance set, its
cross-covariances cleared: it has no correlation with the past, so its column of
``P_j Φ_jᵀ`` is zeroed), and states still held fixed (zero variance: no gain).

**Memory.** The gain is computed during the forward pass (it needs ``P⁻_{j+1}``, known right
after the propagation) and written with the two nominal states to an unlinked temporary file:
about 3.4 kB a step for one radar, read back once, backwards. Nothing grows in memory with the
run's length but the pose indices.

Only the poses are smoothed; covariances, velocities and biases that the filter reports stay
the filter's (its covariances are therefore conservative for the smoothed poses).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from ..formats.atomic import scratch_file
from .eskf import BA, BG, TH, ErrorStateEKF, P, V, exp_so3

__all__ = ["RtsSmoother", "rts_gain"]


def rts_gain(posterior_cov: np.ndarray, transition: np.ndarray, predicted_cov: np.ndarray,
             released: Sequence[int] = ()) -> np.ndarray:
    """The smoother gain ``G = P Φᵀ (P⁻)⁻¹`` of one step, float64 ``(n, n)``.

    Parameters
    ----------
    posterior_cov
        ``P``, float64 ``(n, n)``: the covariance before the step.
    transition
        ``Φ``, float64 ``(n, n)``: the step's state transition.
    predicted_cov
        ``P⁻``, float64 ``(n, n)``: the covariance after it (after any release).
    released
        States that start afresh at this step (no correlation with the past).

    States with zero predicted variance (held fixed) get no gain.
    """
    cross = posterior_cov @ transition.T
    if len(released):
        cross[:, np.asarray(released, dtype=np.int64)] = 0.0
    on = np.diag(predicted_cov) > 0
    gain = np.zeros_like(cross)
    if np.any(on):
        sub = predicted_cov[np.ix_(on, on)]
        gain[:, on] = np.linalg.solve(sub.T, cross[:, on].T).T
    return gain


def _pack(ekf: ErrorStateEKF) -> np.ndarray:
    """The nominal state as one float64 vector ``p v R ba bg td R_ir``."""
    return np.concatenate([ekf.p, ekf.v, ekf.R.ravel(), ekf.ba, ekf.bg, ekf.td,
                           ekf.R_ir.ravel()])


class _Layout:
    """Where each part of a packed nominal state lies (``R`` radars)."""

    def __init__(self, n_radars: int) -> None:
        self.r = n_radars
        self.size = 21 + 10 * n_radars

    def split(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        r = self.r
        return (x[0:3], x[3:6], x[6:15].reshape(3, 3), x[15:18], x[18:21], x[21:21 + r],
                x[21 + r:].reshape(r, 3, 3))


class RtsSmoother:
    """Records the filter's steps and smooths its poses afterwards (module docstring).

    Call :meth:`before` right before each propagation and :meth:`after` right after it (and
    after any calibration release), :meth:`pose_at` for each output pose, then
    :meth:`smoothed_poses` once the filter has run; :meth:`close` (or the context manager)
    frees the temporary file.

    Parameters
    ----------
    ekf
        The filter that will run.
    """

    def __init__(self, ekf: ErrorStateEKF) -> None:
        self.n = ekf.dim
        self.layout = _Layout(ekf.n_radars)
        self._td = [ekf.td_index(r) for r in range(ekf.n_radars)]
        self._phi = [ekf.phi_slice(r) for r in range(ekf.n_radars)]
        self._record = self.n * self.n + 2 * self.layout.size    # float64 values per step
        self._f = scratch_file("coloradar_rts_")
        self.steps = 0
        self._before: tuple[np.ndarray, np.ndarray] | None = None

    def __enter__(self) -> RtsSmoother:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._f.close()

    def before(self, ekf: ErrorStateEKF) -> None:
        """The posterior about to be propagated (the previous event's result)."""
        self._before = (_pack(ekf), ekf.P.copy())

    def after(self, ekf: ErrorStateEKF, released: Sequence[int] = ()) -> None:
        """The prediction; ``released``: error-state indices set afresh since :meth:`before`."""
        if self._before is None:
            raise RuntimeError("RtsSmoother.after without before")
        x0, p0 = self._before
        gain = rts_gain(p0, ekf.transition, ekf.P, released)
        self._f.seek(self.steps * self._record * 8)
        self._f.write(np.concatenate([gain.ravel(), x0, _pack(ekf)]).tobytes())
        self.steps += 1
        self._before = None

    def pose_at(self) -> int:
        """The index of the state an output pose recorded now has (after this event's
        updates); pass it to :meth:`smoothed_poses`."""
        return self.steps

    def _read(self, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        self._f.seek(j * self._record * 8)
        a = np.frombuffer(self._f.read(self._record * 8), dtype=np.float64)
        nn, m = self.n * self.n, self.layout.size
        return a[:nn].reshape(self.n, self.n), a[nn:nn + m], a[nn + m:]

    def _minus(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a ⊟ b`` in the filter's error state."""
        sa, sb = self.layout.split(a), self.layout.split(b)
        d = np.zeros(self.n)
        d[P], d[V], d[BA], d[BG] = sa[0] - sb[0], sa[1] - sb[1], sa[3] - sb[3], sa[4] - sb[4]
        d[TH] = Rotation.from_matrix(sa[2] @ sb[2].T).as_rotvec()
        for r, (ti, ph) in enumerate(zip(self._td, self._phi, strict=True)):
            d[ti] = sa[5][r] - sb[5][r]
            d[ph] = Rotation.from_matrix(sb[6][r].T @ sa[6][r]).as_rotvec()
        return d

    def _plus(self, a: np.ndarray, d: np.ndarray) -> np.ndarray:
        """``a ⊞ d`` (as :meth:`.eskf.ErrorStateEKF.inject`)."""
        p, v, rot, ba, bg, td, rir = self.layout.split(a)
        td = td + d[self._td]
        rir = np.array([rir[r] @ exp_so3(d[ph]) for r, ph in enumerate(self._phi)])
        return np.concatenate([p + d[P], v + d[V], (exp_so3(d[TH]) @ rot).ravel(),
                               ba + d[BA], bg + d[BG], td, rir.ravel()])

    def smoothed_poses(self, ekf: ErrorStateEKF, at: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """The smoothed IMU poses at the states ``at`` (int ``(M,)``, from :meth:`pose_at`).

        Parameters
        ----------
        ekf
            The filter after its run: its state is the last one, where the backward pass
            starts.
        at
            The states wanted.

        Returns
        -------
        position, attitude
            float64 ``(M, 3)`` [m] and ``(M, 3, 3)`` (``world_R_imu``), the filter's world
            frame.
        """
        at = np.asarray(at, dtype=np.int64)
        pos, att = np.zeros((at.size, 3)), np.zeros((at.size, 3, 3))
        order = np.argsort(at)[::-1]
        x = _pack(ekf)
        j = self.steps                       # x is state j (the last)
        for o in order:
            while j > at[o]:
                gain, post, pred = self._read(j - 1)
                x = self._plus(post, gain @ self._minus(x, pred))
                j -= 1
            parts = self.layout.split(x)
            pos[o], att[o] = parts[0], parts[2]
        return pos, att
