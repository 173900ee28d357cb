"""ROS bag export throughput beside reading the same frames.

Simulates one run (single-chip radar with its own point clouds, lidar, IMU, ground truth), then

* reads every lidar scan and single-chip point cloud through the dataset API (the baseline:
  what export cannot do faster, it must read the same frames), and reads them and writes
  their bytes to one plain file (the floor of any export);
* exports the same frames (plus IMU, ground truth, /tf_static) to a ROS 1 and a ROS 2 bag;
* imports each bag back into a run.

Point-cloud frames per second count the lidar and radar scans (a 65,536-point lidar scan is
1 MiB; IMU and pose messages ride along and are in the totals). Best of ``--repeat``.

Run:  python benchmarks/bench_export.py [--duration 5 --repeat 3]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
import warnings
from pathlib import Path

from coloradar import open_sequence
from coloradar.interop import export_bag, import_bag
from coloradar.sim.run import simulate_run


def _read_all(seq) -> int:
    """Read every scan (the bytes export must read too); returns the bytes read."""
    return sum(frame.nbytes for stream in (seq.lidar.pointclouds, seq.single_chip.pointclouds)
               for frame in stream)


def _best(fn, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=5.0, help="simulated seconds (default 5)")
    ap.add_argument("--repeat", type=int, default=3, help="best of N (default 3)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_export_"))
    try:
        res = simulate_run(tmp, duration=args.duration, seed=0, heatmaps=False,
                           sensors=["single_chip", "lidar", "imu", "groundtruth"])
        seq = open_sequence(res.run_path)
        streams = ["lidar/pointclouds", "single_chip/pointclouds", "imu", "groundtruth", "tf_static"]
        frames = len(seq.lidar.pointclouds) + len(seq.single_chip.pointclouds)
        print(f"run of {args.duration:g} s: {len(seq.lidar.pointclouds)} lidar scans + "
              f"{len(seq.single_chip.pointclouds)} single-chip point clouds = {frames} frames, "
              f"{len(seq.imu)} IMU samples, {len(seq.groundtruth)} poses (best of {args.repeat})")
        rows = []
        t_read, _ = _best(lambda: _read_all(open_sequence(res.run_path)), args.repeat)
        rows.append(("read frames (dataset API)", t_read, None))

        def floor(path=tmp / "floor.bin"):
            # Reading the frames and writing their bytes to one file: what any export must do.
            s2 = open_sequence(res.run_path)
            with open(path, "wb") as f:
                for stream in (s2.lidar.pointclouds, s2.single_chip.pointclouds):
                    for frame in stream:
                        f.write(frame.tobytes())

        t_floor, _ = _best(floor, args.repeat)
        rows.append(("read + write the same bytes to one file", t_floor, None))
        for fmt in ("ros1", "ros2"):
            out = tmp / ("bag.bag" if fmt == "ros1" else "bag_ros2")

            def export(fmt=fmt, out=out):
                return export_bag(open_sequence(res.run_path), out, fmt, streams=streams,
                                  overwrite=True)

            t_exp, r = _best(export, args.repeat)
            size = sum(p.stat().st_size for p in ([out] if out.is_file() else out.rglob("*")))
            rows.append((f"export {fmt} ({r.messages} messages, {size / 2**20:.0f} MiB)", t_exp, r))

            def back(out=out, fmt=fmt):
                dest = tmp / f"imported_{fmt}"
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    return import_bag(out, dest, name="run", overwrite=True)

            t_imp, _ = _best(back, args.repeat)
            rows.append((f"import {fmt}", t_imp, None))
        print(f"  {'':44}{'s':>8}{'frames/s':>11}{'x read':>9}")
        for label, sec, _ in rows:
            print(f"  {label:<44}{sec:8.3f}{frames / sec:11.1f}{sec / t_read:9.2f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
