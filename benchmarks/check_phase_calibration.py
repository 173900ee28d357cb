"""Issue 39's figures: the phase calibration measured from data, and the Doppler alias choice on
matched, uncalibrated and data-calibrated boards (docs/calibration.md, docs/dsp.md).

    python benchmarks/check_phase_calibration.py [--seeds 5] [--trials 40]

1. ``self_calibrate`` on cells generated from the model (far-field point per cell, a second
   scatterer in a fifth of them, 15 dB): per-channel phase error after the unobservable ramps,
   over seeds, both radars, and its cost.
2. ``coloradar calibrate phase``'s estimator on simulated corridor runs with planted errors
   (TX ±180°, RX ±10°, 2 dB) and no calibration (the cascade's own random channel phases and
   delays then unknown too), or the board's own gone stale (cascade), against the truth.
3. Targets beyond v_max (as ``tests/test_dsp_honest_detection.py``: 15 dB, ±50°): share within
   one azimuth bin and 1.5 Doppler bins on the planted board before (folded, or fooled by the
   stale calibration) and with the measured calibration; the trials' common azimuth offset.
4. The slow runs' points: how many have an alias other than 0, before and calibrated.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from coloradar.calib import PhaseFrequencyCalib, with_phase_calibration
from coloradar.dataset import open_sequence
from coloradar.dsp import RadarProcessor
from coloradar.dsp.phase_estimate import (
    PhaseEstimateSettings,
    estimate_phase_calibration,
    gauge_aligned_error,
    self_calibrate,
)
from coloradar.geometry import rig_velocity, trajectory_from_groundtruth
from coloradar.sim import PhaseErrors
from coloradar.sim.run import simulate_run
from coloradar.sim.truth import load_truth
from test_phase_calibration import fast_trials, planted_cells, positions

RADARS = ("single_chip", "cascade")


def synthetic(seeds: int) -> None:
    print("1. self-calibration on model cells (15 dB, 20 % two-scatterer cells); phase error "
          "after ramps [deg]: rms median / worst channel worst, over seeds; time per call")
    for name, k in (("single_chip", 600), ("cascade", 800)):
        tx, rx, rho = positions(name)
        for case in ((180, 20, 5), (180, 180, 180)):
            rms, worst, dt = [], [], []
            for seed in range(seeds):
                x, gain = planted_cells(name, k, 1000 + seed, *case)
                t0 = time.perf_counter()
                fit = self_calibrate(x, tx, rx, rho, PhaseEstimateSettings(
                    elevation_reference="tx"))
                dt.append(time.perf_counter() - t0)
                err = gauge_aligned_error(fit.gain, gain, tx, rx)
                rms.append(np.sqrt(np.mean(err**2)))
                worst.append(np.abs(err).max())
            print(f"   {name:12s} {k} cells, TX/RX/channel ±{case}: rms {np.median(rms):.2f}, "
                  f"worst {max(worst):.2f}; {np.median(dt):.2f} s")


RELEASED = (Path(__file__).resolve().parents[2] / "shared" / "reference" / "coloradar_calib"
            / "cascade" / "phase_frequency_calib.txt")
"""The release's cascade calibration (read, never copied), planted as a board's errors."""
SCENARIOS = (("single_chip", "none", None), ("cascade", "none", None),
             ("cascade", "board", None), ("cascade", "none", RELEASED))
"""(radar, what its calib holds: no phase calibration, or the board's own gone stale; the
board's own errors: the simulator's, or the release's file)."""


def simulated(seeds: int, trials: int, root: Path, only: list[int] | None = None) -> None:
    print("2-4. simulated corridor runs, 4 s, rig at 0.85 m/s, planted TX ±180°, RX ±10°, "
          "2 dB; calib: none, or the board's own without the planted errors (stale)")
    for k, (name, calibration, board) in enumerate(SCENARIOS):
        if only is not None and k not in only:
            continue
        if board is not None and not board.is_file():
            print(f"   (the release's calibration is not at {board}: its scenario is left out)")
            continue
        for seed in range(seeds):
            out = root / f"{name}{calibration}{board is not None}{seed}"
            # the release's errors alone (what it recovers of them), or planted ones on top
            errs = (PhaseErrors(name, 0.0, 0.0, 0.0, calibration, str(board)) if board else
                    PhaseErrors(name, 180.0, 10.0, 2.0, calibration))
            res = simulate_run(out, scene="corridor", duration=4.0, seed=seed,
                               sensors=[name, "groundtruth"], heatmaps=False, board_seed=seed,
                               phase_errors=errs)
            label = "release" if board else calibration
            print(f"   {name:12s} {label:7s} seed {seed}: "
                  + one_run(res.run_path, name, trials, seed), flush=True)


def one_run(path: Path, name: str, trials: int, seed: int) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seq = open_sequence(path)
    rc = seq.calib.radar(name)
    adc = seq.radar(name).adc
    vel = rig_velocity(trajectory_from_groundtruth(seq), adc.timestamps, calib=seq.calib,
                       sensor=name).linear
    t0 = time.perf_counter()
    est = estimate_phase_calibration(adc, rc, velocities=vel)
    cost = time.perf_counter() - t0
    truth = load_truth(path)
    gains, delays = truth[f"{name}/channel_gain"], truth[f"{name}/channel_delay"]
    w = rc.waveform
    hw = PhaseFrequencyCalib(delays, gains, w.slope, w.sample_rate, near_field=False)
    tx, rx, _ = positions(name)
    # the estimate against the truth: as a whole calibration (the file's phases over the
    # board's gains, both relative to channel (0, 0))
    pf = est.calibration
    err = gauge_aligned_error(pf.phase / pf.phase[0, 0], gains, tx, rx)
    cal = with_phase_calibration(seq.calib, pf, name).radar(name)
    v_range = (1.1, 1.7) if name == "single_chip" else (1.3, 2.3)
    ok = {}
    for label, c in (("before", rc), ("calibrated", cal)):
        p = RadarProcessor(c, coupling_subtraction=False, phase_centre=False)
        r = fast_trials(c, hw, p, v_range, trials, seed=7 + seed)
        ok[label] = float(np.mean((np.abs(r[:, 0]) <= 1.0) & (r[:, 1] <= 1.5)))
        if label == "calibrated":
            ok["offset"] = float(np.median(r[:, 0]))
            a = np.abs(r[:, 0] - np.median(r[:, 0]))
            ok["less offset"] = float(np.mean((a <= 1.0) & (r[:, 1] <= 1.5)))
    moved = {}
    for label, c in (("before", rc), ("calibrated", cal)):
        p = RadarProcessor(c)
        al = np.concatenate([p.detect(adc[k]).alias for k in range(len(adc))])
        moved[label] = f"{int(np.sum(al != 0))}/{al.size}"
    derr = ""
    if est.delay is not None:
        d = est.delay - est.delay[0, 0]
        derr = f", delays rms {np.sqrt(np.mean((d - delays) ** 2)):.3f} bins"
    return (f"phase rms {np.sqrt(np.mean(err**2)):.2f}° worst {np.abs(err).max():.2f}°{derr}; "
            f"{est.cells} cells, {cost:.1f} s, azimuth gauge {est.fit.azimuth_reference} | "
            f"fast targets before {100 * ok['before']:.0f} %, calibrated "
            f"{100 * ok['calibrated']:.0f} % (azimuth offset {ok['offset']:+.2f} bins; "
            f"{100 * ok['less offset']:.0f} % less it) | slow scene aliased: before "
            f"{moved['before']}, calibrated {moved['calibrated']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--only", type=int, nargs="+", metavar="K",
                    help="only these simulated scenarios (indices into SCENARIOS), no part 1")
    args = ap.parse_args()
    if args.only is None:
        synthetic(args.seeds)
    root = Path(tempfile.mkdtemp(prefix="phasecal"))
    try:
        simulated(args.seeds, args.trials, root, args.only)
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
