"""Built-in calibration presets of the ColoRadar rig, so that coloradar works without a calib folder.

Numbers come from the ColoRadar paper (Kramer et al., IJRR 2021) and the dataset's documented
sensor configuration: TI MMWCAS-RF-EVM cascade (12 TX x 16 RX, 256 samples, 16 loops, 5 Hz) and
TI AWR1843BOOST single chip (3 TX x 4 RX, 128 samples, 128 loops, 10 Hz), with the cascade's chirp
times in their correct units. Heatmap angle lists follow the shipped heatmaps' labelling
(:func:`~coloradar.calib.heatmap_grid.shipped_angle_bins`). Presets carry no coupling or
phase/frequency calibration: those are per-board measurements.
"""

from __future__ import annotations

import numpy as np

from ..errors import SettingsError
from .antenna import AntennaConfig
from .heatmap_grid import HeatmapConfig, shipped_angle_bins
from .rig import Calibration, RadarCalib
from .transforms import Extrinsic
from .waveform import WaveformConfig

__all__ = ["PRESET_TRANSFORMS", "preset_calibration", "preset_radar"]

CASCADE_WAVEFORM = WaveformConfig(
    num_rx=16, num_tx=12, num_samples=256, num_chirps=16, sample_rate=8.0e6,
    start_frequency=77.0e9, idle_time=5.0e-6, adc_start_time=6.0e-6, ramp_end_time=40.0e-6,
    slope=79.0e12,
)
SINGLE_CHIP_WAVEFORM = WaveformConfig(
    num_rx=4, num_tx=3, num_samples=128, num_chirps=128, sample_rate=10.666e6,
    start_frequency=77.0e9, idle_time=110.0e-6, adc_start_time=7.0e-6, ramp_end_time=20.0e-6,
    slope=100.0e12,
)

# MMWCAS-RF-EVM: four AWR2243 chips. RX azimuth positions in half wavelengths at 76.8 GHz; the
# 12 TX form a 9-element azimuth line (spacing 4) plus three elevated TX on chip 1.
_CASCADE_RX = [(a, 0) for a in (0, 1, 2, 3, 11, 12, 13, 14, 46, 47, 48, 49, 50, 51, 52, 53)]
_CASCADE_TX = [(0, 0), (4, 0), (8, 0), (9, 1), (10, 4), (11, 6),
               (12, 0), (16, 0), (20, 0), (24, 0), (28, 0), (32, 0)]
# AWR1843BOOST: 4 RX at λ/2, TX 0 and TX 1 two RX-array widths apart, TX 2 raised by λ/2.
_SINGLE_RX = [(0, 0), (1, 0), (2, 0), (3, 0)]
_SINGLE_TX = [(0, 0), (4, 0), (2, 1)]

def _extrinsic(translation: list[float], quaternion: list[float]) -> Extrinsic:
    return Extrinsic(np.array(translation), np.array(quaternion))


PRESET_TRANSFORMS: dict[str, Extrinsic] = {
    "cascade": _extrinsic([0.03, 0.12, -0.09], [0.0, 0.0, 0.706825181105, 0.707388269167]),
    "single_chip": _extrinsic([-0.145, 0.09, -0.025], [0.0, 0.0, 0.706825181105, 0.707388269167]),
    "lidar": _extrinsic([-0.075, -0.02, 0.03618], [0.0, 0.0, 0.721382357437, -0.692536998563]),
    "imu": _extrinsic([0.0, 0.0, 0.0],
                      [0.707105451466, 0.707108048814, 0.000209535067884, 0.00020953429822]),
    "vicon": _extrinsic([0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]),
}
"""``base_T_sensor`` of the real ColoRadar rig (the dataset's ``calib/transforms``)."""


def _grid(n_range: int, n_el: int, n_az: int, width: float) -> HeatmapConfig:
    return HeatmapConfig(n_range, n_el, n_az, width, shipped_angle_bins(n_az),
                         shipped_angle_bins(n_el))


def preset_radar(name: str) -> RadarCalib:
    """The built-in calibration of ``"cascade"`` or ``"single_chip"``."""
    if name == "cascade":
        w = CASCADE_WAVEFORM
        return RadarCalib("cascade", w, AntennaConfig(76.8e9, np.array(_CASCADE_RX),
                                                      np.array(_CASCADE_TX)),
                          _grid(128, 32, 128, w.range_bin_width))
    if name == "single_chip":
        w = SINGLE_CHIP_WAVEFORM
        return RadarCalib("single_chip", w, AntennaConfig(76.8e9, np.array(_SINGLE_RX),
                                                          np.array(_SINGLE_TX)),
                          _grid(64, 16, 64, w.range_bin_width))
    raise SettingsError(f"unknown radar {name!r}")


def preset_calibration() -> Calibration:
    """The built-in calibration of the whole rig."""
    return Calibration(preset_radar("cascade"), preset_radar("single_chip"),
                       dict(PRESET_TRANSFORMS), "preset",
                       ("cascade radar", "single_chip radar",
                        *(f"{s} extrinsic" for s in PRESET_TRANSFORMS)))
