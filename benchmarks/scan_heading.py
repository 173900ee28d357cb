"""How well scan matching gives heading: the yaw of registering two disjoint windows of frames.

    nice python benchmarks/scan_heading.py [--seeds 101 102 103] [--radars single_chip cascade]
                                           [--window 4] [--gap 4] [--cache /tmp/coloradar_mc_slam]
    nice python benchmarks/scan_heading.py --run RUN [--calib DIR]   # a dataset run's clouds

A radar-inertial filter cannot see heading (docs/odometry.md, "What limits the worst runs"); a
heading source from the radar itself would be the rotation between scans. This measures what
that rotation is worth, apart from any filter: on the Monte Carlo's point-level loop runs
(``benchmarks/mc_slam.py``'s cache; the scenes cycle over corridor, courtyard, hallway), the
static points (by the true velocity) of the frames in ``[t, t + window)`` and in ``[t + gap,
t + gap + window)`` are each placed in their first frame's base frame with the *ground-truth*
poses — so only the registration is measured, not the odometry — and registered (small_gicp
GICP, :func:`coloradar.slam.registration.register_points`) from the true relative pose turned
by 1° (σ) in yaw and shifted by 5 cm (σ). Printed per run: the pairs registered, their
points, the median fitness, and the yaw error's RMS, median |·| and 90th percentile [deg].

``--run`` measures the same on a dataset run's own single-chip clouds and ground truth (e.g.
the runs in ``../shared/foreign``, written by another program): the radar velocity that picks
the static points is then the ground truth's (:func:`coloradar.geometry.rig_velocity`).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).parent))

from coloradar.geometry import SE3, rig_velocity, trajectory_from_groundtruth
from coloradar.sim.doppler_clouds import radar_velocities
from coloradar.sim.run import DEFAULT_START_TIME
from coloradar.slam import SlamSettings
from coloradar.slam.registration import register_points
from mc_slam import SCENES, _run


def _window(run, poses: np.ndarray, y: np.ndarray, t0: float, length: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """The first frame's ``world_T_base`` and the window's static points in its base frame."""
    b_t_r = run.calib.transforms[run.radar].matrix()
    idx = np.flatnonzero((run.timestamps >= t0) & (run.timestamps < t0 + length))
    ref_inv = np.linalg.inv(poses[idx[0]])
    pts = []
    for k in idx:
        c = run.clouds[k].astype(np.float64)
        if c.shape[0] == 0:
            continue
        rng = np.linalg.norm(c[:, :3], axis=1)
        u = c[:, :3] / rng[:, None]
        keep = (np.abs(c[:, 4] + u @ y[k]) < 0.1) & (rng > 0.4) & (rng < 12.0)
        m = ref_inv @ poses[k] @ b_t_r
        pts.append(c[keep, :3] @ m[:3, :3].T + m[:3, 3])
    return poses[idx[0]], (np.concatenate(pts) if pts else np.zeros((0, 3)))


def dataset_run(path: str, calib: str | None) -> SimpleNamespace:
    """A dataset run's single-chip clouds, ground truth and true radar velocities, with the
    attributes :func:`yaw_errors` reads."""
    from coloradar.dataset import open_sequence

    seq = open_sequence(path, calib=calib)
    stream = seq.single_chip.pointclouds
    t = np.asarray(stream.timestamps, dtype=np.float64)
    gt = trajectory_from_groundtruth(seq)
    keep = (t > gt.timestamps[0] + 0.1) & (t < gt.timestamps[-1] - 0.1)
    t = t[keep]
    clouds = [stream[int(k)] for k in np.flatnonzero(keep)]
    y = rig_velocity(gt, t, calib=seq.calib, sensor="single_chip").linear   # radar frame
    return SimpleNamespace(calib=seq.calib, radar="single_chip", timestamps=t, clouds=clouds,
                           groundtruth=gt, velocities=y, name=seq.name)


def yaw_errors(run, window: float, gap: float, seed: int = 0) -> tuple[np.ndarray, list]:
    """Yaw errors [deg] of the registered pairs of one run, and (points, fitness) per pair."""
    b_t_r = run.calib.transforms[run.radar].matrix()
    y = getattr(run, "velocities", None)
    if y is None:
        y = radar_velocities(run.trajectory, b_t_r, run.timestamps - DEFAULT_START_TIME)
    poses = run.groundtruth.interpolate(run.timestamps, tolerance=1.0).matrices()
    rng = np.random.default_rng(seed)
    s = SlamSettings()
    errs, info = [], []
    t = run.timestamps
    for t0 in np.arange(t[0] + 2.0, t[-1] - gap - window, gap):
        ra, a = _window(run, poses, y, t0, window)
        rb, b = _window(run, poses, y, t0 + gap, window)
        true = np.linalg.inv(ra) @ rb
        d = np.eye(4)
        d[:3, :3] = Rotation.from_euler("z", rng.normal(0.0, 1.0), degrees=True).as_matrix()
        d[:3, 3] = rng.normal(0.0, 0.05, 3)
        reg = register_points(a, b, SE3.from_matrix(true @ d), s)
        if reg.fitness == 0:
            continue
        e = np.linalg.inv(true) @ reg.target_T_source.matrix()
        errs.append(Rotation.from_matrix(e[:3, :3]).as_euler("xyz", degrees=True)[2])
        info.append((a.shape[0], reg.fitness))
    return np.array(errs), info


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[101, 102, 103])
    ap.add_argument("--radars", nargs="+", default=["single_chip", "cascade"])
    ap.add_argument("--window", type=float, default=4.0)
    ap.add_argument("--gap", type=float, default=4.0)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/coloradar_mc_slam"))
    ap.add_argument("--run", nargs="+", help="dataset runs (folders or zips) instead")
    ap.add_argument("--calib", help="calibration folder for --run")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    if args.run:
        print(f"windows of {args.window} s, {args.gap} s apart; yaw error of the registration [deg]")
        for path in args.run:
            run = dataset_run(path, args.calib)
            _report(run.name, *yaw_errors(run, args.window, args.gap))
        return
    args.cache.mkdir(parents=True, exist_ok=True)
    print(f"windows of {args.window} s, {args.gap} s apart; yaw error of the registration [deg]")
    for radar in args.radars:
        for n, seed in enumerate(args.seeds):
            scene = SCENES[n % len(SCENES)]
            e, info = yaw_errors(_run(args.cache, scene, seed, 2.0, radar), args.window, args.gap)
            _report(f"{radar:12s} {scene:10s} {seed:5d}", e, info)


def _report(label: str, e: np.ndarray, info: list) -> None:
    """One line: the pairs registered, their median points and fitness, the yaw errors."""
    if e.size == 0:
        print(f"{label}: no pair registered")
        return
    pts, fit = np.median([i[0] for i in info]), np.median([i[1] for i in info])
    print(f"{label}: {e.size:3d} pairs, {pts:5.0f} points, fitness {fit:.2f}; RMS "
          f"{np.sqrt(np.mean(e**2)):6.2f}, median |.| {np.median(np.abs(e)):5.2f}, 90th "
          f"percentile {np.percentile(np.abs(e), 90):5.2f}", flush=True)


if __name__ == "__main__":
    main()
