"""The heatmap stage: range–Doppler cube → angle spectra → the dataset's heatmap (the peak over
Doppler of each direction's beam power), on the heatmap grid (:mod:`coloradar.dsp.heatmap` holds
the transforms and their engines). Settings: :class:`~coloradar.dsp.settings.ArraySettings`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.fft as sfft

from ..calib import HeatmapConfig, RadarCalib
from .array import AngleGrid, angle_grid, combine_channels
from .cube_stage import CubeStage
from .heatmap import heatmap_from_elements
from .settings import ArraySettings
from .tdm import alias_phase

if TYPE_CHECKING:
    from .detection import Detector

__all__ = ["HeatmapStage"]


class HeatmapStage:
    """Heatmaps of one radar.

    Parameters
    ----------
    calib
        The radar's calibration.
    cube
        The cube stage.
    settings
        The array settings (overlap, signs, ``heatmap_unwrap``).
    detector
        The detection stages, for ``heatmap_unwrap`` (the CFAR cells' aliases); None: the
        heatmap is never unwrapped.
    """

    def __init__(self, calib: RadarCalib, cube: CubeStage, settings: ArraySettings,
                 detector: Detector | None = None) -> None:
        self.calib, self.cube, self.settings, self.detector = calib, cube, settings, detector
        w, hm = calib.waveform, calib.heatmap
        self.grid: AngleGrid = angle_grid(calib.antenna, w.center_frequency,
                                          hm.num_elevation_bins, hm.num_azimuth_bins,
                                          settings.azimuth_sign, settings.elevation_sign)
        """:class:`~coloradar.dsp.array.AngleGrid` of the heatmap."""
        self._read_channels: tuple | None = None      # see read_channels

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
            unwrapped rate (:meth:`unwrapped`).
        """
        if self.reads_channels():
            return self.read_channels(adc)
        rd = self.cube.range_doppler(adc)
        return self.unwrapped(rd) if self.settings.heatmap_unwrap else self.from_cube(rd)

    def reads_channels(self) -> bool:
        """Whether :meth:`heatmap` takes :meth:`read_channels` (the compiled engine
        reading the first pair's channels, the TDM compensation applied in its gather)."""
        s = self.settings
        return self.cube.engine == "numba" and s.overlap == "first" and not s.heatmap_unwrap

    def read_channels(self, adc: np.ndarray) -> np.ndarray:
        """:meth:`from_cube` computing the range–Doppler cube of only the channels it reads
        (the cascade's 134 first pairs of 192 channels), less work. The values are those of
        :meth:`from_cube` with ``tdm_applied=False`` on the full cube to the bit (FFTs do not
        depend on the batch; the kernel multiplies each channel by the same TDM factors), so
        that :meth:`RadarProcessor.products <coloradar.dsp.RadarProcessor.products>` gives
        the same heatmap."""
        c = self.cube
        if self._read_channels is None:
            nrx = self.calib.frame_shape[1]
            first = self.calib.antenna.virtual.first_pair
            used, element_channel = np.unique(first[:, 0] * nrx + first[:, 1],
                                              return_inverse=True)
            tdm = None if c.tdm is None else c.tdm_table[used // nrx]   # (K, nd)
            self._read_channels = used, element_channel, tdm
        used, element_channel, tdm = self._read_channels
        rc = c.range_cube_compiled(c.check(adc), c.num_range_bins, used)  # (K, chirp, range)
        v = sfft.fft(rc, n=c.doppler_fft_size, axis=1, workers=c.settings.workers)
        if c.doppler_fft_size % 2:
            v = sfft.fftshift(v, axes=1)
        # the TDM factors go to the kernel, which applies them while gathering (a pass over
        # the cube less than v *= tdm)
        return heatmap_from_elements(v, self.grid, c.velocities,
                                     workers=c.settings.workers, engine=c.engine,
                                     channels=element_channel, doppler_phase=tdm)

    def from_cube(self, rd: np.ndarray, tdm_applied: bool = True) -> np.ndarray:
        """Heatmap of a range–Doppler cube; ``tdm_applied=False``: ``rd`` lacks the TDM
        compensation, which the engine then applies (``overlap="first"`` only)."""
        c = self.cube
        if self.settings.overlap == "first":
            # the engine reads each element's channel straight from the cube
            ntx, nrx = rd.shape[:2]
            first = self.calib.antenna.virtual.first_pair
            phase = None
            if not tdm_applied and c.tdm is not None:
                phase = c.tdm_table[np.arange(ntx * nrx) // nrx]            # (C, nd)
            return heatmap_from_elements(rd.reshape(ntx * nrx, *rd.shape[2:]), self.grid,
                                         c.velocities, workers=c.settings.workers,
                                         engine=c.engine,
                                         channels=first[:, 0] * nrx + first[:, 1],
                                         doppler_phase=phase)
        if not tdm_applied and c.tdm is not None:
            rd = rd * c.tdm
        elements = combine_channels(rd, self.calib.antenna.virtual, self.settings.overlap)
        return heatmap_from_elements(elements, self.grid, c.velocities,
                                     workers=c.settings.workers, engine=c.engine)

    def unwrapped(self, rd: np.ndarray) -> np.ndarray:
        """Heatmap with disambiguated Doppler (``heatmap_unwrap``), through the same kernel.

        Cells of the range–Doppler map that pass the CFAR get their best alias hypothesis
        (as detections do, at the bin centre); their channels are compensated for it before
        the kernel forms the peak-over-Doppler heatmap, and channel 1 of every output cell
        whose peak came from such a cell carries ``folded rate + 2m·v_max``. Cells below
        the CFAR keep the folded compensation and rate (noise has no Doppler to unwrap).
        """
        found = self.detector.cell_aliases(rd) if self.detector is not None else None
        if found is None or found[0].size == 0:
            return self.from_cube(rd)
        d, r, alias = found
        nd = rd.shape[2]
        rd = rd.copy()
        rd[:, :, d, r] *= alias_phase(rd.shape[0], alias)[:, None, :]
        out = self.from_cube(rd)
        m_map = np.zeros(rd.shape[2:], dtype=np.int64)
        m_map[d, r] = alias
        dv = self.cube.velocities[1] - self.cube.velocities[0]
        di = np.clip(np.rint(out[..., 1] / dv).astype(np.int64) + nd // 2, 0, nd - 1)
        ri = np.arange(out.shape[2])[None, None, :]
        out[..., 1] += (m_map[di, ri] * (nd * dv)).astype(np.float32)
        return out

    def config(self) -> HeatmapConfig:
        """The grid of :meth:`heatmap` with the true angles of its bins (for heatmap_cfg.txt).

        Elevation bins are ``asin(u_z)``; azimuth bins ``asin(u_y)``, exact in the ``el = 0``
        plane (off it the azimuth axis measures ``cos(el)·sin(az)``; see
        :meth:`~coloradar.dsp.array.AngleGrid.directions`).
        """
        c = self.cube
        g = self.grid
        return HeatmapConfig(c.num_range_bins, g.num_el, g.num_az, c.range_bin_width,
                             g.azimuth_angles, g.elevation_angles)
