"""Points of a radar frame, whatever the frame is: the one place that turns raw ADC frames,
heatmaps or the sensor's own point clouds into float32 ``(N, 5)`` clouds
(``x y z intensity range_rate``, radar frame), and the one place that puts a heatmap cell in
space.

Odometry, the scene viewer, the rerun logger and the map builder all take their radar points
from here, so that a heatmap cell or an ADC detection lands at the same spot in each.

Heatmap cells are placed by direction sines, as the FFT grid measures them (``docs/dsp.md``):
a cell at bin angles ``(α, ε)`` and range index ``r`` lies at ``R·(√(1 − u_y² − u_z²), u_y, u_z)``
with ``u_y = sin α``, ``u_z = sin ε`` and ``R = r · range_bin_width``. (Reading the two angles
as spherical azimuth and elevation instead, ``R·(cos ε cos α, cos ε sin α, sin ε)``, moves an
off-axis cell by several centimetres at 10 m.)
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal, Protocol, get_args

import numpy as np

from ..calib import HeatmapConfig, RadarCalib
from ..errors import ColoradarError, MissingDataError
from .detect import heatmap_cell_xyz, heatmap_pointcloud

__all__ = [
    "POINT_SOURCES",
    "FramePoints",
    "PointSource",
    "default_point_source",
    "heatmap_cell_xyz",
    "radar_point_stream",
    "strongest",
]

PointSource = Literal["pointclouds", "adc", "heatmaps"]
"""Where a radar's points come from: the sensor's own point clouds, CFAR detections of raw ADC
frames (:meth:`RadarProcessor.pointcloud`), or CFAR peaks of heatmaps
(:func:`~coloradar.dsp.detect.heatmap_pointcloud`)."""

POINT_SOURCES: tuple[PointSource, ...] = get_args(PointSource)
"""The sources in order of preference when none is named."""

HEATMAP_MIN_RANGE = 0.3
"""Default near limit of heatmap points [m]: antenna coupling fills the first bins."""


def strongest(points: np.ndarray, max_points: int | None) -> np.ndarray:
    """The ``max_points`` points of highest intensity (column 3), in their original order."""
    if max_points is None or len(points) <= max_points:
        return points
    keep = np.sort(np.argpartition(points[:, 3], len(points) - max_points)[-max_points:])
    return points[keep]


class FramePoints:
    """Turns frames of one radar stream into point clouds.

    Parameters
    ----------
    calib
        The radar's calibration.
    source
        What the frames are (:data:`PointSource`).
    processing
        ``adc``: settings of :class:`~coloradar.dsp.RadarProcessor` (keyword overrides);
        ``heatmaps``: keyword arguments of :func:`~coloradar.dsp.detect.heatmap_pointcloud`
        (``min_range`` defaults to :data:`HEATMAP_MIN_RANGE`).
    heatmap_config
        Grid of the heatmaps (default: the calibration's ``heatmap_cfg``); give the
        ``heatmap_cfg.txt`` stored beside heatmaps made on another grid.
    max_points
        Keep at most this many points per frame, the strongest (None: all).

    Calling the object with a frame returns float32 ``(N, 5)``: x y z [m], intensity,
    range rate [m/s] (radar frame).
    """

    def __init__(self, calib: RadarCalib, source: PointSource, *,
                 processing: Mapping[str, Any] | None = None,
                 heatmap_config: HeatmapConfig | None = None,
                 max_points: int | None = None) -> None:
        if source not in POINT_SOURCES:
            raise ColoradarError(f"unknown point source {source!r}; expected one of "
                                 f"{', '.join(POINT_SOURCES)}")
        self.calib, self.source, self.max_points = calib, source, max_points
        opts = dict(processing or {})
        self._processor = None
        if source == "adc":
            from .processor import RadarProcessor

            self._processor = RadarProcessor(calib, **opts)
        elif source == "heatmaps":
            opts.setdefault("min_range", HEATMAP_MIN_RANGE)
        self._heatmap_opts = opts
        self.heatmap_config = heatmap_config or calib.heatmap

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        if self.source == "adc":
            assert self._processor is not None
            pts = self._processor.pointcloud(frame)
        elif self.source == "heatmaps":
            pts = heatmap_pointcloud(frame, self.heatmap_config, **self._heatmap_opts)
        else:
            pts = np.asarray(frame, dtype=np.float32)
        return strongest(pts, self.max_points)

    def __repr__(self) -> str:
        return f"<FramePoints {self.calib.name} {self.source}>"


class _Seq(Protocol):
    name: str
    location: str

    def available(self) -> list[str]: ...

    def radar(self, name: str) -> Any: ...


def default_point_source(seq: _Seq, radar: str) -> PointSource | None:
    """The first of :data:`POINT_SOURCES` that the run has for ``radar``, or None."""
    have = set(seq.available())
    return next((s for s in POINT_SOURCES if f"{radar}/{s}" in have), None)


def radar_point_stream(seq: _Seq, radar: str, source: PointSource | None = None, *,
                       processing: Mapping[str, Any] | None = None,
                       max_points: int | None = None) -> tuple[Any, FramePoints]:
    """A radar's frames and the converter that makes points of each.

    Parameters
    ----------
    seq
        A :class:`coloradar.Sequence`.
    radar
        ``"cascade"`` or ``"single_chip"``.
    source
        :data:`PointSource`; None: :func:`default_point_source`.
    processing, max_points
        See :class:`FramePoints`.

    Returns
    -------
    tuple
        ``(stream, points)``: the :class:`~coloradar.dataset.FrameStream` and a
        :class:`FramePoints`; ``points(stream[k])`` is frame ``k``'s cloud.
    """
    src = source or default_point_source(seq, radar)
    if src is None:
        have = ", ".join(seq.available()) or "nothing"
        raise MissingDataError(f"{seq.location}: the {radar} radar has no point clouds, ADC "
                               f"frames or heatmaps in this run (present: {have})")
    if src not in POINT_SOURCES:
        raise ColoradarError(f"unknown source {src!r}; expected one of "
                             f"{', '.join(POINT_SOURCES)}")
    sensor = seq.radar(radar)
    stream = getattr(sensor, src)
    # Heatmaps are placed on the grid they were made on (heatmap_cfg.txt beside them).
    grid = getattr(sensor, "heatmap_config", None) if src == "heatmaps" else None
    return stream, FramePoints(sensor.calib, src, processing=processing, heatmap_config=grid,
                               max_points=max_points)
