"""Speed of this tree's radar chain beside another tree's, in one process, job against job.

Run: ``python benchmarks/bench_dsp_refactor.py --base-tree DIR [--frames N] [--repeat R]
[--calib DIR] [--cpu-time]``

``DIR`` holds the other tree (``DIR/src/coloradar``, e.g. a ``git archive`` of the commit before
a refactor). Its package is copied under the name ``coloradar_base`` (coloradar imports itself
only relatively) and imported beside this tree's ``coloradar``, so that both chains run in one
interpreter on the very same frames (``bench_dsp.py``'s: far-field frames of both radars with the
calibration's errors and coupling, and for the cascade exact spherical-wave frames with the
release calibration, focusing on). The jobs — heatmap (default and numpy engine), point cloud,
``products``, the near-field point cloud and heatmap, the plain detection chain — of both trees
take turns item by item for ``--repeat`` rounds (``bench_dsp.interleaved``); each job keeps its
items' best times. Printed: ms per frame of each tree and their ratio (new / base). A shared,
busy machine moves single figures by several per cent; the ratios of jobs run side by side
move much less.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # before numpy loads OpenBLAS

import argparse
import importlib
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import bench_dsp  # noqa: E402  (this tree's frames and timing loop)


def _base_package(tree: Path, folder: Path):
    """The other tree's ``coloradar`` imported as ``coloradar_base``."""
    shutil.copytree(tree / "src" / "coloradar", folder / "coloradar_base",
                    ignore=shutil.ignore_patterns("__pycache__"))
    sys.path.insert(0, str(folder))
    return importlib.import_module("coloradar_base")


def _calib(pkg, name: str, calib_dir: Path, far_field: bool):
    """The radar's calibration loaded by ``pkg`` (each tree's own classes), as bench_dsp's."""
    from dataclasses import replace
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = pkg.calib.load_calibration(calib_dir).radar(name)
    if far_field and rc.phase_frequency is not None:
        rc = replace(rc, phase_frequency=replace(rc.phase_frequency, near_field=False))
    return rc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base-tree", type=Path, required=True)
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--repeat", type=int, default=7, help="rounds (best one kept)")
    ap.add_argument("--calib", type=Path, default=bench_dsp.REAL_CALIB)
    ap.add_argument("--cpu-time", action="store_true")
    args = ap.parse_args()
    bench_dsp.CPU_CLOCK = args.cpu_time
    import coloradar as new
    tmp = Path(tempfile.mkdtemp(prefix="coloradar_ab_"))
    try:
        base = _base_package(args.base_tree.resolve(), tmp)
        print(f"cores: {os.cpu_count()}, load average: {os.getloadavg()[0]:.2f}; "
              f"{args.frames} frames, best of {args.repeat} interleaved rounds; "
              f"{'CPU' if args.cpu_time else 'wall'} ms per frame; base {args.base_tree}, "
              f"new {HERE.parent}")
        for name in ("cascade", "single_chip"):
            jobs = {}
            calib, _ = bench_dsp.calibration(name, args.calib)
            fr = bench_dsp.frames(calib, args.frames)
            near = bench_dsp.near_field_frames(name, args.calib, args.frames)
            plain = dict(noise_weighting="off", cfar_excision=False, doppler_unwrap=0.0,
                         sidelobe_guard=False, beam_doppler=False)
            for label, pkg in (("base", base), ("new", new)):
                rc = _calib(pkg, name, args.calib, far_field=True)
                proc = pkg.dsp.RadarProcessor(rc)
                jobs[("heatmap", label)] = (proc.heatmap, fr)
                jobs[("heatmap, numpy engine", label)] = (
                    pkg.dsp.RadarProcessor(rc, engine="numpy").heatmap, fr)
                jobs[("point cloud", label)] = (proc.pointcloud, fr)
                jobs[("products", label)] = (proc.products, fr)
                jobs[("point cloud, plain chain", label)] = (
                    pkg.dsp.RadarProcessor(rc, **plain).pointcloud, fr)
                if near is not None:
                    nf = pkg.dsp.RadarProcessor(_calib(pkg, name, args.calib, far_field=False))
                    jobs[("near-field point cloud", label)] = (nf.pointcloud, near[1])
                    jobs[("near-field heatmap", label)] = (nf.heatmap, near[1])
            for (job, label), (fn, items) in jobs.items():      # same outputs, and warm
                other = jobs[(job, "new" if label == "base" else "base")][0]
                a, b = fn(items[0]), other(items[0])
                same = all(np.array_equal(x, y) for x, y in zip(
                    a if isinstance(a, tuple) else (a,), b if isinstance(b, tuple) else (b,),
                    strict=True))
                assert same, f"{name} {job}: the trees' outputs differ"
            t = bench_dsp.interleaved(jobs, args.repeat)
            print(f"\n== {name} (real calibration files)          base ms    new ms   new/base")
            for job in dict.fromkeys(j for j, _ in jobs):
                b, n = t[(job, "base")], t[(job, "new")]
                print(f"  {job:<34s}{b:9.2f}{n:10.2f}{n / b:10.3f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
