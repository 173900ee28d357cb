"""What the radar-inertial filter (:mod:`.rio`) records at each output pose while it runs.

Every pose's time, attitude and position are kept (about 100 bytes a pose). The rest of a
pose's state — the 6 × 6 pose covariance, velocity and its covariance, biases, time offsets,
the mask of the points the gate took as static, about 600 bytes and more a pose — is kept
either at every pose (``coloradar odometry`` writes them all) or, when the caller passes
``keep`` to :func:`~coloradar.odometry.rio_odometry`, only at the poses it asks for, the
anchoring pose (:attr:`PoseOutputs.anchor`) and the last: SLAM's front end needs
covariances at its keyframes only, and so runs in memory that grows by little with the
run's length.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["KeepPose", "PoseOutputs", "PoseState"]

KeepPose = Callable[[int, int, np.ndarray, np.ndarray], bool]
"""``keep(index, frame, position, attitude) -> bool``, called at each output pose in time
order: the pose's index, the first radar's frame, and ``world_T_base`` in the filter's own
world frame (gravity-aligned, before the output is re-anchored at the initial pose; a rigid
motion, so distances and relative angles are already the output's): position float64
``(3,)`` [m], attitude float64 ``(3, 3)``. True: keep the pose's state (see
:class:`PoseOutputs`)."""


@dataclass(frozen=True)
class PoseState:
    """The filter's state at one output pose, beyond the pose itself (filter world frame).

    Attributes
    ----------
    velocity
        float64 ``(3,)``: the IMU's velocity [m/s].
    covariance
        float64 ``(6, 6)``: base position [m²] and attitude (rotation vector) [rad²].
    biases
        float64 ``(4, 3)``: accelerometer bias [m/s²] and its standard deviation, gyro bias
        [rad/s] and its standard deviation.
    time_offset
        float64 ``(2, R)``: each radar's time offset [s] and its standard deviation.
    velocity_covariance
        float64 ``(3, 3)`` [m²/s²].
    mask
        bool over the first radar's cloud: the points the gate took as static (None: no
        point update at this pose).
    """

    velocity: np.ndarray
    covariance: np.ndarray
    biases: np.ndarray
    time_offset: np.ndarray
    velocity_covariance: np.ndarray
    mask: np.ndarray | None


class PoseOutputs:
    """The filter's outputs at up to ``m`` poses, recorded in time order (:meth:`record`).

    Parameters
    ----------
    m
        Most poses the run can have.
    n_radars
        Radars of the filter (columns of the time offsets).
    keep
        None: every pose's :class:`PoseState` is kept. Else called at each pose
        (:data:`KeepPose`); the state is kept where it returns True, at the anchoring pose
        (the first ``anchor_delay`` seconds after the first pose) and at the last pose.
    anchor_delay
        [s] (:attr:`coloradar.odometry.rio.RioConfig.anchor_delay`).
    """

    def __init__(self, m: int, n_radars: int, keep: KeepPose | None, anchor_delay: float):
        self.t = np.full(m, np.nan)
        self.R = np.zeros((m, 3, 3))
        self.p = np.zeros((m, 3))
        self.keep, self.anchor_delay = keep, anchor_delay
        self.anchor: int | None = None
        self._n_r = n_radars
        self._rows: dict[int, PoseState] = {}
        self._last: tuple[int, PoseState] | None = None
        n = m if keep is None else 0
        self._v, self._cov = np.zeros((n, 3)), np.zeros((n, 6, 6))
        self._b, self._td = np.zeros((n, 4, 3)), np.zeros((n, 2, n_radars))
        self._vcov = np.zeros((n, 3, 3))
        self._masks: list[np.ndarray | None] = [None] * n

    def record(self, i: int, frame: int, tau: float, rotation: np.ndarray,
               position: np.ndarray, state: PoseState,
               base: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Pose ``i`` (radar frame ``frame``) at IMU time ``tau`` [s]: the IMU's attitude
        ``(3, 3)`` and position ``(3,)`` [m], its state, and ``base``: the base's position
        and attitude (what ``keep`` is shown; needed only with ``keep``)."""
        self.t[i], self.R[i], self.p[i] = tau, rotation, position
        if self.anchor is None and tau >= self.t[0] + self.anchor_delay:
            self.anchor = i
        if self.keep is None:
            self._v[i], self._cov[i], self._b[i] = state.velocity, state.covariance, state.biases
            self._td[i], self._vcov[i] = state.time_offset, state.velocity_covariance
            self._masks[i] = state.mask
            return
        if (base is not None and self.keep(i, frame, *base)) or i == self.anchor:
            self._rows[i] = state
        self._last = (i, state)

    def states(self, n: int) -> tuple[np.ndarray | None, tuple[np.ndarray, ...],
                                      list[np.ndarray | None]]:
        """The kept states of the first ``n`` poses (those recorded).

        Returns
        -------
        kept
            int64 ``(K,)``: the poses whose state is kept, in order; None: all ``n``.
        arrays
            ``velocity (K, 3), covariance (K, 6, 6), biases (K, 4, 3), time_offset (K, 2, R),
            velocity_covariance (K, 3, 3)``.
        masks
            ``K`` masks (None where no point update).
        """
        if self.keep is None:
            return None, tuple(a[:n] for a in (self._v, self._cov, self._b, self._td,
                                               self._vcov)), self._masks[:n]
        rows = dict(self._rows)
        if self._last is not None:
            rows.setdefault(*self._last)
        kept = np.array(sorted(rows), dtype=np.int64)      # recorded in order: all < n
        st = [rows[int(i)] for i in kept]
        arrays = (np.array([s.velocity for s in st]).reshape(-1, 3),
                  np.array([s.covariance for s in st]).reshape(-1, 6, 6),
                  np.array([s.biases for s in st]).reshape(-1, 4, 3),
                  np.array([s.time_offset for s in st]).reshape(-1, 2, self._n_r),
                  np.array([s.velocity_covariance for s in st]).reshape(-1, 3, 3))
        return kept, arrays, [s.mask for s in st]
