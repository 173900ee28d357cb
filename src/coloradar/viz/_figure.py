"""Figure plumbing shared by the plots: headless figures, atomic saving, axis helpers.

Figures are built with :class:`matplotlib.figure.Figure` and an Agg canvas attached directly,
never through ``pyplot``: nothing needs a display, no global backend is switched for a user
who also plots interactively, and a figure is freed when it goes out of scope.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from ..errors import MissingDependencyError, SettingsError
from ..formats.atomic import atomic_write_bytes, new_output_path

try:
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise MissingDependencyError("coloradar.viz needs matplotlib: pip install 'coloradar[viz]'"
                                 ) from exc

__all__ = ["cell_edges", "check_image_path", "colorbar_beside", "new_figure", "save_figure",
           "to_db"]


def check_image_path(path: str | os.PathLike[str], overwrite: bool = False) -> Path:
    """``path`` as a :class:`~pathlib.Path` for an image about to be saved, checked before any
    work: its suffix names a format matplotlib writes (none means PNG) and it does not exist
    unless ``overwrite``.

    Raises
    ------
    SettingsError
        For an unsupported suffix (naming the supported ones).
    OutputExistsError
        When ``path`` exists and ``overwrite`` is not set.
    """
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower()
    supported = FigureCanvasAgg.get_supported_filetypes()
    if fmt and fmt not in supported:
        raise SettingsError(f"{path}: cannot write a .{fmt} image; expected one of "
                            f"{', '.join('.' + s for s in sorted(supported))}")
    return new_output_path(path, overwrite)

matplotlib.rcParams.setdefault("figure.max_open_warning", 0)


def colorbar_beside(fig: Figure, mappable, ax, label: str):
    """A colour bar beside ``ax``, exactly as tall as the axes are drawn.

    ``fig.colorbar(…, ax=ax)`` sizes the bar to the axes' layout slot; an equal-aspect axes (a
    bird's-eye view, a trajectory) is drawn smaller than its slot, and the bar then stands
    twice the plot's height. An inset axes follows the drawn box (and constrained layout makes
    room for it).
    """
    cax = ax.inset_axes((1.03, 0.0, 0.035, 1.0))
    return fig.colorbar(mappable, cax=cax, label=label)


def new_figure(width: float = 8.0, height: float = 6.0, dpi: int = 100, *,
               ncols: int = 1, projection: str | None = None) -> Figure:
    """A figure of ``width x height`` inches at ``dpi`` (the PNG is ``width·dpi`` pixels wide)
    with ``ncols`` axes side by side, laid out so that labels stay inside."""
    fig = Figure(figsize=(width, height), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    for k in range(ncols):
        fig.add_subplot(1, ncols, k + 1, projection=projection)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
    """Render ``fig`` to ``path`` (format from the suffix: png, pdf, svg, jpg), atomically.

    Raises :class:`~coloradar.OutputExistsError` when ``path`` exists and not ``overwrite``.
    The image has exactly the figure's size in pixels (no tight cropping).
    """
    path = check_image_path(path, overwrite)
    buf = io.BytesIO()
    fmt = path.suffix.lstrip(".").lower() or "png"
    fig.savefig(buf, format=fmt, dpi=fig.dpi)
    atomic_write_bytes(path, buf.getvalue())
    return path


def to_db(power: np.ndarray, floor_db: float = -300.0) -> np.ndarray:
    """``10·log10(power)`` in float32, with zeros mapped to ``floor_db`` instead of -inf."""
    p = np.asarray(power, dtype=np.float32)
    with np.errstate(divide="ignore"):
        out = 10.0 * np.log10(np.maximum(p, 0))
    return np.maximum(out, np.float32(floor_db))


def cell_edges(centres: np.ndarray) -> np.ndarray:
    """Cell boundaries ``(N + 1,)`` around ascending cell ``centres`` ``(N,)``: midpoints inside,
    half a neighbouring step outside (non-uniform grids such as sin-spaced angles)."""
    c = np.asarray(centres, dtype=np.float64).reshape(-1)
    if c.size == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = (c[1:] + c[:-1]) / 2
    return np.concatenate([[c[0] - (c[1] - c[0]) / 2], mid, [c[-1] + (c[-1] - c[-2]) / 2]])
