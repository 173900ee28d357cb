"""Automatic zero-velocity detection: the radar sees a still world and the IMU is quiet.

Nobody tells the filter when the rig stands still. A radar frame is declared *static* when

- its ego-velocity is usable and slower than ``max_speed``, or its cloud shows a still world
  (:func:`still_world`: most points at zero range rate; this needs no ego-velocity, so it
  holds for the sparse clouds of a radar at rest too; :func:`still_rates` judges the range
  rates against the radar's own Doppler noise, the filter's test when it has the points), and
- over ``window`` seconds around it the IMU is quiet: the per-axis standard deviation of the
  angular rate is below ``max_gyro_std`` and that of the specific force below
  ``max_accel_std`` (a rig moving at constant velocity would pass the radar test only at zero
  speed anyway; the IMU test rejects a rig that turns or shakes in place).

The thresholds default to a few times the 3DM-GX5-25's white noise at 300 Hz (0.0015 rad/s,
0.017 m/s² per sample) with room for the vibration of a rig held still by hand.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

__all__ = ["ZeroVelocityConfig", "imu_quiet", "static_frames", "still_rates", "still_world"]


@dataclass(frozen=True)
class ZeroVelocityConfig:
    """Settings of the zero-velocity detector.

    Attributes
    ----------
    max_speed
        Largest radar ego-speed of a static frame [m/s].
    max_gyro_std, max_accel_std
        Largest per-axis standard deviation of the IMU's rate [rad/s] and specific force
        [m/s²] over the window.
    window
        Length of the IMU window centred on the frame [s].
    still_rate, still_fraction, still_min_points
        :func:`still_world`: a cloud of at least ``still_min_points`` points of which
        ``still_fraction`` have ``|range rate| < still_rate`` [m/s] shows a still world.
    still_sigmas, still_point_fraction, still_probability
        :func:`still_rates` (the filter's own test when it is given the points): at least
        ``still_min_points`` points, ``still_point_fraction`` of them within ``still_sigmas``
        Doppler standard deviations of zero, and zero velocity within the chi-square
        quantile ``still_probability`` of the velocity those points fit.
    """

    max_speed: float = 0.03
    max_gyro_std: float = 0.01
    max_accel_std: float = 0.08
    window: float = 0.4
    still_rate: float = 0.05
    still_fraction: float = 0.8
    still_min_points: int = 3
    still_sigmas: float = 3.0
    still_point_fraction: float = 0.6
    still_probability: float = 0.999


def still_world(cloud: np.ndarray, config: ZeroVelocityConfig | None = None,
                min_range: float = 0.3) -> bool:
    """Whether a radar point cloud shows a still world: at least ``still_min_points`` points
    beyond ``min_range`` [m], and ``still_fraction`` of them with ``|range rate| <
    still_rate``. It needs no ego-velocity, so it also holds for the sparse clouds of a radar
    at rest (e.g. the single chip's on-board detections, too few for RANSAC).

    Parameters
    ----------
    cloud
        float ``(N, 5)``: ``x y z intensity range_rate``, radar frame.
    """
    cfg = config or ZeroVelocityConfig()
    c = np.asarray(cloud)
    if c.ndim != 2 or c.shape[1] < 5 or c.shape[0] == 0:
        return False
    r = np.linalg.norm(c[:, :3], axis=1)
    rr = c[:, 4]
    use = np.isfinite(r) & np.isfinite(rr) & (r > min_range)
    n = int(use.sum())
    if n < cfg.still_min_points:
        return False
    return bool(np.mean(np.abs(rr[use]) < cfg.still_rate) >= cfg.still_fraction)


def still_rates(points: np.ndarray, range_rate_std: float,
                config: ZeroVelocityConfig | None = None) -> bool:
    """Whether a frame's Doppler points show a still world, judged against the radar's Doppler
    noise ``σ``: at least ``still_min_points`` points, ``still_point_fraction`` of them with
    ``|range rate| <= still_sigmas · σ``, and zero velocity consistent with those points
    (``bᵀ A⁺ b / σ² <= χ²_k(still_probability)``, ``A = Σ u uᵀ``, ``b = Σ u ṙ``: the velocity
    they fit, ``A⁺ b``, is no further from zero than their noise explains).

    The fixed ``still_rate`` of :func:`still_world` (5 cm/s) is below the Doppler noise of a
    sparse single-chip cloud (3–8 cm/s): at rest a third of its points fall outside it and
    the rest goes unseen. Relative to the noise, a rig at rest keeps ≥ 99 % of its static
    points (3σ) and the ghosts that happen to be slow, while one moving at ``s`` keeps only
    the points more than ``acos(3σ/s)`` off its motion: few in a forward field of view once
    ``s`` exceeds about 6σ. Slower motion, whose range rates all lie within the window, is
    what the chi-square test catches (a rig creeping at 6 cm/s seen by 20 points of 5 cm/s
    noise fits a velocity ≈ 4σ from zero), and :func:`imu_quiet` beside it. Ghosts and movers
    (≤ 20–30 % of a cloud) stay below ``1 − still_point_fraction``.

    Parameters
    ----------
    points
        float ``(K, 4)``: unit directions and range rates ``ux uy uz ṙ`` of the frame's usable
        points (:func:`~coloradar.odometry.doppler.doppler_points`) [-, m/s].
    range_rate_std
        The radar's Doppler error [m/s] (:class:`~coloradar.odometry.doppler.PointNoise`).
    """
    cfg = config or ZeroVelocityConfig()
    p = np.asarray(points, dtype=np.float64).reshape(-1, 4)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] < max(cfg.still_min_points, 1):
        return False
    near = np.abs(p[:, 3]) <= cfg.still_sigmas * range_rate_std
    if np.mean(near) < cfg.still_point_fraction:
        return False
    u, rr = p[near, :3], p[near, 3]
    a = u.T @ u
    b = u.T @ rr
    lam, q = np.linalg.eigh(a)
    keep = lam > 1e-9 * max(float(lam[-1]), 1e-300)
    # bᵀ A⁺ b / σ² in A's eigenbasis: a direction no point observes adds nothing.
    stat = float(np.sum((q[:, keep].T @ b) ** 2 / lam[keep])) / range_rate_std**2
    return stat <= float(chi2.ppf(cfg.still_probability, int(keep.sum())))


def imu_quiet(imu_t: np.ndarray, imu_f: np.ndarray, imu_w: np.ndarray, times: np.ndarray,
              config: ZeroVelocityConfig) -> np.ndarray:
    """bool ``(M,)``: whether the IMU is quiet in the window around each of ``times``.

    Per-window sums come from cumulative sums, so the cost is O(N + M) whatever the window;
    they are taken over the stretch of IMU that a block of ``times`` needs, so that the
    temporaries stay the size of a block, not of the run.
    """
    t = np.asarray(imu_t, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    lo = np.searchsorted(t, times - config.window / 2)
    hi = np.searchsorted(t, times + config.window / 2)
    n = hi - lo
    out = n >= 5
    block = 512
    for b in range(0, times.size, block):
        s = slice(b, b + block)
        a, z = int(lo[s].min(initial=t.size)), int(hi[s].max(initial=0))
        if z <= a:                      # no IMU sample near these frames: n < 5 there
            continue
        for data, limit in ((imu_w, config.max_gyro_std), (imu_f, config.max_accel_std)):
            x = np.asarray(data[a:z], dtype=np.float64)
            x = x - x.mean(axis=0)                  # better conditioned sums
            c1 = np.concatenate([np.zeros((1, 3)), np.cumsum(x, 0)])
            c2 = np.concatenate([np.zeros((1, 3)), np.cumsum(x * x, 0)])
            i, j = lo[s] - a, hi[s] - a
            with np.errstate(invalid="ignore", divide="ignore"):
                m1 = (c1[j] - c1[i]) / n[s, None]
                var = (c2[j] - c2[i]) / n[s, None] - m1**2
            out[s] &= np.all(np.sqrt(np.maximum(var, 0.0)) < limit, axis=1)
    return out


def static_frames(speeds: np.ndarray, ok: np.ndarray, quiet: np.ndarray,
                  config: ZeroVelocityConfig, still: np.ndarray | None = None) -> np.ndarray:
    """bool ``(M,)``: radar frames at which the rig is taken to stand still.

    Parameters
    ----------
    speeds
        float ``(M,)``: ego-speed of each frame [m/s] (NaN where not estimated).
    ok
        bool ``(M,)``: the frame has a usable ego-velocity.
    quiet
        bool ``(M,)``: :func:`imu_quiet` at the frames' times.
    still
        bool ``(M,)``: :func:`still_world` of each frame's cloud (a frame without an
        ego-velocity can still show a still world); None: not known.
    """
    s = np.asarray(speeds, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        slow = np.asarray(ok, dtype=bool) & np.isfinite(s) & (s < config.max_speed)
    if still is not None:
        slow = slow | np.asarray(still, dtype=bool)
    return slow & np.asarray(quiet, dtype=bool)
