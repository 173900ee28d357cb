"""Radar images: range–Doppler map, range–azimuth (polar and bird's-eye), heatmap slices.

Every function takes arrays plus their axes (bin centres in metres, radians, m/s) and returns a
:class:`matplotlib.figure.Figure`; save it with :func:`coloradar.viz.save_figure`. Images are
drawn so that the radar's left (+y, positive azimuth, docs/conventions.md §3) is on the picture's left,
as seen from behind the sensor, and range grows upward.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..calib import HeatmapConfig
from ..errors import FrameIndexError, SettingsError
from ._figure import cell_edges, colorbar_beside, new_figure, to_db

__all__ = [
    "HeatmapView",
    "SliceOptions",
    "plot_heatmap_slice",
    "plot_range_azimuth",
    "plot_range_doppler",
]

RANGE_RATE_LABEL = "range rate [m/s] (+ receding)"

HeatmapView = Literal["azimuth-range", "elevation-azimuth"]
"""The two slices of a heatmap :func:`plot_heatmap_slice` draws."""


def _uniform_extent(centres: np.ndarray) -> tuple[float, float]:
    c = np.asarray(centres, dtype=np.float64)
    step = (c[-1] - c[0]) / (c.size - 1) if c.size > 1 else 1.0
    if c.size > 2 and not np.allclose(np.diff(c), step, rtol=1e-6, atol=0):
        raise SettingsError("bin centres must be uniformly spaced for this image")
    return float(c[0] - step / 2), float(c[-1] + step / 2)


def _levels(img: np.ndarray, dynamic_range: float | None) -> tuple[float, float]:
    finite = img[np.isfinite(img)]
    vmax = float(finite.max()) if finite.size else 1.0
    vmin = float(finite.min()) if finite.size else 0.0
    if dynamic_range is not None:
        vmin = max(vmin, vmax - dynamic_range)
    return vmin, max(vmax, vmin + 1e-6)


def _target_axes(fig: Figure | None, ax: Axes | None, size: tuple[float, float]) -> tuple[
        Figure, Axes]:
    if ax is not None:
        # An axes inside a SubFigure: callers get (and save) the whole figure.
        f = ax.figure
        return (f if isinstance(f, Figure) else f.figure), ax
    fig = fig or new_figure(*size)
    return fig, (fig.axes[0] if fig.axes else fig.add_subplot())


def plot_range_doppler(power: np.ndarray, range_bins: np.ndarray, velocity_bins: np.ndarray, *,
                       db: bool = True, dynamic_range: float | None = 60.0,
                       max_range: float | None = None, title: str | None = None,
                       ax: Axes | None = None, size: tuple[float, float] = (7.0, 6.0)) -> Figure:
    """Range–Doppler map.

    Parameters
    ----------
    power
        float ``(range, doppler)``: power (linear) per range bin and Doppler bin, e.g.
        summed over the virtual channels.
    range_bins
        float ``(range,)``: bin centres [m], uniform.
    velocity_bins
        float ``(doppler,)``: bin centres as range rate [m/s], ascending, uniform.
    db
        Show ``10·log10(power)``.
    dynamic_range
        Colour scale spans this many dB below the maximum (None: the full range).
    max_range
        Clip the range axis [m].
    title, ax, size
        Title; an axes to draw into (else a new figure of ``size`` inches).

    Returns
    -------
    Figure
        ``ax.images[0]`` holds the array as drawn; its extent maps array cells to metres and
        m/s (``origin="lower"``: row 0 is the nearest range).
    """
    p = np.asarray(power)
    r = np.asarray(range_bins, dtype=np.float64)
    v = np.asarray(velocity_bins, dtype=np.float64)
    if p.shape != (r.size, v.size):
        raise SettingsError(f"power is {p.shape} but the axes are {r.size} ranges x {v.size} "
                            "Doppler bins")
    if max_range is not None:
        keep = r <= max_range
        p, r = p[keep], r[keep]
    img = to_db(p) if db else p.astype(np.float32)
    fig, ax = _target_axes(None, ax, size)
    vmin, vmax = _levels(img, dynamic_range if db else None)
    im = ax.imshow(img, origin="lower", aspect="auto", interpolation="nearest",
                   extent=(*_uniform_extent(v), *_uniform_extent(r)), vmin=vmin, vmax=vmax,
                   cmap="viridis")
    ax.set_xlabel(RANGE_RATE_LABEL)
    ax.set_ylabel("range [m]")
    ax.set_title(title or "range–Doppler", fontsize="medium")
    fig.colorbar(im, ax=ax, label="power [dB]" if db else "power")
    return fig


def plot_range_azimuth(power: np.ndarray, range_bins: np.ndarray, azimuth_bins: np.ndarray, *,
                       mode: Literal["bev", "polar"] = "bev", db: bool = True,
                       dynamic_range: float | None = 40.0,
                       max_range: float | None = None, title: str | None = None,
                       ax: Axes | None = None, size: tuple[float, float] = (8.0, 6.0)) -> Figure:
    """Range–azimuth image, as a bird's-eye view or on range/azimuth axes.

    Parameters
    ----------
    power
        float ``(azimuth, range)`` linear power (a heatmap's elevation slice or maximum).
    range_bins
        float ``(range,)`` bin centres [m].
    azimuth_bins
        float ``(azimuth,)`` bin centres [rad], ascending; positive = toward +y (left).
    mode
        ``"bev"``: Cartesian bird's-eye view, x (boresight) up and y (left) to the left, in
        metres; ``"polar"``: azimuth [deg] across (left on the left), range [m] up.
    db, dynamic_range, max_range, title, ax, size
        As :func:`plot_range_doppler`.

    Returns
    -------
    Figure
        ``ax.collections[0]`` is the :class:`~matplotlib.collections.QuadMesh`; its
        coordinates are the cell corners in the plotted units.
    """
    p = np.asarray(power)
    r = np.asarray(range_bins, dtype=np.float64)
    az = np.asarray(azimuth_bins, dtype=np.float64)
    if p.shape != (az.size, r.size):
        raise SettingsError(f"power is {p.shape} but the axes are {az.size} azimuths x {r.size} "
                            "ranges")
    if max_range is not None:
        keep = r <= max_range
        p, r = p[:, keep], r[keep]
    img = (to_db(p) if db else p.astype(np.float32)).T                 # (range, azimuth)
    r_edges = np.maximum(cell_edges(r), 0.0)
    a_edges = np.clip(cell_edges(az), -np.pi / 2, np.pi / 2)
    if mode == "bev" and ax is None:
        # A figure of the fan's own shape (width across y over height along x), so that the
        # equal-aspect fan fills it instead of floating in white space.
        span = r_edges[-1] * (np.sin(a_edges.max()) - np.sin(a_edges.min()))
        size = (size[0], min(size[1], 0.8 * size[0] * r_edges[-1] / max(span, 1e-9) + 1.4))
    fig, ax = _target_axes(None, ax, size)
    vmin, vmax = _levels(img, dynamic_range if db else None)
    if mode == "polar":
        mesh = ax.pcolormesh(np.degrees(a_edges), r_edges, img, vmin=vmin, vmax=vmax,
                             cmap="viridis", shading="flat")
        ax.set_xlim(np.degrees(a_edges[-1]), np.degrees(a_edges[0]))   # +azimuth (left) on left
        ax.set_xlabel("azimuth [deg] (+ = left)")
        ax.set_ylabel("range [m]")
    elif mode == "bev":
        rr, aa = np.meshgrid(r_edges, a_edges, indexing="ij")           # (R+1, A+1)
        x, y = rr * np.cos(aa), rr * np.sin(aa)
        mesh = ax.pcolormesh(y, x, img, vmin=vmin, vmax=vmax, cmap="viridis", shading="flat")
        ax.set_aspect("equal")
        ax.set_xlim(y.max(), y.min())                                   # +y (left) on the left
        ax.set_ylim(0, r_edges[-1])
        ax.set_xlabel("y [m] (left +)")
        ax.set_ylabel("x [m] (boresight)")
    else:
        raise SettingsError(f"mode must be 'bev' or 'polar', got {mode!r}")
    ax.set_title(title or "range–azimuth", fontsize="medium")
    colorbar_beside(fig, mesh, ax, "power [dB]" if db else "power")
    return fig


def _pick(hm: np.ndarray, axis: int, index: int | None, reduce: Literal["slice", "max"]) -> tuple[np.ndarray,
                                                                               np.ndarray, int]:
    """Slice (or max-reduce) intensity and range rate along ``axis`` of ``(el, az, range)``."""
    inten, rate = hm[..., 0], hm[..., 1]
    if reduce == "max":
        arg = np.argmax(inten, axis=axis)
        return (np.take_along_axis(inten, np.expand_dims(arg, axis), axis).squeeze(axis),
                np.take_along_axis(rate, np.expand_dims(arg, axis), axis).squeeze(axis), -1)
    if reduce != "slice":
        raise SettingsError(f"reduce must be 'slice' or 'max', got {reduce!r}")
    if index is None:
        index = int(np.unravel_index(np.argmax(inten), inten.shape)[axis])
    if not -inten.shape[axis] <= index < inten.shape[axis]:
        raise FrameIndexError(f"bin {index} out of range for an axis of {inten.shape[axis]} bins")
    return np.take(inten, index, axis), np.take(rate, index, axis), index % inten.shape[axis]


@dataclass(frozen=True)
class SliceOptions:
    """How :func:`plot_heatmap_slice` cuts and draws a heatmap (each field is also one of its
    keywords, documented there)."""

    view: HeatmapView = "azimuth-range"
    index: int | None = None
    reduce: Literal["slice", "max"] = "slice"
    db: bool = True
    dynamic_range: float = 40.0
    show_range_rate: bool = True
    max_range: float | None = None
    title: str | None = None
    size: tuple[float, float] | None = None


def plot_heatmap_slice(heatmap: np.ndarray, config: HeatmapConfig,
                       options: SliceOptions | None = None, **fields: Any) -> Figure:
    """A 2-D cut through a 3-D radar heatmap, with its range-rate channel beside it.

    Parameters
    ----------
    heatmap
        float ``(el, az, range, 2)`` (channel 0 intensity, channel 1 range rate [m/s]) or
        ``(el, az, range)`` intensity only.
    config
        The heatmap's grid (bin angles and range bin width); for the dataset's shipped
        heatmaps, the calib's ``heatmap_cfg`` (see docs/calibration.md on its angle lists).
    options
        A :class:`SliceOptions` (its fields are listed below); keyword arguments named like
        its fields replace them (``plot_heatmap_slice(hm, cfg, view="elevation-azimuth")``).

    Other Parameters
    ----------------
    view
        ``"azimuth-range"`` (at one elevation bin) or ``"elevation-azimuth"`` (at one range
        bin).
    index
        The elevation (resp. range) bin; default the bin holding the heatmap's maximum.
    reduce
        ``"slice"`` or ``"max"`` (maximum over all elevation, resp. range, bins).
    show_range_rate
        Add a second panel with the range rate of cells within 20 dB of the slice's maximum.

    Returns
    -------
    Figure
        ``axes[0].collections[0]``: the intensity mesh (corners in degrees and metres).
    """
    o = replace(options or SliceOptions(), **fields)
    view, index, reduce, db, show_range_rate = o.view, o.index, o.reduce, o.db, o.show_range_rate
    hm = np.asarray(heatmap, dtype=np.float32)
    if hm.ndim == 3:
        hm = np.stack([hm, np.zeros_like(hm)], axis=-1)
        show_range_rate = False
    if hm.shape[:3] != config.shape or hm.shape[3] != 2:
        raise SettingsError(f"heatmap is {hm.shape}, the grid (el, az, range) is {config.shape}")
    if view == "azimuth-range":
        inten, rate, idx = _pick(hm, 0, index, reduce)                     # (az, range)
        where = ("max over elevation" if idx < 0 else
                 f"elevation {np.degrees(config.elevation_bins[idx]):+.1f}° (bin {idx})")
    elif view == "elevation-azimuth":
        inten, rate, idx = _pick(hm, 2, index, reduce)                     # (el, az)
        where = ("max over range" if idx < 0 else
                 f"range {config.range_bins[idx]:.2f} m (bin {idx})")
    else:
        raise SettingsError(f"view must be 'azimuth-range' or 'elevation-azimuth', got {view!r}")
    ncols = 2 if show_range_rate else 1
    fig = new_figure(*(o.size or (6.5 * ncols, 5.5)), ncols=ncols)
    img = to_db(inten) if db else inten
    vmin, vmax = _levels(img, o.dynamic_range if db else None)
    strong = img >= (vmax - 20.0 if db else 0.1 * vmax)
    az_edges = np.degrees(np.clip(cell_edges(config.azimuth_bins), -np.pi / 2, np.pi / 2))
    panels = [(img, "viridis", vmin, vmax, "intensity [dB]" if db else "intensity")]
    if show_range_rate:
        lim = float(np.max(np.abs(rate[strong]))) if strong.any() else 1.0
        panels.append((np.where(strong, rate, np.nan), "coolwarm", -max(lim, 1e-3),
                       max(lim, 1e-3), RANGE_RATE_LABEL))
    for ax, (data, cmap, lo, hi, label) in zip(fig.axes, panels, strict=False):
        if view == "azimuth-range":
            r_edges = np.maximum(cell_edges(config.range_bins), 0.0)
            mesh = ax.pcolormesh(az_edges, r_edges, data.T, cmap=cmap, vmin=lo, vmax=hi)
            ax.set_ylabel("range [m]")
            if o.max_range is not None:
                ax.set_ylim(0, o.max_range)
        else:
            el_edges = np.degrees(np.clip(cell_edges(config.elevation_bins), -np.pi / 2,
                                          np.pi / 2))
            mesh = ax.pcolormesh(az_edges, el_edges, data, cmap=cmap, vmin=lo, vmax=hi)
            ax.set_ylabel("elevation [deg] (+ = up)")
        ax.set_xlim(az_edges[-1], az_edges[0])                              # left on the left
        ax.set_xlabel("azimuth [deg] (+ = left)")
        fig.colorbar(mesh, ax=ax, label=label)
    fig.axes[0].set_title(f"{view}: {where}", fontsize="medium")
    if o.title:
        fig.suptitle(o.title, fontsize="medium")
    if show_range_rate:
        fig.axes[1].set_title("range rate of the strong cells", fontsize="medium")
    return fig
