"""Geometry hot paths against simple baselines measured in the same run.

Run: ``python benchmarks/bench_geometry.py``. Prints median wall time of each variant.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial.transform import Rotation

from coloradar.geometry import SE3, Trajectory, nearest_indices, voxel_downsample


def bench(fn, repeat: int = 21) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def main() -> None:
    rng = np.random.default_rng(0)
    rows = []

    # One Ouster scan (65,536 points) into the world frame.
    scan = rng.normal(scale=20, size=(65536, 4)).astype(np.float32)
    pose = SE3(Rotation.random(None, rng), rng.normal(size=3))
    m = pose.matrix()
    rows.append(("transform 65k-point scan, SE3.apply_to_cloud (float32)",
                 bench(lambda: pose.apply_to_cloud(scan)),
                 "homogeneous 4x4 float64 matmul",
                 bench(lambda: np.c_[scan[:, :3].astype(np.float64), np.ones(len(scan))] @ m.T)))

    # Associate 3,000 lidar frames with 1,500 radar frames.
    a = np.sort(rng.uniform(0, 300, 3000))
    b = np.sort(rng.uniform(0, 300, 1500))
    rows.append(("nearest_indices 3000 x 1500 (searchsorted)",
                 bench(lambda: nearest_indices(a, b, 0.05)),
                 "brute-force |a - b| table argmin",
                 bench(lambda: np.argmin(np.abs(a[:, None] - b[None, :]), axis=1))))

    # Voxel down-sampling of 1 M map points.
    pts = rng.uniform(-50, 50, (1_000_000, 4)).astype(np.float32)

    def unique_rows():
        keys = np.floor(pts[:, :3] / 0.2).astype(np.int64)
        _, inv = np.unique(keys, axis=0, return_inverse=True)
        return inv

    rows.append(("voxel_downsample 1M points, 0.2 m (packed int64 keys)",
                 bench(lambda: voxel_downsample(pts, 0.2), 3),
                 "np.unique(axis=0) on the key rows only", bench(unique_rows, 3)))

    # Interpolating 10,000 poses out of a 6,000-knot ground truth.
    n = 6000
    traj = Trajectory(1.6e9 + np.arange(n) * 0.1, rng.normal(size=(n, 3)),
                      Rotation.random(n, rng))
    tq = np.sort(rng.uniform(traj.start, traj.end, 10_000))
    rows.append(("Trajectory.interpolate_arrays 10k times",
                 bench(lambda: traj.interpolate_arrays(tq)),
                 "per-time Trajectory.at loop (1k times, x10)",
                 10 * bench(lambda: [traj.at(t) for t in tq[:1000]], 1)))

    w = max(len(r[0]) for r in rows)
    for name, t, base, tb in rows:
        print(f"{name:<{w}}  {t * 1e3:9.2f} ms   | {base}: {tb * 1e3:9.2f} ms  "
              f"({tb / t:5.1f}x)")


if __name__ == "__main__":
    main()
