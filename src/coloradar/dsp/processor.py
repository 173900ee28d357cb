"""The radar processor: one object per radar that turns ADC frames into heatmaps, range–Doppler
maps, detections and point clouds. It is a thin composition of the chain's stages, each built
once per radar from the calibration and its own settings group
(:class:`~coloradar.dsp.settings.ProcessingSettings`)::

    adc (tx, rx, chirp, sample) complex64
      → CubeStage      coupling, DC, calibration, windows, range FFT,
                       Doppler FFT, TDM compensation           (cube_stage)   = range_doppler(adc)
      → Σ|·|² over channels                                                   = range_doppler_power(adc)
      → HeatmapStage   unique virtual elements → 2D angle FFT per cell
                       → peak over Doppler                      (heatmap_stage) = heatmap(adc)
      → Detector       CFAR → cells and aliases → angle peaks → several-source
                       resolution → guard → points              (detection/)  = detect(adc)
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from ..calib import HeatmapConfig, RadarCalib
from .array import AngleGrid
from .cube_stage import CubeStage
from .detect import Detections
from .detection import Detector
from .detection.cfar_stage import STRONG_NEIGHBOUR
from .detection.resolve import MAX_SOURCES
from .heatmap import resolve_engine
from .heatmap_stage import HeatmapStage
from .settings import (
    ANGLE_METHODS,
    COUPLING_DOMAINS,
    NOISE_WEIGHTINGS,
    AngleMethod,
    CouplingDomain,
    NoiseWeighting,
    ProcessingSettings,
)

__all__ = ["ANGLE_METHODS", "COUPLING_DOMAINS", "MAX_SOURCES", "NOISE_WEIGHTINGS",
           "STRONG_NEIGHBOUR", "AngleMethod", "CouplingDomain", "NoiseWeighting",
           "ProcessingSettings", "RadarProcessor"]


class RadarProcessor:
    """ADC frames of one radar → range–Doppler cubes, heatmaps, detections, point clouds.

    Parameters
    ----------
    calib
        The radar's calibration (``seq.calib.cascade`` or ``seq.calib.single_chip``).
    settings
        A :class:`ProcessingSettings`; keyword arguments override single settings.

    Attributes
    ----------
    cube, heatmaps, detector
        The stages: :class:`~coloradar.dsp.cube_stage.CubeStage`,
        :class:`~coloradar.dsp.heatmap_stage.HeatmapStage`,
        :class:`~coloradar.dsp.detection.Detector`.

    Examples
    --------
    >>> proc = RadarProcessor(seq.calib.cascade, angle_method="capon")   # doctest: +SKIP
    >>> hm = proc.heatmap(seq.cascade.adc[0])         # (el, az, range, 2) float32
    >>> pts = proc.pointcloud(seq.cascade.adc[0])     # (N, 5) float32
    """

    def __init__(self, calib: RadarCalib, settings: ProcessingSettings | None = None,
                 **overrides) -> None:
        s = (settings or ProcessingSettings()).replace(**overrides)
        self.calib = calib
        self.settings = s
        self.cube = CubeStage(calib, s.cube, resolve_engine(s.engine))
        self.detector = Detector(calib, s, self.cube)
        self.heatmaps = HeatmapStage(calib, self.cube, s.array, self.detector)

    # ------------------------------------------------------------ geometry
    @property
    def range_fft_size(self) -> int:
        """Range FFT length (samples, or more with zero padding)."""
        return self.cube.range_fft_size

    @property
    def doppler_fft_size(self) -> int:
        """Doppler FFT length (chirp loops, or more with zero padding)."""
        return self.cube.doppler_fft_size

    @property
    def num_range_bins(self) -> int:
        """Range bins kept (heatmap and detection)."""
        return self.cube.num_range_bins

    @property
    def range_bin_width(self) -> float:
        """Range of one range bin [m]."""
        return self.cube.range_bin_width

    @property
    def velocities(self) -> np.ndarray:
        """float64 ``(doppler,)``: range rate of each Doppler bin [m/s]."""
        return self.cube.velocities

    @property
    def grid(self) -> AngleGrid:
        """:class:`~coloradar.dsp.array.AngleGrid` of the heatmap."""
        return self.heatmaps.grid

    @property
    def detection_grid(self) -> AngleGrid:
        """:class:`~coloradar.dsp.array.AngleGrid` of detection (the heatmap's, oversampled)."""
        return self.detector.beams.grid

    # ------------------------------------------------------------------ cubes
    def range_doppler(self, adc: np.ndarray) -> np.ndarray:
        """Calibrated, TDM-compensated range–Doppler cube.

        Parameters
        ----------
        adc
            complex ``(tx, rx, chirp, sample)`` ADC frame.

        Returns
        -------
        numpy.ndarray
            complex64 ``(tx, rx, doppler, range)``; Doppler index ``i`` ↔ range rate
            ``velocities[i]``, range index ``r`` ↔ ``r · range_bin_width``. Unit coherent gain:
            a target of amplitude ``a`` (counts) at bin centres gives ``a`` in its cell.
        """
        return self.cube.range_doppler(adc)

    def range_doppler_power(self, adc: np.ndarray) -> np.ndarray:
        """Non-coherent range–Doppler power, float32 ``(doppler, range)``: ``Σ_{tx,rx} |·|²``."""
        mag = np.abs(self.range_doppler(adc))
        np.square(mag, out=mag)
        return mag.sum(axis=(0, 1))

    # ---------------------------------------------------------------- heatmap
    def heatmap(self, adc: np.ndarray) -> np.ndarray:
        """Heatmap in the dataset's format.

        Returns
        -------
        numpy.ndarray
            float32 ``(el, az, range, 2)`` on :meth:`heatmap_config`'s grid: channel 0 the peak
            over Doppler of the angle spectrum's power (a target of amplitude ``a`` per channel
            gives ``|a|²``), channel 1 the range rate of that peak [m/s]: the centre of the
            peak's Doppler bin, *folded* into ``[−v_max, v_max)``, with the angle spectrum
            TDM-compensated for that folded bin. With ``heatmap_unwrap`` the cells that pass
            the CFAR are compensated for their best Doppler alias and channel 1 carries the
            unwrapped rate (:meth:`HeatmapStage.unwrapped
            <coloradar.dsp.heatmap_stage.HeatmapStage.unwrapped>`).
        """
        return self.heatmaps.heatmap(adc)

    def heatmap_config(self) -> HeatmapConfig:
        """The grid of :meth:`heatmap` with the true angles of its bins (for heatmap_cfg.txt).

        Elevation bins are ``asin(u_z)``; azimuth bins ``asin(u_y)``, exact in the ``el = 0``
        plane (off it the azimuth axis measures ``cos(el)·sin(az)``; see
        :meth:`~coloradar.dsp.array.AngleGrid.directions`).
        """
        return self.heatmaps.config()

    # ------------------------------------------------------------- detection
    def detect(self, adc: np.ndarray) -> Detections:
        """CFAR detections on the range–Doppler power map, each with its direction.

        Returns
        -------
        Detections
        """
        rcube = self.cube.range_cube(adc, extra=True)
        nr = self.num_range_bins
        return self.detector.detect(rcube[..., :nr],
                                    self.cube.doppler(rcube[..., :nr], compensate=False),
                                    self.cube.doppler(rcube[..., nr:], compensate=False))

    def pointcloud(self, adc: np.ndarray) -> np.ndarray:
        """Point cloud of one frame, float32 ``(N, 5)``: ``x y z intensity range_rate``."""
        return self.detect(adc).pointcloud()

    def products(self, adc: np.ndarray, heatmap: bool = True, pointcloud: bool = True
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Heatmap and/or point cloud of one frame from one range–Doppler computation.

        Returns
        -------
        tuple
            ``(heatmap or None, pointcloud or None)`` as :meth:`heatmap` and :meth:`pointcloud`.
        """
        nr = self.num_range_bins
        cube, hms = self.cube, self.heatmaps
        in_kernel = heatmap and hms.reads_channels()    # TDM applied as heatmap() does
        rcube = cube.range_cube(adc, extra=pointcloud)
        rd = cube.doppler(rcube[..., :nr], compensate=not (pointcloud or in_kernel))
        pts = None
        if pointcloud:
            pts = self.detector.detect(rcube[..., :nr], rd,
                                       cube.doppler(rcube[..., nr:], compensate=False)
                                       ).pointcloud()
            if heatmap and not in_kernel and cube.tdm is not None:
                rd *= cube.tdm                       # as CubeStage.doppler: the heatmap's bits
        if not heatmap:
            return None, pts
        if in_kernel:
            return hms.from_cube(rd, tdm_applied=False), pts
        return (hms.unwrapped(rd) if self.settings.heatmap_unwrap else hms.from_cube(rd)), pts

    def __repr__(self) -> str:
        changed = {f.name: getattr(self.settings, f.name) for f in fields(self.settings)
                   if getattr(self.settings, f.name) != f.default}
        return f"RadarProcessor({self.calib.name!r}, {changed})"
