"""Radar signal processing: raw ADC frames → range–Doppler cubes, heatmaps, point clouds.

Pure array functions, one module per stage, composed by :class:`RadarProcessor`:

=========  ==============================================================================
cube       DC removal, phase/frequency calibration, coupling signal, range & Doppler FFTs
tdm        TDM-MIMO Doppler phase compensation
array      virtual array → azimuth × elevation FFT grid, bin angles, beamforming
angle      Bartlett and Capon/MVDR spectra per detection, sub-bin peak refinement
heatmap    peak-over-Doppler heatmap in the dataset's format
cfar       CA/GO/SO/OS CFAR in 1D/2D/3D with thresholds from a false-alarm probability
detect     detections, point clouds, point clouds from (shipped) heatmaps, cell placement
points     points of any radar frame (ADC, heatmap, shipped cloud): one converter for all
signs      which azimuth/elevation sign convention matches a sensor's own point clouds
=========  ==============================================================================

See ``docs/dsp.md`` for the chain, conventions and choices.
"""

from .angle import bartlett_spectrum, capon_spectrum, covariance, refine_peak
from .array import (
    OVERLAP_MODES,
    AngleGrid,
    OverlapMode,
    angle_grid,
    beamform,
    combine_channels,
    sines_to_unit,
)
from .cfar import (
    CFAR_EDGES,
    CFAR_KINDS,
    CFAREdge,
    CFARKind,
    CFARResult,
    cfar,
    cfar_scale,
    cfar_window,
    false_alarm_rate,
)
from .cube import (
    apply_phase_frequency_calibration,
    coupling_signal,
    doppler_fft,
    phase_frequency_factors,
    range_fft,
    remove_dc,
    signed_doppler_bins,
)
from .detect import Detections, heatmap_cell_xyz, heatmap_pointcloud, local_maxima
from .heatmap import heatmap_from_elements
from .points import (
    POINT_SOURCES,
    FramePoints,
    PointSource,
    default_point_source,
    radar_point_stream,
)
from .processor import (
    ANGLE_METHODS,
    COUPLING_DOMAINS,
    AngleMethod,
    CouplingDomain,
    ProcessingSettings,
    RadarProcessor,
)
from .signs import SignMatch, match_sign_convention
from .tdm import compensate_tdm, tdm_phase
from .windows import WINDOWS, WindowName, coherent_window, window

__all__ = [
    "ANGLE_METHODS",
    "CFAR_EDGES",
    "CFAR_KINDS",
    "COUPLING_DOMAINS",
    "OVERLAP_MODES",
    "POINT_SOURCES",
    "WINDOWS",
    "AngleGrid",
    "AngleMethod",
    "CFAREdge",
    "CFARKind",
    "CFARResult",
    "CouplingDomain",
    "Detections",
    "FramePoints",
    "OverlapMode",
    "PointSource",
    "ProcessingSettings",
    "RadarProcessor",
    "SignMatch",
    "WindowName",
    "angle_grid",
    "apply_phase_frequency_calibration",
    "bartlett_spectrum",
    "beamform",
    "capon_spectrum",
    "cfar",
    "cfar_scale",
    "cfar_window",
    "coherent_window",
    "combine_channels",
    "compensate_tdm",
    "coupling_signal",
    "covariance",
    "default_point_source",
    "doppler_fft",
    "false_alarm_rate",
    "heatmap_cell_xyz",
    "heatmap_from_elements",
    "heatmap_pointcloud",
    "local_maxima",
    "match_sign_convention",
    "phase_frequency_factors",
    "radar_point_stream",
    "range_fft",
    "refine_peak",
    "remove_dc",
    "signed_doppler_bins",
    "sines_to_unit",
    "tdm_phase",
    "window",
]
