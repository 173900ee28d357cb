"""Typed, frozen calibration objects parsed from ColoRadar calib files, and derived quantities.

One file kind per module (:mod:`.waveform`, :mod:`.antenna`, :mod:`.heatmap_grid`,
:mod:`.coupling`, :mod:`.phase_frequency`, :mod:`.transforms`); :mod:`.rig` holds the records of
a radar and of the whole rig, :mod:`.presets` builds them from the real rig's values, and
:mod:`.sensor` loads them from a calib folder or zip (falling back to the presets) and writes
them back.
"""

from .antenna import AntennaConfig, VirtualArray, format_antenna_cfg, parse_antenna_cfg
from .coupling import (
    CouplingCalib,
    format_coupling_calib,
    parse_coupling_calib,
    read_coupling_calib,
    write_coupling_calib,
)
from .heatmap_grid import HeatmapConfig, format_heatmap_cfg, parse_heatmap_cfg, shipped_angle_bins
from .phase_frequency import (
    PhaseFrequencyCalib,
    format_phase_frequency_calib,
    identity_phase_calib,
    parse_phase_frequency_calib,
    read_phase_frequency_calib,
    write_phase_frequency_calib,
)
from .presets import PRESET_TRANSFORMS, preset_calibration, preset_radar
from .rig import RADARS, SENSORS, Calibration, RadarCalib
from .sensor import (
    load_calibration,
    load_radar_calib,
    with_coupling,
    with_phase_calibration,
    write_calibration,
)
from .transforms import Extrinsic, format_transform, parse_transform
from .waveform import SPEED_OF_LIGHT, WaveformConfig, format_waveform_cfg, parse_waveform_cfg

__all__ = [
    "PRESET_TRANSFORMS",
    "RADARS",
    "SENSORS",
    "SPEED_OF_LIGHT",
    "AntennaConfig",
    "Calibration",
    "CouplingCalib",
    "Extrinsic",
    "HeatmapConfig",
    "PhaseFrequencyCalib",
    "RadarCalib",
    "VirtualArray",
    "WaveformConfig",
    "format_antenna_cfg",
    "format_coupling_calib",
    "format_heatmap_cfg",
    "format_phase_frequency_calib",
    "format_transform",
    "format_waveform_cfg",
    "identity_phase_calib",
    "load_calibration",
    "load_radar_calib",
    "parse_antenna_cfg",
    "parse_coupling_calib",
    "parse_heatmap_cfg",
    "parse_phase_frequency_calib",
    "parse_transform",
    "parse_waveform_cfg",
    "preset_calibration",
    "preset_radar",
    "read_coupling_calib",
    "read_phase_frequency_calib",
    "shipped_angle_bins",
    "with_coupling",
    "with_phase_calibration",
    "write_calibration",
    "write_coupling_calib",
    "write_phase_frequency_calib",
]
