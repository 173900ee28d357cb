"""KITTI-style drift against a brute-force loop of the devkit's rule; ATE and final-position
error on trajectories with a known error; the ground truth that `evaluate` writes for evo."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from _trajectories import T0
from _trajectories import wander as _wander
from coloradar.geometry import Trajectory
from coloradar.odometry import (
    absolute_trajectory_error,
    evaluate_trajectory,
    read_tum,
    write_evaluation,
)
from coloradar.odometry.metrics import DRIFT_LENGTHS, final_position_error, trajectory_drift


def _drifting(ref, seed=4):
    """An estimate that drifts: integrated noise in position and attitude."""
    rng = np.random.default_rng(seed)
    n = len(ref)
    walk = np.cumsum(rng.normal(scale=0.01, size=(n, 3)), axis=0)
    att = Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.003, size=(n, 3)), axis=0))
    return Trajectory(ref.timestamps, ref.translations + walk, att * ref.rotations, "estimate")


def _mat(tr, k):
    m = np.eye(4)
    m[:3, :3] = tr.rotations[k].as_matrix()
    m[:3, 3] = tr.translations[k]
    return m


def _kitti_brute(est, ref, lengths):
    """The KITTI devkit's averaging, written out: for every start pose and every length L the
    segment ends at the first pose whose path length along the ground truth from the start is
    at least L; error = inv(Δest) · Δgt; every segment of every length counts once in the mean
    of |t|/L and angle/L."""
    p = ref.translations
    dist = [0.0]
    for k in range(1, len(p)):
        dist.append(dist[-1] + float(np.linalg.norm(p[k] - p[k - 1])))
    t_ratios, r_ratios = [], []
    for first in range(len(p)):
        for length in lengths:
            last = next((k for k in range(first, len(p)) if dist[k] >= dist[first] + length),
                        None)
            if last is None:
                continue
            d_gt = np.linalg.inv(_mat(ref, first)) @ _mat(ref, last)
            d_est = np.linalg.inv(_mat(est, first)) @ _mat(est, last)
            e = np.linalg.inv(d_est) @ d_gt
            t_ratios.append(np.linalg.norm(e[:3, 3]) / length)
            cos = np.clip((np.trace(e[:3, :3]) - 1) / 2, -1.0, 1.0)
            r_ratios.append(np.degrees(np.arccos(cos)) / length)
    return 100 * np.mean(t_ratios), np.mean(r_ratios), len(t_ratios)


@pytest.mark.parametrize("lengths", [DRIFT_LENGTHS, (1.0, 3.0)])
def test_kitti_style_drift_matches_a_brute_force_of_the_devkit_rule(lengths):
    ref = _wander(n=400)
    est = _drifting(ref)
    t_pct, r_deg_m, segments = _kitti_brute(est, ref, lengths)
    d = trajectory_drift(est, ref, lengths)
    assert d.lengths == tuple(lengths)
    assert d.pairs == segments > 100
    assert d.translation_percent == pytest.approx(t_pct, rel=1e-9)
    assert d.rotation_deg_per_m == pytest.approx(r_deg_m, rel=1e-6)
    # Pooled over all segments, not a mean of per-length means (the lengths have different
    # numbers of segments here).
    per_length = np.mean([r.translation_percent for r in d.segments])
    assert d.translation_percent != pytest.approx(per_length, rel=1e-6)


def test_drift_of_a_run_shorter_than_every_length_is_nan():
    ref = _wander(n=20)
    d = trajectory_drift(_drifting(ref), ref, (1000.0,))
    assert d.pairs == 0 and np.isnan(d.translation_percent)


def _line(n=101, speed=1.0, dt=0.1):
    """Straight walk along x at ``speed``, yawing at a constant rate."""
    t = T0 + np.arange(n) * dt
    pos = np.zeros((n, 3))
    pos[:, 0] = speed * (t - T0)
    rot = Rotation.from_rotvec(np.outer(t - T0, [0.0, 0.0, 0.05]))
    return Trajectory(t, pos, rot, "line")


def test_ate_and_final_error_of_a_known_error():
    ref = _line()
    n = len(ref)
    # A constant lateral offset of 0.3 m: with no alignment every error is 0.3 m; the first
    # poses put together (origin) remove it, and the end is then exact.
    off = Trajectory(ref.timestamps, ref.translations + np.array([0.0, 0.3, 0.0]), ref.rotations, "off")
    a = absolute_trajectory_error(off, ref, align="none")
    assert a.rmse == pytest.approx(0.3) and a.max == pytest.approx(0.3)
    assert a.path_length == pytest.approx(10.0)
    assert a.rmse_percent == pytest.approx(3.0)
    assert final_position_error(off, ref).error == pytest.approx(0.0, abs=1e-12)
    # A drift growing linearly with time along y, 0.02 m/s over 10 s: error k·0.02·dt at pose
    # k; origin alignment leaves it (it is 0 at the start), so the end is 0.2 m off = 2 % of
    # 10 m, and the RMSE is 0.002·sqrt(Σk²/n).
    k = np.arange(n)
    drift = Trajectory(ref.timestamps, ref.translations + np.outer(0.002 * k, [0, 1, 0]),
                       ref.rotations, "drift")
    fe = final_position_error(drift, ref)
    assert fe.error == pytest.approx(0.2) and fe.percent == pytest.approx(2.0)
    a = absolute_trajectory_error(drift, ref, align="origin")
    assert a.rmse == pytest.approx(0.002 * np.sqrt(np.sum(k * k) / n))
    # A rigid transform of the truth (any frame a user's method may start in) has no error
    # after se3 or origin alignment.
    g = Rotation.from_euler("zyx", [40, -10, 5], degrees=True)
    moved = Trajectory(ref.timestamps, g.apply(np.array(ref.translations)) + np.array([5, -2, 1.0]),
                       g * ref.rotations, "moved")
    for align in ("se3", "origin"):
        res = absolute_trajectory_error(moved, ref, align=align)
        assert res.rmse < 1e-9 and res.rotation_rmse < 1e-6
    assert final_position_error(moved, ref).error < 1e-9


def test_origin_alignment_reads_the_read_only_trajectory_arrays():
    # Trajectory arrays are read-only; SciPy's Rotation.apply used to refuse the first
    # position as a read-only buffer (coloradar evaluate --align origin crashed).
    ref = _line()
    est = Trajectory(ref.timestamps, ref.translations + 0.1, ref.rotations, "est")
    assert not est.translations.flags.writeable
    res = absolute_trajectory_error(est, ref, align="origin")
    assert res.rmse == pytest.approx(0.0, abs=1e-12)


def test_evaluation_writes_the_ground_truth_at_the_estimates_timestamps(tmp_path):
    # Ground truth at 10 Hz, linear motion and constant yaw rate: its value between samples is
    # known in closed form. The estimate (radar frames) lies between the ground-truth samples,
    # and starts before it.
    ref = _line(n=101, speed=0.8)
    te = T0 - 0.3 + 0.0731 + np.arange(130) * 0.0777
    true = np.zeros((te.size, 3))
    true[:, 0] = 0.8 * (te - T0)
    est = Trajectory(te, true + np.array([0.0, 0.05, 0.0]),
                     Rotation.from_rotvec(np.outer(te - T0, [0, 0, 0.05])), "est")
    ev = evaluate_trajectory(est, ref, distances=(1.0,))
    write_evaluation(ev, tmp_path, plot=False)
    gt = read_tum(tmp_path / "groundtruth.txt")
    inside = (te >= T0) & (te <= ref.end)
    np.testing.assert_array_equal(gt.timestamps, te[inside])
    np.testing.assert_allclose(gt.translations, true[inside], atol=1e-9)
    yaw = gt.rotations.as_rotvec()[:, 2]
    np.testing.assert_allclose(yaw, 0.05 * (te[inside] - T0), atol=1e-9)
    # Timestamps written as the estimate's own file writes them: evo matches every pose.
    from coloradar.odometry import write_tum
    write_tum(tmp_path / "trajectory.txt", est)
    stamps = [ln.split()[0] for ln in (tmp_path / "trajectory.txt").read_text().splitlines()
              if not ln.startswith("#")]
    gt_stamps = [ln.split()[0] for ln in (tmp_path / "groundtruth.txt").read_text().splitlines()
                 if not ln.startswith("#")]
    assert set(gt_stamps) <= set(stamps) and len(gt_stamps) == int(inside.sum())
