"""The evaluation figure (needs matplotlib: ``pip install 'coloradar[viz]'``).

Built on :class:`matplotlib.figure.Figure` with an Agg canvas, never ``pyplot``: no display
needed and no global backend switched.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import MissingDependencyError
from ..formats.atomic import atomic_write_bytes, new_output_path

try:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise MissingDependencyError("the odometry plot needs matplotlib: "
                                 "pip install 'coloradar[viz]'") from exc

if TYPE_CHECKING:
    from .metrics import Evaluation

__all__ = ["evaluation_figure", "plot_evaluation"]


ELONGATED = 3.0
"""A top view whose extent along its main direction is over this many times the extent across
is drawn along/across the path (stretched across), not at equal aspect."""


def top_view_frame(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """How to draw the top view of points ``xy`` (float ``(N, 2)`` [m]): the rotation ``R``
    (2 × 2) and centre ``c`` such that ``(xy − c)·Rᵀ`` is (along the main direction, across
    it), the path's first point on the low side, and the extents' ratio along/across."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    c = xy.mean(axis=0) if len(xy) else np.zeros(2)
    if len(xy) < 3:
        return np.eye(2), c, 1.0
    _, vec = np.linalg.eigh(np.cov((xy - c).T))
    major = vec[:, 1]
    if (xy[0] - c) @ major > 0:                  # the path starts at the low end
        major = -major
    rot = np.array([[major[0], major[1]], [-major[1], major[0]]])
    span = np.ptp((xy - c) @ rot.T, axis=0)
    return rot, c, float(span[0] / max(span[1], 1e-9))


def _top_view(ax, ref: np.ndarray, est: np.ndarray, align: str) -> None:
    """Ground truth and aligned estimate from above: at equal aspect, or along/across the
    path where it is long and thin (a hallway at equal aspect is a line in an empty square)."""
    rot, c, ratio = top_view_frame(ref[:, :2])
    if ratio > ELONGATED:
        ref = (ref[:, :2] - c) @ rot.T
        est = (est[:, :2] - c) @ rot.T
    ax.plot(ref[:, 0], ref[:, 1], "k-", lw=1.5, label="ground truth")
    ax.plot(est[:, 0], est[:, 1], "-", color="tab:red", lw=1.0,
            label=f"estimate ({align} aligned)")
    ax.plot(ref[:1, 0], ref[:1, 1], "ko", ms=4)
    if ratio > ELONGATED:
        ax.set(xlabel="along the path's main direction [m]",
               ylabel="across it [m] (stretched)",
               title="trajectory (top view, along / across the path)")
    else:
        ax.set(xlabel="x [m]", ylabel="y [m]", title="trajectory (top view)")
        ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)


def evaluation_figure(ev: Evaluation) -> Figure:
    """Four panels: top view of the aligned estimate and the ground truth, ATE over time,
    ego-velocity against ground truth, RPE per distance."""
    fig = Figure(figsize=(12.0, 8.0), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots(2, 2)
    a = ev.ate
    t0 = ev.reference.timestamps[0]
    ref, est = ev.reference.translations, a.aligned.translations
    _top_view(ax[0, 0], ref, est, ev.info.get("align", "se3"))

    ax[0, 1].plot(a.timestamps - t0, a.errors, color="tab:red", lw=1.0)
    ax[0, 1].set(xlabel="time [s]", ylabel="position error [m]",
                 title=f"ATE: RMSE {a.rmse:.3f} m ({a.rmse_percent:.2f} % of "
                       f"{a.path_length:.1f} m)")
    ax[0, 1].grid(alpha=0.3)

    v = ev.velocity
    if v is not None and v.timestamps.size:
        for k, c in enumerate(("tab:blue", "tab:orange", "tab:green")):
            ax[1, 0].plot(v.timestamps - t0, v.reference[:, k], "-", color=c, lw=1.5, alpha=0.5,
                          label=f"v{'xyz'[k]} truth")
            ax[1, 0].plot(v.timestamps - t0, v.estimate[:, k], ".", color=c, ms=3,
                          label=f"v{'xyz'[k]} radar")
        ax[1, 0].set(xlabel="time [s]", ylabel="velocity, radar frame [m/s]",
                     title=f"ego-velocity: RMSE {v.rmse:.3f} m/s")
        ax[1, 0].legend(loc="best", fontsize=7, ncol=3)
    else:
        ax[1, 0].plot(ev.reference.timestamps - t0, ref[:, 2], "k-", label="ground truth")
        ax[1, 0].plot(a.timestamps - t0, est[:, 2], "-", color="tab:red", label="estimate")
        ax[1, 0].set(xlabel="time [s]", ylabel="z [m]", title="height")
        ax[1, 0].legend(loc="best", fontsize=8)
    ax[1, 0].grid(alpha=0.3)

    d = [r.distance for r in ev.rpe]
    pct = [r.translation_percent for r in ev.rpe]
    rot = [r.rotation_deg_per_m for r in ev.rpe]
    x = np.arange(len(d))
    # two units, two axes: on one, the rotation bars (deg/m, ~0.01) vanish beside the %
    right = ax[1, 1].twinx()
    b1 = ax[1, 1].bar(x - 0.2, pct, 0.4, color="tab:red", label="translation [%]")
    b2 = right.bar(x + 0.2, rot, 0.4, color="tab:gray", label="rotation [deg/m]")
    ax[1, 1].set_xticks(x, [f"{v:g} m" for v in d])
    ax[1, 1].set(xlabel="segment length", ylabel="translation error [%]", title="RPE")
    right.set_ylabel("rotation error [deg/m]")
    ax[1, 1].legend(handles=[b1, b2], loc="best", fontsize=8)
    ax[1, 1].grid(alpha=0.3, axis="y")
    name = ev.info.get("run_name", "")
    if name:
        what = "SLAM" if ev.info.get("estimator") == "slam" else "odometry"
        fig.suptitle(f"{name}: {ev.info.get('radar', '')} radar {what}")
    return fig


def plot_evaluation(ev: Evaluation, path: str | os.PathLike[str], *,
                    overwrite: bool = False) -> Path:
    """Render :func:`evaluation_figure` to ``path`` (format from the suffix), atomically."""
    path = new_output_path(path, overwrite)
    fig = evaluation_figure(ev)
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".").lower() or "png", dpi=fig.dpi)
    atomic_write_bytes(path, buf.getvalue())
    return path
