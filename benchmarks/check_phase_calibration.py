"""Issue 39's figures: the phase calibration measured from data, and the Doppler alias choice on
matched, uncalibrated and data-calibrated boards (docs/calibration.md, docs/dsp.md).

    python benchmarks/check_phase_calibration.py [--seeds 5] [--trials 40]

1. ``self_calibrate`` on cells generated from the model (far-field point per cell, a second
   scatterer in a fifth of them, 15 dB): per-channel phase error after the unobservable ramps,
   over seeds, both radars, and its cost.
2. ``coloradar calibrate phase``'s estimator on simulated corridor runs with planted errors
   (TX ±180°, RX ±10°, 2 dB; the cascade's own random channel errors on top, uncalibrated),
   against the truth's gains; the azimuth offset it leaves (in azimuth bins).
3. Targets beyond v_max (as ``tests/test_dsp_honest_detection.py``: 15 dB, ±50°): share within
   one azimuth bin and 1.5 Doppler bins on a matched board, on the planted board with the
   measured calibration, and on the planted board uncalibrated (folded by default).
4. The slow runs' points: share with an alias other than 0, uncalibrated and calibrated.
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

from _synth import matched  # noqa: E402
from test_phase_calibration import fast_trials, planted_cells, positions  # noqa: E402

from coloradar.calib import PhaseFrequencyCalib, preset_radar, with_phase_calibration  # noqa: E402
from coloradar.dataset import open_sequence  # noqa: E402
from coloradar.dsp import RadarProcessor  # noqa: E402
from coloradar.dsp.phase_estimate import (  # noqa: E402
    PhaseEstimateSettings,
    _slope,
    estimate_phase_calibration,
    gauge_aligned_error,
    self_calibrate,
)
from coloradar.geometry import rig_velocity, trajectory_from_groundtruth  # noqa: E402
from coloradar.sim import PhaseErrors  # noqa: E402
from coloradar.sim.run import simulate_run  # noqa: E402
from coloradar.sim.truth import load_truth  # noqa: E402

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


def simulated(seeds: int, trials: int, root: Path) -> None:
    print("2-4. simulated corridor runs, 4 s, planted TX ±180°, RX ±10°, 2 dB, uncalibrated")
    for name in RADARS:
        rows = []
        for seed in range(seeds):
            out = root / f"{name}{seed}"
            res = simulate_run(out, scene="corridor", duration=4.0, seed=seed,
                               sensors=[name, "groundtruth"], heatmaps=False, board_seed=seed,
                               phase_errors=PhaseErrors(name, tx_phase_deg=180.0,
                                                        rx_phase_deg=10.0, gain_db=2.0))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                seq = open_sequence(res.run_path)
            rc = seq.calib.radar(name)
            adc = seq.radar(name).adc
            vel = rig_velocity(trajectory_from_groundtruth(seq), adc.timestamps,
                               calib=seq.calib, sensor=name).linear
            t0 = time.perf_counter()
            est = estimate_phase_calibration(adc, rc, velocities=vel)
            cost = time.perf_counter() - t0
            gains = load_truth(res.run_path)[f"{name}/channel_gain"]
            tx, rx, rho = positions(name)
            err = gauge_aligned_error(est.fit.gain, gains, tx, rx)
            z = (est.fit.gain * np.conj(gains)).ravel()
            vp = (tx[:, None, :] + rx[None, :, :]).reshape(-1, 2)
            cal = with_phase_calibration(seq.calib, est.calibration, name).radar(name)
            proc = RadarProcessor(cal, coupling_subtraction=False, phase_centre=False)
            az_bin = 2.0 / (proc.grid.num_az * proc.grid.rho)
            offset = _slope(z / np.abs(z), vp[:, 0], coherent=True) / (np.pi * rho) / az_bin
            w = rc.waveform
            hw = PhaseFrequencyCalib(np.zeros(gains.shape), gains, w.slope, w.sample_rate,
                                     near_field=False)
            v_range = (1.1, 1.7) if name == "single_chip" else (1.3, 2.3)
            ok = {}
            for label, c, board in (("matched", matched(preset_radar(name)) if name ==
                                     "single_chip" else None, None),
                                    ("calibrated", cal, hw), ("uncalibrated", rc, hw)):
                if c is None:
                    continue
                p = RadarProcessor(c, coupling_subtraction=False, phase_centre=False)
                board = board or PhaseFrequencyCalib(np.zeros(gains.shape),
                                                     np.ones(gains.shape, complex), w.slope,
                                                     w.sample_rate, near_field=False)
                r = fast_trials(c, board, p, v_range, trials, seed=7 + seed)
                ok[label] = float(np.mean((r[:, 0] <= 1.0) & (r[:, 1] <= 1.5)))
            moved = {}
            for label, c in (("uncal", rc), ("cal", cal)):
                p = RadarProcessor(c)
                al = np.concatenate([p.detect(adc[k]).alias for k in range(len(adc))])
                moved[label] = (int(np.sum(al != 0)), al.size)
            rows.append((seed, np.sqrt(np.mean(err**2)), np.abs(err).max(), offset, cost,
                         est.cells, ok, moved))
        for seed, rms, worst, off, cost, cells, ok, moved in rows:
            fast = ", ".join(f"{k} {100 * v:.0f} %" for k, v in ok.items())
            print(f"   {name:12s} seed {seed}: phase rms {rms:.2f}° worst {worst:.2f}°, "
                  f"azimuth offset {off:+.2f} bins; {cells} cells, {cost:.1f} s | fast targets "
                  f"{fast} | slow scene aliased: uncal {moved['uncal'][0]}/{moved['uncal'][1]}, "
                  f"cal {moved['cal'][0]}/{moved['cal'][1]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--trials", type=int, default=40)
    args = ap.parse_args()
    synthetic(args.seeds)
    root = Path(tempfile.mkdtemp(prefix="phasecal"))
    try:
        simulated(args.seeds, args.trials, root)
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
