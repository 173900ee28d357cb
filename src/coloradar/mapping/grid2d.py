"""A 2-D occupancy grid of a height band, and the ROS ``map_server`` files (PGM + YAML).

**The grid.** Cell ``(i, j)`` covers ``[i·res, (i+1)·res) × [j·res, (j+1)·res)`` of the world's
x and y (anchored at the world origin, as the voxels are, so grids of one resolution built from
different maps line up cell for cell). A cell is **occupied** when an occupied voxel of the
band ``z_min ≤ z < z_max`` (voxel centres) lies over it, **free** when none does and a free
one does, **unknown** otherwise. The resolution is the map's voxel edge.

**The files** (the format ``map_server`` / ``nav2_map_server`` read, as documented at
http://wiki.ros.org/map_server): ``NAME.pgm`` is a binary greyscale PGM (``P5``, maxval 255)
whose first row is the grid's highest y (an image is drawn top down), occupied 0 (black), free
254 (white), unknown 205 (grey); ``NAME.yaml`` holds ``image`` (the PGM's name, relative to the
YAML), ``mode: trinary``, ``resolution`` [m/pixel], ``origin: [x, y, yaw]`` (the world pose of
the image's **lower-left** pixel's corner, yaw 0), ``negate: 0``, ``occupied_thresh: 0.65`` and
``free_thresh: 0.196``. A reader computes ``p = (255 − value)/255`` and calls a pixel occupied
above ``occupied_thresh``, free below ``free_thresh``: 0 → 1.0 occupied, 254 → 0.004 free,
205 → 0.196 unknown (above the free threshold by less than a grey level).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SettingsError
from ..formats.atomic import atomic_write_bytes, atomic_write_text
from .voxels import FREE, OCCUPIED, UNKNOWN, OccupancyMap

__all__ = ["PGM_VALUES", "OccupancyGrid2D", "grid_iou", "occupancy_grid", "write_map_server"]

PGM_VALUES = {OCCUPIED: 0, FREE: 254, UNKNOWN: 205}
"""Grey level of each cell state in the PGM."""

OCCUPIED_THRESH, FREE_THRESH = 0.65, 0.196


@dataclass(frozen=True, eq=False)
class OccupancyGrid2D:
    """A 2-D occupancy grid (module docstring).

    Attributes
    ----------
    states
        int8 ``(ny, nx)``: :data:`~.voxels.OCCUPIED`, ``FREE`` or ``UNKNOWN``; row 0 is the
        lowest y (``states[j − j0, i − i0]`` is cell ``(i, j)``).
    corner
        int64 ``(2,)``: the global indices ``(i0, j0)`` of ``states[0, 0]``.
    resolution
        Cell edge [m].
    band
        ``(z_min, z_max)`` [m] of the voxels it was made of.
    """

    states: np.ndarray
    corner: np.ndarray
    resolution: float
    band: tuple[float, float]

    @property
    def origin(self) -> tuple[float, float]:
        """World ``(x, y)`` [m] of the lower-left corner of the grid."""
        return (float(self.corner[0] * self.resolution), float(self.corner[1] * self.resolution))

    def cells(self, state: int) -> np.ndarray:
        """int64 ``(K, 2)``: global indices ``(i, j)`` of the cells in ``state``."""
        j, i = np.nonzero(self.states == state)
        return np.column_stack([i, j]).astype(np.int64) + self.corner

    def counts(self) -> dict[str, int]:
        """Cells per state."""
        return {n: int(np.sum(self.states == v))
                for n, v in (("occupied", OCCUPIED), ("free", FREE), ("unknown", UNKNOWN))}


def occupancy_grid(m: OccupancyMap, z_min: float, z_max: float, margin: int = 2
                   ) -> OccupancyGrid2D:
    """The 2-D grid of the map's voxels whose centres lie in ``[z_min, z_max)`` [m]
    (module docstring); it spans every voxel of the band with evidence, and ``margin``
    unknown cells round them."""
    if not (math.isfinite(z_min) and math.isfinite(z_max) and z_min < z_max):
        raise SettingsError(f"expected a height band z_min < z_max [m], got {z_min}, {z_max}")
    ijk = m.indices()
    st = m.states()
    zc = (ijk[:, 2] + 0.5) * m.voxel
    band = (zc >= z_min) & (zc < z_max)
    # The extent is that of every voxel with evidence in the band, unknown ones too: a map of
    # one frame (nothing yet certain) still shows the area the sensor looked at.
    seen = ijk[band, :2]
    sel = band & (st != UNKNOWN)
    ij, st = ijk[sel, :2], st[sel]
    if seen.shape[0] == 0:
        return OccupancyGrid2D(np.full((1, 1), UNKNOWN, np.int8), np.zeros(2, np.int64),
                               m.voxel, (float(z_min), float(z_max)))
    lo = seen.min(axis=0) - margin
    dims = seen.max(axis=0) - lo + 1 + margin
    states = np.full((int(dims[1]), int(dims[0])), UNKNOWN, np.int8)
    free = ij[st == FREE] - lo
    states[free[:, 1], free[:, 0]] = FREE
    occ = ij[st == OCCUPIED] - lo
    states[occ[:, 1], occ[:, 0]] = OCCUPIED        # an occupied voxel wins over free ones
    return OccupancyGrid2D(states, lo.astype(np.int64), m.voxel, (float(z_min), float(z_max)))


def _cell_keys(cells: np.ndarray) -> np.ndarray:
    return (cells[:, 0] << 32) + cells[:, 1]


def grid_iou(grid: OccupancyGrid2D, reference: OccupancyGrid2D, *, observed_only: bool = True
             ) -> float:
    """Intersection over union of the two grids' occupied cells (same resolution).

    Parameters
    ----------
    grid, reference
        E.g. a radar map's grid and the lidar's, built with the same poses.
    observed_only
        Count only the reference's occupied cells that ``grid`` observed (free or occupied
        there): a radar that looks forward never saw what the lidar saw behind it.

    Returns
    -------
    float
        ``nan`` when both sets are empty.
    """
    if not math.isclose(grid.resolution, reference.resolution, rel_tol=1e-9):
        raise SettingsError(f"grids of different resolutions: {grid.resolution} and "
                            f"{reference.resolution}")
    a = _cell_keys(grid.cells(OCCUPIED))
    b = _cell_keys(reference.cells(OCCUPIED))
    if observed_only:
        known = np.concatenate([a, _cell_keys(grid.cells(FREE))])
        b = b[np.isin(b, known)]
    union = np.union1d(a, b).size
    return float(np.intersect1d(a, b).size / union) if union else math.nan


def write_map_server(grid: OccupancyGrid2D, yaml_path: str | os.PathLike[str]
                     ) -> tuple[Path, Path]:
    """Write ``NAME.pgm`` and ``NAME.yaml`` (module docstring), each atomically.

    Parameters
    ----------
    grid
        The grid.
    yaml_path
        ``.../NAME.yaml``; the PGM is written beside it as ``NAME.pgm``.

    Returns
    -------
    tuple of pathlib.Path
        ``(pgm, yaml)``.
    """
    y = Path(yaml_path)
    if y.suffix != ".yaml":
        raise SettingsError(f"{y}: expected a .yaml file name")
    pgm = y.with_suffix(".pgm")
    lut = np.full(256, PGM_VALUES[UNKNOWN], np.uint8)
    for state, value in PGM_VALUES.items():
        lut[state & 0xFF] = value
    image = lut[grid.states.astype(np.int64) & 0xFF][::-1]        # first row: highest y
    h, w = image.shape
    header = f"P5\n# coloradar occupancy grid, {grid.resolution:g} m/pixel\n{w} {h}\n255\n"
    atomic_write_bytes(pgm, header.encode("ascii") + np.ascontiguousarray(image).tobytes())
    x0, y0 = grid.origin
    atomic_write_text(y, f"image: {pgm.name}\nmode: trinary\nresolution: {grid.resolution:.6f}\n"
                         f"origin: [{x0:.6f}, {y0:.6f}, 0.0]\nnegate: 0\n"
                         f"occupied_thresh: {OCCUPIED_THRESH}\nfree_thresh: {FREE_THRESH}\n")
    return pgm, y
