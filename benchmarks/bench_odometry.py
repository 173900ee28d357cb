"""Ego-velocity RANSAC, gyro integration and the radar-inertial EKF: speed and accuracy.

    python benchmarks/bench_odometry.py [--repeat 5] [--ekf-only] [--sim SECONDS]
                                        [--rio-runs RUN ...]

Prints, side by side and measured in the same process:

- milliseconds per cloud of :func:`coloradar.odometry.estimate_ego_velocity` (all hypotheses
  scored by one matrix product) and of a textbook RANSAC that scores each hypothesis in a
  Python loop (same 256 hypotheses, same MSAC cost, same final least squares), for clouds of
  50 to 5000 points with half of them on a moving object;
- milliseconds to integrate 30 s of 300 Hz gyro samples with the prefix scan of
  :func:`coloradar.odometry.integrate_gyro` and with a sequential loop of Rotation products;
- the radar-inertial EKF (:func:`coloradar.odometry.rio_odometry`) on 60 s of synthetic
  300 Hz IMU and 10 Hz radar frames: seconds of data per second of computing, with the
  Doppler-point update (single chip alone, 10-40 points a frame; both radars, the cascade
  40-120; issue 25's goals: at least 50x and 30x real time) beside the ego-velocity update
  (the loosely coupled filter) and dead reckoning on the same data (``--ekf-only``: this
  part alone);
- with ``--sim S``: accuracy on a simulated S-second corridor run (ego-velocity RMSE of the
  single chip's point clouds and the cascade's processed ADC, ATE of the radar+IMU baseline);
- with ``--rio-runs RUN ...``: on simulated runs (``coloradar simulate ... --rest 2
  --radar-time-offset 0.025``), the EKF (cascade, single chip, both fused) against dead
  reckoning: final-position error and ATE (SE(3)-aligned RMSE) as % of the distance, and the
  recovered time offset against the truth.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from coloradar.odometry import EgoVelocityConfig, estimate_ego_velocity, integrate_gyro


def _cloud(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    v = np.array([0.9, 0.1, 0.02])
    m = n // 2
    az, el = rng.uniform(-1.2, 1.2, m), rng.uniform(-0.35, 0.35, m)
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
    ps = d * rng.uniform(1, 15, (m, 1))
    vr_s = -d @ v + rng.normal(scale=0.03, size=m)
    po = np.array([3.0, 0.5, 0.0]) + rng.normal(scale=[0.15, 0.15, 0.4], size=(n - m, 3))
    do = po / np.linalg.norm(po, axis=1, keepdims=True)
    vr_o = do @ (np.array([-1.2, 0.0, 0.0]) - v)
    return np.concatenate([ps, po]), np.concatenate([vr_s, vr_o])


def _loop_ransac(pts: np.ndarray, vr: np.ndarray, cfg: EgoVelocityConfig,
                 rng: np.random.Generator) -> np.ndarray:
    """The baseline: one hypothesis at a time, each scored over all points."""
    d = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    best, best_cost = None, np.inf
    thr2 = cfg.threshold**2
    for _ in range(cfg.hypotheses):
        idx = rng.choice(len(d), 3, replace=False)
        try:
            v = np.linalg.solve(-d[idx], vr[idx])
        except np.linalg.LinAlgError:
            continue
        res = d @ v + vr
        cost = np.minimum(res * res, thr2).sum()
        if cost < best_cost:
            best, best_cost = v, cost
    inl = np.abs(d @ best + vr) < cfg.threshold
    return np.linalg.lstsq(-d[inl], vr[inl], rcond=None)[0]


def _best_ms(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3


def _sequential_gyro(t: np.ndarray, w: np.ndarray) -> Rotation:
    steps = Rotation.from_rotvec(0.5 * (w[1:] + w[:-1]) * np.diff(t)[:, None])
    out = [Rotation.identity()]
    for k in range(len(steps)):
        out.append(out[-1] * steps[k])
    return Rotation.concatenate(out)


def _sim_accuracy(seconds: float) -> None:
    from coloradar import open_sequence
    from coloradar.geometry import trajectory_from_groundtruth
    from coloradar.odometry import (
        absolute_trajectory_error,
        radar_inertial_odometry,
        run_ego_velocity,
    )
    from coloradar.sim.run import simulate_run
    from coloradar.sim.truth import load_truth

    print(f"\naccuracy on a simulated {seconds:g} s corridor run (seed 3)")
    print(f"{'radar / source':<26} {'frames ok':>10} {'vel RMSE':>9} {'x':>7} {'y':>7} {'z':>7} "
          f"{'ms/frame':>9} {'ATE imu':>14} {'ATE gt-att':>14}")
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate_run(tmp, duration=seconds, seed=3, heatmaps=False,
                           sensors=("cascade", "single_chip", "imu", "groundtruth"))
        seq = open_sequence(res.run_path)
        truth = load_truth(res.run_path)
        gt = trajectory_from_groundtruth(seq)
        for radar, source in (("single_chip", "pointclouds"), ("single_chip", "adc"),
                              ("cascade", "adc")):
            t0 = time.perf_counter()
            track = run_ego_velocity(seq, radar, source)
            ms = (time.perf_counter() - t0) / len(track) * 1e3
            ok = track.ok
            e = track.velocity[ok] - truth.radar_velocity(radar)[ok]
            ax = np.sqrt(np.mean(e**2, axis=0))
            ates = []
            for att in ("imu", "groundtruth"):
                est = radar_inertial_odometry(track, seq.calib, orientation=att,
                                              imu_timestamps=seq.imu.timestamps,
                                              imu_rates=seq.imu.angular_rates, groundtruth=gt)
                a = absolute_trajectory_error(est, gt)
                ates.append(f"{a.rmse:.3f} m {a.rmse_percent:.2f}%")
            print(f"{radar + ' / ' + source:<26} {f'{ok.sum()}/{len(ok)}':>10} "
                  f"{np.sqrt(np.sum(ax**2)):>9.3f} {ax[0]:>7.3f} {ax[1]:>7.3f} {ax[2]:>7.3f} "
                  f"{ms:>9.1f} {ates[0]:>14} {ates[1]:>14}")
        print(f"distance travelled {a.path_length:.1f} m")


def _ekf_speed(repeat: int) -> None:
    from coloradar.calib import preset_calibration
    from coloradar.odometry import EgoVelocityTrack, radar_inertial_odometry, rio_odometry
    from coloradar.sim.imu import GX5_25, simulate_imu
    from coloradar.sim.paths import EllipsePath
    from coloradar.sim.trajectory import make_trajectory

    calib = preset_calibration()
    seconds = 60.0
    traj = make_trajectory(EllipsePath(np.array([0.0, 0.0, 1.0]), (8.0, 4.0), 1.5, ramp=0.5),
                           "handheld", 0)
    rng = np.random.default_rng(0)
    imu_t = np.arange(0.0, seconds, 1 / 300)
    imu, *_ = simulate_imu(traj, calib.transforms["imu"].matrix(), imu_t, GX5_25, rng)
    from coloradar.odometry import RioConfig
    from coloradar.sim.doppler_clouds import CloudModel, simulate_clouds

    tracks, clouds = [], []
    models = {"cascade": CloudModel(points=(40, 120), azimuth_std=np.radians(1.0),
                                    elevation_std=np.radians(1.6)),
              "single_chip": CloudModel(points=(10, 40), max_velocity=2.45)}
    for radar in ("cascade", "single_chip"):
        tr = np.arange(0.05, seconds - 0.1, 0.1)
        st = traj.state(tr)
        b_T_r = calib.transforms[radar].matrix()
        vb = st.rotation.inv().apply(st.velocity) + np.cross(st.angular_velocity, b_T_r[:3, 3])
        v = vb @ b_T_r[:3, :3] + rng.normal(0, 0.03, vb.shape)
        m = tr.size
        tracks.append(EgoVelocityTrack(tr, v, np.tile(np.eye(3) * 0.03**2, (m, 1, 1)),
                                       np.full(m, 50), np.full(m, 40), np.full(m, 0.03),
                                       np.ones(m, dtype=bool), frame=radar))
        clouds.append(simulate_clouds(traj, b_T_r, tr, models[radar], rng)[0])
    loose = RioConfig(update="ego-velocity")
    ekf1 = _best_ms(lambda: rio_odometry(tracks[0], calib, imu_t, imu, config=loose),
                    repeat) / 1e3
    ekf2 = _best_ms(lambda: rio_odometry(tracks, calib, imu_t, imu, config=loose), repeat) / 1e3
    # The Doppler-point filter: single chip alone (10-40 points a frame), then both radars
    # (the cascade 40-120 points a frame), every point a measurement.
    sc = [tracks[1]], [clouds[1]]
    dop1 = _best_ms(lambda: rio_odometry(sc[0], calib, imu_t, imu, points=sc[1]), repeat) / 1e3
    both = [tracks[1], tracks[0]], [clouds[1], clouds[0]]
    dop2 = _best_ms(lambda: rio_odometry(both[0], calib, imu_t, imu, points=both[1]),
                    repeat) / 1e3
    dr = _best_ms(lambda: radar_inertial_odometry(tracks[0], calib, imu_timestamps=imu_t,
                                                  imu_rates=imu[:, 3:]), repeat) / 1e3
    print(f"\nradar-inertial EKF on {seconds:g} s of 300 Hz IMU + 10 Hz radar velocities "
          f"(best of {repeat}):")
    print(f"  EKF, Doppler points, single chip  {dop1:6.3f} s = {seconds / dop1:6.0f}x real time")
    print(f"  EKF, Doppler points, both radars  {dop2:6.3f} s = {seconds / dop2:6.0f}x real time")
    print(f"  EKF, ego-velocity, one radar      {ekf1:6.3f} s = {seconds / ekf1:6.0f}x real time "
          "(the loosely coupled filter)")
    print(f"  EKF, ego-velocity, two radars     {ekf2:6.3f} s = {seconds / ekf2:6.0f}x real time")
    print(f"  dead reckoning                    {dr:6.3f} s = {seconds / dr:6.0f}x real time")


def _rio_accuracy(runs: list[str]) -> None:
    from coloradar import open_sequence
    from coloradar.geometry import trajectory_from_groundtruth
    from coloradar.odometry import (
        RioConfig,
        absolute_trajectory_error,
        path_length,
        radar_inertial_odometry,
        rio_odometry,
    )
    from coloradar.odometry.pipeline import EgoVelocityJob, _ego_velocity
    from coloradar.sim.truth import load_truth

    cfg = RioConfig()
    print("\nEKF against dead reckoning on simulated runs: final-position error and ATE "
          "(SE(3)-aligned RMSE), % of the distance")
    print(f"{'run':<16} {'dist':>6} {'vmax':>5} " + " ".join(
        f"{n:>13}" for n in ("EKF cascade", "EKF single", "EKF both (def)", "DR cascade",
                             "DR single")) + f" {'t_d est/true':>13} (cascade; single chip)")
    rows = []
    for run in runs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            seq = open_sequence(run)
            gt = trajectory_from_groundtruth(seq)
            truth = load_truth(run)
            tr = {r: _ego_velocity(seq, r, None, EgoVelocityJob(), cfg.zero_velocity)
                  for r in ("cascade", "single_chip")}
            imu = seq.imu

            def score(traj, gt=gt):
                g = gt.interpolate_arrays(traj.timestamps)[0]
                d = path_length(g)[-1]
                end = np.linalg.norm(traj.translations[-1] - g[-1])
                return d, 100 * end / d, absolute_trajectory_error(traj, gt).rmse_percent

            cells, td, td_std, td_sc, td_sc_std = [], 0.0, 0.0, 0.0, 0.0
            for radars in (["cascade"], ["single_chip"], ["cascade", "single_chip"]):
                res = rio_odometry([tr[r][0] for r in radars], seq.calib, imu.timestamps,
                                   imu.data, initial_pose=gt, config=cfg,
                                   still=[tr[r][1] for r in radars])
                cells.append(score(res.trajectory))
                if len(radars) == 2:                  # the default: the cascade's offset
                    td = float(res.time_offset[-1, 0])
                    td_std = float(res.time_offset_std[-1, 0])
                    td_sc = float(res.time_offset[-1, 1])     # and the single chip's
                    td_sc_std = float(res.time_offset_std[-1, 1])
            for r in ("cascade", "single_chip"):
                dr = radar_inertial_odometry(tr[r][0], seq.calib, imu_timestamps=imu.timestamps,
                                             imu_rates=imu.angular_rates, groundtruth=gt)
                cells.append(score(dr))
        vmax = np.linalg.norm(truth["rig_velocity_world"], axis=1).max()
        td_true = float(truth["radar_time_offset"]) if "radar_time_offset" in truth.keys() else 0
        name = Path(run).name
        print(f"{name:<16} {cells[0][0]:>6.1f} {vmax:>5.2f} " + " ".join(
            f"{c[1]:>6.2f}/{c[2]:<6.2f}" for c in cells)
            + f" {1e3 * td:>6.1f}/{1e3 * td_true:<5.1f}ms (σ {1e3 * td_std:.1f})"
            + f" single {1e3 * td_sc:.1f} (σ {1e3 * td_sc_std:.1f})", flush=True)
        rows.append([c[1:] for c in cells])
    if len(rows) > 1:
        a = np.array(rows)                           # runs x methods x (end, ate)
        print(f"{'worst':<16} {'':>6} {'':>5} " + " ".join(
            f"{a[:, j, 0].max():>6.2f}/{a[:, j, 1].max():<6.2f}" for j in range(a.shape[1])))
        print(f"{'mean':<16} {'':>6} {'':>5} " + " ".join(
            f"{a[:, j, 0].mean():>6.2f}/{a[:, j, 1].mean():<6.2f}" for j in range(a.shape[1])))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sim", type=float, metavar="SECONDS",
                    help="also measure accuracy on a simulated run of this length")
    ap.add_argument("--rio-runs", nargs="+", metavar="RUN",
                    help="simulated runs on which to compare the EKF with dead reckoning")
    ap.add_argument("--ekf-only", action="store_true",
                    help="only the filter's speed (Doppler-point and ego-velocity updates)")
    args = ap.parse_args()
    if args.rio_runs:
        _rio_accuracy(args.rio_runs)
        return
    if args.ekf_only:
        _ekf_speed(args.repeat)
        return
    cfg = EgoVelocityConfig()
    print("ego-velocity per cloud (half the points on a moving object), ms")
    print("(coloradar: default settings, up to 3 motions extracted; single: max_models=1, the "
          "same algorithm as the loop baseline)")
    print(f"{'points':>7} {'coloradar':>10} {'single':>8} {'loop RANSAC':>12} "
          f"{'single vs loop':>15} {'|v err| coloradar':>18} {'loop':>8}")
    v = np.array([0.9, 0.1, 0.02])
    single = EgoVelocityConfig(max_models=1)
    for n in (20, 50, 200, 1000, 5000):
        rng = np.random.default_rng(n)
        pts, vr = _cloud(rng, n)
        ours = _best_ms(lambda p=pts, r=vr: estimate_ego_velocity(p, r, cfg, rng=0), args.repeat)
        one = _best_ms(lambda p=pts, r=vr: estimate_ego_velocity(p, r, single, rng=0),
                       args.repeat)
        base = _best_ms(lambda p=pts, r=vr: _loop_ransac(p, r, cfg, np.random.default_rng(0)),
                        args.repeat)
        e1 = np.linalg.norm(estimate_ego_velocity(pts, vr, cfg, rng=0).velocity - v)
        e2 = np.linalg.norm(_loop_ransac(pts, vr, cfg, np.random.default_rng(0)) - v)
        print(f"{n:>7} {ours:>10.2f} {one:>8.2f} {base:>12.2f} {base / one:>14.1f}x "
              f"{e1:>18.3f} {e2:>8.3f}")

    t = np.arange(0, 30.0, 1 / 300)
    w = np.random.default_rng(0).normal(scale=0.3, size=(t.size, 3))
    ours = _best_ms(lambda: integrate_gyro(t, w), args.repeat)
    base = _best_ms(lambda: _sequential_gyro(t, w), max(1, args.repeat // 2))
    err = (integrate_gyro(t, w).inv() * _sequential_gyro(t, w)).magnitude().max()
    print(f"\ngyro integration, {t.size} samples: prefix scan {ours:.1f} ms, sequential loop "
          f"{base:.1f} ms ({base / ours:.0f}x); largest difference {err:.1e} rad")
    _ekf_speed(args.repeat)
    if args.sim:
        _sim_accuracy(args.sim)


if __name__ == "__main__":
    main()
