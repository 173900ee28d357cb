"""The heatmap grid (``heatmap_cfg.txt``): sizes, range bin width and the angle of every bin."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from ._parse import get_floats, get_number, key_values, readonly

__all__ = ["HeatmapConfig", "format_heatmap_cfg", "parse_heatmap_cfg", "shipped_angle_bins"]


@dataclass(frozen=True, eq=False)
class HeatmapConfig:
    """Grid of a 3D radar heatmap ``(el, az, range)``.

    Attributes
    ----------
    num_range_bins, num_azimuth_bins, num_elevation_bins
        Grid sizes.
    range_bin_width
        Metres per range bin; range index r is centred on ``r · range_bin_width``.
    azimuth_bins, elevation_bins
        float64 ``(num_azimuth_bins,)`` and ``(num_elevation_bins,)``: bin angles in radians,
        ascending.
    """

    num_range_bins: int
    num_elevation_bins: int
    num_azimuth_bins: int
    range_bin_width: float
    azimuth_bins: np.ndarray
    elevation_bins: np.ndarray

    def __post_init__(self) -> None:
        az = readonly(np.asarray(self.azimuth_bins, dtype=np.float64))
        el = readonly(np.asarray(self.elevation_bins, dtype=np.float64))
        object.__setattr__(self, "azimuth_bins", az)
        object.__setattr__(self, "elevation_bins", el)
        if az.shape != (self.num_azimuth_bins,) or el.shape != (self.num_elevation_bins,):
            raise CalibrationError(
                f"heatmap_cfg: {az.size} azimuth and {el.size} elevation angles given for "
                f"{self.num_azimuth_bins} x {self.num_elevation_bins} bins")
        for key, a in (("azimuth_bins", az), ("elevation_bins", el)):
            if not np.all(np.isfinite(a)) or np.any(np.abs(a) > np.pi / 2 + 1e-9):
                raise CalibrationError(f"heatmap_cfg: {key} must be finite angles within "
                                       f"±π/2 rad, got values from {float(a.min()):g} to {float(a.max()):g}")
        if np.any(np.diff(az) <= 0) or np.any(np.diff(el) <= 0):
            raise CalibrationError("heatmap_cfg: angle lists must be strictly ascending")
        if min(self.num_range_bins, self.num_azimuth_bins, self.num_elevation_bins) <= 0 or max(
                self.num_range_bins, self.num_azimuth_bins, self.num_elevation_bins) > 65536:
            raise CalibrationError("heatmap_cfg: sizes must lie in 1..65536, got "
                                   f"{self.num_range_bins}, {self.num_azimuth_bins}, "
                                   f"{self.num_elevation_bins}")
        if not (math.isfinite(self.range_bin_width) and 0 < self.range_bin_width <= 100.0):
            raise CalibrationError(f"heatmap_cfg: range_bin_width = {self.range_bin_width!r} m "
                                   "is not physically sensible; expected a value in (0, 100] m")

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(el, az, range)`` shape of one heatmap channel."""
        return (self.num_elevation_bins, self.num_azimuth_bins, self.num_range_bins)

    @property
    def range_bins(self) -> np.ndarray:
        """float64 ``(num_range_bins,)``: centre range of every range bin [m]."""
        return np.arange(self.num_range_bins) * self.range_bin_width

    @property
    def max_range(self) -> float:
        """Range of the last bin's centre [m]."""
        return (self.num_range_bins - 1) * self.range_bin_width


def shipped_angle_bins(n: int) -> np.ndarray:
    """Angles of the shipped ColoRadar heatmap bins, ``asin((2(i+0.5)/n − 1)·76/77)`` [rad].

    This is how the original processing labelled its bins (half a bin off the FFT grid, scaled
    by a carrier ratio that does not match the sensor). Use it to *read* shipped heatmaps; the
    heatmaps coloradar computes carry their true bin angles instead.
    """
    i = np.arange(n)
    return np.arcsin((2.0 * (i + 0.5) / n - 1.0) * 76.0 / 77.0)


def parse_heatmap_cfg(text: str, name: str = "heatmap_cfg.txt") -> HeatmapConfig:
    """Parse ``heatmap_cfg.txt``."""
    kv = key_values(text, name)
    try:
        return HeatmapConfig(
            num_range_bins=get_number(kv, "num_range_bins", name, int),
            num_elevation_bins=get_number(kv, "num_elevation_bins", name, int),
            num_azimuth_bins=get_number(kv, "num_azimuth_bins", name, int),
            range_bin_width=get_number(kv, "range_bin_width", name),
            azimuth_bins=get_floats(kv, "azimuth_bins", name),
            elevation_bins=get_floats(kv, "elevation_bins", name),
        )
    except CalibrationError as exc:
        msg = str(exc)
        raise CalibrationError(msg if msg.startswith(name) else f"{name}: {msg}") from None


def format_heatmap_cfg(h: HeatmapConfig) -> str:
    """The dataset's ``heatmap_cfg.txt`` text for ``h`` (angles at full precision)."""
    return (
        f"num_range_bins {h.num_range_bins}\n"
        f"num_elevation_bins {h.num_elevation_bins}\n"
        f"num_azimuth_bins {h.num_azimuth_bins}\n"
        f"range_bin_width {h.range_bin_width!r}\n"
        "azimuth_bins " + " ".join(repr(float(a)) for a in h.azimuth_bins) + "\n"
        "elevation_bins " + " ".join(repr(float(e)) for e in h.elevation_bins) + "\n"
    )
