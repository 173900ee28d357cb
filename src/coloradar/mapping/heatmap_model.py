"""The inverse sensor model of a 3-D radar heatmap: every range–azimuth–elevation cell is
evidence, with no detection decision in between.

A heatmap ``(el, az, range, 2)`` holds per cell the peak power over Doppler (channel 0). The
**noise floor** is the heatmap's own: the median power of each range bin over all directions
(most directions at any range hold noise; a per-range floor follows the range-dependent gain
and the near-range coupling). A cell's SNR is its power over the floor of its range [dB].

- **Occupied**: a return is a cell that is the maximum of its 3 × 3 × 3 neighbourhood, at
  least ``occupied_db`` above the floor and within ``dynamic_db`` of the strongest cell of its
  range bin (the grid is finer than the array resolves, and a return's main lobe and
  sidelobes spread over many cells: their peak is the return, the rest its blur). Each return
  is then evidence as a point of the radar's point cloud is (:mod:`.sensor_model`: spread by
  the array's resolution at the cell's SNR).
- **Free**: a cell below ``free_db`` (at or under the floor: nothing reflects there) that lies
  in front of the first cell of its beam above ``shadow_db`` by more than ``guard_bins``
  range bins (beyond a return the radar cannot tell emptiness from shadow). Every ``stride``-th
  beam in azimuth and elevation (default: as many as a 64-bin axis has).
- Cells nearer than ``min_range`` (coupling, the rig) say nothing.
- **Movers and ghosts**: with the sensor's velocity, a return whose range rate (channel 1, the
  range rate of the cell's Doppler peak) a static world does not explain is left out
  (:mod:`.static_gate`, ``static_test``); its beam's free space still ends at it.

Cells are placed as :func:`coloradar.dsp.detect.heatmap_cell_xyz` places them (the one heatmap
placement of coloradar).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..calib import HeatmapConfig
from ..dsp.detect import heatmap_cell_xyz
from ..errors import FormatError, SettingsError
from .sensor_model import PointSensorModel, hit_evidence
from .static_gate import StaticTest
from .voxels import OccupancySettings, local_unique_keys, logit

__all__ = ["HeatmapModel", "heatmap_evidence"]


@dataclass(frozen=True, eq=False)
class HeatmapModel:
    """How a heatmap's cells become evidence (module docstring).

    Attributes
    ----------
    config
        The heatmap's grid (angles, range bin width).
    occupied_db, dynamic_db
        A return is at least ``occupied_db`` above the floor [dB] and within ``dynamic_db`` of
        its range bin's strongest cell.
    free_db
        Free below this SNR [dB].
    shadow_db
        A beam is free only in front of its first cell above this SNR [dB] (None:
        ``occupied_db``): a wall seen at a grazing angle answers weakly, and a beam that passes
        it must not carve it away (3 dB was chosen on the tuning runs from 12, 6 and 3:
        the grid IoU against the lidar and the F-score at 0.3 m both rose).
    guard_bins
        Range bins before that cell that are not called free either.
    min_range, max_range
        Cells outside [m] are left out (None: to the last bin).
    stride
        Use every ``stride``-th azimuth and elevation bin for free space (None: as many as a
        64-bin axis has): bounds the work on a fine grid.
    max_returns
        The strongest returns kept per heatmap (a frame has a few hundred peaks, most of them
        sidelobes and noise; 50 was chosen from 40, 50, 60 and 100 on the tuning runs: fewer
        raise the grid IoU against the lidar and lower the F-score at 0.1 m).
    elevation_peak
        Keep only the strongest elevation of each azimuth–range column: an array with few
        elevation rows (the cascade's) answers one return with several elevation lobes of
        nearly its strength, which would each become a return.
    static_test
        The static-world test of the returns (:class:`~.static_gate.StaticTest`; None: none),
        applied to a heatmap of shape ``(el, az, range, 2)`` (channel 1: the range rates)
        when the frame's velocity is given. A dropped return still ends its beam's free space.
    """

    config: HeatmapConfig
    points: PointSensorModel
    occupied_db: float = 12.0
    dynamic_db: float = 20.0
    free_db: float = 0.0
    guard_bins: int = 2
    min_range: float = 0.5
    max_range: float | None = None
    stride: int | None = None
    max_returns: int = 50
    elevation_peak: bool = True
    shadow_db: float | None = 3.0
    static_test: StaticTest | None = None

    def __post_init__(self) -> None:
        if not self.free_db < self.occupied_db:
            raise SettingsError("HeatmapModel: expected free_db < occupied_db, got "
                                f"{self.free_db} and {self.occupied_db}")
        if not (self.dynamic_db > 0 and (self.stride is None or self.stride >= 1)
                and self.guard_bins >= 0):
            raise SettingsError("HeatmapModel: dynamic_db must be > 0, stride >= 1 and "
                                "guard_bins >= 0")

    @property
    def shape(self) -> tuple[int, int, int]:
        c = self.config
        return (c.num_elevation_bins, c.num_azimuth_bins, c.num_range_bins)

    @cached_property
    def cells(self) -> np.ndarray:
        """float32 ``(el, az, range, 3)``: every cell's centre in the radar frame [m]."""
        ne, na, nr = self.shape
        e, a, r = np.meshgrid(np.arange(ne), np.arange(na), np.arange(nr), indexing="ij")
        return heatmap_cell_xyz(self.config, e, a, r).astype(np.float32)

    @cached_property
    def range_mask(self) -> np.ndarray:
        """bool ``(range,)``: range bins inside ``[min_range, max_range]``."""
        r = np.arange(self.shape[2]) * self.config.range_bin_width
        hi = np.inf if self.max_range is None else self.max_range
        return (r >= self.min_range) & (r <= hi)


def _snr_db(heatmap: np.ndarray, model: HeatmapModel) -> np.ndarray:
    h = np.asarray(heatmap)
    if h.ndim == 4:
        h = h[..., 0]
    if h.shape != model.shape:
        raise FormatError(f"expected a heatmap of shape {model.shape} (el, az, range) as its "
                          f"configuration says, got {np.asarray(heatmap).shape}")
    p = np.maximum(h.astype(np.float32), np.float32(1e-30))
    floor = np.median(p[:, ::2].reshape(-1, p.shape[2]), axis=0)      # per range bin
    return (10.0 * np.log10(p / np.maximum(floor, np.float32(1e-30)))).astype(np.float32)


def _peaks(snr: np.ndarray, model: HeatmapModel) -> np.ndarray:
    """bool: the occupied cells: local maxima of their 3 × 3 × 3 neighbourhood at least
    ``occupied_db`` above the floor and within ``dynamic_db`` of their range bin's strongest."""
    best_r = snr.max(axis=(0, 1))
    cand = (snr >= model.occupied_db) & (snr >= best_r[None, None, :] - model.dynamic_db)
    if model.elevation_peak:
        cand &= snr >= snr.max(axis=0, keepdims=True)
    cand &= model.range_mask[None, None, :]
    e, a, r = np.nonzero(cand)
    out = np.zeros_like(cand)
    if e.size == 0:
        return out
    pad = np.pad(snr, 1, mode="constant", constant_values=-np.inf)
    v = snr[e, a, r]
    keep = np.ones(e.size, bool)
    for de in (0, 1, 2):
        for da in (0, 1, 2):
            for dr in (0, 1, 2):           # 26 vectorised comparisons, candidates only
                if (de, da, dr) != (1, 1, 1):
                    keep &= v >= pad[e + de, a + da, r + dr]
    out[e[keep], a[keep], r[keep]] = True
    return out


def heatmap_evidence(heatmap: np.ndarray, rotation: np.ndarray, translation: np.ndarray,
                     model: HeatmapModel, settings: OccupancySettings,
                     velocity: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One heatmap's occupancy and free-space evidence (module docstring).

    Parameters
    ----------
    heatmap
        float ``(el, az, range, 2)`` or ``(el, az, range)``: power (channel 0).
    rotation, translation
        ``world_T_radar``: float ``(3, 3)`` and ``(3,)``.
    model
        :class:`HeatmapModel` of the heatmap's grid.
    settings
        The map's voxel and probabilities.
    velocity
        float ``(3,)``: the radar's velocity [m/s], radar frame, for ``model.static_test``
        (None: no static test).

    Returns
    -------
    keys : numpy.ndarray
        int64 ``(K,)``, distinct.
    delta : numpy.ndarray
        float32 ``(K,)``: log-odds to add (> 0 occupied, < 0 free).
    """
    snr = _snr_db(heatmap, model)
    occ = _peaks(snr, model)
    rot = np.asarray(rotation, np.float32)
    t = np.asarray(translation, np.float32)
    nr = snr.shape[2]
    stop = model.occupied_db if model.shadow_db is None else model.shadow_db
    strong = (snr >= stop) & model.range_mask[None, None, :]
    first = np.where(strong.any(axis=2), strong.argmax(axis=2), nr)   # (el, az): first return
    s = model.stride or max(1, model.config.num_azimuth_bins // 64)
    rng_idx = np.arange(nr)
    free = ((snr[::s, ::s] < model.free_db)
            & (rng_idx[None, None, :] < first[::s, ::s, None] - model.guard_bins)
            & model.range_mask[None, None, :])
    free_pts = model.cells[::s, ::s][free] @ rot.T + t
    free_keys = local_unique_keys(free_pts, settings.voxel)
    peaks = np.column_stack([model.cells[occ].astype(np.float64), snr[occ]])
    h = np.asarray(heatmap)
    if velocity is not None and model.static_test is not None and h.ndim == 4:
        rates = h[..., 1][occ].astype(np.float64)
        peaks = peaks[model.static_test(np.column_stack([peaks, rates]), velocity)]
    if peaks.shape[0] > model.max_returns:
        peaks = peaks[np.argpartition(-peaks[:, 3], model.max_returns)[:model.max_returns]]
    hit_keys, q = hit_evidence(peaks, np.asarray(rotation, np.float64),
                               np.asarray(translation, np.float64), model.points, settings)
    free_keys = free_keys[~np.isin(free_keys, hit_keys, assume_unique=True)]
    keys = np.concatenate([hit_keys, free_keys])
    delta = np.concatenate([q, np.full(free_keys.size, logit(settings.p_miss))])
    return keys, delta.astype(np.float32)
