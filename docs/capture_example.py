"""Write a synthetic DCA1000 capture of an AWR1843BOOST, to try ``coloradar import-capture``
without a radar (docs/capture.md, "Worked example").

    python docs/capture_example.py example_capture

writes ``example_capture/adc_data.bin`` (4 frames, laid out as mmWave Studio's post-processed
file of a 2-lane xWR18xx capture: per chirp each RX's samples in turn, complex values in pairs
``I0 I1 Q0 Q1``) and ``example_capture/profile.cfg`` (the SDK CLI profile it was "recorded"
with), and prints the targets it holds. The frames come from coloradar's physics simulator.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from coloradar.calib import AntennaConfig, HeatmapConfig, RadarCalib, WaveformConfig
from coloradar.sim.radar_if import synthesize_adc

TARGETS = [(5.0, 20.0, 1.6), (9.0, -30.0, -2.4)]   # range m, azimuth deg, range rate m/s
"""What the capture holds (elevation 0)."""

PROFILE = """\
% AWR1843BOOST, TX0 -> TX2 -> TX1, 4 RX, 64 complex samples at 10 Msps, 16 loops, 20 Hz
sensorStop
flushCfg
dfeDataOutputMode 1
channelCfg 15 7 0
adcCfg 2 1
adcbufCfg -1 0 0 1 1
profileCfg 0 77 30 6 20 0 0 60 1 64 10000 0 0 30
chirpCfg 0 0 0 0 0 0 0 1
chirpCfg 1 1 0 0 0 0 0 4
chirpCfg 2 2 0 0 0 0 0 2
frameCfg 0 2 16 4 50 1 0
lvdsStreamCfg -1 0 1 0
sensorStart
"""


def main(out: Path, num_frames: int = 4) -> None:
    # The profile above, as a waveform; TX slots TX0, TX2, TX1 at their board positions.
    w = WaveformConfig(num_rx=4, num_tx=3, num_samples=64, num_chirps=16, sample_rate=10e6,
                       start_frequency=77e9, idle_time=30e-6, adc_start_time=6e-6,
                       ramp_end_time=20e-6, slope=60e12)
    ant = AntennaConfig(76.8e9, np.array([(0, 0), (1, 0), (2, 0), (3, 0)], float),
                        np.array([(0, 0), (4, 0), (2, 1)], float))
    grid = HeatmapConfig(64, 1, 1, w.range_bin_width, np.zeros(1), np.zeros(1))
    calib = RadarCalib("single_chip", w, ant, grid)
    az = np.radians([t[1] for t in TARGETS])
    u = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], axis=1)
    pos = u * np.array([t[0] for t in TARGETS])[:, None]
    vel = u * np.array([t[2] for t in TARGETS])[:, None]
    rng = np.random.default_rng(0)
    words = []
    for _ in range(num_frames):
        f = synthesize_adc(calib, pos, vel, 4e4, noise_std=2.0, rng=rng)   # (tx, rx, loop, s)
        v = f.transpose(2, 0, 1, 3).reshape(-1, 2)      # chirps in time order, pairs of values
        iq = np.stack([v.real, v.imag], axis=1)          # (pairs, I|Q, 2): I0 I1 Q0 Q1
        words.append(np.rint(iq).astype("<i2").ravel())
    out.mkdir(parents=True, exist_ok=True)
    (out / "adc_data.bin").write_bytes(np.concatenate(words).tobytes())
    (out / "profile.cfg").write_text(PROFILE)
    print(f"{out}: {num_frames} frames; targets (range m, azimuth deg, range rate m/s): "
          f"{TARGETS}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "example_capture"))
