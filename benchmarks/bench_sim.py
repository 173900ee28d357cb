"""The simulator's hot paths against their straightforward versions, in one run.

    python benchmarks/bench_sim.py [--duration 10] [--scene corridor] [--skip-run]

Prints, side by side with a baseline measured in the same process:

- ADC synthesis of K scatterers: the float64 reference model
  (:func:`coloradar.sim.synthesize_adc`) vs the complex64 twin used by the simulator;
- one lidar scan's ray casting: every ray against every rectangle vs the azimuth-sector method;
- a whole run of every sensor (wall time against the simulated duration, real time = 1.0),
  with and without heatmaps.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

from coloradar.calib import preset_radar
from coloradar.sim import builtin_scene, simulate_run, synthesize_adc
from coloradar.sim.lidar import LidarModel
from coloradar.sim.raycast import cast_rays


def _best(fn, *args, repeat: int = 3, **kwargs) -> float:
    """Best wall time of ``fn(*args, **kwargs)`` over ``repeat`` calls [s]."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn(*args, **kwargs)
        best = min(best, time.perf_counter() - t0)
    return best


def bench_adc() -> None:
    print("ADC synthesis per frame [ms]      reference (f64)   simulator (c64)   speed-up")
    rng = np.random.default_rng(0)
    for radar in ("cascade", "single_chip"):
        calib = preset_radar(radar)
        for k in (500, 2000):
            p = rng.uniform(-6, 6, (k, 3))
            p[:, 0] = np.abs(p[:, 0]) + 0.5
            v = rng.normal(size=(k, 3))
            a = rng.uniform(1, 100, k) * np.exp(1j * rng.uniform(0, 6, k))
            ref = _best(synthesize_adc, calib, p, v, a, repeat=2)
            fast = _best(synthesize_adc, calib, p, v, a, precision="single")
            print(f"  {radar:<12} K={k:<5}          {ref * 1e3:>10.0f}        {fast * 1e3:>10.0f}"
                  f"        {ref / fast:>5.1f}x")


def bench_raycast() -> None:
    print("lidar scan ray casting [ms]        every rectangle   azimuth sectors   speed-up")
    model = LidarModel()
    for name in ("corridor", "mine"):
        scene = builtin_scene(name)
        rects = scene.static_rect_arrays
        d = np.swapaxes(model.directions(), 0, 1)                  # (columns, beams, 3)
        o = np.broadcast_to(np.array([0.3, 0.1, 1.1]), (model.columns, 1, 3))
        dense = _best(cast_rays, o, d, rects, method="dense", repeat=2)
        sect = _best(cast_rays, o, d, rects, method="sectors")
        print(f"  {name:<10} ({rects.count:>3} rectangles)   {dense * 1e3:>10.0f}        "
              f"{sect * 1e3:>10.0f}        {dense / sect:>5.1f}x")


def bench_run(duration: float, scene: str) -> None:
    print(f"whole run, {duration:g} s of '{scene}', all sensors (cpu count {os.cpu_count()})")
    for heatmaps in (False, True):
        with tempfile.TemporaryDirectory() as d:
            res = simulate_run(d, scene=scene, duration=duration, heatmaps=heatmaps)
            size = sum(f.stat().st_size for f in res.run_path.rglob("*") if f.is_file())
            print(f"  heatmaps={'on ' if heatmaps else 'off'}  wall {res.seconds:6.1f} s   "
                  f"real-time factor {res.seconds / duration:5.2f}   written {size / 1e6:6.0f} MB")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--scene", default="corridor")
    ap.add_argument("--skip-run", action="store_true", help="only the micro-benchmarks")
    args = ap.parse_args()
    bench_adc()
    bench_raycast()
    if not args.skip_run:
        bench_run(args.duration, args.scene)


if __name__ == "__main__":
    main()
