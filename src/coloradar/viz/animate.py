"""Animation of a run: each sensor's latest reading and the ground truth, frame by frame.

What the original devkit's ``plot_pointclouds.py`` showed, rendered headless to a file: a
fixed-rate timeline (``fps`` pictures per second of run time, so the video plays in real
time), each picture a :func:`~coloradar.viz.scene.gather_scene` in a rig- or sensor-centric
frame. GIFs are written with Pillow; MP4 with ffmpeg, found through ``imageio-ffmpeg``
(``pip install 'coloradar[viz]'``) or on the PATH.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib import animation
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize

from ..errors import MissingDataError, MissingDependencyError, SettingsError
from ..formats.atomic import default_file_mode, make_output_dir, new_output_path
from ._figure import new_figure
from .scene import (
    REFERENCE_STREAMS,
    _has,
    _rate_norm,
    _run_start,
    _stream,
    draw_scene,
    gather_scene,
)

__all__ = ["AnimationSettings", "animate_run", "animation_times", "ffmpeg_path"]


def ffmpeg_path() -> str | None:
    """The ffmpeg executable: imageio-ffmpeg's bundled binary, else ``ffmpeg`` on the PATH."""
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        return shutil.which("ffmpeg")


def _writer(suffix: str, fps: float) -> animation.AbstractMovieWriter:
    if suffix == ".gif":
        # matplotlib's stubs say int; both writers take a fractional rate (Pillow: a frame lasts
        # 1000/fps ms; ffmpeg: -r fps).
        return animation.PillowWriter(fps=fps)  # type: ignore[arg-type]
    if suffix == ".mp4":
        exe = ffmpeg_path()
        if exe is None:
            raise MissingDependencyError("writing .mp4 needs ffmpeg: pip install imageio-ffmpeg "
                                         "(or 'coloradar[viz]'), or write a .gif")
        matplotlib.rcParams["animation.ffmpeg_path"] = exe
        # yuv420p: the pixel format every player decodes; even sizes are ensured by the figure.
        return animation.FFMpegWriter(fps=fps, codec="libx264",  # type: ignore[arg-type]
                                      extra_args=["-pix_fmt", "yuv420p"])
    raise SettingsError(f"unsupported animation format {suffix!r}: use .mp4 or .gif")


def animation_times(seq, start: float = 0.0, duration: float | None = None,
                    fps: float = 10.0) -> np.ndarray:
    """The picture times [s]: from ``start`` seconds after the run's start (its first
    ground-truth pose, else its first frame) for ``duration`` seconds (default: to the last
    frame of any shown stream), ``fps`` per second."""
    t0 = _run_start(seq) + start
    ends = [float(_stream(seq, s).timestamps[-1]) for s in REFERENCE_STREAMS
            if _has(seq, s) and len(_stream(seq, s).timestamps)]
    if not ends:
        raise MissingDataError(f"{seq.name}: no radar or lidar frames to animate")
    t1 = max(ends) if duration is None else t0 + duration
    n = int(np.floor((t1 - t0) * fps + 1e-9)) + 1
    if n < 1 or t0 > max(ends):
        raise MissingDataError(f"{seq.name}: nothing to animate from {start:g} s "
                               f"(the run's frames end {max(ends) - _run_start(seq):.2f} s in)")
    return t0 + np.arange(n) / fps


@dataclass(frozen=True)
class AnimationSettings:
    """What :func:`animate_run` renders and how (each field is also one of its keywords,
    documented there)."""

    start: float = 0.0
    duration: float | None = None
    fps: float = 10.0
    frame: str = "base"
    view: str = "bev"
    extent: float = 20.0
    rate_limit: float | None = None
    size: tuple[float, float] = (8.0, 7.2)
    dpi: int = 100


_ANIMATION_FIELDS = frozenset(f.name for f in fields(AnimationSettings))


def animate_run(seq, out: str | os.PathLike[str], settings: AnimationSettings | None = None, *,
                overwrite: bool = False, progress: Callable[[int, int], None] | None = None,
                **options: Any) -> Path:
    """Render a run to ``out`` (``.mp4`` or ``.gif``).

    Parameters
    ----------
    seq
        A sequence.
    out
        Output file; written atomically (a temporary file in the same folder, then renamed).
    settings
        An :class:`AnimationSettings` (its fields are listed below); keyword arguments named
        like its fields replace them (``animate_run(seq, "run.gif", fps=4)``), the others go
        to :func:`~coloradar.viz.scene.gather_scene`.
    overwrite
        Replace an existing ``out``; otherwise :class:`~coloradar.OutputExistsError`.
    progress
        Called as ``progress(done, total)`` after each picture.
    **options
        Fields of :class:`AnimationSettings`, and keywords of
        :func:`~coloradar.viz.scene.gather_scene`.

    Other Parameters
    ----------------
    start, duration, fps
        See :func:`animation_times`.
    frame
        ``"base"`` (rig-centric, default), a sensor name (sensor-centric) or ``"world"``.
    view, extent, rate_limit
        See :func:`~coloradar.viz.scene.draw_scene` and :func:`~coloradar.viz.plot_scene`.
    size, dpi
        Picture size in inches and resolution (``size·dpi`` pixels; rounded to even).

    Returns
    -------
    pathlib.Path
        ``out``.
    """
    s = replace(settings or AnimationSettings(),
                **{k: v for k, v in options.items() if k in _ANIMATION_FIELDS})
    gather = {k: v for k, v in options.items() if k not in _ANIMATION_FIELDS}
    fps, frame, view, extent, dpi = s.fps, s.frame, s.view, s.extent, s.dpi
    out = new_output_path(out, overwrite)
    suffix = out.suffix.lower()
    writer = _writer(suffix, fps)
    times = animation_times(seq, s.start, s.duration, fps)
    w, h = (2 * round(v * dpi / 2) / dpi for v in s.size)  # even pixel counts for x264
    fig = new_figure(w, h, dpi, projection="3d" if view == "3d" else None)
    ax = fig.axes[0]
    if s.rate_limit is None:
        probe = gather_scene(seq, float(times[0]), frame=frame, **gather)
        norm = _rate_norm(seq, probe, None)
    else:
        norm = Normalize(-s.rate_limit, s.rate_limit)
    fig.colorbar(ScalarMappable(norm=norm, cmap="coolwarm"), ax=ax,
                 label="radar range rate [m/s] (+ receding)", shrink=0.8)
    t_run = _run_start(seq)
    cache: dict = {}
    make_output_dir(out.parent)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.stem}.", suffix=f".tmp{suffix}", dir=out.parent)
    os.close(fd)
    try:
        with writer.saving(fig, tmp, dpi):
            for k, t in enumerate(times):
                ax.clear()
                scene = gather_scene(seq, float(t), frame=frame, cache=cache, **gather)
                draw_scene(ax, scene, seq.calib, view=view, extent=extent, norm=norm)
                ax.set_title(f"{seq.name}\nt = {t - t_run:6.2f} s, {frame} frame",
                             fontsize="medium")
                writer.grab_frame()
                if k == 0:  # freeze the layout so that the picture does not jitter
                    fig.set_layout_engine("none")
                if progress is not None:
                    progress(k + 1, len(times))
        os.chmod(tmp, default_file_mode())
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return out
