"""The RIO literature's evaluation protocol (rpg_trajectory_evaluation, Zhang & Scaramuzza, IROS
2018): position + yaw alignment checked against a brute-force search over yaw, and the relative
error over travelled distances against a loop written from rpg's rule and against the closed
form of estimates with a known scale or heading-rate error."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from coloradar.geometry import Trajectory
from coloradar.odometry import absolute_trajectory_error, evaluate_trajectory
from coloradar.odometry.alignment import posyaw_alignment
from coloradar.odometry.benchmark import CSV_COLUMNS, _pooled_re
from coloradar.odometry.evaluation import evaluation_dict, format_evaluation
from coloradar.odometry.metrics import RPG_LENGTHS, rpg_relative_error

T0 = 1_608_580_000.0


def _heaving_walk(n=400, seed=5):
    """A walk that turns, rises and falls (z ±0.5 m) with a rolling, pitching attitude."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    yaw = np.cumsum(rng.normal(scale=0.05, size=n))
    p = np.cumsum(np.column_stack([0.1 * np.cos(yaw), 0.1 * np.sin(yaw), np.zeros(n)]), axis=0)
    p[:, 2] = 0.5 * np.sin(2 * np.pi * 0.04 * t)
    rot = Rotation.from_euler("ZYX", np.column_stack([yaw, 0.05 * np.sin(t), 0.04 * np.cos(t)]))
    return Trajectory(T0 + t, p, rot, "reference")


def _moved(tr, rot, shift, noise=0.0, seed=1):
    rng = np.random.default_rng(seed)
    p = rot.apply(np.array(tr.translations)) + shift + rng.normal(scale=noise, size=(len(tr), 3))
    return Trajectory(tr.timestamps, p, rot * tr.rotations, "estimate")


def _brute_posyaw_cost(x, y):
    """min over yaw of Σ|y − R_z(θ)x − t|² with the best t (the centroid difference) for each
    θ: a 0.1° grid, then a 0.0005° grid around its best; returns (θ [rad], RMSE [m])."""
    xc, yc = x - x.mean(axis=0), y - y.mean(axis=0)

    def costs(thetas):
        r = Rotation.from_euler("z", thetas[:, None]).as_matrix()           # (K, 3, 3)
        moved = np.einsum("kab,nb->kna", r, xc)
        return np.sum((yc[None] - moved) ** 2, axis=(1, 2))

    coarse = np.radians(np.arange(-180.0, 180.0, 0.1))
    best = coarse[np.argmin(costs(coarse))]
    fine = best + np.radians(np.arange(-0.1, 0.1, 0.0005))
    c = costs(fine)
    return fine[np.argmin(c)], float(np.sqrt(c.min() / len(x)))


def test_posyaw_recovers_a_known_yaw_and_translation_and_never_rolls():
    ref = _heaving_walk()
    g = Rotation.from_euler("z", 123.0, degrees=True)
    est = _moved(ref, g, [4.0, -2.0, 0.7], noise=0.02)
    al = posyaw_alignment(est.translations, ref.translations)
    # Maps the estimate back: the inverse of the applied transform, to the noise's precision.
    inv = g.inv()
    assert np.degrees((al.rotation * g).magnitude()) < 0.2
    np.testing.assert_allclose(al.translation, -inv.apply([4.0, -2.0, 0.7]), atol=0.02)
    assert al.scale == 1.0
    m = al.rotation.as_matrix()
    assert m[2, 2] == pytest.approx(1.0, abs=1e-15) and np.allclose(m[2, :2], 0, atol=1e-15)
    # The same minimum as a brute-force search over yaw.
    theta, rmse = _brute_posyaw_cost(np.array(est.translations), np.array(ref.translations))
    assert al.rotation.as_rotvec()[2] == pytest.approx(theta, abs=np.radians(0.001))
    ate = absolute_trajectory_error(est, ref, align="posyaw")
    assert ate.rmse == pytest.approx(rmse, rel=1e-5)
    assert ate.rmse < 0.05


def test_posyaw_cannot_undo_a_tilt_that_se3_removes():
    # A world rolled by 3° (a wrong gravity direction): SE(3) aligns it away, position + yaw
    # alignment must not; its ATE is the brute-force minimum over yaw and translation.
    ref = _heaving_walk()
    est = _moved(ref, Rotation.from_euler("x", 3.0, degrees=True), [1.0, 2.0, 3.0])
    se3 = absolute_trajectory_error(est, ref, align="se3")
    posyaw = absolute_trajectory_error(est, ref, align="posyaw")
    assert se3.rmse < 1e-9
    _, rmse = _brute_posyaw_cost(np.array(est.translations), np.array(ref.translations))
    assert posyaw.rmse == pytest.approx(rmse, rel=1e-6) and posyaw.rmse > 0.05
    rv = posyaw.alignment.rotation.as_rotvec()
    assert abs(rv[0]) < 1e-15 and abs(rv[1]) < 1e-15
    # The attitude error after the alignment: the roll (and the small yaw the fit chose), the
    # same at every pose.
    tilt = (posyaw.alignment.rotation * Rotation.from_euler("x", 3.0, degrees=True)).magnitude()
    assert np.degrees(tilt) >= 3.0
    np.testing.assert_allclose(posyaw.rotation_errors, np.degrees(tilt), rtol=1e-9)


def _brute_rpg(ref, est, d):
    """rpg_trajectory_evaluation's rule, as a loop: for every pose i, scan j = i, i+1, …
    along the reference's accumulated distance and keep the j whose distance from i is
    nearest d when strictly within 0.2·d (earliest on a tie); fewer than two pairs: none.
    Errors of T_err = (gt_i⁻¹ gt_j)⁻¹ (es_i⁻¹ es_j) seen in world axes through es_j's
    rotation: |t| / d [%] and |yaw| of its z-y-x Euler angles [deg]."""
    p = np.array(ref.translations)
    acc = [0.0]
    for k in range(1, len(p)):
        acc.append(acc[-1] + float(np.linalg.norm(p[k] - p[k - 1])))
    pairs = []
    for i in range(len(p)):
        best, err = -1, 0.2 * d
        for j in range(i, len(p)):
            if abs(acc[j] - (acc[i] + d)) < err:
                best, err = j, abs(acc[j] - (acc[i] + d))
        if best != -1:
            pairs.append((i, best))
    if len(pairs) < 2:
        return [], np.zeros(0), np.zeros(0)

    def mat(tr, k):
        m = np.eye(4)
        m[:3, :3] = tr.rotations[k].as_matrix()
        m[:3, 3] = tr.translations[k]
        return m

    pct, yaw = [], []
    for i, j in pairs:
        e = np.linalg.inv(np.linalg.inv(mat(ref, i)) @ mat(ref, j)) @ (
            np.linalg.inv(mat(est, i)) @ mat(est, j))
        r2 = np.eye(4)
        r2[:3, :3] = mat(est, j)[:3, :3]
        w = r2 @ e @ r2.T
        pct.append(100 * np.linalg.norm(w[:3, 3]) / d)
        yaw.append(abs(Rotation.from_matrix(w[:3, :3]).as_euler("ZYX", degrees=True)[0]))
    return pairs, np.array(pct), np.array(yaw)


def test_relative_error_matches_a_loop_of_rpgs_rule():
    ref = _heaving_walk(300)       # about 30 m
    rng = np.random.default_rng(2)
    n = len(ref)
    est = Trajectory(ref.timestamps, ref.translations + np.cumsum(
        rng.normal(scale=0.01, size=(n, 3)), axis=0),
        Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.003, size=(n, 3)), axis=0))
        * ref.rotations, "estimate")
    lengths = (5.0, 12.5, 20.0, 40.0)
    for d, res in zip(lengths, rpg_relative_error(est, ref, lengths), strict=True):
        pairs, pct, yaw = _brute_rpg(ref, est, d)
        got = list(zip(np.searchsorted(ref.timestamps, res.start_times),
                       np.searchsorted(ref.timestamps, res.end_times), strict=True))
        assert got == pairs and res.pairing == "rpg"
        st = res.statistics()
        if not pairs:          # 40 m on a 30 m walk: n/a
            assert d == 40.0 and res.pairs == 0 and np.isnan(st["translation_percent"]["mean"])
            continue
        assert np.all(yaw > 0)
        np.testing.assert_allclose(100 * res.translation_errors / d, pct, rtol=1e-9)
        np.testing.assert_allclose(res.yaw_errors, yaw, rtol=1e-6, atol=1e-9)
        assert st["translation_percent"]["mean"] == pytest.approx(pct.mean(), rel=1e-9)
        assert st["yaw_deg"]["median"] == pytest.approx(np.median(yaw), rel=1e-6)
        assert st["yaw_deg"]["rmse"] == pytest.approx(np.sqrt(np.mean(yaw ** 2)), rel=1e-6)


def _straight(length, step=0.12, speed=1.0):
    n = round(length / step) + 1
    p = np.zeros((n, 3))
    p[:, 0] = step * np.arange(n)
    return Trajectory(T0 + p[:, 0] / speed, p, Rotation.identity(n), "reference")


def test_relative_error_of_a_known_scale_and_heading_rate_error():
    ref = _straight(60.0)          # 501 poses 0.12 m apart, 1 m/s
    t = 0.12 * np.arange(len(ref))

    def lengths_of(r):
        return 0.12 * (np.searchsorted(ref.timestamps, r.end_times)
                       - np.searchsorted(ref.timestamps, r.start_times))

    # 1 % too long: every segment's error is 1 % of its length (a segment near the end may be
    # up to 20 % shorter than d, rpg's tolerance: the % is of d).
    scaled = Trajectory(ref.timestamps, 1.01 * np.array(ref.translations), ref.rotations, "s")
    res = rpg_relative_error(scaled, ref, (25.0, 50.0, 75.0, 100.0))
    r25 = res[0]
    lengths = lengths_of(r25)
    # Starts up to 35 m reach about 25 m (24.96 m, the nearest pose); later starts up to
    # 39.96 m (less than 5 m short) end at the last pose.
    assert r25.pairs == 334 and lengths.min() == pytest.approx(20.04, abs=1e-9)
    assert lengths.max() == pytest.approx(24.96, abs=1e-9)
    np.testing.assert_allclose(100 * r25.translation_errors / 25.0, 1.0 * lengths / 25.0,
                               rtol=1e-9)
    np.testing.assert_allclose(r25.yaw_errors, 0.0, atol=1e-12)
    # 50 m: starts up to 19.92 m; 75 m and 100 m: none on 60 m (n/a).
    assert res[1].pairs == 167 and [r.pairs for r in res[2:]] == [0, 0]
    # A heading that drifts at 0.5°/s: the estimate walks an arc; over a segment of length L
    # (time L at 1 m/s) the yaw error is 0.5·L degrees and the position error the gap between
    # the arc's chord and the straight segment.
    w = np.radians(0.5)
    arc = np.column_stack([np.sin(w * t) / w, (1 - np.cos(w * t)) / w, np.zeros_like(t)])
    turning = Trajectory(ref.timestamps, arc, Rotation.from_euler("z", w * t[:, None]), "turning")
    (r,) = rpg_relative_error(turning, ref, (25.0,))
    dt = lengths_of(r)
    np.testing.assert_allclose(r.yaw_errors, 0.5 * dt, rtol=1e-9)
    phi = w * dt
    gap = np.hypot(np.sin(phi) / w - dt, (1 - np.cos(phi)) / w)
    np.testing.assert_allclose(r.translation_errors, gap, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(r.rotation_errors, 0.5 * dt, rtol=1e-9)


def test_evaluate_reports_posyaw_and_the_relative_error_table():
    ref = _straight(60.0)
    est = _moved(ref, Rotation.from_euler("z", 30.0, degrees=True), [1.0, 2.0, 0.0])
    est = Trajectory(est.timestamps, 1.01 * np.array(est.translations), est.rotations, "e")
    ev = evaluate_trajectory(est, ref, distances=(1.0,))
    assert ev.ate_posyaw is not None and ev.rpg_relative is not None
    assert [r.distance for r in ev.rpg_relative] == list(RPG_LENGTHS)
    text = format_evaluation(ev)
    assert "ATE RMSE (posyaw)" in text
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.lstrip().startswith("RE (rpg) over"))
    assert lines[k].split()[3:] == ["pairs", "trans", "mean", "[%]", "median", "RMSE", "yaw",
                                    "mean", "[deg]", "median", "RMSE"]
    row25, row75 = lines[k + 1].split(), lines[k + 3].split()
    assert row25[:3] == ["25", "m", "334"] and row75 == ["75", "m", "0"] + ["n/a"] * 6
    assert float(row25[3]) == pytest.approx(
        np.mean(100 * ev.rpg_relative[0].translation_errors / 25.0), abs=0.006)
    d = evaluation_dict(ev)
    assert d["ate_posyaw"]["align"] == "posyaw" and d["ate"]["align"] == "se3"
    assert d["info"]["rpg_lengths"] == [25.0, 50.0, 75.0, 100.0]
    e25, e100 = d["rpg_relative"][0], d["rpg_relative"][3]
    assert e25["pairs"] == 334 and e25["yaw_deg_max"] < 1e-9
    assert e100["pairs"] == 0 and e100["translation_percent_mean"] is None
    # A run shorter than every length: one line says so.
    short = _straight(12.0)
    text = format_evaluation(evaluate_trajectory(short, short, distances=(1.0,)))
    assert "RE (rpg) over 25, 50, 75, 100 m: n/a (no pose pairs on 12.0 m of path)" in text
    # With --align posyaw the main ATE is the posyaw one, not printed twice.
    ev2 = evaluate_trajectory(est, ref, align="posyaw", distances=(1.0,))
    assert ev2.ate_posyaw is ev2.ate and format_evaluation(ev2).count("(posyaw") == 1


def test_benchmark_columns_keep_their_order_and_pool_segments():
    old = ("run", "method", "status", "ate_rmse_m", "ate_rmse_percent", "final_error_m",
           "final_error_percent", "drift_percent", "rotation_drift_deg_per_m",
           "ego_velocity_rmse_m_s", "frames_per_s", "real_time_factor", "poses",
           "path_length_m", "estimator_s", "nees_position", "nees_attitude", "error")
    assert CSV_COLUMNS[:len(old)] == old
    assert {"ate_posyaw_m", "ate_posyaw_percent", "re25_percent", "re100_yaw_deg"} \
        <= set(CSV_COLUMNS)
    # rpg pools the errors of all runs: a mean over segments, not over runs.
    rows = [{"rpg_relative": [{"distance_m": 25.0, "pairs": 3, "translation_percent_mean": 1.0,
                               "yaw_deg_mean": 2.0}]},
            {"rpg_relative": [{"distance_m": 25.0, "pairs": 1, "translation_percent_mean": 5.0,
                               "yaw_deg_mean": 6.0},
                              {"distance_m": 50.0, "pairs": 0, "translation_percent_mean": None,
                               "yaw_deg_mean": None}]},
            {}]                                   # a row of an older benchmark
    pooled = _pooled_re(rows)
    assert pooled["re25_percent"] == pytest.approx(2.0) and pooled["re25_yaw_deg"] == 3.0
    assert pooled["re50_percent"] is None and pooled["re100_yaw_deg"] is None
