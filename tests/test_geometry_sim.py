"""coloradar.geometry against a simulated run's exact truth (poses, velocities, scatterers)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from coloradar.dataset import open_sequence
from coloradar.geometry import (
    SE3,
    associate,
    rig_velocity,
    sensor_to_base,
    trajectory_from_groundtruth,
    world_T_sensor,
)
from coloradar.sim import run as sim_run
from coloradar.sim import truth as sim_truth

RADARS = ("cascade", "single_chip")


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    res = sim_run.simulate_run(out, duration=2.0, seed=3, heatmaps=False,
                               sensors=("cascade", "single_chip", "groundtruth"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seq = open_sequence(res.run_path)
    truth = sim_truth.load_truth(res.run_path)
    # The simulator's scene frame is the ground truth's world frame moved by the start pose.
    scene_T_world = SE3.from_matrix(truth["world_T_start"])
    return seq, truth, scene_T_world, trajectory_from_groundtruth(seq)


@pytest.mark.parametrize("radar", RADARS)
def test_interpolated_radar_poses_match_the_truth(simulated, radar):
    seq, truth, scene_T_world, traj = simulated
    ts = seq.radar(radar).adc.timestamps
    np.testing.assert_array_equal(ts, truth.radar_timestamps(radar))
    est = (scene_T_world @ world_T_sensor(traj, seq.calib, radar, ts)).matrices()
    exact = truth[f"{radar}/world_T_radar"]
    # 10 Hz ground truth, frames between its samples: linear/SLERP interpolation error only.
    assert np.abs(est[:, :3, 3] - exact[:, :3, 3]).max() < 5e-3
    cos = (np.einsum("nij,nij->n", est[:, :3, :3], exact[:, :3, :3]) - 1) / 2
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.1


@pytest.mark.parametrize("radar", RADARS)
def test_radar_velocity_from_ground_truth_matches_the_truth(simulated, radar):
    seq, truth, _, traj = simulated
    ts = truth.radar_timestamps(radar)
    vel = rig_velocity(traj, ts, calib=seq.calib, sensor=radar)
    exact_v, exact_w = truth.radar_velocity(radar), truth.radar_angular_velocity(radar)
    assert np.abs(exact_v).max() > 0.3                      # the rig does move
    # Finite differences over ±0.1 s of a 10 Hz ground truth: a few percent of the speed.
    assert np.abs(vel.linear - exact_v).max() < 0.03
    assert np.abs(vel.angular - exact_w).max() < 3e-3


def test_a_scatterer_seen_by_both_radars_maps_to_one_world_point(simulated):
    seq, truth, scene_T_world, traj = simulated
    statics = truth["static_position"]
    ia, ib = associate(truth.radar_timestamps("cascade"), truth.radar_timestamps("single_chip"),
                       tolerance=0.06, mutual=False)
    assert ia.size > 0
    checked = 0
    for i, j in zip(ia, ib, strict=True):
        world = {}
        for radar, k in (("cascade", i), ("single_chip", j)):
            t = truth.targets(radar, int(k))
            keep = t["ident"] < len(statics)
            pose = scene_T_world @ traj.at(truth.radar_timestamps(radar)[k]) @ sensor_to_base(
                seq.calib, radar)
            world[radar] = dict(zip(t["ident"][keep].tolist(), pose.apply(t["position"][keep]),
                                    strict=True))
        common = sorted(set(world["cascade"]) & set(world["single_chip"]))
        assert common
        a = np.array([world["cascade"][c] for c in common])
        b = np.array([world["single_chip"][c] for c in common])
        assert np.abs(a - b).max() < 5e-3                     # the same point, both sensors
        assert np.abs(a - statics[common]).max() < 5e-3       # and where the scene has it
        checked += len(common)
    assert checked > 100
