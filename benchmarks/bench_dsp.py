"""Benchmark of coloradar.dsp against bare FFTs and a straightforward NumPy implementation.

Run: ``python benchmarks/bench_dsp.py [--frames N] [--repeat R] [--calib DIR]``

For each radar, on the same synthesized frames (several moving targets, noise, channel errors
and coupling when the calibration has them), prints the time per frame of

* ``RadarProcessor.heatmap`` and ``RadarProcessor.pointcloud``;
* the bare scipy FFTs those stages need: the textbook chain (range FFT, Doppler FFT, full 2D
  angle FFT of every range–Doppler cell) and the FFTs coloradar's chain actually calls
  (azimuth FFT of the occupied elevation rows, then the elevation FFT);
* a straightforward NumPy version of the same heatmap (whole-cube operations, ``np.fft``,
  ``fft2`` of every cell, ``argmax`` over Doppler), checked to give the same heatmap;
* the detection chain's additions of issue 10 one at a time on top of the plain chain
  (noise whitening, CFAR excision, Doppler alias search, sidelobe guard) and the
  disambiguated heatmap (``heatmap_unwrap``) beside the plain heatmap. ``--only detection``
  runs just these.

The jobs take turns for ``--repeat`` rounds and each keeps its best round (the machine may be
shared); times are ms per frame, wall clock (or process CPU time with ``--cpu-time``).
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
import scipy.fft as sfft

from coloradar.calib import CouplingCalib, PhaseFrequencyCalib, load_calibration, preset_radar
from coloradar.dsp import RadarProcessor, coupling_signal, phase_frequency_factors
from coloradar.dsp.heatmap import CHUNK_SIZE
from coloradar.sim import apply_channel_errors, synthesize_adc

REAL_CALIB = Path(__file__).resolve().parents[1].parent / "shared/reference/coloradar_calib"
CPU_CLOCK = False


def calibration(name: str, calib_dir: Path | None):
    """Real calibration when available, else the preset with realistic errors and coupling."""
    if calib_dir is not None and calib_dir.is_dir():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return load_calibration(calib_dir).radar(name), "real calib files"
    rc = preset_radar(name)
    g = np.random.default_rng(0)
    w = rc.waveform
    shape = (w.num_tx, w.num_rx)
    coupling = CouplingCalib(2e3 * np.exp(-np.arange(rc.heatmap.num_range_bins) / 2.0)
                             * (g.standard_normal((*shape, rc.heatmap.num_range_bins)) + 1j),
                             w.num_chirps)
    pf = None
    if name == "cascade":
        pf = PhaseFrequencyCalib(51 + 0.3 * g.standard_normal(shape),
                                 np.exp(2j * np.pi * g.random(shape)), w.slope, w.sample_rate)
    return replace(rc, coupling=coupling, phase_frequency=pf), "presets + synthetic errors"


def frames(calib, n: int) -> list[np.ndarray]:
    g = np.random.default_rng(1)
    w = calib.waveform
    coupling = coupling_signal(calib.coupling, w.num_samples)[:, :, None, :]
    out = []
    for _ in range(n):
        k = 12
        r = g.uniform(1.0, 0.9 * calib.heatmap.num_range_bins * w.range_bin_width, k)
        az, el = g.uniform(-1.0, 1.0, k), g.uniform(-0.3, 0.3, k)
        u = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
        v = g.uniform(-0.9, 0.9, (k, 1)) * w.max_velocity * u
        adc = synthesize_adc(calib, r[:, None] * u, v, 300.0 * r**2, noise_std=20.0, rng=g)
        if calib.phase_frequency is not None:
            adc = apply_channel_errors(adc, calib.phase_frequency)
        out.append((adc + coupling).astype(np.complex64))
    return out


def numpy_heatmap(calib, adc: np.ndarray) -> np.ndarray:
    """The same heatmap written the straightforward way (no fusing, chunking or pruning)."""
    w, h, ant = calib.waveform, calib.heatmap, calib.antenna
    ntx, nrx, nc, ns = w.frame_shape
    nr, ne, na = h.num_range_bins, h.num_elevation_bins, h.num_azimuth_bins
    x = adc - coupling_signal(calib.coupling, ns)[:, :, None, :]
    x = x - x.mean(axis=-1, keepdims=True)
    if calib.phase_frequency is not None:
        x = x * phase_frequency_factors(calib.phase_frequency, w)[:, :, None, :]
    wr = np.hanning(ns + 1)[:-1]
    wd = np.hanning(nc + 1)[:-1]
    x = x * (wr / wr.sum())
    rng = np.fft.fft(x, axis=-1)[..., :nr] * (wd / wd.sum())[:, None]
    dop = np.fft.fftshift(np.fft.fft(rng, axis=2), axes=2)               # (tx, rx, Nd, Nr)
    k = np.arange(nc) - nc // 2
    dop = dop * np.exp(-2j * np.pi * np.arange(ntx)[:, None, None, None] * k[:, None]
                       / (nc * ntx))
    v = ant.virtual
    elems = dop.reshape(ntx * nrx, nc, nr)[v.first_pair[:, 0] * nrx + v.first_pair[:, 1]]
    pos = np.rint(v.unique_positions).astype(int)
    grid = np.zeros((nc, nr, ne, na), dtype=complex)
    # element at +p gets exp(−jπρ p u): place at −p so that the FFT sums exp(+j2π k p / N)
    grid[:, :, (-pos[:, 1]) % ne, (-pos[:, 0]) % na] = elems.transpose(1, 2, 0)
    spec = np.fft.fftshift(np.fft.fft2(grid, axes=(2, 3)), axes=(2, 3))
    power = np.abs(spec) ** 2 / len(pos) ** 2
    d = power.argmax(axis=0)                                              # (Nr, Ne, Na)
    vel = k * w.wavelength / (2 * nc * w.tdm_period)
    out = np.empty((ne, na, nr, 2), dtype=np.float32)
    out[..., 0] = np.take_along_axis(power, d[None], 0)[0].transpose(1, 2, 0)
    out[..., 1] = vel[d].transpose(1, 2, 0)
    return out


def _clock():
    return time.process_time() if CPU_CLOCK else time.perf_counter()


def interleaved(jobs: dict, rounds: int) -> dict[str, float]:
    """Best time per item [ms] of each ``name: (fn, items)`` job.

    The jobs take turns round after round, so that a shared machine's changing load affects
    all of them alike; the best round of each is kept. The clock is process CPU time with
    ``--cpu-time`` (everything here is single-threaded), wall time otherwise.
    """
    best = dict.fromkeys(jobs, np.inf)
    for _ in range(rounds):
        for name, (fn, items) in jobs.items():
            t0 = _clock()
            for it in items:
                fn(it)
            best[name] = min(best[name], (_clock() - t0) / len(items))
    return {k: v * 1e3 for k, v in best.items()}


def fft_jobs(calib, proc: RadarProcessor) -> dict:
    """The bare scipy FFTs of one frame: the textbook chain's and the ones coloradar calls."""
    w, h = calib.waveform, calib.heatmap
    g = np.random.default_rng(2)
    ntx, nrx, nc, ns = w.frame_shape
    nr, ne, na = h.num_range_bins, h.num_elevation_bins, h.num_azimuth_bins

    def c64(*shape):
        return (g.standard_normal(shape) + 1j * g.standard_normal(shape)).astype(np.complex64)

    cube, rcube = c64(ntx, nrx, nc, ns), c64(ntx, nrx, nc, nr)
    full_grid = c64(nc * nr, ne, na)
    grid = proc.grid
    rows, cols = int(grid.el_pos.max()) + 1, int(grid.az_pos.max()) + 1
    rc = max(1, min(nr, CHUNK_SIZE // (nc * grid.n_el * grid.n_az)))   # as heatmap_from_elements
    az_in = c64(rc, nc, rows, cols)
    el_in = c64(rc, nc, rows, grid.n_az)
    wk = proc.settings.workers

    def chunked_angle_ffts(_) -> None:
        for _ in range(0, nr, rc):              # results dropped, as the engine drops them
            sfft.fft(az_in, n=grid.n_az, axis=3, workers=wk)
            sfft.fft(el_in, n=grid.n_el, axis=2, workers=wk)

    return {
        "FFT range": (lambda _: sfft.fft(cube, axis=-1, workers=wk), [0] * 5),
        "FFT Doppler": (lambda _: sfft.fft(rcube, axis=2, workers=wk), [0] * 5),
        "FFT angle 2D, every cell": (lambda _: sfft.fft2(full_grid, axes=(1, 2), workers=wk),
                                     [0]),
        "FFT angle az rows + el": (chunked_angle_ffts, [0]),
    }


# ------------------------------------------------------------------ detection additions
DETECTION_STEPS = (
    ("plain chain", dict(noise_weighting="off", cfar_excision=False, doppler_unwrap=0.0,
                         sidelobe_guard=False)),
    ("+ noise whitening", dict(cfar_excision=False, doppler_unwrap=0.0, sidelobe_guard=False)),
    ("+ CFAR excision", dict(doppler_unwrap=0.0, sidelobe_guard=False)),
    ("+ Doppler alias search", dict(sidelobe_guard=False)),
    ("+ sidelobe guard (default)", {}),
)


def detection_costs(calib, fr: list[np.ndarray], repeat: int) -> None:
    """Point cloud time with each detection addition switched on in turn, and the
    disambiguated heatmap beside the plain one (same frames, interleaved rounds)."""
    jobs = {name: (RadarProcessor(calib, **kw).pointcloud, fr) for name, kw in DETECTION_STEPS}
    jobs["heatmap"] = (RadarProcessor(calib).heatmap, fr)
    jobs["heatmap, heatmap_unwrap"] = (RadarProcessor(calib, heatmap_unwrap=True).heatmap, fr)
    t = interleaved(jobs, repeat)
    base = t[DETECTION_STEPS[0][0]]
    print("  -- ADC -> point cloud, detection additions (ms/frame, x plain chain)")
    for name, _ in DETECTION_STEPS:
        print(f"  {name:<28s}{t[name]:8.2f}  {t[name] / base:5.2f}x")
    print(f"  {'heatmap':<28s}{t['heatmap']:8.2f}")
    print(f"  {'heatmap_unwrap=True':<28s}{t['heatmap, heatmap_unwrap']:8.2f}  "
          f"{t['heatmap, heatmap_unwrap'] / t['heatmap']:5.2f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=7, help="rounds (best one kept)")
    ap.add_argument("--calib", type=Path, default=REAL_CALIB)
    ap.add_argument("--only", choices=("all", "heatmap", "detection"), default="all",
                    help="run only the heatmap section or the detection-additions section")
    ap.add_argument("--cpu-time", action="store_true",
                    help="measure process CPU time instead of wall time (everything here runs "
                         "on one thread, so on a busy shared machine this is the fairer clock)")
    args = ap.parse_args()
    global CPU_CLOCK
    CPU_CLOCK = args.cpu_time
    print(f"cores: {os.cpu_count()}, load average: {os.getloadavg()[0]:.2f}; "
          f"{args.frames} frames, best of {args.repeat} interleaved rounds; "
          f"{'CPU' if CPU_CLOCK else 'wall'} time in ms per frame")
    for name in ("cascade", "single_chip"):
        calib, what = calibration(name, args.calib)
        proc = RadarProcessor(calib)
        fr = frames(calib, args.frames)
        if args.only == "detection":
            print(f"\n== {name} ({what})")
            detection_costs(calib, fr, args.repeat)
            continue
        ref = numpy_heatmap(calib, fr[0])
        got = proc.heatmap(fr[0])
        err = np.max(np.abs(got[..., 0] - ref[..., 0])) / ref[..., 0].max()
        same_v = np.mean(got[..., 1] == ref[..., 1])
        jobs = {"ADC -> heatmap": (proc.heatmap, fr),
                "ADC -> point cloud": (proc.pointcloud, fr),
                "numpy heatmap": (partial(numpy_heatmap, calib), fr[:1]),
                **fft_jobs(calib, proc)}
        t = interleaved(jobs, args.repeat)
        textbook = t["FFT range"] + t["FFT Doppler"] + t["FFT angle 2D, every cell"]
        ours = t["FFT range"] + t["FFT Doppler"] + t["FFT angle az rows + el"]
        npts = np.mean([len(proc.pointcloud(a)) for a in fr])
        print(f"\n== {name} ({what}); heatmap {calib.heatmap_shape}, {npts:.0f} points/frame")
        for k, v in t.items():
            print(f"  {k:<28s}{v:8.2f}")
        print(f"  (numpy heatmap = ours: max rel. diff {err:.1e}, same Doppler bin in "
              f"{same_v:.3%} of cells)")
        hm = t["ADC -> heatmap"]
        print(f"  bare FFTs, textbook chain (range + Doppler + 2D angle)  {textbook:8.2f}")
        print(f"  bare FFTs, coloradar's chain (range + Doppler + az + el) {ours:8.2f}")
        print(f"  heatmap / textbook bare FFTs   {hm / textbook:6.2f}x")
        print(f"  heatmap / own bare FFTs        {hm / ours:6.2f}x")
        print(f"  numpy heatmap / heatmap        {t['numpy heatmap'] / hm:6.1f}x")
        if args.only == "all":
            detection_costs(calib, fr, args.repeat)


if __name__ == "__main__":
    main()
