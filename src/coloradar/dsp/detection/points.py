"""The point stage of detection: where each kept source is. Range and Doppler are refined on the
source's own beam over its 3 × 3 neighbourhood, the range corrected for the range–Doppler
coupling, and the point placed from the virtual array's phase centre.

Input: the kept sources with their beam neighbourhoods; output:
:class:`~coloradar.dsp.detect.Detections`. Settings: :class:`~coloradar.dsp.settings.PointSettings`.
"""

from __future__ import annotations

import numpy as np

from ...calib import RadarCalib
from ..angle import refine_peak
from ..array import phase_centre, sines_to_unit
from ..cube_stage import CubeStage
from ..detect import Detections
from ..settings import ArraySettings, PointSettings
from .cfar_stage import CFARCells
from .guard import Sources

__all__ = ["PointStage"]


class PointStage:
    """Points of one radar's kept sources.

    Parameters
    ----------
    calib
        The radar's calibration.
    cube
        The cube stage (range bins, range rates).
    settings
        The stage's settings.
    array
        The array settings (sign conventions of the phase centre).
    """

    def __init__(self, calib: RadarCalib, cube: CubeStage, settings: PointSettings,
                 array: ArraySettings) -> None:
        self.cube, self.settings = cube, settings
        w = calib.waveform
        # Where a point is: range and direction are measured from the virtual array's phase
        # centre; the Doppler shift within a chirp moves the beat frequency (f_c·v/S of range).
        self.centre = (phase_centre(calib.antenna, array.azimuth_sign, array.elevation_sign)
                       if settings.phase_centre else np.zeros(3))
        self.range_doppler = float(w.center_frequency / w.slope)

    def place(self, src: Sources, nb: np.ndarray, d_ref: np.ndarray, found: CFARCells
              ) -> Detections:
        """Detections of the kept sources ``src``: ``nb`` float64 ``(P, 3, 3)`` their beam
        neighbourhoods, ``d_ref`` float64 ``(P,)`` their cells' Doppler bins refined on the
        statistic (used without ``beam_doppler``)."""
        stat, noise = found.stat, found.noise
        nd, nr = stat.shape
        pd, pr, palias, uy, uz, peak = src.d, src.r, src.alias, src.uy, src.uz, src.peak
        r_ref = refine_peak(nb[:, 1, :], pr, nr, wrap=False)
        if self.settings.beam_doppler:
            dref = refine_peak(nb[:, :, 1], pd, nd, wrap=True)
        else:
            dref = d_ref
        k_true = dref - nd // 2 + (palias * nd if palias is not None else 0)
        rate = k_true * (self.cube.velocities[1] - self.cube.velocities[0])
        # Range–Doppler coupling: the Doppler shift within a chirp raises the beat frequency
        # by 2·f_c·v/c, which the range FFT reads as f_c·v/S of range.
        rng_c = r_ref * self.cube.range_bin_width - rate * self.range_doppler
        unit = sines_to_unit(uy, uz)
        # Range and direction are measured from the virtual array's phase centre.
        xyz = self.centre[None, :] + rng_c[:, None] * unit
        rng = np.linalg.norm(xyz, axis=1)
        return Detections(
            range_bin=pr.astype(np.int64), doppler_bin=pd.astype(np.int64), range=rng,
            range_rate=rate, azimuth=np.arctan2(xyz[:, 1], xyz[:, 0]),
            elevation=np.arcsin(np.clip(xyz[:, 2] / np.maximum(rng, 1e-12), -1.0, 1.0)),
            xyz=xyz, intensity=peak, power=found.plain_at(pd * nr + pr).astype(np.float64),
            snr=stat[pd, pr] / noise[pd, pr], alias=palias)
