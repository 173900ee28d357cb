"""The clean-room odometry ladder (issue 42, item 1).

Runs come from :mod:`_ladder`, a generator written here from first principles (closed-form
trajectories and their exact derivatives; not :mod:`coloradar.sim`). Two groups of tests:

* the generator against physics: its body rates are the derivatives of its rotations, its
  velocities and accelerations those of its positions, its range rates those of its ranges, and
  a strapdown integration of its noiseless IMU gives back its trajectory;
* a ladder of rungs (:data:`_ladder.RUNGS`, cumulative: white noise → turn-on biases → bias
  walks → direction noise → ghosts and a mover → a 15 ms radar–IMU time offset), one 30 s run
  each, walk and vehicle alternating, the IMU at and away from the base origin alternating.
  On each, the filter's **default** (``RioConfig()``, the single chip's default ego-velocity
  settings) has an ATE (SE(3)-aligned, % of distance) no worse than 1.5× that of dead
  reckoning with the true attitude and the 3-D ego-velocity model, and no worse than the
  loosely coupled update (``RioConfig(update="ego-velocity")``), each with an absolute slack
  of :data:`SLACK` (0.02 % of distance) so that a tie cannot fail by noise. On the vehicle
  rungs ``--model planar`` (the non-holonomic constraint a wheeled vehicle keeps) is no worse
  than the loosely coupled update either.

The ladder checks whatever the default is: ``benchmarks/ladder_odometry.py`` prints its
figures with the alternatives over several seeds. The single chip's default is 3-D (issue
42; with the planar model, rungs 1 and 3, a walk that rises and falls, failed the
dead-reckoning check: ATE 0.21 % against 1.5 × 0.055 + 0.02). One check still fails and is a
strict xfail (:data:`KNOWN_MISSES`): rung 2 (vehicle, exact directions) the loosely coupled
check (0.058 % against 0.028 + 0.02). The loosely coupled update's per-frame velocities are
planar, the non-holonomic constraint this vehicle keeps; with 3-D velocities it is behind the
default (``benchmarks/ladder_odometry.py --rungs 2``: 0.076 % against 0.058 %, median of 3
seeds), and ``--model planar`` is level with it (docs/odometry.md, "Why issue 42 is
blocked"). A strict xfail fails the day it passes.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import _ladder as lad
from coloradar.odometry import (
    DopplerConfig,
    RioConfig,
    absolute_trajectory_error,
    ego_velocity_config,
    estimate_ego_velocities,
    radar_inertial_odometry,
    rio_odometry,
)
from coloradar.odometry.metrics import final_position_error

SLACK = 0.02
"""Absolute slack of every ladder comparison [% of distance]."""
DR_FACTOR = 1.5
DURATION = 30.0
SEED = 0

# --------------------------------------------------------------------------------------------
# The generator against physics


def _times(duration: float = 20.0) -> np.ndarray:
    """Times through the rest, the ramp and the motion (none at the ramp's kinks)."""
    return np.concatenate([[0.5, 1.9, 2.3, 3.1, 3.9], np.linspace(4.5, duration, 60)])


@pytest.mark.parametrize("motion", sorted(lad.MOTIONS))
def test_body_rates_are_the_rotations_derivatives(motion):
    m = lad.st_motion(lad.RunSpec(motion=motion, seed=3))
    t, h = _times(), 1e-4
    st = lad.kinematics(m, t)
    lo, hi = lad.kinematics(m, t - h), lad.kinematics(m, t + h)
    omega_fd = (lo.rotation.inv() * hi.rotation).as_rotvec() / (2 * h)     # body axes
    np.testing.assert_allclose(st.omega, omega_fd, atol=1e-6)
    np.testing.assert_allclose(st.domega, (hi.omega - lo.omega) / (2 * h), atol=1e-5)
    np.testing.assert_allclose(st.velocity, (hi.position - lo.position) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(st.acceleration, (hi.velocity - lo.velocity) / (2 * h), atol=1e-5)
    # The attitude convention: base +y (forward) along the horizontal velocity once moving,
    # and the rig really turns, pitches and rolls.
    moving = t > 4.5
    fwd = st.rotation.apply(np.array([0.0, 1.0, 0.0]))[moving]
    heading_v = np.arctan2(-st.velocity[moving, 0], st.velocity[moving, 1])
    heading_f = np.arctan2(-fwd[:, 0], fwd[:, 1])
    np.testing.assert_allclose(np.angle(np.exp(1j * (heading_v - heading_f))), 0, atol=1e-9)
    assert np.ptp(np.unwrap(heading_v)) > 0.3
    assert np.abs(st.omega[moving, 0]).max() > 0.02 and np.abs(st.omega[moving, 1]).max() > 0.02


@pytest.mark.parametrize("motion", sorted(lad.MOTIONS))
def test_rest_is_still_and_the_imu_reads_gravity(motion):
    spec = lad.RunSpec(motion=motion, rung=1, imu_at_origin=False, duration=3.0, seed=1)
    m = lad.st_motion(spec)
    t = np.linspace(0.0, 2.0, 9)
    st = lad.kinematics(m, t)
    assert np.abs(st.velocity).max() == 0 and np.abs(st.omega).max() == 0
    assert np.ptp(st.rotation.as_quat(), axis=0).max() == 0
    imu = lad.ideal_imu(st, lad.calibration(False).transforms["imu"].matrix())
    np.testing.assert_allclose(np.linalg.norm(imu[:, :3], axis=1), lad.G0, rtol=1e-12)
    # IMU axes: the specific force is the world's "up" seen in the IMU frame.
    r_wi = st.rotation * Rotation.from_matrix(lad.calibration().transforms["imu"].matrix()[:3, :3])
    np.testing.assert_allclose(r_wi.apply(imu[:, :3]), np.tile([0, 0, lad.G0], (9, 1)), atol=1e-9)


@pytest.mark.parametrize("motion", sorted(lad.MOTIONS))
def test_strapdown_of_the_noiseless_imu_gives_back_the_trajectory(motion):
    m = lad.st_motion(lad.RunSpec(motion=motion, seed=2))
    b_t_i = lad.calibration(imu_at_origin=False).transforms["imu"].matrix()
    dt = 1.0 / 400.0
    t = np.arange(0.0, 20.0 + dt / 2, dt)
    st = lad.kinematics(m, t)
    pos, vel, _ = lad.sensor_motion(st, b_t_i[:3, 3])
    r_wi = (st.rotation * Rotation.from_matrix(b_t_i[:3, :3])).as_matrix()
    p, r = lad.strapdown(lad.ideal_imu(st, b_t_i), dt, r_wi[0], vel[0], pos[0])
    travelled = np.sum(np.linalg.norm(np.diff(pos, axis=0), axis=1))
    assert travelled > 15.0
    assert np.linalg.norm(p - pos[::2], axis=1).max() < 1e-5                  # 0.01 mm
    att = Rotation.from_matrix(r) * Rotation.from_matrix(r_wi[::2]).inv()
    assert att.magnitude().max() < 1e-8


@pytest.mark.parametrize("motion", sorted(lad.MOTIONS))
def test_range_rates_are_the_ranges_derivatives(motion):
    spec = lad.RunSpec(motion=motion, seed=4)
    m = lad.st_motion(spec)
    b_t_r = lad.calibration().transforms[lad.RADAR].matrix()
    scene = lad.cave(m, 20.0, np.random.default_rng(0))[:200]
    t, h = _times(), 1e-4
    st = lad.kinematics(m, t)
    q, rr = lad.radar_view(st, b_t_r, scene)
    q_lo, _ = lad.radar_view(lad.kinematics(m, t - h), b_t_r, scene)
    q_hi, _ = lad.radar_view(lad.kinematics(m, t + h), b_t_r, scene)
    fd = (np.linalg.norm(q_hi, axis=-1) - np.linalg.norm(q_lo, axis=-1)) / (2 * h)
    np.testing.assert_allclose(rr, fd, atol=1e-7)
    # The radar-frame form of the same thing: ṙ = −u·v_radar, v_radar in the radar's axes.
    _, v_world, _ = lad.sensor_motion(st, b_t_r[:3, 3])
    r_wr = st.rotation * Rotation.from_matrix(b_t_r[:3, :3])
    v_radar = r_wr.inv().apply(v_world)
    u = q / np.linalg.norm(q, axis=-1, keepdims=True)
    np.testing.assert_allclose(rr, -np.einsum("tki,ti->tk", u, v_radar), atol=1e-9)
    # A mover: ṙ = u·(v_point − v_radar).
    mp, mv = lad.mover_points(m, t)
    _, mrr = lad.radar_view(st, b_t_r, mp, mv)
    mq_lo, _ = lad.radar_view(lad.kinematics(m, t - h), b_t_r, lad.mover_points(m, t - h)[0])
    mq_hi, _ = lad.radar_view(lad.kinematics(m, t + h), b_t_r, lad.mover_points(m, t + h)[0])
    mfd = (np.linalg.norm(mq_hi, axis=-1) - np.linalg.norm(mq_lo, axis=-1)) / (2 * h)
    np.testing.assert_allclose(mrr, mfd, atol=1e-7)


def test_clouds_hold_what_the_rung_promises():
    """Rung 1: every point static, in the field of view, with its range rate within the noise
    of the exact one; rung 5: ghosts and the mover on top, the static points unchanged."""
    spec = lad.RunSpec(motion="walk", rung=1, duration=8.0, seed=5)
    run = lad.make_run(spec)
    st = lad.kinematics(run.motion, run.frame_t)
    _, v_world, _ = lad.sensor_motion(st, run.calib.transforms[lad.RADAR].translation)
    r_wr = st.rotation * Rotation.from_matrix(run.calib.transforms[lad.RADAR].matrix()[:3, :3])
    v_radar = r_wr.inv().apply(v_world)
    res = []
    for cloud, v in zip(run.clouds, v_radar, strict=True):
        assert spec.fov.points[0] <= len(cloud) <= spec.fov.points[1]
        xyz = cloud[:, :3].astype(np.float64)
        u = xyz / np.linalg.norm(xyz, axis=1, keepdims=True)
        assert np.all(np.abs(np.arcsin(u[:, 2])) <= spec.fov.elevation + 1e-6)
        res.append(cloud[:, 4] + u @ v)
    res_all = np.concatenate(res)
    assert abs(res_all.std() - lad.RUNGS[1].range_rate_std) < 0.005 and abs(res_all.mean()) < 0.005
    assert run.folded == 0
    assert lad.V_MAX == pytest.approx(run.calib.radar(lad.RADAR).waveform.max_velocity)
    noisy = lad.make_run(lad.RunSpec(motion="walk", rung=5, duration=8.0, seed=5))
    extra = sum(len(c) for c in noisy.clouds) - sum(len(c) for c in run.clouds)
    assert extra > 0.1 * sum(len(c) for c in run.clouds)
    # Every kind of noise has its own stream: rung 5's IMU is rung 1's plus the bias.
    np.testing.assert_allclose(noisy.imu - run.imu, noisy.bias, atol=1e-12)
    assert np.abs(noisy.bias[:, 3:]).max() > 1e-4
    # The mover (three points walking the path ahead) is in view in most frames.
    st5 = lad.kinematics(noisy.motion, noisy.frame_t)
    mq, _ = lad.radar_view(st5, noisy.calib.transforms[lad.RADAR].matrix(),
                           *lad.mover_points(noisy.motion, noisy.frame_t))
    assert np.mean(lad.visible(mq, spec.fov).any(axis=1)) > 0.5


# --------------------------------------------------------------------------------------------
# The ladder


@dataclass(frozen=True)
class Figures:
    """ATE (SE(3)-aligned) and final error, % of distance, per method."""

    default: tuple[float, float]
    loose: tuple[float, float]
    dr_true_3d: tuple[float, float]
    planar: tuple[float, float] | None       # vehicle rungs only

    def line(self) -> str:
        return " ".join(f"{k} {v[0]:.3f}/{v[1]:.3f}" for k, v in vars(self).items()
                        if v is not None)




def _score(traj, gt) -> tuple[float, float]:
    return (absolute_trajectory_error(traj, gt).rmse_percent,
            final_position_error(traj, gt).percent)


@functools.cache
def figures(rung: int) -> Figures:
    spec = lad.ladder_spec(rung, SEED, DURATION)
    run = lad.make_run(spec)
    radar = run.calib.radar(lad.RADAR)
    cfg, cfg_3d = ego_velocity_config(radar), ego_velocity_config(radar, planar=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        track = estimate_ego_velocities(run.clouds, run.frame_t, cfg, frame=lad.RADAR)
        track_3d = (track if cfg_3d == cfg else
                    estimate_ego_velocities(run.clouds, run.frame_t, cfg_3d, frame=lad.RADAR))
        default = rio_odometry([track], run.calib, run.imu_t, run.imu, config=RioConfig(),
                               initial_pose=run.gt, points=[run.clouds])
        loose = rio_odometry([track], run.calib, run.imu_t, run.imu,
                             config=RioConfig(update="ego-velocity"), initial_pose=run.gt)
        planar = None if spec.motion != "vehicle" else rio_odometry(
            [track], run.calib, run.imu_t, run.imu,
            config=RioConfig(doppler=DopplerConfig(planar=None)), initial_pose=run.gt,
            points=[run.clouds]).trajectory
        dr = radar_inertial_odometry(track_3d, run.calib, orientation="groundtruth",
                                     groundtruth=run.gt, radar=lad.RADAR)
    return Figures(_score(default.trajectory, run.gt), _score(loose.trajectory, run.gt),
                   _score(dr, run.gt), None if planar is None else _score(planar, run.gt))


RUNG_IDS = [f"{r}-{lad.RUNG_NAMES[r].replace(' ', '_')}" for r in lad.RUNGS]


KNOWN_MISSES: dict[str, dict[int, str]] = {
    "dr": {},
    "loose": {2: "issue 42 (blocked): on a vehicle the loosely coupled update's planar "
                 "velocities keep the non-holonomic constraint the 3-D default does not"},
}


def _rungs(check: str) -> list:
    return [pytest.param(r, marks=pytest.mark.xfail(reason=KNOWN_MISSES[check][r], strict=True))
            if r in KNOWN_MISSES[check] else r for r in lad.RUNGS]


@pytest.mark.slow
@pytest.mark.parametrize("rung", _rungs("dr"), ids=RUNG_IDS)
def test_default_is_within_1_5x_dead_reckoning_with_true_attitude(rung):
    f = figures(rung)
    assert f.default[0] <= DR_FACTOR * f.dr_true_3d[0] + SLACK, f"rung {rung}: {f.line()}"


@pytest.mark.slow
@pytest.mark.parametrize("rung", _rungs("loose"), ids=RUNG_IDS)
def test_default_is_no_worse_than_the_loosely_coupled_update(rung):
    f = figures(rung)
    assert f.default[0] <= f.loose[0] + SLACK, f"rung {rung}: {f.line()}"


VEHICLE_RUNGS = [r for r in lad.RUNGS if lad.ladder_spec(r, SEED, DURATION).motion == "vehicle"]


@pytest.mark.slow
@pytest.mark.parametrize("rung", VEHICLE_RUNGS,
                         ids=[i for r, i in zip(lad.RUNGS, RUNG_IDS, strict=True)
                              if r in VEHICLE_RUNGS])
def test_the_planar_model_keeps_a_vehicle_as_the_loosely_coupled_update_does(rung):
    """``--model planar`` is the non-holonomic constraint a wheeled vehicle keeps on its
    grades (its radar's ``v_z`` is 0): the tightly coupled update with it is no worse than the
    loosely coupled update, whose per-frame ego-velocities are planar too. With the direction
    noise assumed (3° / 5°) instead of measured, rung 2's exact directions were over-corrected
    (0.091 % against 0.028 %)."""
    f = figures(rung)
    assert f.planar is not None
    assert f.planar[0] <= f.loose[0] + SLACK, f"rung {rung}: {f.line()}"
