"""Stage 8b: detections and point clouds (from ADC-derived cubes or from shipped heatmaps).

Point clouds are float32 ``(N, 5)``: ``x y z intensity range_rate`` in the radar frame (x
boresight, y left, z up). From a range–Doppler detection at range ``R`` and direction sines
``(u_y, u_z)`` the point is ``R·(√(1 − u_y² − u_z²), u_y, u_z)`` — the same as
``(R cos el cos az, R cos el sin az, R sin el)`` with ``el = asin(u_z)``,
``az = atan2(u_y, u_x)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import maximum_filter

from ..calib import HeatmapConfig
from ..errors import FormatError
from .array import sines_to_unit
from .cfar import cfar

__all__ = ["Detections", "heatmap_cell_xyz", "heatmap_pointcloud", "local_maxima"]


@dataclass(frozen=True, eq=False)
class Detections:
    """Detections of one frame; every attribute is an array of length N.

    Attributes
    ----------
    range_bin, doppler_bin
        int64: cell of the range–Doppler map (Doppler index of the centred axis).
    range
        float64 [m], refined between bins.
    range_rate
        float64 [m/s], refined; negative = approaching.
    azimuth, elevation
        float64 [rad]: ``atan2(y, x)`` and ``asin(z/R)`` of the point.
    xyz
        float64 ``(N, 3)`` [m], radar frame.
    intensity
        float64: peak of the angle spectrum, in the heatmap's power units.
    power
        float64: range–Doppler power (sum over virtual channels) of the cell.
    snr
        float64: ``power`` over the CFAR noise estimate of the cell.
    """

    range_bin: np.ndarray
    doppler_bin: np.ndarray
    range: np.ndarray
    range_rate: np.ndarray
    azimuth: np.ndarray
    elevation: np.ndarray
    xyz: np.ndarray
    intensity: np.ndarray
    power: np.ndarray
    snr: np.ndarray

    def __len__(self) -> int:
        return int(self.range_bin.size)

    def pointcloud(self) -> np.ndarray:
        """float32 ``(N, 5)``: ``x y z intensity range_rate``."""
        out = np.empty((len(self), 5), dtype=np.float32)
        out[:, :3] = self.xyz
        out[:, 3] = self.intensity
        out[:, 4] = self.range_rate
        return out


def local_maxima(power: np.ndarray, mode: str | tuple[str, ...]) -> np.ndarray:
    """bool mask of cells not smaller than any of their neighbours (3 cells per axis)."""
    return power >= maximum_filter(power, size=3, mode=mode)


def heatmap_cell_xyz(config: HeatmapConfig, el: np.ndarray, az: np.ndarray,
                     rng: np.ndarray) -> np.ndarray:
    """Radar-frame positions of heatmap cells: the one heatmap-cell placement of coloradar.

    Parameters
    ----------
    config
        The heatmap's grid (angle lists in radians, range bin width in metres).
    el, az, rng
        int ``(N,)``: elevation, azimuth and range indices of the cells.

    Returns
    -------
    numpy.ndarray
        float64 ``(N, 3)`` [m]: ``r·width·(√(1 − u_y² − u_z²), u_y, u_z)`` with
        ``u_y = sin(azimuth_bins[az])``, ``u_z = sin(elevation_bins[el])`` (an FFT grid
        measures direction sines, see :func:`heatmap_pointcloud`). Corner cells outside the
        visible region (``u_y² + u_z² > 1``) are projected onto its edge so that they keep
        their range.
    """
    u = sines_to_unit(np.sin(config.azimuth_bins[np.asarray(az)]),
                      np.sin(config.elevation_bins[np.asarray(el)]))
    return (np.asarray(rng) * config.range_bin_width)[..., None] * u


def heatmap_pointcloud(heatmap: np.ndarray, config: HeatmapConfig, *, kind: str = "ca",
                       guard: int | tuple[int, int, int] = (0, 1, 1),
                       train: int | tuple[int, int, int] = (0, 4, 4), pfa: float = 1e-4,
                       threshold: float | None = None, min_range: float = 0.0,
                       peaks_only: bool = True) -> np.ndarray:
    """Point cloud from a heatmap ``(el, az, range, 2)`` (shipped or computed).

    Cells are detected by a 3D CFAR on channel 0 (or, with ``threshold``, by a fixed intensity
    threshold), optionally kept only where they are local maxima, and placed with the angle
    lists of ``config``. An FFT heatmap's azimuth axis measures the direction sine
    ``u_y = cos(el)·sin(az)`` and its elevation axis ``u_z = sin(el)`` (this holds for the shipped
    heatmaps as for coloradar's), so a cell at bin angles ``(α, ε)`` and range ``R = r·width`` is
    placed at ``R·(√(1 − sin²α − sin²ε), sin α, sin ε)``; in the ``el = 0`` plane this is
    ``(R cos α, R sin α, 0)``.

    Parameters
    ----------
    heatmap
        float ``(el, az, range, 2)``.
    config
        The heatmap's grid; for shipped heatmaps the ``heatmap_cfg.txt`` that came with them.
    kind, guard, train, pfa
        CFAR settings (axes el, az, range; edges mirrored). By default the training cells
        lie in the cell's own elevation row: both radars' elevation apertures are a few
        elements, so a target fills much of an elevation column and would raise its own
        threshold. The CFAR assumes exponential cell power; the peak-over-Doppler of a
        heatmap is not, so ``pfa`` is nominal here.
    threshold
        Use a fixed channel-0 threshold instead of CFAR.
    min_range
        Drop cells closer than this [m] (antenna coupling lives there).
    peaks_only
        Keep only local maxima of channel 0.

    Returns
    -------
    numpy.ndarray
        float32 ``(N, 5)``.
    """
    hm = np.asarray(heatmap)
    if hm.ndim != 4 or hm.shape[:3] != config.shape or hm.shape[3] != 2:
        raise FormatError(f"heatmap has shape {hm.shape}; its heatmap_cfg says "
                          f"{(*config.shape, 2)} (el, az, range, 2)")
    p = hm[..., 0].astype(np.float64)
    if threshold is None:
        mask = cfar(p, kind, guard, train, pfa, mode="mirror").detections
    else:
        mask = p > threshold
    if peaks_only:
        mask &= local_maxima(p, "mirror")
    mask[:, :, : int(np.ceil(min_range / config.range_bin_width))] = False
    e, a, r = np.nonzero(mask)
    out = np.empty((e.size, 5), dtype=np.float32)
    out[:, :3] = heatmap_cell_xyz(config, e, a, r)
    out[:, 3] = hm[e, a, r, 0]
    out[:, 4] = hm[e, a, r, 1]
    return out
