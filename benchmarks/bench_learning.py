"""HDF5 learning export: frames/s and bytes per frame against the raw folders.

Simulates one run (single-chip radar with heatmaps and its own point clouds, lidar, ground
truth), then, on the same samples (one per radar frame):

* reads the raw frames a sample is made of through the dataset API (heatmap, point cloud,
  nearest lidar scan): the floor of any export, which must read them too;
* builds the samples in memory from the folder (``SyncedSamples``: views, lidar map, targets);
* exports them to one HDF5 file with gzip, lzf and no compression;
* reads the samples back from the file, and from the folder.

Bytes per frame: the file size over the samples, beside the raw folder's bytes per radar frame
(the radar's heatmap and point-cloud files, plus the run's lidar scans shared over the radar
frames). Best of ``--repeat``.

Run:  python benchmarks/bench_learning.py [--duration 5 --repeat 2]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from coloradar import open_sequence
from coloradar.interop.hdf5 import export_hdf5
from coloradar.learning import SyncedSamples, TargetSettings
from coloradar.sim.run import simulate_run

PRODUCTS = ("heatmap", "points", "polar", "bev")


def _best(fn, repeat: int):
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def _folder_bytes(run: Path, parts: tuple[str, ...]) -> int:
    return sum(p.stat().st_size for part in parts for p in (run / part).rglob("*.bin"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=5.0, help="simulated seconds (default 5)")
    ap.add_argument("--repeat", type=int, default=2, help="best of N (default 2)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench_learning_"))
    try:
        res = simulate_run(tmp, duration=args.duration, seed=0,
                           sensors=["single_chip", "lidar", "groundtruth"])
        run = res.run_path
        seq = open_sequence(run)
        opts = dict(radar="single_chip", products=PRODUCTS, lidar=False, targets=True,
                    target_settings=TargetSettings(voxel_size=0.1))
        view = SyncedSamples(seq, **opts)
        n = len(view)
        raw_radar = _folder_bytes(run, ("single_chip/heatmaps", "single_chip/pointclouds"))
        raw_lidar = _folder_bytes(run, ("lidar",))
        print(f"run of {args.duration:g} s: {n} single-chip samples ({PRODUCTS}, lidar targets at "
              f"0.1 m), {len(seq.lidar.pointclouds)} lidar scans; best of {args.repeat}")
        print(f"raw folder: {raw_radar / n / 1024:.0f} KiB/frame of radar files + "
              f"{raw_lidar / n / 1024:.0f} KiB/frame of lidar scans = "
              f"{(raw_radar + raw_lidar) / n / 1024:.0f} KiB/frame")

        def read_raw() -> int:
            sc, lid = seq.single_chip, seq.lidar.pointclouds
            r = view._runs[0]
            nbytes = 0
            for i in range(n):
                nbytes += sc.heatmaps[int(r.radar_k[i])].nbytes
                nbytes += sc.pointclouds[int(r.points_k[i])].nbytes
            return nbytes + sum(scan.nbytes for scan in lid)

        def build() -> int:
            v = SyncedSamples(open_sequence(run), **opts)
            return sum(len(v[i]) for i in range(n))

        rows = []
        t, _ = _best(read_raw, args.repeat)
        rows.append(("read raw frames (heatmap, points, every lidar scan)", t, None))
        t, _ = _best(build, args.repeat)
        rows.append(("build samples from the folder (no file)", t, None))
        for comp, level in (("gzip", 4), ("gzip", 1), ("lzf", 0), ("none", 0)):
            out = tmp / f"run_{comp}.h5"
            t, r = _best(lambda c=comp, o=out, k=level: export_hdf5(
                run, o, compression=c, compression_level=k or 4, overwrite=True, **opts),
                args.repeat)
            rows.append((f"export hdf5 ({comp}{f' level {level}' if level else ''})", t, r.bytes))
        back = SyncedSamples(tmp / "run_gzip.h5")

        def read_back() -> int:
            return sum(len(back[i]) for i in range(n))

        t, _ = _best(read_back, args.repeat)
        rows.append(("read samples back from the gzip file", t, None))
        base = rows[0][1]
        print(f"{'':<54}{'frames/s':>10}{'x raw read':>12}{'KiB/frame':>11}")
        for name, sec, nbytes in rows:
            size = f"{nbytes / n / 1024:>11.0f}" if nbytes else f"{'':>11}"
            print(f"  {name:<52}{n / sec:>10.1f}{sec / base:>12.2f}{size}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
