"""Pictures of radar data and of a whole run: range–Doppler, range–azimuth, heatmap slices,
multi-sensor scenes and animations. Headless (matplotlib's Agg canvas, no display needed);
requires ``pip install 'coloradar[viz]'``.

Every ``plot_*`` returns a :class:`matplotlib.figure.Figure`; :func:`save_figure` writes it.
"""

from ._figure import cell_edges, new_figure, save_figure, to_db
from .animate import AnimationSettings, animate_run, animation_times, ffmpeg_path
from .frame_views import (
    VIEWS,
    FrameViewOptions,
    frame_figure,
    range_azimuth_figure,
    range_doppler_figure,
)
from .radar import SliceOptions, plot_heatmap_slice, plot_range_azimuth, plot_range_doppler
from .scene import Scene, draw_scene, gather_scene, plot_scene, scene_time

__all__ = [
    "VIEWS",
    "AnimationSettings",
    "FrameViewOptions",
    "Scene",
    "SliceOptions",
    "animate_run",
    "animation_times",
    "cell_edges",
    "draw_scene",
    "ffmpeg_path",
    "frame_figure",
    "gather_scene",
    "new_figure",
    "plot_heatmap_slice",
    "plot_range_azimuth",
    "plot_range_doppler",
    "plot_scene",
    "range_azimuth_figure",
    "range_doppler_figure",
    "save_figure",
    "scene_time",
    "to_db",
]
