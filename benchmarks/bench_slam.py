"""Radar SLAM: speed (times real time) and memory against run length, beside its front end.

    nice python benchmarks/bench_slam.py [--minutes 2 5 10] [--scene corridor]
                                         [--cache /tmp/coloradar_bench_slam]

For single-chip runs of each length (simulated at the point-cloud level and cached), each in a
fresh subprocess (so that one length's memory does not carry into the next):

- seconds of data per second of computing of :func:`coloradar.slam.slam_from_clouds` (the
  issue's goal: at least 10x real time for the single chip on a 2-core machine), beside the
  front end alone (ego-velocities and the radar-inertial filter, what ``coloradar odometry``
  computes) on the same clouds;
- **peak RSS** of the SLAM call: the process's high-water mark of resident memory during the
  call (``VmHWM``, reset through ``/proc/self/clear_refs`` just before) less the resident
  memory before it; the run's clouds and IMU, loaded before, are the caller's;
- the **peak of traced allocations** (``tracemalloc``, a second pass) per stage of the call:
  ego-velocities (static points go to disk), the filter (:func:`coloradar.odometry.rio_odometry`
  with ``keep``: its state kept at the keyframes only), submaps, scale, loops, graph, map;
- for comparison, the filter as ``coloradar odometry`` runs it (every pose's state kept):
  what its **result** (``RioResult``) holds when it returns (traced memory it keeps, also per
  frame) and its traced peak.

Flat in run length means the figures grow by little from 2 to 10 minutes; the script prints
the growth per minute of each.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np

from coloradar.odometry import ego_velocity_config, rio_odometry
from coloradar.sim.point_runs import simulate_point_run
from coloradar.slam import slam_from_clouds
from coloradar.slam.frontend import estimate_track

STAGES = ("ego_velocity", "filter", "submaps", "scale", "loops", "graph", "map")


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


def _track(r):
    return estimate_track(r.clouds, r.timestamps, ego_velocity_config(r.calib.single_chip),
                          frame=r.radar)


def _filter(r, track, still):
    """The filter as ``coloradar odometry`` and SLAM's front end run it (every point updates
    it; the clouds in memory here, the caller's)."""
    return rio_odometry(track, r.calib, r.imu_timestamps, r.imu_data, radars=(r.radar,),
                        initial_pose=r.groundtruth, still=[still], points=[r.clouds])


def _status_kb(field: str) -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise RuntimeError(f"no {field} in /proc/self/status")


def _peak_rss_mb(fn, r) -> float:
    """Peak resident memory added by ``fn(r)`` [MB] (Linux: VmHWM reset before the call)."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    before = _status_kb("VmRSS")
    fn(r)
    return (_status_kb("VmHWM") - before) / 1024


def child(cache: Path, scene: str, minutes: float) -> dict:
    """One length's figures (run in a fresh process)."""
    warnings.simplefilter("ignore")
    r = _run(cache, scene, minutes)
    dur = float(r.timestamps[-1] - r.timestamps[0])
    out: dict = {"minutes": minutes, "frames": len(r.clouds), "duration": dur}
    t = time.perf_counter()
    res = _slam(r)
    out["slam_s"] = time.perf_counter() - t
    out["keyframes"] = int(res.keyframes.size)
    del res
    t = time.perf_counter()
    _filter(r, *_track(r))
    out["frontend_s"] = time.perf_counter() - t
    out["rss_mb"] = _peak_rss_mb(_slam, r)
    tracemalloc.start()
    try:
        res = _slam(r)
        out["stage_peak_mb"] = {k: res.timings[f"peak_mb_{k}"] for k in STAGES}
        out["kept_mb"] = tracemalloc.get_traced_memory()[0] / 2**20
        del res
        track, still = _track(r)
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        rio = _filter(r, track, still)
        cur, peak = tracemalloc.get_traced_memory()
        out["filter_result_mb"] = (cur - base) / 2**20
        out["filter_peak_mb"] = (peak - base) / 2**20
        out["filter_frames"] = len(rio.trajectory)
    finally:
        tracemalloc.stop()
    return out


def _growth(rows: list[dict], value) -> float:
    """Growth per minute [MB/min] of ``value(row)`` from the shortest to the longest run."""
    a, b = rows[0], rows[-1]
    return (value(b) - value(a)) / max(b["minutes"] - a["minutes"], 1e-9)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[2.0, 5.0, 10.0])
    ap.add_argument("--scene", default="corridor")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/coloradar_bench_slam"))
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    if args.child:
        print(json.dumps(child(args.cache, args.scene, args.minutes[0])))
        return
    print(f"single chip, scene {args.scene}, {os.cpu_count()} CPUs, load average "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    print("run     frames  keyframes  SLAM [s]  x real time | front end [s]  x real time | "
          "peak RSS SLAM [MB] | traced peak per stage [MB]: " + " ".join(STAGES)
          + " | filter: result, peak [MB]")
    rows = []
    for m in args.minutes:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
        cmd = [sys.executable, __file__, "--child", "--minutes", str(m), "--scene", args.scene,
               "--cache", str(args.cache)]
        r = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True,
                                      env=env).stdout.strip().splitlines()[-1])
        rows.append(r)
        st = " ".join(f"{r['stage_peak_mb'][k]:.1f}" for k in STAGES)
        print(f"{m:4.0f} min {r['frames']:6d}  {r['keyframes']:9d}  {r['slam_s']:8.1f}  "
              f"{r['duration'] / r['slam_s']:11.1f} | {r['frontend_s']:13.1f}  "
              f"{r['duration'] / r['frontend_s']:11.1f} | {r['rss_mb']:18.1f} | {st} | "
              f"{r['filter_result_mb']:.1f}, {r['filter_peak_mb']:.1f}", flush=True)
    if len(rows) > 1:
        fr = rows[-1]["filter_frames"]
        print(f"growth per minute: peak RSS {_growth(rows, lambda r: r['rss_mb']):+.2f} MB; "
              "traced peak of the stages after the filter "
              f"{_growth(rows, lambda r: max(r['stage_peak_mb'][k] for k in STAGES[2:])):+.2f} "
              f"MB; filter's result {_growth(rows, lambda r: r['filter_result_mb']):+.2f} MB "
              f"({rows[-1]['filter_result_mb'] * 2**20 / fr:.0f} bytes a frame), filter's peak "
              f"{_growth(rows, lambda r: r['filter_peak_mb']):+.2f} MB; "
              f"ego-velocity stage {_growth(rows, lambda r: r['stage_peak_mb']['ego_velocity']):+.2f} MB")
    print(f"load average at the end {' '.join(f'{x:.1f}' for x in os.getloadavg())}; "
          f"{np.mean([r['frames'] / r['duration'] for r in rows]):.1f} frames a second")


if __name__ == "__main__":
    main()
