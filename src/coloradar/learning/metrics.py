"""Metrics for radar-to-lidar outputs: point-set distances and bird's-eye occupancy scores.

The point-set distances are those of :mod:`coloradar.geometry.cloud_metrics` (one
implementation, re-exported here); this module adds the per-frame scores of a learning output.

The definitions (Chamfer, modified Hausdorff, F-score, occupancy IoU / precision / recall) and
their references are in that module's docstring.

Empty sets: a distance to an empty set is ``inf``; a ratio with a zero denominator is ``nan``
(F is 0 when precision and recall are both 0 or one of them is undefined for an empty set
against a non-empty one). Means over frames (:func:`mean_scores`) skip ``nan``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..geometry.cloud_metrics import (
    chamfer_distance,
    f_from,
    f_score,
    mean_or_nan,
    modified_hausdorff,
    nearest_distances,
    occupancy_scores,
    xyz_points,
)
from .views import BevGrid, lidar_bev

__all__ = ["CloudScores", "chamfer_distance", "f_score", "mean_scores", "modified_hausdorff",
           "nearest_distances", "occupancy_scores", "score_clouds"]


# One implementation for the package (coloradar.geometry.cloud_metrics); the names below stay
# importable from here.
_xyz = xyz_points
_mean = mean_or_nan
_f = f_from


@dataclass(frozen=True)
class CloudScores:
    """Scores of one predicted cloud against its target (see the module docstring).

    Distances in metres; ``bev_*`` are ``nan`` when no grid was given.
    """

    chamfer: float
    modified_hausdorff: float
    f_score: float
    precision: float
    recall: float
    bev_iou: float
    bev_precision: float
    bev_recall: float
    num_pred: int
    num_target: int

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def score_clouds(pred: np.ndarray, target: np.ndarray, threshold: float = 0.2,
                 grid: BevGrid | None = None, valid: np.ndarray | None = None) -> CloudScores:
    """Every metric of one predicted cloud against its target.

    Parameters
    ----------
    pred, target
        float ``(N, ≥3)``, ``(M, ≥3)`` in one frame (the radar frame for lidar targets) [m].
    threshold
        F-score distance [m].
    grid
        BEV grid for the occupancy scores (both clouds rasterised with :func:`lidar_bev`).
    valid
        bool ``(nx, ny)``: cells scored (e.g. the radar's field of view).
    """
    p, t = _xyz(pred, "prediction"), _xyz(target, "target")
    d_pt, d_tp = nearest_distances(p, t), nearest_distances(t, p)
    if p.shape[0] == 0 and t.shape[0] == 0:
        cd = mhd = 0.0
    elif p.shape[0] == 0 or t.shape[0] == 0:
        cd = mhd = math.inf
    else:
        cd = _mean(d_pt) + _mean(d_tp)
        mhd = max(_mean(d_pt), _mean(d_tp))
    prec, rec = _mean(d_pt <= threshold), _mean(d_tp <= threshold)
    iou = bp = br = math.nan
    if grid is not None:
        iou, bp, br = occupancy_scores(lidar_bev(p, grid)[0], lidar_bev(t, grid)[0], valid)
    return CloudScores(cd, mhd, _f(prec, rec), prec, rec, iou, bp, br, int(p.shape[0]),
                       int(t.shape[0]))


def mean_scores(scores: list[CloudScores]) -> dict[str, float]:
    """Mean of every field over frames, skipping ``nan`` (and ``inf`` distances counted as
    such: a frame with an empty prediction makes the mean distance ``inf``)."""
    out: dict[str, float] = {}
    if not scores:
        return out
    for key in scores[0].to_dict():
        v = np.array([getattr(s, key) for s in scores], dtype=np.float64)
        v = v[~np.isnan(v)]
        out[key] = float(v.mean()) if v.size else math.nan
    return out
