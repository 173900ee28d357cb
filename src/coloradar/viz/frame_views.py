"""One picture of one frame of a run, by view name: the library side of ``coloradar plot``.

Range–Doppler and range–azimuth images are computed from raw ADC frames with
:class:`coloradar.dsp.RadarProcessor`; heatmap slices use the run's shipped heatmaps when it
has them (else heatmaps computed from ADC); the scene view is :func:`~.scene.plot_scene`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
from matplotlib.figure import Figure

from ..calib import RadarCalib
from ..errors import MissingDataError, SettingsError
from .radar import HeatmapView, plot_heatmap_slice, plot_range_azimuth, plot_range_doppler
from .scene import _has, _run_start, plot_scene, radar_source

__all__ = ["VIEWS", "FrameViewOptions", "frame_figure", "range_azimuth_figure",
           "range_doppler_figure"]

VIEWS = ("range-doppler", "range-azimuth", "heatmap", "scene")


def _processor(calib: RadarCalib):
    from ..dsp import RadarProcessor

    return RadarProcessor(calib)


def range_doppler_figure(adc: np.ndarray, calib: RadarCalib, *, title: str | None = None,
                         **kw) -> Figure:
    """Range–Doppler map of one ADC frame ``(tx, rx, chirp, sample)``: the processor's
    non-coherent power over all virtual channels (see :func:`~.radar.plot_range_doppler` for
    ``**kw``)."""
    proc = _processor(calib)
    power = np.asarray(proc.range_doppler_power(adc)).T                # (range, doppler)
    ranges = np.arange(power.shape[0]) * proc.range_bin_width
    return plot_range_doppler(power, ranges, proc.velocities,
                              title=title or f"{calib.name} range–Doppler", **kw)


def range_azimuth_figure(adc: np.ndarray, calib: RadarCalib, *,
                         mode: Literal["bev", "polar"] = "bev",
                         title: str | None = None, **kw) -> Figure:
    """Range–azimuth image of one ADC frame (maximum over elevation of its heatmap)."""
    proc = _processor(calib)
    hm = np.asarray(proc.heatmap(adc))
    cfg = proc.heatmap_config()
    return plot_range_azimuth(hm[..., 0].max(axis=0), cfg.range_bins, cfg.azimuth_bins,
                              mode=mode, title=title or f"{calib.name} range–azimuth", **kw)


@dataclass(frozen=True)
class FrameViewOptions:
    """How :func:`frame_figure` draws a frame (each field is also one of its keywords,
    documented there)."""

    coords: str = "base"
    scene_view: str = "bev"
    stream: str | None = None
    extent: float | None = 20.0
    heatmap_slice: HeatmapView = "azimuth-range"
    polar: bool = False
    max_range: float | None = None


def frame_figure(seq, view: str, index: int = 0, options: FrameViewOptions | None = None, *,
                 radar: str | None = None, **fields: Any) -> Figure:
    """The ``view`` picture of frame ``index`` of ``seq``.

    Parameters
    ----------
    seq
        A sequence.
    view
        One of :data:`VIEWS`.
    index
        Frame index in the radar's ADC stream (range-doppler, range-azimuth), its heatmap
        stream (heatmap), or the scene's reference stream (scene; see ``stream``).
    options
        A :class:`FrameViewOptions` (its fields are listed below); keyword arguments named
        like its fields replace them (``frame_figure(seq, "scene", 3, coords="world")``).
    radar
        ``"cascade"`` or ``"single_chip"``; None: the cascade, and for the scene both radars.
        A scene with a radar named shows the lidar and that radar only, and ``index`` counts
        in that radar's point stream unless ``stream`` is given.

    Other Parameters
    ----------------
    coords, scene_view, stream, extent
        Scene: frame (``"base"``, ``"world"`` or a sensor name), ``"bev"`` or ``"3d"``, the
        stream ``index`` counts in, half-width [m] (:func:`~.scene.plot_scene`).
    heatmap_slice
        ``"azimuth-range"`` or ``"elevation-azimuth"``.
    polar
        Range–azimuth on azimuth/range axes instead of a bird's-eye view.
    max_range
        Clip range axes [m].
    """
    o = replace(options or FrameViewOptions(), **fields)
    stream, heatmap_slice, polar, max_range = o.stream, o.heatmap_slice, o.polar, o.max_range
    if view not in VIEWS:
        raise SettingsError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")
    if view == "scene":
        gather: dict[str, Any] = {}
        if radar is not None:
            if stream is None:
                stream = radar_source(seq, radar)
                if stream is None:
                    raise MissingDataError(f"{seq.name}: no {radar} point clouds, ADC frames "
                                           f"or heatmaps to show (present: "
                                           f"{', '.join(seq.available()) or 'nothing'})")
            gather["sensors"] = ("lidar", radar)
        return plot_scene(seq, index=index, stream=stream, frame=o.coords, view=o.scene_view,
                          extent=o.extent, **gather)
    radar = radar or "cascade"
    calib = seq.calib.radar(radar)
    t_run = _run_start(seq)
    has_adc, has_hm = _has(seq, f"{radar}/adc"), _has(seq, f"{radar}/heatmaps")
    if has_hm and (view == "heatmap" or (view == "range-azimuth" and not has_adc)):
        stream_ = seq.radar(radar).heatmaps
        hm = stream_[index]
        when = f"{seq.name} {radar} heatmap {index}, t = {stream_.timestamps[index] - t_run:.2f} s"
        if view == "heatmap":
            return plot_heatmap_slice(hm, calib.heatmap, view=heatmap_slice, max_range=max_range,
                                      title=f"heatmap, {when}")
        return plot_range_azimuth(hm[..., 0].max(axis=0), calib.heatmap.range_bins,
                                  calib.heatmap.azimuth_bins, mode="polar" if polar else "bev",
                                  max_range=max_range, title=f"range–azimuth\n{when}")
    if not has_adc:
        need = f"{radar}/adc" if view == "range-doppler" else f"{radar}/adc or {radar}/heatmaps"
        raise MissingDataError(f"{seq.name}: the {view} view needs {need} frames "
                               f"(present: {', '.join(seq.available()) or 'nothing'})")
    stream_ = seq.radar(radar).adc
    adc = stream_[index]
    when = f"{seq.name} {radar} ADC frame {index}, t = {stream_.timestamps[index] - t_run:.2f} s"
    if view == "range-doppler":
        return range_doppler_figure(adc, calib, title=f"range–Doppler\n{when}",
                                    max_range=max_range)
    if view == "range-azimuth":
        return range_azimuth_figure(adc, calib, mode="polar" if polar else "bev",
                                    title=f"range–azimuth\n{when}", max_range=max_range)
    proc = _processor(calib)
    return plot_heatmap_slice(proc.heatmap(adc), proc.heatmap_config(), view=heatmap_slice,
                              max_range=max_range, title=f"heatmap computed from ADC, {when}")
