"""The SLAM picture (needs matplotlib: ``pip install 'coloradar[viz]'``): the radar map from
above, the trajectory before and after optimisation, loop edges, and the ground truth when the
run has it. Built on :class:`matplotlib.figure.Figure` with an Agg canvas, never ``pyplot``."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from ..errors import MissingDependencyError
from ..formats.atomic import atomic_write_bytes
from ..geometry import Trajectory
from ..odometry.plot import ELONGATED, top_view_frame
from .system import SlamResult

try:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise MissingDependencyError("the SLAM picture needs matplotlib: "
                                 "pip install 'coloradar[viz]'") from exc

__all__ = ["plot_slam", "slam_figure"]


def slam_figure(res: SlamResult, groundtruth: Trajectory | None = None, title: str = "") -> Figure:
    """Top view (x–y, world frame [m]) of the map (grey, darker where more keyframes saw it),
    the odometry (dashed), the optimised trajectory, accepted loops (green) and rejected
    candidates (red), and the ground truth (black) when given."""
    # A long, thin path (a hallway, in any direction) is drawn along / across its main
    # direction; the figure takes the map's shape (a long corridor is a wide, low picture).
    rot, c, elongation = top_view_frame(res.trajectory.translations[:, :2])
    if elongation <= ELONGATED:
        rot, c = np.eye(2), np.zeros(2)

    def flat(p: np.ndarray) -> np.ndarray:
        return (np.asarray(p)[:, :2] - c) @ rot.T

    m = res.map_points.copy()
    m[:, :2] = flat(m) if m.shape[0] else m[:, :2]
    xy = np.vstack([flat(res.trajectory.translations), m[:, :2]]) if m.shape[0] else \
        flat(res.trajectory.translations)
    span = np.ptp(xy, axis=0) + 2.0
    ratio = span[0] / span[1]
    height = float(np.clip(10.0 / ratio, 3.5, 9.0)) + 1.6
    fig = Figure(figsize=(10.0, height), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    if m.shape[0]:
        ax.scatter(m[:, 0], m[:, 1], s=2, c=np.minimum(m[:, 3], 10), cmap="Greys", vmin=0,
                   vmax=12, linewidths=0, label=f"radar map ({m.shape[0]:,} voxels)")
    kp = (np.zeros((0, 2)) if res.keyframe_poses is None
          else flat(res.keyframe_poses.translations))
    for accepted, colour in ((False, "tab:red"), (True, "tab:green")):
        segs = [(kp[lp.i, :2], kp[lp.j, :2]) for lp in res.loops if lp.accepted == accepted]
        if segs:
            ax.add_collection(LineCollection(segs, colors=colour, linewidths=0.6,
                                             alpha=0.8 if accepted else 0.4,
                                             label=f"{'accepted' if accepted else 'rejected'} "
                                                   f"loops ({len(segs)})"))
    if groundtruth is not None:
        g = flat(groundtruth.translations)
        ax.plot(g[:, 0], g[:, 1], color="black", lw=1.0, label="ground truth")
    o, t = flat(res.odometry.translations), flat(res.trajectory.translations)
    ax.plot(o[:, 0], o[:, 1], color="tab:orange", lw=1.0, ls="--", label="odometry (before)")
    ax.plot(t[:, 0], t[:, 1], color="tab:blue", lw=1.2, label="SLAM (after)")
    along = elongation > ELONGATED
    ax.set_xlabel("along the path's main direction [m]" if along else "x [m]")
    if ratio <= ELONGATED:
        ax.set_aspect("equal", adjustable="box")
        ax.set_ylabel("across it [m]" if along else "y [m]")
    else:  # a long corridor: stretched across so that the loops can be seen
        ax.set_ylabel("across it [m] (stretched)" if along else "y [m] (stretched)")
    ax.set_title(title or "radar SLAM", fontsize=10)
    fig.legend(loc="outside lower center", ncol=3, fontsize=8)
    return fig


def plot_slam(path: str | os.PathLike[str], res: SlamResult,
              groundtruth: Trajectory | None = None, title: str = "") -> Path:
    """Write :func:`slam_figure` as a PNG (atomically) and return its path."""
    buf = io.BytesIO()
    slam_figure(res, groundtruth, title).savefig(buf, format="png")
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)
