"""The two engines' contract: what each compiled kernel computes, stated once.

Every stage of the chain runs on one of two engines (``ProcessingSettings.engine``): numpy, or
numba, where a compiled kernel (:mod:`coloradar.dsp._kernels`) replaces a numpy step. Each
kernel is defined by the numpy step it replaces — same inputs, same result to float32
rounding — and is called from one place, the stage method named below, which picks the engine.
``tests/test_dsp_engines.py`` holds one table of cases, each running such a stage method on both
engines with the same inputs and comparing them against this table's tolerance; it also checks
that every kernel has a contract here and a case there.

This module is data only (no numba needed to read it).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CONTRACTS", "KernelContract"]


@dataclass(frozen=True)
class KernelContract:
    """One compiled kernel's contract.

    Attributes
    ----------
    stage
        The stage method that calls it and picks the engine (``module:Class.method``, relative
        to :mod:`coloradar.dsp`).
    numpy
        The numpy code it replaces there (a function, or "the numpy branch of" the method).
    computes
        What both compute, in one line.
    rtol
        Relative tolerance of the two engines' results (float32 rounding; 0: identical).
    """

    stage: str
    numpy: str
    computes: str
    rtol: float


CONTRACTS: dict[str, KernelContract] = {
    "prepare_chirps": KernelContract(
        "cube_stage:CubeStage.range_cube", "the numpy branch of CubeStage.range_cube",
        "chirps less coupling and their mean, times calibration and windows, zero-padded", 1e-4),
    "power": KernelContract(
        "detection.cfar_stage:CFARStage.statistic", "np.abs(rd) ** 2",
        "|x|² of every channel and cell (float32)", 1e-5),
    "median_bits": KernelContract(
        "detect:channel_noise", "np.partition of each channel's cell powers",
        "each channel's median cell power beyond min_range (its noise power)", 0.0),
    "group_peaks": KernelContract(
        "detection.cfar_stage:CFARStage.group", "detection.cfar_stage.group_peaks",
        "CFAR cells that are peaks of the statistic, with their strong neighbours' peaks", 0.0),
    "peak_over_doppler": KernelContract(
        "heatmap:heatmap_from_elements", "heatmap_from_elements(engine='numpy')",
        "elevation transform, |·|² and maximum over Doppler of the azimuth spectra", 2e-4),
    "peak_over_doppler_planar": KernelContract(
        "heatmap:heatmap_from_elements", "heatmap_from_elements(engine='numpy')",
        "the whole heatmap of a planar array from the cube (azimuth FFT included)", 2e-4),
    "gather_rows": KernelContract(
        "heatmap:heatmap_from_elements", "the numpy gather of heatmap_from_elements",
        "the elements of a range chunk on their rows and azimuth positions", 2e-4),
    "steer_columns": KernelContract(
        "detection.beams:Beams.steer", "angle.steering",
        "beam weights exp(j(ca·az·u_y + cb·el·u_z)) of every element and direction", 1e-4),
    "focus_multiply": KernelContract(
        "detection.beams:Beams.focused", "angle.NearField.focus_sines",
        "vectors times the near-field focusing phases of their directions and ranges", 1e-4),
    "newton_refine": KernelContract(
        "detection.beams:Beams.newton", "angle.newton_refine",
        "directions refined by Newton steps on the Bartlett beam power", 1e-4),
    "elevation_search": KernelContract(
        "detection.beams:Beams.elevation_search", "the numpy branch of the method",
        "elevation of the strongest beam along a given azimuth, and its power", 1e-4),
    "azimuth_peaks": KernelContract(
        "detection.beams:Beams.azimuth_peaks", "angle.azimuth_peaks",
        "significant peaks of each azimuth profile, strongest first", 0.0),
    "beam_neighbourhood": KernelContract(
        "detection.guard:GuardStage.beam_neighbourhood", "the numpy branch of the method",
        "beam power at each point's direction over its 3 × 3 range–Doppler cells", 1e-4),
    "joint_amplitudes": KernelContract(
        "detection.resolve:ResolveStage.joint_amplitudes", "the numpy branch of the method",
        "least-squares amplitudes of the sources of each cell", 1e-4),
    "secondary_residual": KernelContract(
        "detection.resolve:ResolveStage.resolve", "the numpy branch of the method",
        "what is left of each secondary peak with its cell's strongest source removed", 1e-3),
    "secondary_bound": KernelContract(
        "detection.resolve:ResolveStage.resolve", "the elevation search of every secondary",
        "an upper bound of a secondary peak's residual over all elevations", 1e-3),
    "secondary_bound_focused": KernelContract(
        "detection.resolve:ResolveStage.resolve", "the elevation search of every secondary",
        "the same bound with near-field focusing", 1e-3),
    "joint_round": KernelContract(
        "detection.resolve:ResolveStage.resolve", "ResolveStage._joint_numpy",
        "one round of joint amplitudes and keep tests of cells with several sources", 1e-3),
    "joint_residuals": KernelContract(
        "detection.resolve:ResolveStage.resolve", "ResolveStage._joint_numpy",
        "each source's cell vector less the other sources' fit", 1e-3),
    "joint_powers": KernelContract(
        "detection.resolve:ResolveStage.resolve", "ResolveStage._joint_numpy",
        "the final joint powers of cells with several sources", 1e-3),
    "source_pairs": KernelContract(
        "detect:source_fit_residuals", "source_fit_residuals(kernel=None)",
        "residuals of the best two-source fits of each filled row", 1e-4),
}
"""Each public kernel of :mod:`coloradar.dsp._kernels` → its contract."""
