"""Ego-velocity RANSAC and gyro integration: coloradar against plain-loop baselines, in one run.

    python benchmarks/bench_odometry.py [--repeat 5] [--sim SECONDS]

Prints, side by side and measured in the same process:

- milliseconds per cloud of :func:`coloradar.odometry.estimate_ego_velocity` (all hypotheses
  scored by one matrix product) and of a textbook RANSAC that scores each hypothesis in a
  Python loop (same 256 hypotheses, same MSAC cost, same final least squares), for clouds of
  50 to 5000 points with half of them on a moving object;
- milliseconds to integrate 30 s of 300 Hz gyro samples with the prefix scan of
  :func:`coloradar.odometry.integrate_gyro` and with a sequential loop of Rotation products;
- with ``--sim S``: accuracy on a simulated S-second corridor run (ego-velocity RMSE of the
  single chip's point clouds and the cascade's processed ADC, ATE of the radar+IMU baseline).
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sim", type=float, metavar="SECONDS",
                    help="also measure accuracy on a simulated run of this length")
    args = ap.parse_args()
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
    if args.sim:
        _sim_accuracy(args.sim)


if __name__ == "__main__":
    main()
