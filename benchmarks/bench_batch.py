"""Whole-dataset processing throughput: frames per second with 1, 2 … N workers.

Simulates a small dataset (both radars, raw ADC only), then processes all of it

* with a plain loop over :func:`coloradar.batch.run_processing.process_frames` in this process
  (the baseline: what one would write by hand, no chunks, no resume bookkeeping);
* with ``process_dataset`` serially in this process (``--jobs 1``);
* on a local process pool of 1, 2 … N workers;
* on a Dask ``LocalCluster`` of N single-threaded worker processes (when dask is installed),
  once as Dask starts them (its nanny sets ``MALLOC_TRIM_THRESHOLD_=65536``, which makes
  every large temporary array a fresh ``mmap``: page faults, ~3× slower here) and once
  without that variable;
* and once more over the complete output (a resumed job with nothing left to do).

Wall time and frames/s count from the call to the end of the report; starting the workers
(spawn, import) is timed apart (``start s``), as it is paid once per job, not per frame.
Peak memory is the peak resident set of each worker process (``ru_maxrss``) as its chunks
report it; for the in-process rows it is this process's, which also holds the driver.

Run:  python benchmarks/bench_batch.py [--runs 3 --duration 4 --chunk-size 8 --max-jobs N]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

from coloradar.batch.driver import process_dataset
from coloradar.batch.executors import DaskExecutor, LocalExecutor
from coloradar.batch.run_processing import process_frames
from coloradar.dataset import open_dataset


def _simulate(root: Path, runs: int, duration: float) -> None:
    for seed in range(runs):
        subprocess.run([sys.executable, "-m", "coloradar", "simulate", str(root), "--duration",
                        str(duration), "--seed", str(seed), "--sensors", "cascade,single_chip",
                        "--no-heatmaps", "--quiet"], check=True, stdout=subprocess.DEVNULL)


def _self_peak() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _warm(_: int) -> int:
    """A task that makes a fresh worker import the processing code."""
    import coloradar.batch.chunks  # noqa: F401

    time.sleep(0.2)
    return os.getpid()


def _row(name: str, frames: int, seconds: float, base: float, peak: int, workers: int,
         start: float = 0.0) -> str:
    fps = frames / seconds
    return (f"{name:<44} {frames:>6} {seconds:>8.2f} {fps:>9.1f} {fps / base:>8.2f}x "
            f"{workers:>7} {peak / 2**20:>9.0f} {start:>8.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--duration", type=float, default=4.0, help="seconds per run")
    ap.add_argument("--chunk-size", type=int, default=8)
    ap.add_argument("--max-jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--no-dask", action="store_true")
    args = ap.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="bench_batch_"))
    try:
        root = tmp / "dataset"
        t = time.perf_counter()
        _simulate(root, args.runs, args.duration)
        ds = open_dataset(root)
        counts = {n: {r: len(ds[n].radar(r).adc) for r in ("cascade", "single_chip")}
                  for n in ds.sequences}
        total = sum(sum(c.values()) for c in counts.values())
        print(f"dataset: {args.runs} runs × {args.duration:g} s, {total} ADC frames "
              f"({sum(c['cascade'] for c in counts.values())} cascade, "
              f"{sum(c['single_chip'] for c in counts.values())} single-chip), "
              f"simulated in {time.perf_counter() - t:.1f} s; {os.cpu_count()} cores; "
              f"chunk size {args.chunk_size}")
        print(f"{'configuration':<44} {'frames':>6} {'wall s':>8} {'frames/s':>9} "
              f"{'vs base':>9} {'workers':>7} {'peak MiB':>9} {'start s':>8}")

        out = tmp / "baseline"
        t = time.perf_counter()
        for name in ds.sequences:
            for radar, n in counts[name].items():
                process_frames(ds.path(name), root / "calib", radar, ("heatmaps", "pointclouds"),
                               range(n), out / name)
        base_s = time.perf_counter() - t
        base = total / base_s
        print(_row("baseline: process_frames loop", total, base_s, base, _self_peak(), 1))

        def run(name: str, start_s: float = 0.0, **kw) -> None:
            dest = tmp / name.replace(" ", "_").replace(",", "")
            rep = process_dataset(root, dest, chunk_size=args.chunk_size, progress=False, **kw)
            assert rep.ok, rep.summary()
            peak = max(rep.workers.values(), default=0)
            print(_row(name, rep.totals()["done"], rep.seconds, base, peak,
                       max(len(rep.workers), 1), start_s))
            shutil.rmtree(dest)

        run("serial (--jobs 1)", jobs=1)
        for j in range(1, args.max_jobs + 1):
            t = time.perf_counter()
            with LocalExecutor(j) as ex:
                # Start the workers (spawn + import) before the clock, and report it apart.
                list(ex.imap_unordered(_warm, range(2 * j)))
                run(f"local pool, {j} worker{'s' * (j > 1)}", time.perf_counter() - t,
                    executor=ex)
        if not args.no_dask:
            try:
                from distributed import Client, LocalCluster
            except ImportError:
                print("(dask not installed: no Dask row)")
            else:
                import dask

                n = args.max_jobs
                saved_env = dict(os.environ)
                env = dict(dask.config.get("distributed.nanny.pre-spawn-environ"))
                trim = env.pop("MALLOC_TRIM_THRESHOLD_", None)
                for label, environ in ((f"nanny env, trim {trim}", None),
                                       ("MALLOC_TRIM_THRESHOLD_ unset", env)):
                    cfg = {} if environ is None else {
                        "distributed.nanny.pre-spawn-environ": environ}
                    t = time.perf_counter()
                    with dask.config.set(cfg), warnings.catch_warnings(), \
                            LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                         dashboard_address=":0") as cluster, \
                            Client(cluster) as client:
                        warnings.simplefilter("ignore")
                        client.run(_warm, 0)
                        run(f"dask {n} procs ({label})", time.perf_counter() - t,
                            executor=DaskExecutor(client=client))
                    # The nanny leaves its variables in this process's environment too.
                    for k in ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                              "OPENBLAS_NUM_THREADS"):
                        if k in saved_env:
                            os.environ[k] = saved_env[k]
                        else:
                            os.environ.pop(k, None)

        dest = tmp / "resume"
        process_dataset(root, dest, jobs=args.max_jobs, chunk_size=args.chunk_size,
                        progress=False)
        t = time.perf_counter()
        rep = process_dataset(root, dest, jobs=args.max_jobs, progress=False)
        print(f"resume over complete output: {rep.totals()['skipped']} frames checked and "
              f"skipped in {time.perf_counter() - t:.2f} s")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
