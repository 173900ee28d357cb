"""Which azimuth/elevation sign convention matches a sensor's own point clouds.

The antenna file's axes could be mirrored relative to the radar frame (docs/conventions.md §3). The
single-chip sensor shipped its own detections (``single_chip/pointclouds``) for the same frames
as its ADC data; processing the ADC frames under each of the four sign choices and measuring
how far our points lie from the sensor's tells which choice is right.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..calib import RadarCalib
from ..errors import SettingsError
from .processor import ProcessingSettings, RadarProcessor

__all__ = ["SignMatch", "match_sign_convention"]


@dataclass(frozen=True)
class SignMatch:
    """Result of :func:`match_sign_convention`.

    Attributes
    ----------
    azimuth_sign, elevation_sign
        The best choice.
    scores
        ``{(azimuth_sign, elevation_sign): score}``: mean distance [m] from each of our points
        to the nearest reference point of the same frame, each distance capped at
        ``max_distance`` (lower is better).
    num_points
        Our points compared, per choice.
    """

    azimuth_sign: int
    elevation_sign: int
    scores: dict[tuple[int, int], float]
    num_points: dict[tuple[int, int], int]

    @property
    def margin(self) -> float:
        """How much worse the second-best choice scored [m]; small margins are not conclusive."""
        s = sorted(self.scores.values())
        return float(s[1] - s[0]) if len(s) > 1 else float("inf")


def match_sign_convention(calib: RadarCalib, adc_frames: Sequence[np.ndarray],
                          reference_clouds: Sequence[np.ndarray], *, max_distance: float = 1.0,
                          settings: ProcessingSettings | None = None, **overrides) -> SignMatch:
    """Score the four (azimuth_sign, elevation_sign) choices against reference point clouds.

    Parameters
    ----------
    calib
        The radar's calibration.
    adc_frames
        ADC frames, each complex ``(tx, rx, chirp, sample)``.
    reference_clouds
        For each frame, the sensor's own points, float ``(N, ≥3)`` (x y z first), radar frame.
    max_distance
        Cap on each nearest-neighbour distance [m], so that points with no counterpart (a
        detection only one side made) weigh the same under every choice.
    settings, overrides
        Processing settings (the signs are set by this function).

    Returns
    -------
    SignMatch
    """
    if len(adc_frames) != len(reference_clouds):
        raise SettingsError(f"{len(adc_frames)} ADC frames but {len(reference_clouds)} reference "
                            "point clouds; give one cloud per frame")
    trees = [cKDTree(np.asarray(c, dtype=np.float64)[:, :3]) if len(c) else None
             for c in reference_clouds]
    scores: dict[tuple[int, int], float] = {}
    counts: dict[tuple[int, int], int] = {}
    for sa in (1, -1):
        for se in (1, -1):
            proc = RadarProcessor(calib, settings, **{**overrides, "azimuth_sign": sa,
                                                       "elevation_sign": se})
            dists = []
            for adc, tree in zip(adc_frames, trees, strict=True):
                pts = proc.pointcloud(adc)[:, :3]
                if not len(pts):
                    continue
                if tree is None:
                    dists.append(np.full(len(pts), max_distance))
                else:
                    dists.append(np.minimum(tree.query(pts)[0], max_distance))
            d = np.concatenate(dists) if dists else np.empty(0)
            scores[(sa, se)] = float(d.mean()) if d.size else float("inf")
            counts[(sa, se)] = int(d.size)
    # Ties resolve to the project's default (+1, +1), listed first.
    best = min(scores, key=lambda key: scores[key])
    return SignMatch(best[0], best[1], scores, counts)
