"""Benchmark of coloradar.dsp against a plain scipy chain and the bare transforms it needs.

Run: ``python benchmarks/bench_dsp.py [--frames N] [--repeat R] [--calib DIR] [--cpu-time]``

For each radar, on the same synthesized frames (several moving targets, noise, channel errors
and coupling when the calibration has them), prints the time per frame of

* ``RadarProcessor.heatmap`` (default engine, and the numpy engine) and ``.pointcloud``;
* for a radar whose real calibration holds a near reflector's phases (the cascade's), the
  point cloud and heatmap of frames consistent with that calibration: exact spherical waves
  (``tests/_synth.py``: ``exact_adc``) with the hardware errors behind the calibration
  (``calibrated_hardware``), processed with the calibration as released, so that near-field
  focusing is on as on real frames (the frames above are far-field and their calibration is
  marked so, which leaves it off); ``near-field point cloud / heatmap`` compares that point
  cloud with the heatmap of the frames above;
* the **plain scipy chain** (the baseline): coupling, DC removal, calibration and windows,
  range FFT, Doppler FFT, TDM compensation, virtual array, the 2D angle FFT of the full
  elevation × azimuth grid of every range–Doppler cell, ``|·|²`` and the maximum (``argmax``)
  over Doppler, written straightforwardly with ``scipy.fft`` in complex64; it is checked to
  give the same heatmap;
* the bare FFTs (``scipy.fft``, one thread, cache-sized calls) of the same shapes: range FFT
  of the ADC cube, Doppler FFT of the range cube, azimuth FFT of the occupied elevation rows;
* a **floor**: the floating-point operations of the transforms no heatmap can skip, at the
  best FFT rate measured in the same run (GFLOP/s of the bare FFTs above, counting
  ``5·N·log2(N)`` per complex ``N``-point FFT). The transforms, each counted as an FFT pruned
  to its nonzero inputs (``5·N·log2(L)`` for ``L`` of ``N`` nonzero, twiddles left out):
  range FFT of every channel the heatmap reads and chirp, Doppler FFT of every such channel
  and range bin, azimuth FFT of each occupied elevation row (``L`` its width) of every
  range–Doppler cell, and for every cell and azimuth bin the elevation FFT from the occupied
  rows (``L`` = their number) to the elevation bins. Every beam value of every cell must be
  computed (the heatmap is a maximum over them); power, Doppler maximum, calibration,
  windows, TDM, gathers and output are not counted. ``heatmap / floor`` near 1 says the
  whole heatmap costs what its transforms alone would cost at scipy's FFT speed;
* the detection chain's additions of issue 10 one at a time on top of the plain chain
  (noise whitening, CFAR excision, Doppler alias search, sidelobe guard, beam-steered
  Doppler refinement) and the
  disambiguated heatmap (``heatmap_unwrap``) beside the plain heatmap. ``--only detection``
  runs just these, ``--only heatmap`` just the sections above.

The jobs take turns for ``--repeat`` rounds and each keeps its best round (the machine may be
shared); times are ms per frame, wall clock (or process CPU time with ``--cpu-time``).
Everything runs on one thread: ``OPENBLAS_NUM_THREADS=1`` is set unless given (OpenBLAS's
threads make the thin elevation matmul many times slower on a shared machine).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # before numpy loads OpenBLAS

import argparse
import sys
import time
import warnings
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
import scipy.fft as sfft

from coloradar.calib import CouplingCalib, PhaseFrequencyCalib, load_calibration, preset_radar
from coloradar.dsp import RadarProcessor, coupling_signal, phase_frequency_factors
from coloradar.dsp.heatmap import CHUNK_SIZE, available_engines, elevation_steering
from coloradar.sim import apply_channel_errors, synthesize_adc

REAL_CALIB = Path(os.environ.get(
    "COLORADAR_REFERENCE_CALIB",
    Path(__file__).resolve().parents[1].parent / "shared/reference/coloradar_calib"))
CPU_CLOCK = False
NF_PC = "ADC -> point cloud, near field"
NF_HM = "ADC -> heatmap, near field"


def calibration(name: str, calib_dir: Path | None):
    """Real calibration when available, else the preset with realistic errors and coupling."""
    # frames() synthesises far-field echoes and imposes the file's channel errors as they are:
    # the calibration is marked as carrying no near-field phases, so that it describes these
    # frames (real frames get focusing relative to the file's reflector, docs/dsp.md).
    if calib_dir is not None and calib_dir.is_dir():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rc = load_calibration(calib_dir).radar(name)
        if rc.phase_frequency is not None:
            rc = replace(rc, phase_frequency=replace(rc.phase_frequency, near_field=False))
        return rc, "real calib files"
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
                                 np.exp(2j * np.pi * g.random(shape)), w.slope, w.sample_rate,
                                 near_field=False)
    return replace(rc, coupling=coupling, phase_frequency=pf), "presets + synthetic errors"


def frames(calib, n: int, synth=synthesize_adc, errors=None) -> list[np.ndarray]:
    """``n`` frames of 12 moving point targets with noise, the channel errors ``errors``
    (default: the calibration's own) and the calibration's coupling; ``synth`` makes the
    echoes (:func:`coloradar.sim.synthesize_adc`: far field)."""
    g = np.random.default_rng(1)
    w = calib.waveform
    coupling = coupling_signal(calib.coupling, w.num_samples)[:, :, None, :]
    errors = calib.phase_frequency if errors is None else errors
    out = []
    for _ in range(n):
        k = 12
        r = g.uniform(1.0, 0.9 * calib.heatmap.num_range_bins * w.range_bin_width, k)
        az, el = g.uniform(-1.0, 1.0, k), g.uniform(-0.3, 0.3, k)
        u = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
        v = g.uniform(-0.9, 0.9, (k, 1)) * w.max_velocity * u
        adc = synth(calib, r[:, None] * u, v, 300.0 * r**2, noise_std=20.0, rng=g)
        if errors is not None:
            adc = apply_channel_errors(adc, errors)
        out.append((adc + coupling).astype(np.complex64))
    return out


def near_field_frames(name: str, calib_dir: Path | None, n: int):
    """Frames as real ones with a calibration measured on a near reflector: the release
    calibration as it is (near-field phases, focusing on, docs/dsp.md) and frames of exact
    spherical waves (tests/_synth.py ``exact_adc``) carrying the hardware's channel errors
    behind that calibration (``calibrated_hardware``: the calibration less its reflector's
    near-field phases). Returns ``(calib, frames)``, or None where the calibration has no
    near-field phases (the single chip's, the presets)."""
    if calib_dir is None or not calib_dir.is_dir():
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = load_calibration(calib_dir).radar(name)
    if rc.phase_frequency is None or not rc.phase_frequency.near_field:
        return None
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from _synth import calibrated_hardware, exact_adc
    return rc, frames(rc, n, synth=exact_adc, errors=calibrated_hardware(rc))


def scipy_chain_heatmap(calib, adc: np.ndarray) -> np.ndarray:
    """The baseline: the same heatmap by the plain scipy chain, complex64 throughout.

    Range FFT, Doppler FFT, TDM compensation, virtual array, 2D angle FFT of the full
    elevation × azimuth grid of every range–Doppler cell, ``|·|²``, maximum over Doppler —
    whole-array operations, no fusing, chunking or pruning.
    """
    w, h, ant = calib.waveform, calib.heatmap, calib.antenna
    ntx, nrx, nc, ns = w.frame_shape
    nr, ne, na = h.num_range_bins, h.num_elevation_bins, h.num_azimuth_bins
    c64 = np.complex64
    x = adc - coupling_signal(calib.coupling, ns)[:, :, None, :].astype(c64)
    x = x - x.mean(axis=-1, keepdims=True)
    if calib.phase_frequency is not None:
        x = x * phase_frequency_factors(calib.phase_frequency, w)[:, :, None, :].astype(c64)
    wr = np.hanning(ns + 1)[:-1]
    wd = np.hanning(nc + 1)[:-1]
    x = x * (wr / wr.sum()).astype(np.float32)
    rng = sfft.fft(x, axis=-1)[..., :nr] * (wd / wd.sum()).astype(np.float32)[:, None]
    dop = sfft.fftshift(sfft.fft(rng, axis=2), axes=2)                  # (tx, rx, Nd, Nr)
    k = np.arange(nc) - nc // 2
    dop = dop * np.exp(-2j * np.pi * np.arange(ntx)[:, None, None, None] * k[:, None]
                       / (nc * ntx)).astype(c64)
    v = ant.virtual
    elems = dop.reshape(ntx * nrx, nc, nr)[v.first_pair[:, 0] * nrx + v.first_pair[:, 1]]
    pos = np.rint(v.unique_positions).astype(int)
    grid = np.zeros((nc, nr, ne, na), dtype=c64)
    # element at +p gets exp(−jπρ p u): place at −p so that the FFT sums exp(+j2π k p / N)
    grid[:, :, (-pos[:, 1]) % ne, (-pos[:, 0]) % na] = elems.transpose(1, 2, 0)
    spec = sfft.fftshift(sfft.fft2(grid, axes=(2, 3)), axes=(2, 3))
    power = np.abs(spec) ** 2 / np.float32(len(pos) ** 2)
    d = power.argmax(axis=0)                                              # (Nr, Ne, Na)
    vel = k * w.wavelength / (2 * nc * w.tdm_period)
    out = np.empty((ne, na, nr, 2), dtype=np.float32)
    out[..., 0] = np.take_along_axis(power, d[None], 0)[0].transpose(1, 2, 0)
    out[..., 1] = vel[d].transpose(1, 2, 0)
    return out


def _clock():
    return time.process_time() if CPU_CLOCK else time.perf_counter()


def interleaved(jobs: dict, rounds: int) -> dict[str, float]:
    """Time per item [ms] of each ``name: (fn, items)`` job.

    The jobs take turns round after round, so that a shared machine's changing load affects
    all of them alike. Each item keeps its best time over the rounds and a job's time is the
    mean of its items' best times (a load spike then spoils one item's round, not a whole
    job's). The clock is process CPU time with ``--cpu-time`` (everything here is
    single-threaded), wall time otherwise.
    """
    best = {name: np.full(len(items), np.inf) for name, (_, items) in jobs.items()}
    for _ in range(rounds):
        for name, (fn, items) in jobs.items():
            for i, it in enumerate(items):
                t0 = _clock()
                fn(it)
                best[name][i] = min(best[name][i], _clock() - t0)
    return {k: float(v.mean()) * 1e3 for k, v in best.items()}


def _fft_flops(n: int, nonzero: float | None = None) -> float:
    """Operations of one complex ``n``-point FFT: ``5·n·log2(n)``, or ``5·n·log2(L)`` when only
    ``L`` inputs are nonzero (a pruned FFT: ``n/L`` transforms of ``L`` points; its twiddle
    multiplications are left out, so this is a lower bound)."""
    k = n if nonzero is None else min(max(nonzero, 1.0), n)
    return 5.0 * n * np.log2(k)


def floor_flops(calib, proc: RadarProcessor) -> dict[str, float]:
    """Operations of the transforms a heatmap cannot skip, per frame (see the module notes)."""
    w = calib.waveform
    nc, ns = w.num_chirps, w.num_samples
    nr, nd, nfft = proc.num_range_bins, proc.doppler_fft_size, proc.range_fft_size
    grid = proc.grid
    first = calib.antenna.virtual.first_pair
    read = np.unique(first[:, 0] * w.num_rx + first[:, 1]).size       # channels read
    rows = np.unique(grid.el_pos)
    widths = [np.ptp(grid.az_pos[grid.el_pos == q]) + 1 for q in rows]
    cells = nd * nr
    return {"range": read * nc * _fft_flops(nfft, ns),
            "Doppler": read * nr * _fft_flops(nd, nc),
            "azimuth": cells * sum(_fft_flops(grid.n_az, wq) for wq in widths),
            "elevation": cells * grid.n_az * _fft_flops(grid.n_el, rows.size)}


def fft_jobs(calib, proc: RadarProcessor) -> tuple[dict, dict[str, float]]:
    """The bare FFTs of one frame on random arrays of the right shapes, and their flops."""
    w = calib.waveform
    g = np.random.default_rng(2)
    ntx, nrx, nc, ns = w.frame_shape
    nr, nd = proc.num_range_bins, proc.doppler_fft_size
    grid = proc.grid
    rows, _ = elevation_steering(grid)
    width = int(grid.az_pos.max()) + 1

    def c64(*shape):
        return (g.standard_normal(shape) + 1j * g.standard_normal(shape)).astype(np.complex64)

    cube, rcube = c64(ntx, nrx, nc, ns), c64(ntx, nrx, nc, nr)
    # In cache-sized chunks (whole-frame calls are slower).
    rc = max(1, min(nr, CHUNK_SIZE // (rows.size * nd * grid.n_az)))
    az_rows = c64(rows.size, rc * nd, width)

    def azimuth(_) -> None:
        for _ in range(0, nr, rc):
            sfft.fft(az_rows, n=grid.n_az, axis=2)

    n_az_calls = -(-nr // rc)
    flops = {"FFT range": ntx * nrx * nc * _fft_flops(proc.range_fft_size),
             "FFT Doppler": ntx * nrx * nr * _fft_flops(nd),
             "FFT azimuth, occupied rows": n_az_calls * rows.size * rc * nd
             * _fft_flops(grid.n_az)}
    jobs = {
        "FFT range": (lambda _: sfft.fft(cube, n=proc.range_fft_size, axis=-1), [0] * 5),
        "FFT Doppler": (lambda _: sfft.fft(rcube, n=nd, axis=2), [0] * 5),
        "FFT azimuth, occupied rows": (azimuth, [0] * 2),
    }
    return jobs, flops


# ------------------------------------------------------------------ detection additions
DETECTION_STEPS = (
    ("plain chain", dict(noise_weighting="off", cfar_excision=False, doppler_unwrap=0.0,
                         sidelobe_guard=False, beam_doppler=False)),
    ("+ noise whitening", dict(cfar_excision=False, doppler_unwrap=0.0, sidelobe_guard=False,
                               beam_doppler=False)),
    ("+ CFAR excision", dict(doppler_unwrap=0.0, sidelobe_guard=False, beam_doppler=False)),
    ("+ Doppler alias search", dict(sidelobe_guard=False, beam_doppler=False)),
    ("+ sidelobe guard", dict(beam_doppler=False)),
    ("+ beam Doppler (default)", {}),
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
        proc_np = RadarProcessor(calib, engine="numpy")
        fr = frames(calib, args.frames)
        if args.only == "detection":
            print(f"\n== {name} ({what})")
            detection_costs(calib, fr, args.repeat)
            continue
        ref = scipy_chain_heatmap(calib, fr[0])
        checks = []
        for label, p in (("default", proc), ("numpy", proc_np)):
            got = p.heatmap(fr[0])
            err = np.max(np.abs(got[..., 0] - ref[..., 0])) / ref[..., 0].max()
            checks.append(f"{label} engine: max rel. diff {err:.1e}, same Doppler bin in "
                          f"{np.mean(got[..., 1] == ref[..., 1]):.3%} of cells")
        ffts, fft_flops = fft_jobs(calib, proc)
        jobs = {"ADC -> heatmap": (proc.heatmap, fr),
                "ADC -> heatmap, numpy engine": (proc_np.heatmap, fr),
                "ADC -> point cloud": (proc.pointcloud, fr),
                "scipy chain heatmap (baseline)": (partial(scipy_chain_heatmap, calib), fr[:2]),
                **ffts}
        near = near_field_frames(name, args.calib, args.frames)
        if near is not None:
            proc_nf = RadarProcessor(near[0])
            assert proc_nf.detector.beams.focus
            jobs[NF_PC] = (proc_nf.pointcloud, near[1])
            jobs[NF_HM] = (proc_nf.heatmap, near[1])
        t = interleaved(jobs, args.repeat)
        rate = max(fft_flops[k] / t[k] for k in ffts) * 1e-6          # GFLOP/s (t in ms)
        need = floor_flops(calib, proc)
        floor = sum(need.values()) / rate * 1e-6                        # ms
        npts = np.mean([len(proc.pointcloud(a)) for a in fr])
        engine = "numba" if "numba" in available_engines() else "numpy"
        print(f"\n== {name} ({what}); heatmap {calib.heatmap_shape}, {npts:.0f} points/frame; "
              f"default heatmap engine: {engine}")
        for k, v in t.items():
            print(f"  {k:<34s}{v:8.2f}")
        for c in checks:
            print(f"  (vs baseline, {c})")
        hm, base = t["ADC -> heatmap"], t["scipy chain heatmap (baseline)"]
        print(f"  floor: {sum(need.values()) * 1e-6:.1f} MFLOP of transforms ("
              + ", ".join(f"{k} {v * 1e-6:.1f}" for k, v in need.items())
              + f") at the best FFT rate measured, {rate:.1f} GFLOP/s: {floor:.2f} ms")
        print(f"  baseline / heatmap              {base / hm:6.2f}x   "
              f"(goal >= {16 if name == 'cascade' else 35})")
        print(f"  heatmap / floor                 {hm / floor:6.2f}x")
        print(f"  baseline / numpy-engine heatmap {base / t['ADC -> heatmap, numpy engine']:6.2f}x")
        print(f"  point cloud / baseline heatmap  {t['ADC -> point cloud'] / base:6.1%}   "
              f"(goal <= 15 %)")
        print(f"  point cloud / heatmap           {t['ADC -> point cloud'] / hm:6.2f}x   "
              f"(goal <= 1)")
        if near is not None:
            print(f"  near-field point cloud / heatmap{t[NF_PC] / t[NF_HM]:6.2f}x   (goal <= 1; "
                  f"{np.mean([len(proc_nf.pointcloud(a)) for a in near[1]]):.0f} points/frame)")
        if args.only == "all":
            detection_costs(calib, fr, args.repeat)


if __name__ == "__main__":
    main()
