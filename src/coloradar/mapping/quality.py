"""A map against a reference: precision, completeness and F-score at several distances, and the
IoU of the 2-D grids' occupied cells.

With ``d(p, Q)`` the distance from ``p`` to the nearest point of ``Q``
(:func:`coloradar.geometry.cloud_metrics.nearest_distances`), at a distance τ:

- **precision**: the share of the map's occupied voxel centres within τ of the reference;
- **completeness** (recall): the share of reference points within τ of an occupied voxel
  centre. A radar sees a cone in front of it, a lidar all round: when the map's own
  evidence is given (``observed``), only the reference points the map observed count: those
  in a voxel, or next to one (26 neighbours), that any frame's evidence reached;
- **F-score**: ``2PC / (P + C)`` (Knapitsch et al., "Tanks and Temples", SIGGRAPH 2017).

The **grid IoU** is :func:`.grid2d.grid_iou` of the map's 2-D grid against the reference's
(the lidar's occupancy grid built with the same poses: lidar free space from lidar rays).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import SettingsError
from ..geometry.cloud_metrics import f_from, mean_or_nan, nearest_distances, xyz_points
from .build import OccupancyJob, build_occupancy_map
from .grid2d import OccupancyGrid2D, occupancy_grid
from .voxels import OccupancyMap, OccupancySettings, voxel_keys

__all__ = ["MapQuality", "format_map_quality", "lidar_grid", "map_quality", "observed_mask"]


@dataclass(frozen=True)
class MapQuality:
    """Scores of a map (distances in metres; shares in [0, 1]; ``nan`` when undefined).

    Attributes
    ----------
    thresholds
        The distances τ.
    precision, completeness, f_score
        One value per threshold.
    grid_iou
        IoU of the occupied cells of the 2-D grids (None: not computed).
    num_map, num_reference
        Occupied voxels of the map; reference points scored (the observed ones when the map's
        evidence was given).
    """

    thresholds: tuple[float, ...]
    precision: tuple[float, ...]
    completeness: tuple[float, ...]
    f_score: tuple[float, ...]
    grid_iou: float | None
    num_map: int
    num_reference: int

    def to_dict(self) -> dict:
        """JSON-compatible (non-finite values as None)."""
        def clean(v):
            if isinstance(v, float):
                return v if math.isfinite(v) else None
            if isinstance(v, tuple | list):
                return [clean(x) for x in v]
            return v
        return {k: clean(v) for k, v in asdict(self).items()}


def observed_mask(points: np.ndarray, observed: OccupancyMap) -> np.ndarray:
    """bool ``(N,)``: which points lie in or next to (26 neighbours) a voxel of ``observed``
    that any evidence reached."""
    p = xyz_points(points, "reference")
    keys = observed.keys()
    if keys.size == 0 or p.shape[0] == 0:
        return np.zeros(p.shape[0], bool)
    v = observed.voxel
    base = np.floor(p / v)
    out = np.zeros(p.shape[0], bool)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):          # 27 vectorised look-ups
                k = voxel_keys((base + np.array([dx, dy, dz]) + 0.5) * v, v)
                rows = np.minimum(np.searchsorted(keys, k), keys.size - 1)
                out |= keys[rows] == k
    return out


def map_quality(occupied: np.ndarray, reference: np.ndarray,
                thresholds: tuple[float, ...] = (0.1, 0.3), *,
                observed: OccupancyMap | None = None, grid_iou: float | None = None
                ) -> MapQuality:
    """Precision, completeness and F-score of a map at each threshold (module docstring).

    Parameters
    ----------
    occupied
        float ``(N, ≥3)``: the map's occupied voxel centres (or any map's points) [m].
    reference
        float ``(M, ≥3)``: reference points in the same frame [m].
    thresholds
        Distances τ [m].
    observed
        The map's evidence: completeness counts only the reference points it observed.
    grid_iou
        A grid IoU to report with the scores.
    """
    if not thresholds or not all(t > 0 for t in thresholds):
        raise SettingsError(f"thresholds must be positive distances, got {thresholds}")
    p, ref = xyz_points(occupied, "map"), xyz_points(reference, "reference")
    if observed is not None:
        ref = ref[observed_mask(ref, observed)]
    d_pr, d_rp = nearest_distances(p, ref), nearest_distances(ref, p)
    prec = tuple(mean_or_nan(d_pr <= t) for t in thresholds)
    comp = tuple(mean_or_nan(d_rp <= t) for t in thresholds)
    f = tuple(f_from(a, b) for a, b in zip(prec, comp, strict=True))
    return MapQuality(tuple(float(t) for t in thresholds), prec, comp, f, grid_iou,
                      int(p.shape[0]), int(ref.shape[0]))


def format_map_quality(q: MapQuality, title: str = "") -> str:
    """The scores as a short table (the style of ``coloradar evaluate``)."""
    lines = [title] if title else []
    lines.append(f"occupied voxels       {q.num_map:,}  (reference points scored "
                 f"{q.num_reference:,})")
    lines.append("  within    precision  completeness  F-score")
    for t, p, c, f in zip(q.thresholds, q.precision, q.completeness, q.f_score, strict=True):
        lines.append(f"  {t:4.2f} m   {100 * p:8.1f} %  {100 * c:10.1f} %  {100 * f:6.1f} %")
    if q.grid_iou is not None:
        lines.append(f"grid IoU (occupied)   {100 * q.grid_iou:.1f} %")
    return "\n".join(lines) + "\n"


def lidar_grid(seq, trajectory, voxel: float, band: tuple[float, float], stride: int = 2
               ) -> OccupancyGrid2D:
    """The lidar's 2-D occupancy grid of a run (every ``stride``-th scan placed by
    ``trajectory``, lidar free space from lidar rays, voxels of ``voxel`` [m], the height band
    ``band`` [m]): the reference a radar map's grid is scored against."""
    res = build_occupancy_map(seq, trajectory, OccupancyJob(sensor="lidar", stride=stride),
                              OccupancySettings(voxel=voxel))
    return occupancy_grid(res.map, *band)
