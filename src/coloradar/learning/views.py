"""Images of a radar frame and of a lidar scan on one grid: range–azimuth (polar) and bird's-eye.

Two grids, both in the **radar frame** (x along the boresight, y to the left, z up;
docs/conventions.md §3):

* **Polar** (range–azimuth): the heatmap's own bins. Row ``k`` is range bin ``k`` (centred on
  ``k·range_bin_width``), column ``j`` azimuth bin ``j`` (angle ``azimuth_bins[j]``, ascending,
  i.e. from the radar's right to its left). Images are ``(C, num_range_bins, num_azimuth_bins)``.
* **Cartesian BEV** (:class:`BevGrid`): square cells of ``cell`` metres; image ``[c, i, j]`` is
  the cell centred on ``x_i = x_min + (i + ½)·cell``, ``y_j = y_min + (j + ½)·cell``. Images are
  ``(C, nx, ny)``.

Heatmap geometry (as :func:`coloradar.dsp.heatmap_pointcloud` uses it): an FFT heatmap's
azimuth axis measures the direction sine ``u_y = cos(el)·sin(az)`` and its elevation axis
``u_z = sin(el)``; bin ``(i, j, k)`` is centred on ``R_k·(√(1 − s_j² − t_i²), s_j, t_i)`` with
``s_j = sin(azimuth_bins[j])``, ``t_i = sin(elevation_bins[i])``, ``R_k = k·range_bin_width``.
A 3D point belongs to the bin whose sines and range are nearest (bins are bounded half-way to
their neighbours; the outer bins by half their spacing beyond their centres). A point outside
every bin is outside the radar's field of view or range. The lidar images use the same rule, so
radar and lidar images of one frame align pixel for pixel.

The angles come from a :class:`~coloradar.calib.HeatmapConfig`: use
``seq.<radar>.heatmap_config`` (the grid stored beside the heatmaps: true angles for heatmaps
that coloradar or its simulator computed, the release's labelling for shipped ones; see
docs/calibration.md) or ``RadarProcessor(calib).heatmap_config()``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np

from ..calib import HeatmapConfig
from ..errors import SettingsError

__all__ = ["DB_FLOOR", "LIDAR_CHANNELS", "BevGrid", "BevProjector", "ViewOptions", "fov_mask", "lidar_bev",
           "lidar_polar", "point_bins", "radar_bev", "radar_polar"]

DB_FLOOR = -200.0
"""Intensity in dB given to a cell of zero power (10·log10 of 1e-20)."""

LIDAR_CHANNELS = ("occupancy", "height", "intensity")
"""Channels of the lidar images: 1 where a point falls in the cell (else 0); the highest
point's z in the radar frame [m] (0 where empty); the largest intensity (0 where empty)."""

Reduce = Literal["max", "mean"]


@dataclass(frozen=True)
class BevGrid:
    """A Cartesian bird's-eye grid in the radar frame.

    Attributes
    ----------
    x_min, x_max, y_min, y_max
        Extent [m]; ``x_max − x_min`` and ``y_max − y_min`` are whole multiples of ``cell``.
    cell
        Edge of a square cell [m].
    z_min, z_max
        Height band of the lidar images [m, radar frame]: points outside it are left out.
    """

    x_min: float = 0.0
    x_max: float = 16.0
    y_min: float = -16.0
    y_max: float = 16.0
    cell: float = 0.1
    z_min: float = -2.0
    z_max: float = 2.0

    def __post_init__(self) -> None:
        vals = asdict(self)
        if not all(math.isfinite(v) for v in vals.values()):
            raise SettingsError(f"BevGrid: every value must be finite, got {vals}")
        if not self.cell > 0 or self.x_max <= self.x_min or self.y_max <= self.y_min \
                or self.z_max <= self.z_min:
            raise SettingsError(f"BevGrid: need cell > 0 and max > min on every axis, got {vals}")
        for lo, hi, ax in ((self.x_min, self.x_max, "x"), (self.y_min, self.y_max, "y")):
            n = (hi - lo) / self.cell
            if abs(n - round(n)) > 1e-6 * max(1.0, n):
                raise SettingsError(f"BevGrid: the {ax} extent {hi - lo:g} m is not a whole "
                                    f"number of {self.cell:g} m cells")

    @classmethod
    def for_radar(cls, config: HeatmapConfig, cell: float = 0.1, z_min: float = -2.0,
                  z_max: float = 2.0) -> BevGrid:
        """The smallest grid of ``cell`` metres holding the radar's whole field of view.

        x from 0 to the outer edge of the last range bin, y symmetric, covering the widest
        azimuth bin at that range.
        """
        r = (config.num_range_bins - 0.5) * config.range_bin_width
        s = _bin_edges(np.sin(config.azimuth_bins))
        half = r * min(1.0, float(np.max(np.abs(s))))
        nx = math.ceil(r / cell - 1e-9)
        ny = math.ceil(half / cell - 1e-9)
        return cls(0.0, nx * cell, -ny * cell, ny * cell, cell, z_min, z_max)

    @property
    def shape(self) -> tuple[int, int]:
        """``(nx, ny)``: image rows along x, columns along y."""
        return (round((self.x_max - self.x_min) / self.cell),
                round((self.y_max - self.y_min) / self.cell))

    @property
    def x_centers(self) -> np.ndarray:
        """float64 ``(nx,)``: x of every row's cell centres [m]."""
        return self.x_min + (np.arange(self.shape[0]) + 0.5) * self.cell

    @property
    def y_centers(self) -> np.ndarray:
        """float64 ``(ny,)``: y of every column's cell centres [m]."""
        return self.y_min + (np.arange(self.shape[1]) + 0.5) * self.cell

    def cell_index(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Row and column of points ``(N, ≥2)`` and whether each lies on the grid."""
        nx, ny = self.shape
        i = np.floor((xy[:, 0] - self.x_min) / self.cell).astype(np.int64)
        j = np.floor((xy[:, 1] - self.y_min) / self.cell).astype(np.int64)
        ok = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
        return i, j, ok

    def to_dict(self) -> dict[str, float]:
        """The grid as plain numbers (stored as HDF5 attributes)."""
        return {k: float(v) for k, v in asdict(self).items()}


def _bin_edges(centres: np.ndarray) -> np.ndarray:
    """Edges of bins around ascending ``centres``: half-way between neighbours, and half the
    outer spacing beyond the outer centres. float64 ``(n + 1,)``."""
    c = np.asarray(centres, dtype=np.float64)
    if c.size == 1:
        return np.array([c[0] - 1.0, c[0] + 1.0])  # one bin: it takes every sine
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[c[0] - 0.5 * (c[1] - c[0])], mid, [c[-1] + 0.5 * (c[-1] - c[-2])]])


def _digitize(u: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Bin of each value (``edges[b] <= u < edges[b+1]``), -1 outside."""
    b = np.searchsorted(edges, u, side="right") - 1
    return np.where((b >= 0) & (b < edges.size - 1), b, -1)


def point_bins(xyz: np.ndarray, config: HeatmapConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The heatmap bin ``(el, az, range)`` of points in the radar frame; -1 outside.

    Parameters
    ----------
    xyz
        float ``(N, 3)`` points in the radar frame [m].
    config
        The heatmap grid.

    Returns
    -------
    el, az, rng : numpy.ndarray
        int64 ``(N,)`` each; all three are -1 for a point outside the field of view or range
        (or behind the radar).
    """
    p = np.asarray(xyz, dtype=np.float64)
    r = np.linalg.norm(p, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        uy = np.where(r > 0, p[:, 1] / r, 0.0)
        uz = np.where(r > 0, p[:, 2] / r, 0.0)
    el = _digitize(uz, _bin_edges(np.sin(config.elevation_bins)))
    az = _digitize(uy, _bin_edges(np.sin(config.azimuth_bins)))
    rk = np.floor(r / config.range_bin_width + 0.5).astype(np.int64)
    ok = (el >= 0) & (az >= 0) & (rk < config.num_range_bins) & (p[:, 0] >= 0)
    return np.where(ok, el, -1), np.where(ok, az, -1), np.where(ok, rk, -1)


def fov_mask(xyz: np.ndarray, config: HeatmapConfig, min_range: float = 0.0) -> np.ndarray:
    """bool ``(N,)``: points (radar frame) inside a heatmap bin and at least ``min_range`` away."""
    p = np.asarray(xyz, dtype=np.float64)[:, :3]
    return (point_bins(p, config)[0] >= 0) & (np.linalg.norm(p, axis=1) >= min_range)


def _db(power: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.maximum(10.0 * np.log10(np.maximum(power, 0.0)), DB_FLOOR).astype(np.float32)


def _check_heatmap(heatmap: np.ndarray, config: HeatmapConfig) -> np.ndarray:
    h = np.asarray(heatmap)
    if h.shape != (*config.shape, 2):
        raise SettingsError(f"expected a heatmap of shape {(*config.shape, 2)} (el, az, range, "
                            f"2) for this grid, got {h.shape}")
    return h


def radar_polar(heatmap: np.ndarray, config: HeatmapConfig, reduce: Reduce = "max",
                range_rate: bool = True) -> np.ndarray:
    """Range–azimuth image of a heatmap: elevation reduced, intensity in dB.

    Parameters
    ----------
    heatmap
        float32 ``(el, az, range, 2)``: intensity, range rate [m/s].
    config
        Its grid (for the shape check; the polar image keeps the heatmap's bins).
    reduce
        ``"max"``: the strongest elevation bin, with its range rate; ``"mean"``: the mean
        intensity over elevation, with the intensity-weighted mean range rate.
    range_rate
        Add the range-rate channel.

    Returns
    -------
    numpy.ndarray
        float32 ``(C, num_range_bins, num_azimuth_bins)``: channel 0 intensity
        ``10·log10(·)`` [dB] (``DB_FLOOR`` for zero power), channel 1 (if asked) range rate [m/s].
    """
    h = _check_heatmap(heatmap, config)
    inten = h[..., 0].astype(np.float64)
    if reduce == "max":
        k = np.argmax(inten, axis=0)
        p = np.take_along_axis(inten, k[None], axis=0)[0]
        v = np.take_along_axis(h[..., 1], k[None], axis=0)[0]
    elif reduce == "mean":
        p = inten.mean(axis=0)
        w = inten.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            v = np.where(w > 0, (inten * h[..., 1]).sum(axis=0) / w, 0.0)
    else:
        raise SettingsError(f"reduce must be 'max' or 'mean', got {reduce!r}")
    chans = [_db(p).T]
    if range_rate:
        chans.append(np.asarray(v, dtype=np.float32).T)
    return np.ascontiguousarray(np.stack(chans))


class BevProjector:
    """Resamples heatmaps of one grid onto a :class:`BevGrid` (index tables built once).

    Every BEV cell is a vertical column at its centre ``(x, y)``. For each elevation row ``i``
    of the heatmap, the point of that column seen at elevation sine ``t_i`` (slant range
    ``R = ρ / √(1 − t_i²)``, ``ρ = √(x² + y²)``, azimuth sine ``y / R``) falls in one heatmap
    bin of that row, or in none (outside the field of view or range). The cell reduces the
    intensities of those bins over the rows (max or mean) and is ``fill`` when there is none.

    Parameters
    ----------
    config
        The heatmap grid.
    grid
        The BEV grid.

    Attributes
    ----------
    valid
        bool ``(nx, ny)``: cells inside the radar's field of view and range.
    """

    def __init__(self, config: HeatmapConfig, grid: BevGrid):
        self.config = config
        self.grid = grid
        x = grid.x_centers[:, None]
        y = grid.y_centers[None, :]
        rho = np.hypot(x, y)
        n_el, n_az, n_r = config.shape
        t = np.sin(config.elevation_bins)[:, None, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = rho[None] / np.sqrt(np.clip(1.0 - t**2, 1e-12, None))
            uy = np.where(r > 0, y[None] / r, 0.0)
        az = _digitize(uy, _bin_edges(np.sin(config.azimuth_bins)))
        rk = np.floor(r / config.range_bin_width + 0.5).astype(np.int64)
        ok = (az >= 0) & (rk < n_r) & (x[None] >= 0)
        el = np.broadcast_to(np.arange(n_el)[:, None, None], ok.shape)
        self._flat = np.where(ok, (el * n_az + az) * n_r + rk, 0).astype(np.int64)
        self._ok = ok
        self.valid = ok.any(axis=0)

    def __call__(self, heatmap: np.ndarray, reduce: Reduce = "max", range_rate: bool = True,
                 fill: float = np.nan) -> np.ndarray:
        """BEV image of one heatmap.

        Returns
        -------
        numpy.ndarray
            float32 ``(C, nx, ny)``: intensity [dB] and (if asked) range rate [m/s] (as in
            :func:`radar_polar`); cells outside the field of view are ``fill``.
        """
        h = _check_heatmap(heatmap, self.config)
        inten = h[..., 0].reshape(-1)[self._flat].astype(np.float64)
        rate = h[..., 1].reshape(-1)[self._flat]
        ok = self._ok
        if reduce == "max":
            masked = np.where(ok, inten, -np.inf)
            k = np.argmax(masked, axis=0)
            p = np.take_along_axis(masked, k[None], axis=0)[0]
            v = np.take_along_axis(rate, k[None], axis=0)[0]
        elif reduce == "mean":
            w = np.where(ok, inten, 0.0)
            n = ok.sum(axis=0)
            with np.errstate(invalid="ignore", divide="ignore"):
                p = np.where(n > 0, w.sum(axis=0) / np.maximum(n, 1), 0.0)
                s = w.sum(axis=0)
                v = np.where(s > 0, (w * rate).sum(axis=0) / s, 0.0)
        else:
            raise SettingsError(f"reduce must be 'max' or 'mean', got {reduce!r}")
        chans = [_db(np.where(self.valid, p, 0.0))]
        if range_rate:
            chans.append(np.asarray(v, dtype=np.float32))
        out = np.stack(chans)
        out[:, ~self.valid] = fill
        return out


def radar_bev(heatmap: np.ndarray, config: HeatmapConfig, grid: BevGrid, reduce: Reduce = "max",
              range_rate: bool = True, fill: float = np.nan) -> np.ndarray:
    """Bird's-eye image of one heatmap (see :class:`BevProjector`; build one to reuse its tables
    over many frames).

    Returns
    -------
    numpy.ndarray
        float32 ``(C, nx, ny)``.
    """
    return BevProjector(config, grid)(heatmap, reduce, range_rate, fill)


def _scatter_channels(n_cells: int, cell: np.ndarray, z: np.ndarray,
                      intensity: np.ndarray) -> np.ndarray:
    occ = np.zeros(n_cells, dtype=np.float32)
    height = np.full(n_cells, -np.inf)
    inten = np.full(n_cells, -np.inf)
    occ[cell] = 1.0
    np.maximum.at(height, cell, z)
    np.maximum.at(inten, cell, intensity)
    height[occ == 0] = 0.0
    inten[occ == 0] = 0.0
    return np.stack([occ, height.astype(np.float32), inten.astype(np.float32)])


def _points(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] < 3:
        raise SettingsError(f"expected points of shape (N, >=3), got {p.shape}")
    p = p[np.all(np.isfinite(p[:, :3]), axis=1)]
    inten = p[:, 3].astype(np.float64) if p.shape[1] > 3 else np.zeros(p.shape[0])
    return p[:, :3].astype(np.float64), inten


def lidar_bev(points: np.ndarray, grid: BevGrid, config: HeatmapConfig | None = None) -> np.ndarray:
    """Bird's-eye image of a lidar scan or a lidar target, on ``grid``.

    Parameters
    ----------
    points
        float ``(N, 3)`` or ``(N, ≥4)`` (x y z [intensity]) in the **radar frame** [m].
    grid
        The BEV grid; points outside ``[z_min, z_max]`` are left out.
    config
        When given, only points inside the radar's field of view and range count.

    Returns
    -------
    numpy.ndarray
        float32 ``(3, nx, ny)``: :data:`LIDAR_CHANNELS` (occupancy, height, intensity).
    """
    xyz, inten = _points(points)
    keep = (xyz[:, 2] >= grid.z_min) & (xyz[:, 2] <= grid.z_max)
    if config is not None:
        keep &= point_bins(xyz, config)[0] >= 0
    i, j, ok = grid.cell_index(xyz)
    keep &= ok
    nx, ny = grid.shape
    out = _scatter_channels(nx * ny, i[keep] * ny + j[keep], xyz[keep, 2], inten[keep])
    return out.reshape(3, nx, ny)


def lidar_polar(points: np.ndarray, config: HeatmapConfig) -> np.ndarray:
    """Range–azimuth image of a lidar scan or target on the heatmap's polar grid.

    Each point inside the field of view and range goes to the bin ``(range, azimuth)`` it
    belongs to (:func:`point_bins`), over every elevation row.

    Returns
    -------
    numpy.ndarray
        float32 ``(3, num_range_bins, num_azimuth_bins)``: :data:`LIDAR_CHANNELS`.
    """
    xyz, inten = _points(points)
    _, az, rk = point_bins(xyz, config)
    keep = az >= 0
    n_az, n_r = config.num_azimuth_bins, config.num_range_bins
    out = _scatter_channels(n_r * n_az, rk[keep] * n_az + az[keep], xyz[keep, 2], inten[keep])
    return out.reshape(3, n_r, n_az)


@dataclass(frozen=True)
class ViewOptions:
    """How image views are made from heatmaps (:mod:`coloradar.learning.views`).

    Attributes
    ----------
    grid
        The BEV grid; None: :meth:`BevGrid.for_radar` of the first run's heatmap grid.
    reduce
        ``"max"`` or ``"mean"`` over elevation.
    range_rate
        Add the range-rate channel to radar images.
    angles
        ``"stream"``: the grid stored with the heatmaps (``seq.<radar>.heatmap_config``: the
        true angles for heatmaps coloradar computed, the release's labels for shipped ones);
        ``"true"``: ``RadarProcessor(calib).heatmap_config()``, the FFT grid of the virtual
        array.
    """

    grid: BevGrid | None = None
    reduce: str = "max"
    range_rate: bool = True
    angles: str = "stream"

    def __post_init__(self) -> None:
        if self.reduce not in ("max", "mean"):
            raise SettingsError(f"reduce must be 'max' or 'mean', got {self.reduce!r}")
        if self.angles not in ("stream", "true"):
            raise SettingsError(f"angles must be 'stream' or 'true', got {self.angles!r}")
