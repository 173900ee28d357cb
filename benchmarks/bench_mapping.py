"""Speed and memory of occupancy mapping (``coloradar.mapping``), beside today's point map.

    nice python benchmarks/bench_mapping.py [--cache /tmp/coloradar_mc_mapping] [--minutes 10]

Uses the runs ``benchmarks/mc_mapping.py`` caches (run it first: a 2-lap single-chip corridor
walk of seed 1000 and a 12 s full corridor run of seed 1000). In one process (numpy is
single-threaded here), CPU time:

- **single chip, point clouds** (the walk's clouds with 2°/4° direction noise and 10 % ghosts,
  ground-truth poses): the occupancy map against :func:`coloradar.geometry.accumulate_clouds`
  (today's point map, voxel down-sampled at the same voxel), in × real time;
- **cascade, heatmaps** (read from the run's files, ground truth): the occupancy map against
  today's point map of the cascade (``coloradar map --sensor cascade``: points from ADC);
- **memory over a long run of a bounded area**: the walk's frames (and the cascade's
  heatmaps) fed again and again along their own poses for ``--minutes`` of data; the map's
  bytes and voxels are printed every minute of data (flat once the area is covered), with
  the process's peak RSS.
"""

from __future__ import annotations

import argparse
import pickle
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import coloradar as cr
from coloradar.geometry import accumulate_clouds, build_map, trajectory_from_groundtruth
from coloradar.geometry.se3 import SE3
from coloradar.mapping import (
    OccupancyJob,
    OccupancyMap,
    OccupancySettings,
    build_occupancy_map,
    frame_evidence,
    radar_sensor_model,
)
from coloradar.mapping.build import _stream
from mc_mapping import degrade


def _cpu() -> float:
    return time.process_time()


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def single_chip(cache: Path, minutes: float) -> None:
    run = pickle.load(open(cache / "corridor_1000_2.0_single_chip.pkl", "rb"))
    clouds = degrade(run.clouds, 1000)
    m = run.groundtruth.interpolate(run.timestamps, tolerance=1.0).matrices() @ \
        run.calib.transforms["single_chip"].matrix()
    s = OccupancySettings()
    ev = frame_evidence(radar_sensor_model(run.calib.single_chip), s)
    span = float(run.timestamps[-1] - run.timestamps[0])
    t = _cpu()
    occ = OccupancyMap(s)
    for k, c in enumerate(clouds):
        occ.integrate(*ev(c, m[k, :3, :3], m[k, :3, 3]))
    t_occ = _cpu() - t
    t = _cpu()
    accumulate_clouds(clouds, [SE3.from_matrix(x) for x in m], voxel_size=s.voxel)
    t_pts = _cpu() - t
    print(f"single chip, point clouds: {len(clouds)} frames, {span:.0f} s of data")
    print(f"  occupancy map   {1e3 * t_occ / len(clouds):6.2f} ms/frame  "
          f"{span / t_occ:7.1f}x real time  ({len(occ):,} voxels, {occ.nbytes / 1e6:.2f} MB)")
    print(f"  point map today {1e3 * t_pts / len(clouds):6.2f} ms/frame  {span / t_pts:7.1f}x "
          "real time")
    print(f"  {minutes:g} minutes of data round the same corridor (every minute: map MB, voxels, "
          "peak RSS MB):")
    occ = OccupancyMap(s)
    per_min = round(60 * len(clouds) / span)
    n = int(minutes * per_min)
    for i in range(n):
        k = i % len(clouds)
        occ.integrate(*ev(clouds[k], m[k, :3, :3], m[k, :3, 3]))
        if (i + 1) % per_min == 0:
            print(f"    {(i + 1) // per_min:3d} min  {occ.nbytes / 1e6:6.2f} MB  {len(occ):8,}  "
                  f"{_rss_mb():6.0f}", flush=True)


def cascade(cache: Path, minutes: float) -> None:
    root = cache / "full_corridor_1000_12"
    seq = cr.open_sequence(sorted(p for p in root.glob("*_run*") if p.is_dir())[0])
    gt = trajectory_from_groundtruth(seq)
    s = OccupancySettings()
    t = _cpu()
    res = build_occupancy_map(seq, gt, OccupancyJob(sensor="cascade", source="heatmaps"), s)
    t_occ = _cpu() - t
    span = float(res.timestamps[-1] - res.timestamps[0]) + 0.2       # 5 Hz: one frame period
    t = _cpu()
    build_map(seq, "cascade", voxel_size=s.voxel)
    t_pts = _cpu() - t
    n = res.frame_indices.size
    print(f"cascade, heatmaps: {n} frames, {span:.0f} s of data")
    print(f"  occupancy map (heatmaps, files read)  {1e3 * t_occ / n:6.1f} ms/frame  "
          f"{span / t_occ:6.1f}x real time  ({len(res.map):,} voxels)")
    print(f"  point map today (points from ADC)     {1e3 * t_pts / n:6.1f} ms/frame  "
          f"{span / t_pts:6.1f}x real time")
    stream, _, _, model = _stream(seq, OccupancyJob(sensor="cascade", source="heatmaps"))
    heat = [stream[int(i)] for i in res.frame_indices]
    trans, rot = gt.interpolate_arrays(res.timestamps)
    mount = seq.calib.transforms["cascade"].matrix()
    r_ws = rot.as_matrix() @ mount[:3, :3]
    t_ws = trans + rot.apply(mount[:3, 3])
    ev = frame_evidence(model, s)
    occ = OccupancyMap(s)
    per_min = round(60 * n / span)
    print(f"  {minutes:g} minutes of data over the same heatmaps (map MB, voxels, peak RSS MB):")
    for i in range(int(minutes * per_min)):
        k = i % n
        occ.integrate(*ev(heat[k], r_ws[k], t_ws[k]))
        if (i + 1) % per_min == 0:
            print(f"    {(i + 1) // per_min:3d} min  {occ.nbytes / 1e6:6.2f} MB  {len(occ):8,}  "
                  f"{_rss_mb():6.0f}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cache", type=Path, default=Path("/tmp/coloradar_mc_mapping"))
    ap.add_argument("--minutes", type=float, default=10.0)
    args = ap.parse_args()
    single_chip(args.cache, args.minutes)
    cascade(args.cache, args.minutes)


if __name__ == "__main__":
    main()
