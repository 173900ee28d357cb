"""A clean-room generator of radar–inertial runs for the odometry ladder (issue 42).

Written from first principles and on purpose **without** :mod:`coloradar.sim`, whose
conventions and blind spots it would share. Everything is closed form:

- the rig's path is a sum of sinusoids (plus a forward drift) in a warped time ``τ(t)`` that
  holds still for the first ``rest`` seconds and then ramps smoothly (C³) to ``τ̇ = 1``; every
  derivative is exact (the chain rule through ``τ``);
- the base's attitude is ``R = Rz(ψ)·Rx(θ)·Ry(φ)`` in the base frame of docs/conventions.md §3
  (x right, y forward, z up): heading ``ψ`` along the horizontal velocity, pitch ``θ`` about the
  right axis (nose up positive), roll ``φ`` about the forward axis; the body rates and their
  derivatives follow from the Euler-rate kinematics (:func:`body_rates`);
- the IMU measures the specific force ``f = R_wiᵀ (a_i − g)``, ``g = (0, 0, −9.80665)``, and the
  angular rate, both in its own axes, at its own origin (lever arm included);
- the radar sees fixed world points of a "cave" around the path; a point's range rate is
  ``ṙ = d|s − p_r|/dt = −u·v_r`` (receding positive) with ``v_r`` the radar origin's exact
  velocity (``ω × lever arm`` included).

Noise comes in rungs (:data:`RUNGS`, cumulative): white noise; turn-on biases; bias walks;
direction noise; ghosts and a mover; a radar–IMU time offset.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from coloradar.calib import Calibration, Extrinsic, preset_calibration
from coloradar.geometry import Trajectory

G0 = 9.80665
GRAVITY = np.array([0.0, 0.0, -G0])
DEG = np.pi / 180.0
RADAR = "single_chip"
V_MAX = 2.4543366605456582
"""The single chip's unambiguous range rate [m/s] (its waveform's; range rates are folded into
``[−V_MAX, V_MAX)`` as the radar reports them)."""

# --------------------------------------------------------------------------------------------
# Closed-form signals


@dataclass(frozen=True)
class Sines:
    """``offset + slope·τ + Σ amp·sin(2π·freq·τ + phase)`` and its exact derivatives."""

    amp: tuple[float, ...] = ()
    freq: tuple[float, ...] = ()
    phase: tuple[float, ...] = ()
    slope: float = 0.0
    offset: float = 0.0

    def d(self, tau: np.ndarray, k: int = 0) -> np.ndarray:
        """The ``k``-th derivative with respect to ``τ`` at ``tau``."""
        out = np.zeros_like(tau, dtype=np.float64)
        if k == 0:
            out = out + self.offset + self.slope * tau
        elif k == 1:
            out = out + self.slope
        for a, f, p in zip(self.amp, self.freq, self.phase, strict=True):
            w = 2.0 * np.pi * f
            out = out + a * w**k * np.sin(w * tau + p + k * np.pi / 2.0)
        return out


@dataclass(frozen=True)
class Warp:
    """Run time → path time ``τ``: still for ``rest`` s, then ``τ̇`` rises from 0 to 1 over
    ``ramp`` s along the C³ step ``S(x) = 35x⁴ − 84x⁵ + 70x⁶ − 20x⁷``."""

    rest: float = 2.0
    ramp: float = 2.0

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``τ, τ̇, τ̈`` at run times ``t``."""
        x = np.clip((np.asarray(t, dtype=np.float64) - self.rest) / self.ramp, 0.0, 1.0)
        step = 35 * x**4 - 84 * x**5 + 70 * x**6 - 20 * x**7
        dstep = (140 * x**3 - 420 * x**4 + 420 * x**5 - 140 * x**6) / self.ramp
        integral = 7 * x**5 - 14 * x**6 + 10 * x**7 - 2.5 * x**8       # ∫₀ˣ S, = 0.5 at 1
        after = np.maximum(np.asarray(t, dtype=np.float64) - self.rest - self.ramp, 0.0)
        return self.ramp * integral + after, step, dstep


def _atan2_d(u: tuple, w: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``atan2(u, w)`` and its first two derivatives from those of ``u`` and ``w``."""
    d = u[0] ** 2 + w[0] ** 2
    n = u[1] * w[0] - u[0] * w[1]
    dn = u[2] * w[0] - u[0] * w[2]
    dd = 2.0 * (u[0] * u[1] + w[0] * w[1])
    return np.arctan2(u[0], w[0]), n / d, (dn * d - n * dd) / d**2


def _chain(f: tuple, tau_d: tuple) -> tuple:
    """A function of ``τ`` (value, ``d/dτ``, ``d²/dτ²``) as a function of run time."""
    _, t1, t2 = tau_d
    return f[0], f[1] * t1, f[2] * t1**2 + f[1] * t2


# --------------------------------------------------------------------------------------------
# Motion


@dataclass(frozen=True)
class Motion:
    """A rig motion: path channels in ``τ`` (world x, y, z [m]) and attitude sways [rad].

    ``grade_pitch``: the pitch follows the path's grade (a vehicle on a slope) plus the sway;
    else the pitch is the sway alone (a carried rig). ``yaw0`` turns the whole path."""

    name: str
    x: Sines
    y: Sines
    z: Sines
    pitch: Sines
    roll: Sines
    grade_pitch: bool = False
    yaw0: float = 0.0
    warp: Warp = field(default_factory=Warp)


def _draw(rng: np.random.Generator, amps: tuple[float, ...], freqs: tuple[tuple[float, float], ...],
          **kw: float) -> Sines:
    return Sines(tuple(amps), tuple(float(rng.uniform(*f)) for f in freqs),
                 tuple(float(p) for p in rng.uniform(0, 2 * np.pi, len(amps))), **kw)


def walk(rng: np.random.Generator) -> Motion:
    """A person carrying the rig at ~1.4 m/s: wandering heading (turns of up to ~±45° and
    quicker wiggles), heave ±0.5 m at 0.02–0.06 Hz, a 2 Hz step bob of ±3 cm, pitch ±0.08 rad
    at ~0.7 Hz, roll ±0.1 rad at ~0.9 Hz."""
    return Motion(
        "walk",
        x=_draw(rng, (6.0, 2.0, 0.5), ((0.015, 0.025), (0.04, 0.05), (0.12, 0.18))),
        y=_draw(rng, (0.3,), ((0.08, 0.12),), slope=1.4),
        z=_draw(rng, (0.3, 0.2, 0.03), ((0.02, 0.035), (0.04, 0.06), (1.8, 2.2))),
        pitch=_draw(rng, (0.08, 0.02), ((0.6, 0.8), (0.05, 0.1))),
        roll=_draw(rng, (0.1, 0.02), ((0.8, 1.0), (0.05, 0.1))),
        yaw0=float(rng.uniform(-np.pi, np.pi)))


def vehicle(rng: np.random.Generator) -> Motion:
    """A vehicle at 2.1–2.35 m/s (kept below the single chip's 2.45 m/s unambiguous range rate)
    on long slopes: ±3 m of height over a ~100 s period, so a pitch of up to ~5° held for tens
    of seconds with the matching climb; gentle turns, little sway."""
    return Motion(
        "vehicle",
        x=_draw(rng, (5.0, 1.0), ((0.018, 0.022), (0.05, 0.07))),
        y=_draw(rng, (0.15,), ((0.08, 0.12),), slope=2.1),
        z=_draw(rng, (3.0, 0.01), ((0.009, 0.011), (1.3, 1.7))),
        pitch=_draw(rng, (0.01,), ((1.0, 1.4),)),
        roll=_draw(rng, (0.02,), ((0.5, 0.7),)),
        grade_pitch=True, yaw0=float(rng.uniform(-np.pi, np.pi)))


MOTIONS = {"walk": walk, "vehicle": vehicle}


@dataclass(frozen=True)
class State:
    """The base frame at N times: position, velocity, acceleration of its origin (world), its
    attitude ``world_R_base``, body angular velocity and acceleration (base axes)."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    rotation: Rotation
    omega: np.ndarray
    domega: np.ndarray


def path_derivatives(m: Motion, tau: np.ndarray) -> list[np.ndarray]:
    """World path ``P(τ)`` and its derivatives of order 0..3, each ``(N, 3)``."""
    c, s = np.cos(m.yaw0), np.sin(m.yaw0)
    out = []
    for k in range(4):
        x, y = m.x.d(tau, k), m.y.d(tau, k)
        out.append(np.column_stack([c * x - s * y, s * x + c * y, m.z.d(tau, k)]))
    return out


def euler_angles(m: Motion, tau: np.ndarray) -> tuple[tuple, tuple, tuple]:
    """Heading, pitch and roll as functions of ``τ``: each (value, ``d/dτ``, ``d²/dτ²``)."""
    p = path_derivatives(m, tau)
    # Heading: the forward axis (base +y) along the horizontal velocity P' = (x', y').
    psi = _atan2_d((-p[1][:, 0], -p[2][:, 0], -p[3][:, 0]), (p[1][:, 1], p[2][:, 1], p[3][:, 1]))
    sway = tuple(m.pitch.d(tau, k) for k in range(3))
    if m.grade_pitch:
        h = np.hypot(p[1][:, 0], p[1][:, 1])
        h1 = (p[1][:, 0] * p[2][:, 0] + p[1][:, 1] * p[2][:, 1]) / h
        h2 = (p[2][:, 0] ** 2 + p[1][:, 0] * p[3][:, 0] + p[2][:, 1] ** 2
              + p[1][:, 1] * p[3][:, 1] - h1**2) / h
        grade = _atan2_d((p[1][:, 2], p[2][:, 2], p[3][:, 2]), (h, h1, h2))
        theta = tuple(g + s for g, s in zip(grade, sway, strict=True))
    else:
        theta = sway
    phi = tuple(m.roll.d(tau, k) for k in range(3))
    return psi, theta, phi


def body_rates(psi: tuple, theta: tuple, phi: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Body angular velocity and acceleration (base axes) of ``R = Rz(ψ)·Rx(θ)·Ry(φ)``.

    ``ω_b = Ry(φ)ᵀ (Rx(θ)ᵀ e_z ψ̇ + e_x θ̇) + e_y φ̇``, written out and differentiated."""
    (_, dps, ddps), (th, dth, ddth), (ph, dph, ddph) = psi, theta, phi
    st, ct, sp, cp = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    w = np.column_stack([cp * dth - sp * ct * dps,
                         st * dps + dph,
                         sp * dth + cp * ct * dps])
    dw = np.column_stack([
        -sp * dph * dth + cp * ddth - (cp * dph * ct * dps - sp * st * dth * dps + sp * ct * ddps),
        ct * dth * dps + st * ddps + ddph,
        cp * dph * dth + sp * ddth - sp * dph * ct * dps - cp * st * dth * dps + cp * ct * ddps])
    return w, dw


def attitude(psi: np.ndarray, theta: np.ndarray, phi: np.ndarray) -> Rotation:
    """``Rz(ψ)·Rx(θ)·Ry(φ)`` (scipy's intrinsic ``"ZXY"``)."""
    return Rotation.from_euler("ZXY", np.column_stack([psi, theta, phi]))


def kinematics(m: Motion, t: np.ndarray) -> State:
    """The exact state of the base at run times ``t``."""
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    tau_d = m.warp(t)
    p = path_derivatives(m, tau_d[0])
    t1, t2 = tau_d[1][:, None], tau_d[2][:, None]
    angles = [_chain(a, tau_d) for a in euler_angles(m, tau_d[0])]
    w, dw = body_rates(*angles)
    return State(t, p[0], p[1] * t1, p[2] * t1**2 + p[1] * t2,
                 attitude(angles[0][0], angles[1][0], angles[2][0]), w, dw)


def sensor_motion(st: State, b_t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World position, velocity and acceleration of a sensor origin at ``b_t_s`` (base)."""
    lever = np.tile(np.asarray(b_t_s, dtype=np.float64), (st.t.size, 1))
    pos = st.position + st.rotation.apply(lever)
    vel = st.velocity + st.rotation.apply(np.cross(st.omega, lever))
    acc = st.acceleration + st.rotation.apply(
        np.cross(st.domega, lever) + np.cross(st.omega, np.cross(st.omega, lever)))
    return pos, vel, acc


def ideal_imu(st: State, base_t_imu: np.ndarray) -> np.ndarray:
    """Noiseless IMU samples ``(N, 6)``: specific force [m/s²] and angular rate [rad/s] in the
    IMU's axes."""
    r_bi, r = base_t_imu[:3, :3], base_t_imu[:3, 3]
    _, _, acc = sensor_motion(st, r)
    f_base = st.rotation.inv().apply(acc - GRAVITY)
    return np.hstack([f_base @ r_bi, st.omega @ r_bi])                           # R_biᵀ x


# --------------------------------------------------------------------------------------------
# Noise ladder


@dataclass(frozen=True)
class Noise:
    """What a rung adds. IMU figures are the 3DM-GX5-25 datasheet's; the bias walks are three
    times the datasheet-derived densities (instability / √100 s), as the filter assumes."""

    imu_white: bool = True
    accel_density: float = 100e-6 * G0                 # m/s²/√Hz
    gyro_density: float = 0.005 * DEG                   # rad/s/√Hz
    range_rate_std: float = 0.04                        # m/s
    range_std: float = 0.04                             # m
    accel_turn_on: float = 0.0                          # m/s², per axis ±
    gyro_turn_on: float = 0.0                           # rad/s, per axis ±
    accel_walk: float = 0.0                             # m/s²/√s
    gyro_walk: float = 0.0                              # rad/s/√s
    azimuth_std: float = 0.0                            # rad
    elevation_std: float = 0.0                          # rad
    ghost_fraction: float = 0.0
    mover: bool = False
    time_offset: float = 0.0                            # s: the radar stamps this late
    # (a frame stamped t shows the motion at t − time_offset: the filter's t_d of
    # docs/conventions.md §3 is −time_offset)


def _rungs() -> dict[int, Noise]:
    r1 = Noise()
    r2 = replace(r1, accel_turn_on=0.002 * G0, gyro_turn_on=0.04 * DEG)
    r3 = replace(r2, accel_walk=3 * 0.04e-3 * G0 / 10.0, gyro_walk=3 * 8.0 * DEG / 3600.0 / 10.0)
    r4 = replace(r3, azimuth_std=2.0 * DEG, elevation_std=4.0 * DEG)
    r5 = replace(r4, ghost_fraction=0.10, mover=True)
    r6 = replace(r5, time_offset=0.015)
    return {1: r1, 2: r2, 3: r3, 4: r4, 5: r5, 6: r6}


RUNGS = _rungs()
RUNG_NAMES = {1: "white noise", 2: "+ turn-on biases", 3: "+ bias walks",
              4: "+ direction noise", 5: "+ ghosts, mover", 6: "+ time offset 15 ms"}

# --------------------------------------------------------------------------------------------
# Rig and scene

IMU_LEVER = np.array([0.12, -0.12, 0.10])
"""The IMU's offset from the base origin when it is not at it [m] (0.197 m)."""


def calibration(imu_at_origin: bool = True) -> Calibration:
    """The preset calibration (the rig's extrinsics), with the IMU moved to :data:`IMU_LEVER`
    when not ``imu_at_origin``. The same calibration made the data and is given to the
    methods."""
    calib = preset_calibration()
    if imu_at_origin:
        return calib
    tf = dict(calib.transforms)
    tf["imu"] = Extrinsic(IMU_LEVER.copy(), np.asarray(tf["imu"].quaternion))
    return replace(calib, transforms=tf)


@dataclass(frozen=True)
class Fov:
    """What the radar sees: range, azimuth and elevation limits; points per frame."""

    max_range: float = 18.0
    min_range: float = 0.5
    azimuth: float = 60.0 * DEG
    elevation: float = 20.0 * DEG
    points: tuple[int, int] = (12, 30)


def cave(m: Motion, duration: float, rng: np.random.Generator) -> np.ndarray:
    """Fixed world scatterers ``(K, 3)`` 3–15 m around the path (horizontally), −2.5 to
    +3.5 m in height about it, none closer than 3 m (horizontally) to the path."""
    tau_end = float(m.warp(np.array([duration]))[0][0]) + 10.0
    tau = np.arange(-10.0, tau_end, 0.5)
    centres = path_derivatives(m, tau)[0]
    k = 12
    ang = rng.uniform(0, 2 * np.pi, (tau.size, k))
    dist = rng.uniform(3.0, 15.0, (tau.size, k))
    pts = np.stack([centres[:, None, 0] + dist * np.cos(ang), centres[:, None, 1] + dist * np.sin(ang),
                    centres[:, None, 2] + rng.uniform(-2.5, 3.5, (tau.size, k))], axis=-1)
    pts = pts.reshape(-1, 3)
    near = np.min(np.hypot(pts[:, None, 0] - centres[None, :, 0],
                           pts[:, None, 1] - centres[None, :, 1]), axis=1)
    return pts[near >= 3.0]


def radar_view(st: State, base_t_radar: np.ndarray, world_pts: np.ndarray,
               world_vel: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Exact radar-frame positions ``(T, K, 3)`` and range rates ``(T, K)`` of world points
    (``world_vel``: their world velocities ``(T, K, 3)``; None: static) at the states' times."""
    pos, vel, _ = sensor_motion(st, base_t_radar[:3, 3])
    w_r_r = (st.rotation * Rotation.from_matrix(base_t_radar[:3, :3])).as_matrix()   # (T,3,3)
    rel = world_pts[None, :, :] - pos[:, None, :] if world_pts.ndim == 2 else world_pts - pos[:, None, :]
    q = np.einsum("tji,tkj->tki", w_r_r, rel)                                       # R_wrᵀ rel
    u = rel / np.linalg.norm(rel, axis=-1, keepdims=True)
    rel_vel = -vel[:, None, :] if world_vel is None else world_vel - vel[:, None, :]
    return q, np.einsum("tki,tki->tk", u, rel_vel)


# --------------------------------------------------------------------------------------------
# A run


@dataclass(frozen=True)
class RunSpec:
    """One run of the ladder: motion, rung, where the IMU sits, sizes and the seed."""

    motion: str = "walk"
    rung: int = 1
    imu_at_origin: bool = True
    duration: float = 40.0
    seed: int = 0
    imu_rate: float = 200.0
    radar_rate: float = 10.0
    fov: Fov = field(default_factory=Fov)


@dataclass(frozen=True)
class LadderRun:
    """What the methods get (IMU, radar frames, calibration) and the truth."""

    spec: RunSpec
    imu_t: np.ndarray
    imu: np.ndarray
    frame_t: np.ndarray            # radar stamps (late by the rung's time offset)
    clouds: list[np.ndarray]       # per frame float32 (N, 5): x y z intensity range_rate
    gt: Trajectory                 # world_T_base, 100 Hz
    calib: Calibration
    motion: Motion
    bias: np.ndarray               # (N, 6) the IMU's bias in every sample
    folded: int                    # static points whose range rate folded (beyond V_MAX)

    @property
    def distance(self) -> float:
        return float(np.sum(np.linalg.norm(np.diff(self.gt.translations, axis=0), axis=1)))


def imu_errors(noise: Noise, n: int, rate: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The bias ``(n, 6)`` (turn-on plus walk) and white noise ``(n, 6)`` of the IMU, each part
    from its own stream of ``seed`` (a rung that adds a part leaves the others as they were)."""
    dt = 1.0 / rate
    turn_on = np.random.default_rng([seed, 10]).uniform(-1, 1, 6) * np.repeat(
        [noise.accel_turn_on, noise.gyro_turn_on], 3)
    steps = np.random.default_rng([seed, 11]).normal(size=(n, 6)) * np.sqrt(dt) * np.repeat(
        [noise.accel_walk, noise.gyro_walk], 3)
    steps[0] = 0.0
    bias = turn_on + np.cumsum(steps, axis=0)
    white = np.random.default_rng([seed, 12]).normal(size=(n, 6)) * np.sqrt(rate) * np.repeat(
        [noise.accel_density, noise.gyro_density], 3)
    return bias, white if noise.imu_white else np.zeros_like(white)


def _measure(q: np.ndarray, rr: np.ndarray, noise: Noise, rng: np.random.Generator) -> np.ndarray:
    """Noisy ``(N, 5)`` points from exact radar-frame positions and range rates."""
    r = np.linalg.norm(q, axis=1)
    az = np.arctan2(q[:, 1], q[:, 0]) + rng.normal(0, 1, r.size) * noise.azimuth_std
    el = np.arcsin(q[:, 2] / r) + rng.normal(0, 1, r.size) * noise.elevation_std
    r = r + rng.normal(0, noise.range_std, r.size)
    xyz = r[:, None] * np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    rate = rr + rng.normal(0, noise.range_rate_std, r.size)
    return np.column_stack([xyz, rng.uniform(5, 30, r.size), rate])


def visible(q: np.ndarray, fov: Fov) -> np.ndarray:
    """Which radar-frame points ``(..., 3)`` the radar can see."""
    r = np.linalg.norm(q, axis=-1)
    az = np.arctan2(q[..., 1], q[..., 0])
    el = np.arcsin(np.clip(q[..., 2] / np.maximum(r, 1e-9), -1, 1))
    return ((r <= fov.max_range) & (r >= fov.min_range) & (np.abs(az) <= fov.azimuth)
            & (np.abs(el) <= fov.elevation))


def _fold(rate: np.ndarray) -> np.ndarray:
    return (rate + V_MAX) % (2 * V_MAX) - V_MAX


MOVER_LEAD, MOVER_PACE = 7.0, 0.85
"""The mover walks the rig's path at path time ``MOVER_PACE·τ + MOVER_LEAD``: still while the
rig rests (about 10 m ahead of a walker, 15 m of a vehicle), then a little slower than the rig,
which closes in on it (by 4 s of path over a 30 s run)."""


def mover_points(m: Motion, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mover, three scatterers 0.5 m apart in height, at run times ``t``: world positions
    and velocities, each ``(T, 3, 3)``."""
    tau, tau1, _ = m.warp(t)
    p = path_derivatives(m, MOVER_PACE * tau + MOVER_LEAD)
    offs = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5], [0.0, 0.0, -0.5]])
    vel = p[1] * (MOVER_PACE * tau1)[:, None]
    return p[0][:, None, :] + offs[None], np.repeat(vel[:, None, :], 3, axis=1)


def _frame_clouds(spec: RunSpec, st: State, calib: Calibration, scene: np.ndarray
                  ) -> tuple[list[np.ndarray], int]:
    """Per frame (capture states ``st``) the noisy cloud, and the count of folded points. The
    static points (which, and their noise), the mover's and the ghosts come from streams of
    their own: a rung that adds ghosts leaves the static points as they were."""
    noise, fov = RUNGS[spec.rung], spec.fov
    rng, rng_mover, rng_ghost = (np.random.default_rng([spec.seed, k]) for k in (20, 21, 22))
    b_t_r = calib.transforms[RADAR].matrix()
    q_all, rr_all = radar_view(st, b_t_r, scene)
    mq = mrr = None
    if noise.mover:
        mq, mrr = radar_view(st, b_t_r, *mover_points(st_motion(spec), st.t))
    clouds, folded = [], 0
    for k in range(st.t.size):
        vis = np.flatnonzero(visible(q_all[k], fov))
        n = min(vis.size, int(rng.integers(fov.points[0], fov.points[1] + 1)))
        pick = rng.choice(vis, n, replace=False)
        folded += int(np.sum(np.abs(rr_all[k, pick]) >= V_MAX))
        parts = [_measure(q_all[k, pick], rr_all[k, pick], noise, rng)]
        if mq is not None and mrr is not None:
            mv = visible(mq[k], fov)
            parts.append(_measure(mq[k, mv], mrr[k, mv], noise, rng_mover))
        n_ghost = round(noise.ghost_fraction * n / (1.0 - noise.ghost_fraction))
        if n_ghost:
            r = rng_ghost.uniform(1.0, fov.max_range, n_ghost)
            az = rng_ghost.uniform(-fov.azimuth, fov.azimuth, n_ghost)
            el = rng_ghost.uniform(-fov.elevation, fov.elevation, n_ghost)
            xyz = r[:, None] * np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                                np.sin(el)])
            parts.append(np.column_stack([xyz, rng_ghost.uniform(5, 30, n_ghost),
                                          rng_ghost.uniform(-V_MAX, V_MAX, n_ghost)]))
        cloud = np.concatenate(parts)
        cloud[:, 4] = _fold(cloud[:, 4])
        clouds.append(cloud[rng_ghost.permutation(len(cloud))].astype(np.float32))
    return clouds, folded


def ladder_spec(rung: int, seed: int = 0, duration: float = 40.0) -> RunSpec:
    """The ladder's run of a rung: walk on odd rungs, vehicle on even ones; the IMU at the base
    origin on rungs 1, 2, 5, 6 and :data:`IMU_LEVER` away from it on rungs 3, 4."""
    return RunSpec(motion="walk" if rung % 2 else "vehicle", rung=rung,
                   imu_at_origin=rung not in (3, 4), duration=duration, seed=seed)


def st_motion(spec: RunSpec) -> Motion:
    """The run's motion (drawn from its own stream of the seed, the same on every rung)."""
    return MOTIONS[spec.motion](np.random.default_rng([spec.seed, 1, len(spec.motion)]))


def make_run(spec: RunSpec) -> LadderRun:
    """Generate one run. The motion and the scene depend only on the seed and motion (the
    same on every rung and IMU placement); each kind of noise has a stream of its own, so a
    rung differs from the one below only by what it adds."""
    motion = st_motion(spec)
    calib = calibration(spec.imu_at_origin)
    noise = RUNGS[spec.rung]
    scene = cave(motion, spec.duration, np.random.default_rng([spec.seed, 3]))
    imu_t = np.arange(0.0, spec.duration, 1.0 / spec.imu_rate)
    imu = ideal_imu(kinematics(motion, imu_t), calib.transforms["imu"].matrix())
    bias, white = imu_errors(noise, imu_t.size, spec.imu_rate, spec.seed)
    frame_t = np.arange(0.05, spec.duration - 0.1, 1.0 / spec.radar_rate)
    capture = kinematics(motion, frame_t - noise.time_offset)
    clouds, folded = _frame_clouds(spec, capture, calib, scene)
    tg = np.arange(0.0, spec.duration, 0.01)
    sg = kinematics(motion, tg)
    gt = Trajectory(tg, sg.position, sg.rotation, "groundtruth")
    return LadderRun(spec, imu_t, imu + bias + white, frame_t, clouds, gt, calib, motion, bias,
                     folded)


# --------------------------------------------------------------------------------------------
# Strapdown integration (the generator's self-check)


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def strapdown(imu: np.ndarray, dt: float, r0: np.ndarray, v0: np.ndarray, p0: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Integrate IMU samples taken every ``dt`` with RK4 over steps of ``2·dt`` (the odd samples
    are the midpoints): ``Ṙ = R[ω]×``, ``v̇ = R f + g``, ``ṗ = v``. Returns the IMU's world
    positions ``(M, 3)`` and attitudes ``(M, 3, 3)`` at the even samples."""

    def deriv(r: np.ndarray, v: np.ndarray, s: np.ndarray) -> tuple:
        return r @ _skew(s[3:]), r @ s[:3] + GRAVITY, v

    r, v, p = r0.copy(), v0.copy(), p0.copy()
    ps, rs = [p.copy()], [r.copy()]
    h = 2.0 * dt
    for k in range(0, imu.shape[0] - 2, 2):
        a, b, c = imu[k], imu[k + 1], imu[k + 2]
        k1 = deriv(r, v, a)
        k2 = deriv(r + h / 2 * k1[0], v + h / 2 * k1[1], b)
        k3 = deriv(r + h / 2 * k2[0], v + h / 2 * k2[1], b)
        k4 = deriv(r + h * k3[0], v + h * k3[1], c)
        r = r + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        p = p + h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
        v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        u, _, vt = np.linalg.svd(r)
        r = u @ vt
        ps.append(p.copy())
        rs.append(r.copy())
    return np.array(ps), np.array(rs)
