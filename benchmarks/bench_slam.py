"""Radar SLAM: speed (times real time) and memory against run length, beside its front end.

    nice python benchmarks/bench_slam.py [--minutes 2 5 10] [--scene corridor]
                                         [--cache /tmp/coloradar_bench_slam]

For single-chip runs of each length (simulated at the point-cloud level and cached), in one
process:

- seconds of data per second of computing of :func:`coloradar.slam.slam_from_clouds` (the
  issue's goal: at least 10x real time for the single chip on a 2-core machine), beside the
  front end alone (ego-velocities and the radar-inertial filter, what ``coloradar odometry``
  computes) on the same clouds;
- the peak of memory allocated during the call (``tracemalloc``, a second pass), for SLAM and
  for the front end: flat in run length means the peak grows by little from 2 to 10 minutes
  (the clouds themselves are the caller's; SLAM keeps each frame's static points on disk and
  one voxel summary per keyframe).
"""

from __future__ import annotations

import argparse
import os
import pickle
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np

from coloradar.odometry import ego_velocity_config
from coloradar.sim.point_runs import simulate_point_run
from coloradar.slam import slam_from_clouds
from coloradar.slam.frontend import estimate_track, radar_inertial_frontend


def _run(cache: Path, scene: str, minutes: float):
    f = cache / f"{scene}_{minutes:g}min.pkl"
    if f.is_file():
        with open(f, "rb") as fh:
            return pickle.load(fh)
    r = simulate_point_run(scene, 60.0 * minutes, 7, lidar_every=None)
    with open(f.with_suffix(".tmp"), "wb") as fh:
        pickle.dump(r, fh)
    os.replace(f.with_suffix(".tmp"), f)
    return r


def _slam(r):
    return slam_from_clouds(r.clouds, r.timestamps, r.calib, r.imu_timestamps, r.imu_data,
                            radar=r.radar, frontend=ego_velocity_config(r.calib.single_chip),
                            groundtruth=r.groundtruth)


def _frontend(r):
    track, still = estimate_track(r.clouds, r.timestamps, ego_velocity_config(r.calib.single_chip),
                                  frame=r.radar)
    return radar_inertial_frontend(track, still, r.calib, r.imu_timestamps, r.imu_data,
                                   radar=r.radar, groundtruth=r.groundtruth)


def _timed(fn, r) -> float:
    t = time.perf_counter()
    fn(r)
    return time.perf_counter() - t


def _peak(fn, r) -> float:
    tracemalloc.start()
    try:
        fn(r)
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[2.0, 5.0, 10.0])
    ap.add_argument("--scene", default="corridor")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/coloradar_bench_slam"))
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    warnings.simplefilter("ignore")
    print(f"single chip, scene {args.scene}, {os.cpu_count()} CPUs")
    print("run      frames  keyframes  SLAM [s]  x real time | front end [s]  x real time |"
          " peak MB SLAM  front end")
    for m in args.minutes:
        r = _run(args.cache, args.scene, m)
        dur = float(r.timestamps[-1] - r.timestamps[0])
        t_slam = _timed(_slam, r)
        t_fe = _timed(_frontend, r)
        res = _slam(r)
        p_slam, p_fe = _peak(_slam, r), _peak(_frontend, r)
        print(f"{m:4.0f} min  {len(r.clouds):6d}  {res.keyframes.size:9d}  {t_slam:8.1f}  "
              f"{dur / t_slam:11.1f} | {t_fe:13.1f}  {dur / t_fe:11.1f} | {p_slam:12.1f}  "
              f"{p_fe:9.1f}", flush=True)
    print(f"(clouds: {np.mean([len(c) for c in r.clouds]):.0f} points a frame on average)")


if __name__ == "__main__":
    main()
