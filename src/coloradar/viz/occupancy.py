"""The occupancy grid from above (needs matplotlib: ``pip install 'coloradar[viz]'``):
occupied cells black, free white, unknown grey, in world metres, with the trajectory."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from ..mapping.grid2d import OccupancyGrid2D
from ..mapping.voxels import FREE, OCCUPIED
from ._figure import new_figure

__all__ = ["occupancy_figure"]

# Index 0 unknown, 1 free, 2 occupied: the map_server greys (205, 254, 0).
_COLOURS = ListedColormap([(0.80, 0.80, 0.80), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0)])


def occupancy_figure(grid: OccupancyGrid2D, trajectory_xy: np.ndarray | None = None,
                     title: str = "", width: float = 8.0) -> Figure:
    """The grid from above (x right, y up, world frame [m]).

    Parameters
    ----------
    grid
        The 2-D grid (:func:`coloradar.mapping.occupancy_grid`).
    trajectory_xy
        float ``(N, ≥2)``: the path drawn over it (world x, y [m]), or None.
    title
        The axes' title.
    width
        Figure width [inches]; the height follows the grid's shape.
    """
    idx = np.zeros(grid.states.shape, np.int8)
    idx[grid.states == FREE] = 1
    idx[grid.states == OCCUPIED] = 2
    x0, y0 = grid.origin
    ny, nx = grid.states.shape
    extent = (x0, x0 + nx * grid.resolution, y0, y0 + ny * grid.resolution)
    ratio = max(nx, 1) / max(ny, 1)
    fig = new_figure(width, float(np.clip(width / ratio, 2.5, 10.0)) + 1.0, dpi=110)
    ax = fig.axes[0]
    ax.imshow(idx, origin="lower", extent=extent, cmap=_COLOURS, vmin=0, vmax=2,
              interpolation="nearest")
    handles: list = [Patch(facecolor=_COLOURS(2), label="occupied"),
               Patch(facecolor=_COLOURS(1), edgecolor="0.5", label="free"),
               Patch(facecolor=_COLOURS(0), label="unknown")]
    if trajectory_xy is not None and len(trajectory_xy):
        t = np.asarray(trajectory_xy)
        (line,) = ax.plot(t[:, 0], t[:, 1], color="tab:red", lw=1.0, label="trajectory")
        handles.append(line)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    z0, z1 = grid.band
    ax.set_title(title or f"occupancy, z in [{z0:.2f}, {z1:.2f}) m", fontsize=10)
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    return fig
