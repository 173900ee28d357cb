"""Radar ego-velocity from the range rates of one point cloud (RANSAC, then least squares).

Model (docs/conventions.md §3: range rate > 0 = receding). A static point seen in direction ``d_i``
(unit vector, sensor frame) by a sensor whose origin moves with velocity ``v`` (sensor frame)
has range rate::

    vr_i = −d_i · v                                  i.e.  A v = b,  A = −D,  b = vr

Three points in general position determine ``v``. Moving objects and false alarms break the
model, so ``v`` is found by RANSAC (Fischler & Bolles 1981) with the MSAC cost (Torr &
Zisserman 2000): many minimal sets of 3 are drawn, each solved in closed form, and all
hypotheses are scored at once with one matrix product ``V · Dᵀ`` (hypotheses × points). The
winner's inliers are refined by least squares until the inlier set stops changing; the
covariance is ``σ² (AᵀA)⁻¹`` with ``σ²`` the inlier residuals' variance (``n − 3`` degrees of
freedom). This is the estimator of Kellner et al., "Instantaneous ego-motion estimation using
Doppler radar" (ITSC 2013), in 3D as in Doer & Trommer (MFI 2020).

**Moving objects that fill half the cloud.** A rigid object translating with ``u`` is itself
a perfectly consistent motion ``v − u``; when it holds as many points as the static world,
counting inliers cannot tell the two apart. Two things use the fact that the static world
surrounds the sensor while a moving object is compact:

- the MSAC cost weighs each point by ``1 / (points in its angular cell)`` (cells of
  ``cell_deg`` in azimuth × elevation), so every occupied direction casts one vote in total and
  a dense object cannot outvote the walls;
- up to ``max_models`` motions are extracted in turn (each found by RANSAC among the points the
  previous ones left over), and among those with at least ``min_support`` times the largest
  support the one whose inliers occupy the most cells is taken as the static world.

The final velocity is the plain (unweighted) least-squares fit on the chosen motion's inliers.

**Doppler aliasing.** Range rates are measured modulo ``2·v_max``. With ``max_velocity`` given,
residuals are wrapped into ``[−v_max, v_max)`` and the inliers' measurements are unwrapped
against the model before the least-squares step. Speeds above ``v_max`` then work as long as
enough static points see a range rate below ``v_max`` to form the minimal sets (points to the
side of the motion). Point clouds from :class:`coloradar.dsp.RadarProcessor` carry range rates
already unwrapped by its Doppler alias search (``doppler_unwrap``), and the wrapping leaves
those alone (a residual within the threshold wraps to itself).

**What aliasing leaves ambiguous.** Wrapped residuals make any velocity whose predicted range
rates differ from the truth's by multiples of ``2·v_max`` at most points fit nearly as well.
Minimal sets are therefore also solved for the alias shifts of their range rates (speeds up
to ``max_speed``), so that the right velocity is among the hypotheses even when every range
rate is folded; and a frame is reported as not ok ("ambiguous") when a second velocity more
than ``ambiguity_distance`` away explains nearly as much of the cloud (``ambiguity_ratio`` of
its weighted support and angular coverage). A **velocity prior** (e.g. from an IMU:
``velocity_prior=VelocityPrior(v, sigma)``) resolves it: range rates are unwrapped towards the
prior's prediction, hypotheses are kept within its gate, and an estimate that leaves the gate is
not ok."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import SettingsError

__all__ = ["EgoVelocity", "EgoVelocityConfig", "VelocityPrior", "estimate_ego_velocity",
           "static_inlier_threshold"]


@dataclass(frozen=True)
class EgoVelocityConfig:
    """Settings of :func:`estimate_ego_velocity`.

    Attributes
    ----------
    threshold
        Largest ``|vr_i + d_i·v|`` of an inlier [m/s]. About 3-5 times the range-rate noise;
        :func:`static_inlier_threshold` derives one from a radar's velocity resolution.
    max_velocity
        Unambiguous range rate ``v_max`` [m/s] of the radar (``WaveformConfig.max_velocity``),
        to handle Doppler aliasing; None: range rates are taken as they are.
    hypotheses
        Minimal sets drawn per RANSAC run (256 leaves a chance below 1e-5 of missing an
        all-static set when a third of the points are static).
    min_inliers
        Fewest inliers a motion needs; a frame without such a motion is reported as not ok.
    min_range, max_range
        Points closer than ``min_range`` (the rig itself, leakage) or farther than
        ``max_range`` [m] are not used. None: no upper limit.
    max_models
        Motions extracted in turn (1 = plain RANSAC, the largest consensus wins).
    min_support
        A motion competes for "static" only with at least this fraction of the largest
        motion's inliers.
    cell_deg
        Cell size of the angular coverage grid [deg].
    min_spread
        Smallest singular value of the inliers' direction matrix divided by ``sqrt(n)``, below
        which the geometry leaves some direction of ``v`` unobserved (e.g. all points in one
        plane and a velocity component normal to it) and the frame is reported as degenerate.
    refine_iterations
        Most least-squares / re-selection rounds after RANSAC.
    planar
        Estimate ``v_x, v_y`` only, with ``v_z = 0`` (minimal sets of 2): for a radar whose
        elevation is too coarse to observe ``v_z`` (the single chip's point clouds) on a rig
        moving on a floor. The points keep their measured elevation in ``d_i``; the
        covariance's z row and column are 0 (fixed, not estimated).
    max_speed
        Largest sensor speed [m/s] searched when range rates may be aliased
        (``max_velocity`` given): minimal sets are also solved for the alias shifts of their
        range rates up to it.
    min_inlier_fraction
        The estimate is not ok when its inliers are fewer than this fraction of the usable
        points: no motion explains the cloud (at high speed, direction errors of a coarse
        array move range rates beyond the threshold, and a few chance inliers decide).
    ambiguity_distance, ambiguity_ratio
        With ``max_velocity`` given, the estimate is not ok when another velocity more than
        ``ambiguity_distance`` [m/s] away has at least ``ambiguity_ratio`` of its weighted
        support and angular coverage (aliasing leaves the two indistinguishable).
    """

    threshold: float = 0.15
    max_velocity: float | None = None
    hypotheses: int = 256
    min_inliers: int = 6
    min_range: float = 0.3
    max_range: float | None = None
    max_models: int = 3
    min_support: float = 0.3
    cell_deg: float = 5.0
    min_spread: float = 0.02
    refine_iterations: int = 10
    planar: bool = False
    max_speed: float = 10.0
    ambiguity_distance: float = 0.2
    ambiguity_ratio: float = 0.8
    min_inlier_fraction: float = 0.3

    def __post_init__(self) -> None:
        if not self.threshold > 0:
            raise SettingsError(f"threshold must be positive, got {self.threshold}")
        if self.max_velocity is not None and not self.max_velocity > 0:
            raise SettingsError(f"max_velocity must be positive or None, got {self.max_velocity}")
        if self.hypotheses < 1 or self.max_models < 1 or self.min_inliers < 3:
            raise SettingsError("hypotheses and max_models must be >= 1, min_inliers >= 3")
        if not self.max_speed > 0 or not 0 < self.ambiguity_ratio <= 1:
            raise SettingsError("max_speed must be positive and ambiguity_ratio in (0, 1]")

    @property
    def dims(self) -> int:
        """Velocity components estimated: 2 when planar, else 3."""
        return 2 if self.planar else 3


def static_inlier_threshold(velocity_bin_width: float, floor: float = 0.1) -> float:
    """An inlier threshold [m/s] for a radar with Doppler bins ``velocity_bin_width`` wide.

    Peak interpolation leaves errors of a fraction of a bin; 0.75 bin keeps every static point
    of the cascade (0.22 m/s bins) and ``floor`` keeps a margin for radars with fine Doppler
    bins (single chip: 0.04 m/s), whose error is dominated by angle errors of the direction.
    """
    return max(float(floor), 0.75 * float(velocity_bin_width))


@dataclass(frozen=True, eq=False)
class VelocityPrior:
    """A prior on the sensor's velocity (from an IMU, a motion model or the last frame).

    Attributes
    ----------
    velocity
        float ``(3,)`` [m/s], sensor frame.
    sigma
        Standard deviation [m/s] of each component (scalar or ``(3,)``).
    gate
        Estimates farther than ``gate·sigma`` (plus the inlier threshold) from the prior are
        not searched, and a final estimate outside is not ok.
    """

    velocity: np.ndarray
    sigma: float | np.ndarray = 0.5
    gate: float = 3.0

    def __post_init__(self) -> None:
        v = np.asarray(self.velocity, dtype=np.float64).reshape(-1)
        if v.size != 3 or not np.all(np.isfinite(v)):
            raise SettingsError(f"velocity_prior must be 3 finite numbers [m/s], got {v}")
        sig = np.broadcast_to(np.asarray(self.sigma, dtype=np.float64), (3,))
        if not np.all(sig > 0) or not self.gate > 0:
            raise SettingsError("velocity_prior sigma and gate must be positive")
        object.__setattr__(self, "velocity", v)
        object.__setattr__(self, "sigma", sig.copy())

    def radius(self, threshold: float) -> np.ndarray:
        """Half-width of the search box per component [m/s]."""
        return self.gate * np.asarray(self.sigma) + threshold


@dataclass(frozen=True, eq=False)
class EgoVelocity:
    """The sensor's velocity estimated from one point cloud.

    Attributes
    ----------
    velocity
        float64 ``(3,)`` [m/s]: the sensor origin's velocity in the sensor frame; NaN when no
        motion could be estimated.
    covariance
        float64 ``(3, 3)`` [m²/s²]: ``σ² (AᵀA)⁻¹``; NaN when not estimated.
    inliers
        bool ``(N,)`` over the input points: the points used for the final least squares
        (the static points).
    num_points
        Points that passed the range filter.
    sigma
        Standard deviation of the inlier residuals [m/s].
    spread
        Smallest singular value of the inlier directions over ``sqrt(n)`` (see
        :attr:`EgoVelocityConfig.min_spread`).
    coverage
        Occupied angular cells of the inliers.
    num_models
        Motions found in the frame (static world, moving objects).
    ok
        True when the estimate is usable.
    reason
        Why not, when ``ok`` is False (empty otherwise).
    """

    velocity: np.ndarray
    covariance: np.ndarray
    inliers: np.ndarray
    num_points: int
    sigma: float
    spread: float
    coverage: int
    num_models: int
    ok: bool
    reason: str = ""

    @property
    def num_inliers(self) -> int:
        """Number of inlier points."""
        return int(self.inliers.sum())

    @property
    def speed(self) -> float:
        """``|v|`` [m/s]."""
        return float(np.linalg.norm(self.velocity))


def _failed(n_in: int, n_valid: int, reason: str, n_models: int = 0) -> EgoVelocity:
    return EgoVelocity(np.full(3, np.nan), np.full((3, 3), np.nan), np.zeros(n_in, dtype=bool),
                       n_valid, float("nan"), float("nan"), 0, n_models, False, reason)


def _split_cloud(points: np.ndarray, range_rates: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] < 3:
        raise SettingsError(f"expected points of shape (N, 3) or a cloud (N, 5), got {p.shape}")
    if range_rates is None:
        if p.shape[1] < 5:
            raise SettingsError(f"a cloud of shape {p.shape} has no range-rate column; expected "
                                "(N, 5) x y z intensity range_rate, or pass range_rates")
        vr = p[:, 4]
    else:
        vr = np.asarray(range_rates).reshape(-1)
        if vr.size != p.shape[0]:
            raise SettingsError(f"{p.shape[0]} points but {vr.size} range rates")
    return p[:, :3].astype(np.float64), vr.astype(np.float64)


def _wrap(res: np.ndarray, vmax: float | None) -> np.ndarray:
    if vmax is None:
        return res
    return (res + vmax) % (2.0 * vmax) - vmax


def _draw_sets(rng: np.random.Generator, n: int, count: int, k: int) -> np.ndarray:
    """``(count, k)`` indices into ``range(n)``, distinct within each row."""
    idx = rng.integers(0, n, size=(count, k))
    while True:
        srt = np.sort(idx, axis=1)
        dup = np.any(srt[:, 1:] == srt[:, :-1], axis=1)
        if not dup.any():
            return idx
        idx[dup] = rng.integers(0, n, size=(int(dup.sum()), k))


def _hypotheses(d: np.ndarray, vr: np.ndarray, rng: np.random.Generator, count: int,
                k: int, period: float | None = None, max_speed: float = np.inf) -> np.ndarray:
    """Velocities ``(H, 3)`` solving ``−D_s v = vr_s`` for random minimal sets of ``k`` points
    (``k = 2``: planar, ``v_z = 0``); singular sets are dropped.

    With ``period`` (``2·v_max``), each set is also solved for every shift of its range rates
    by multiples of the period that ``max_speed`` allows (a range rate of a static point is
    at most the speed), and solutions faster than ``max_speed`` are dropped.
    """
    n = 0
    if period is not None and np.isfinite(max_speed):
        n = int(np.ceil((max_speed + period / 2) / period))
        # every set brings up to (2n+1)^k hypotheses: fewer sets keep the total bounded
        # (32 sets still hold an all-static one with probability > 98 % at half outliers)
        count = max(32, min(count, 8 * count // (2 * n + 1) ** k))
    idx = _draw_sets(rng, d.shape[0], count, k)
    m = -d[idx][:, :, :k]                                          # (H, k, k)
    # |det| of k unit vectors is the volume they span; tiny ones are (near-)degenerate.
    good = np.abs(np.linalg.det(m)) > 1e-6
    m, rates = m[good], vr[idx[good]]                              # (G, k, k), (G, k)
    if n and period is not None:
        grid = np.stack(np.meshgrid(*[np.arange(-n, n + 1)] * k, indexing="ij"), -1).reshape(-1, k)
        shifted = rates[:, None, :] + period * grid[None]          # (G, S, k)
        # the true range rate of a static point lies within ±max_speed
        ok = np.all(np.abs(shifted) <= max_speed + period / 2, axis=2)
        g_i, s_i = np.nonzero(ok)
        m, rates = m[g_i], shifted[g_i, s_i]
    out = np.zeros((m.shape[0], 3))
    if m.shape[0]:
        out[:, :k] = np.linalg.solve(m, rates[:, :, None])[:, :, 0]
    if np.isfinite(max_speed):
        out = out[np.linalg.norm(out, axis=1) <= max_speed]
    return out


def _lstsq(d: np.ndarray, b: np.ndarray, k: int) -> np.ndarray:
    v = np.zeros(3)
    v[:k] = np.linalg.lstsq(-d[:, :k], b, rcond=None)[0]
    return v


def _msac_best(d: np.ndarray, vr: np.ndarray, w: np.ndarray, hyp: np.ndarray, thr: float,
               vmax: float | None, block: int = 1 << 22) -> np.ndarray:
    """The hypothesis of least weighted MSAC cost ``Σ w_i min(r_i², thr²)``."""
    return hyp[int(np.argmin(_msac_costs(d, vr, w, hyp, thr, vmax, block)))]


def _msac_costs(d: np.ndarray, vr: np.ndarray, w: np.ndarray, hyp: np.ndarray, thr: float,
                vmax: float | None, block: int = 1 << 22) -> np.ndarray:
    """Weighted MSAC cost ``Σ w_i min(r_i², thr²)`` of every hypothesis, float32 ``(H,)``.

    Hypotheses are scored in blocks of ``block / N`` at once (one matrix product each), in
    float32: the cost only ranks hypotheses; the winner is refined in float64.
    """
    costs = np.empty(hyp.shape[0], dtype=np.float32)
    step = max(1, block // max(1, d.shape[0]))
    # (H, N) layout: the product with the (3, N) transposed directions is a fast BLAS call,
    # unlike (N, 3) @ (3, H) with a strided right operand.
    dt32 = np.ascontiguousarray(d.T, dtype=np.float32)
    vr32, w32 = vr.astype(np.float32)[None, :], w.astype(np.float32)
    thr2 = np.float32(thr * thr)
    for s in range(0, hyp.shape[0], step):
        h = hyp[s:s + step]
        res = h.astype(np.float32) @ dt32                           # (H, N): −(predicted vr)
        res += vr32                                                 # residual vr − (−d·v)
        res = _wrap(res, None if vmax is None else np.float32(vmax))
        np.square(res, out=res)
        np.minimum(res, thr2, out=res)
        costs[s:s + step] = res @ w32
    return costs


def _refine(d: np.ndarray, vr: np.ndarray, v: np.ndarray, cfg: EgoVelocityConfig,
            usable: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least squares on the inliers of ``v`` among ``usable``, repeated until they settle.

    Returns the velocity, the inlier mask and the unwrapped range rates.
    """
    def unwrapped(v: np.ndarray) -> np.ndarray:
        if cfg.max_velocity is None:
            return vr
        # Bring each measurement to the alias nearest the model's prediction.
        period = 2.0 * cfg.max_velocity
        return vr + period * np.round((-(d @ v) - vr) / period)

    inl = usable & (np.abs(_wrap(d @ v + vr, cfg.max_velocity)) < cfg.threshold)
    for _ in range(cfg.refine_iterations):
        if inl.sum() < 3:
            break
        v = _lstsq(d[inl], unwrapped(v)[inl], cfg.dims)
        new = usable & (np.abs(_wrap(d @ v + vr, cfg.max_velocity)) < cfg.threshold)
        if np.array_equal(new, inl):
            break
        inl = new
    return v, inl, unwrapped(v)


def _cells(d: np.ndarray, cell_deg: float) -> np.ndarray:
    """Index of each direction's azimuth × elevation cell, int64 ``(N,)``."""
    az = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    el = np.degrees(np.arcsin(np.clip(d[:, 2], -1.0, 1.0)))
    return np.floor(az / cell_deg).astype(np.int64) * 1000 + np.floor(el / cell_deg).astype(np.int64)


def estimate_ego_velocity(points: np.ndarray, range_rates: np.ndarray | None = None,
                          config: EgoVelocityConfig | None = None, *,
                          rng: np.random.Generator | int | None = 0,
                          velocity_prior: VelocityPrior | np.ndarray | None = None) -> EgoVelocity:
    """The sensor's own velocity from the range rates of one radar point cloud.

    Parameters
    ----------
    points
        float ``(N, 5)`` cloud ``x y z intensity range_rate`` (the dataset's point clouds and
        :mod:`coloradar.dsp` output), or float ``(N, 3)`` positions [m] in the sensor frame
        with ``range_rates`` given separately.
    range_rates
        float ``(N,)`` [m/s], > 0 receding. None: column 4 of ``points``.
    config
        Thresholds and RANSAC settings (default :class:`EgoVelocityConfig`).
    rng
        Generator or seed of the minimal-set draws; the result is a deterministic function of
        the input and the seed.
    velocity_prior
        Optional :class:`VelocityPrior` (or a ``(3,)`` velocity [m/s], sigma 0.5 m/s): range
        rates are unwrapped towards its prediction, the search is kept within its gate, and
        an estimate outside the gate is not ok.

    Returns
    -------
    EgoVelocity
        ``velocity`` is the sensor origin's velocity in the sensor frame [m/s]; ``ok`` is False
        with a ``reason`` when the frame has too few points, no motion with ``min_inliers``
        support, degenerate geometry, an ambiguity that Doppler aliasing leaves (another
        velocity explains the cloud about as well), or an estimate outside the prior's gate.

    Examples
    --------
    >>> cfg = coloradar.odometry.ego_velocity_config(seq.calib.single_chip)
    >>> ev = estimate_ego_velocity(seq.single_chip.pointclouds[10], config=cfg)
    >>> ev.velocity, np.sqrt(np.diag(ev.covariance)), ev.num_inliers
    """
    cfg = config or EgoVelocityConfig()
    p, vr = _split_cloud(points, range_rates)
    n_in = p.shape[0]
    r = np.linalg.norm(p, axis=1)
    valid = np.isfinite(r) & np.isfinite(vr) & (r > cfg.min_range)
    if cfg.max_range is not None:
        valid &= r <= cfg.max_range
    n_valid = int(valid.sum())
    if n_valid < cfg.min_inliers:
        return _failed(n_in, n_valid, f"too few points ({n_valid} usable, need {cfg.min_inliers})")
    gen = np.random.default_rng(rng)
    sel = np.flatnonzero(valid)
    d = p[sel] / r[sel, None]
    b = vr[sel]
    prior = (velocity_prior if isinstance(velocity_prior, VelocityPrior) or velocity_prior is None
             else VelocityPrior(np.asarray(velocity_prior, dtype=np.float64)))
    period = None if cfg.max_velocity is None else 2.0 * cfg.max_velocity
    k_dim = cfg.dims
    if prior is not None and period is not None:
        # Each range rate to the alias nearest the prior's prediction.
        b = b + period * np.round((-(d @ prior.velocity) - b) / period)

    def search(dd: np.ndarray, bb: np.ndarray) -> np.ndarray:
        if prior is None:
            return _hypotheses(dd, bb, gen, cfg.hypotheses, k_dim, period, cfg.max_speed)
        h = _hypotheses(dd, bb, gen, cfg.hypotheses, k_dim)
        rad = prior.radius(cfg.threshold)
        inside = np.all(np.abs(h - prior.velocity)[:, :k_dim] <= rad[:k_dim], axis=1)
        return h[inside]

    cells = _cells(d, cfg.cell_deg)
    _, cell_of, per_cell = np.unique(cells, return_inverse=True, return_counts=True)
    # Each angular cell casts one vote in total: a dense, compact moving object must not
    # outvote the static world spread over the field of view.
    weight = 1.0 / per_cell[cell_of]
    models, all_hyp, why = _extract_models(d, b, weight, search, cfg)
    if why:
        return _failed(n_in, n_valid, why)

    support = np.array([m[1].sum() for m in models])
    cover = np.array([np.unique(cells[m[1]]).size for m in models])
    cand = np.flatnonzero(support >= cfg.min_support * support.max())
    # Widest coverage wins; more inliers break ties.
    best = int(cand[np.lexsort((-support[cand], -cover[cand]))[0]])
    # Final fit over all usable points: a point the chosen motion explains is static.
    v, inl, bu = _refine(d, b, models[best][0], cfg, np.ones(sel.size, dtype=bool))
    k = cfg.dims
    n = int(inl.sum())
    inliers = np.zeros(n_in, dtype=bool)
    inliers[sel[inl]] = True
    if n < cfg.min_inliers:
        return _failed(n_in, n_valid, f"the chosen motion kept only {n} inliers", len(models))
    a = -d[inl][:, :k]
    res = a @ v[:k] - bu[inl]
    dof = max(n - k, 1)
    sigma = float(np.sqrt(res @ res / dof))
    sv = np.linalg.svd(a, compute_uv=False)
    spread = float(sv[-1] / np.sqrt(n))
    cov = np.zeros((3, 3))
    cov[:k, :k] = np.linalg.pinv(a.T @ a)
    cov = sigma**2 * 0.5 * (cov + cov.T)
    if spread < cfg.min_spread:
        reason = (f"degenerate geometry: the {n} inlier directions leave one velocity "
                  f"component unobserved (spread {spread:.3g} < {cfg.min_spread:g})")
    elif n < cfg.min_inlier_fraction * n_valid:
        reason = (f"only {n} of {n_valid} points fit the chosen motion (fewer than "
                  f"{cfg.min_inlier_fraction:g} of them)")
    elif prior is not None and np.any(np.abs(v - prior.velocity)[:k]
                                      > prior.radius(cfg.threshold)[:k]):
        reason = (f"the estimate {np.round(v, 2).tolist()} m/s lies outside the "
                  f"prior's gate around {np.round(prior.velocity, 2).tolist()} m/s")
    elif period is not None and all_hyp is not None and all_hyp.shape[0]:
        reason = _ambiguity(d, b, weight, all_hyp, v, cfg, inl)
    else:
        reason = ""
    ok = not reason
    return EgoVelocity(v, cov, inliers, n_valid, sigma, spread,
                       int(np.unique(cells[inl]).size), len(models), ok, reason)


def _extract_models(d: np.ndarray, b: np.ndarray, weight: np.ndarray,
                    search: Callable[[np.ndarray, np.ndarray], np.ndarray],
                    cfg: EgoVelocityConfig
                    ) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray | None, str]:
    """Motions extracted one after the other (static world, then moving objects): the
    ``(velocity, inliers)`` models, the first search's hypotheses, and why there is none
    (empty when there are models)."""
    all_hyp: np.ndarray | None = None
    models: list[tuple[np.ndarray, np.ndarray]] = []
    remaining = np.ones(d.shape[0], dtype=bool)
    for _ in range(cfg.max_models):
        rem = np.flatnonzero(remaining)
        if rem.size < cfg.min_inliers:
            break
        hyp = search(d[rem], b[rem])
        if all_hyp is None:
            all_hyp = hyp
        if hyp.shape[0] == 0:
            if not models:
                return [], all_hyp, (f"degenerate geometry: every minimal set of {cfg.dims} "
                                     "directions drawn is singular (coplanar points)")
            break
        v0 = _msac_best(d[rem], b[rem], weight[rem], hyp, cfg.threshold, cfg.max_velocity)
        v, inl, _ = _refine(d, b, v0, cfg, remaining)
        if inl.sum() < cfg.min_inliers:
            break
        models.append((v, inl))
        remaining &= ~inl
    if not models:
        return [], all_hyp, (f"no motion supported by {cfg.min_inliers} points within "
                             f"{cfg.threshold:g} m/s")
    return models, all_hyp, ""


def _ambiguity(d: np.ndarray, b: np.ndarray, weight: np.ndarray, hyp: np.ndarray,
               v: np.ndarray, cfg: EgoVelocityConfig, inl: np.ndarray) -> str:
    """Why ``v`` is ambiguous under Doppler aliasing (empty when it is not): another
    velocity keeps ``ambiguity_ratio`` of its weighted support."""
    alt = _alias_alternative(d, b, weight, hyp, v, cfg, inl)
    if alt is None:
        return ""
    v_alt, w_alt = alt
    w_best = float(weight[inl].sum())
    if w_alt < cfg.ambiguity_ratio * w_best:
        return ""
    return (f"ambiguous: {np.round(v, 2).tolist()} and {np.round(v_alt, 2).tolist()} m/s "
            f"explain the range rates about equally (weighted support {w_best:.1f} and "
            f"{w_alt:.1f}; Doppler aliasing at ±{cfg.max_velocity:.2f} m/s); give a "
            "velocity_prior")


def _alias_alternative(d: np.ndarray, b: np.ndarray, weight: np.ndarray, hyp: np.ndarray,
                       v: np.ndarray, cfg: EgoVelocityConfig, inliers: np.ndarray
                       ) -> tuple[np.ndarray, float] | None:
    """The best velocity more than ``ambiguity_distance`` from ``v`` and the weighted support
    it shares with ``v``'s inliers (the same points explained both ways: aliasing; a moving
    object's motion explains other points and is no ambiguity).

    The hypothesis of least MSAC cost outside that distance is refined like the estimate;
    None when none exists or it converges back to ``v``.
    """
    far = np.linalg.norm(hyp - v, axis=1) > cfg.ambiguity_distance
    if not far.any():
        return None
    cand = hyp[far]
    costs = _msac_costs(d, b, weight, cand, cfg.threshold, cfg.max_velocity)
    v_alt, inl_alt, _ = _refine(d, b, cand[int(np.argmin(costs))], cfg,
                                np.ones(d.shape[0], dtype=bool))
    if np.linalg.norm(v_alt - v) <= cfg.ambiguity_distance or inl_alt.sum() < cfg.min_inliers:
        return None
    return v_alt, float(weight[inl_alt & inliers].sum())
