"""Radar signal processing: raw ADC frames → range–Doppler cubes, heatmaps, point clouds.

Pure array functions, one module per step, and the chain's stages built from them, composed by
:class:`RadarProcessor`:

=============  ==========================================================================
cube           DC removal, phase/frequency calibration, coupling signal, range & Doppler FFTs
tdm            TDM-MIMO Doppler phase compensation, Doppler alias hypotheses
array          virtual array → azimuth × elevation FFT grid, bin angles, beamforming
angle          Bartlett and Capon/MVDR spectra per detection, sub-bin peak refinement
heatmap        peak-over-Doppler heatmap in the dataset's format (numpy and numba engines)
cfar           CA/GO/SO/OS CFAR in 1D/2D/3D with thresholds from a false-alarm probability
detect         detections, point clouds, point clouds from (shipped) heatmaps, cell placement
points         points of any radar frame (ADC, heatmap, shipped cloud): one converter for all
signs          which azimuth/elevation sign convention matches a sensor's own point clouds
settings       :class:`ProcessingSettings` and its groups, one per stage
cube_stage     stage 1, the cube: ADC → range cube → range–Doppler cube
heatmap_stage  stage 2, the heatmap: range–Doppler cube → angle spectra → heatmap
detection/     stage 3, detection: CFAR → cells and aliases → angle peaks → several-source
               resolution → guard → points (one module each, :class:`detection.Detector`)
processor      :class:`RadarProcessor`, the composition
_kernels/      the compiled (numba) kernels, one module per stage
=============  ==========================================================================

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
    CFARConfig,
    CFAREdge,
    CFARKind,
    CFARResult,
    cfar,
    cfar_scale,
    cfar_window,
    false_alarm_rate,
    run_cfar,
)
from .coupling_estimate import CouplingEstimate, estimate_coupling
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
from .processor import RadarProcessor
from .settings import (
    ANGLE_METHODS,
    COUPLING_DOMAINS,
    AliasSettings,
    AngleMethod,
    AngleSettings,
    ArraySettings,
    CFARSettings,
    CouplingDomain,
    CubeSettings,
    GuardSettings,
    PointSettings,
    ProcessingSettings,
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
    "AliasSettings",
    "AngleGrid",
    "AngleMethod",
    "AngleSettings",
    "ArraySettings",
    "CFARConfig",
    "CFAREdge",
    "CFARKind",
    "CFARResult",
    "CFARSettings",
    "CouplingDomain",
    "CouplingEstimate",
    "CubeSettings",
    "Detections",
    "FramePoints",
    "GuardSettings",
    "OverlapMode",
    "PointSettings",
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
    "estimate_coupling",
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
    "run_cfar",
    "signed_doppler_bins",
    "sines_to_unit",
    "tdm_phase",
    "window",
]
