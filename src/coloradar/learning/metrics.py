"""Metrics for radar-to-lidar outputs: point-set distances and bird's-eye occupancy scores.

Point sets are compared on x y z (metres, one frame for both). With ``d(p, Q)`` the distance
from ``p`` to the nearest point of ``Q`` (a :class:`scipy.spatial.cKDTree` query):

* **Chamfer distance** ``mean_{p∈P} d(p, T) + mean_{t∈T} d(t, P)`` (the sum of the two mean
  nearest-neighbour distances; ``squared=True`` averages squared distances instead, as many
  point-cloud up-sampling papers report it).
* **Modified Hausdorff distance** ``max(mean_{p∈P} d(p, T), mean_{t∈T} d(t, P))`` (Dubuisson
  and Jain, "A modified Hausdorff distance for object matching", ICPR 1994).
* **F-score** at a threshold τ (Knapitsch et al., "Tanks and Temples", SIGGRAPH 2017):
  precision = share of predicted points within τ of the target, recall = share of target
  points within τ of the prediction, F = 2PR/(P + R).
* **Occupancy IoU / precision / recall** of two boolean BEV images (optionally only over the
  cells where the radar can see).

Empty sets: a distance to an empty set is ``inf``; a ratio with a zero denominator is ``nan``
(F is 0 when precision and recall are both 0 or one of them is undefined for an empty set
against a non-empty one). Means over frames (:func:`mean_scores`) skip ``nan``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import SettingsError
from .views import BevGrid, lidar_bev

__all__ = ["CloudScores", "chamfer_distance", "f_score", "mean_scores", "modified_hausdorff",
           "nearest_distances", "occupancy_scores", "score_clouds"]


def _xyz(points: np.ndarray, what: str) -> np.ndarray:
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] < 3:
        raise SettingsError(f"{what}: expected points of shape (N, >=3), got {p.shape}")
    p = p[:, :3].astype(np.float64)
    return p[np.all(np.isfinite(p), axis=1)]


def nearest_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """float64 ``(len(a),)``: distance from every point of ``a`` to the nearest point of ``b``
    (``inf`` when ``b`` is empty). Points are ``(N, ≥3)``; only x y z are used."""
    pa, pb = _xyz(a, "a"), _xyz(b, "b")
    if pb.shape[0] == 0:
        return np.full(pa.shape[0], np.inf)
    if pa.shape[0] == 0:
        return np.zeros(0)
    return cKDTree(pb).query(pa, k=1)[0]


def _mean(d: np.ndarray) -> float:
    return float(d.mean()) if d.size else math.nan


def chamfer_distance(pred: np.ndarray, target: np.ndarray, squared: bool = False) -> float:
    """Chamfer distance [m, or m² with ``squared``] (see the module docstring)."""
    d_pt, d_tp = nearest_distances(pred, target), nearest_distances(target, pred)
    if squared:
        d_pt, d_tp = d_pt**2, d_tp**2
    if d_pt.size == 0 and d_tp.size == 0:
        return 0.0
    if d_pt.size == 0 or d_tp.size == 0:
        return math.inf
    return _mean(d_pt) + _mean(d_tp)


def modified_hausdorff(pred: np.ndarray, target: np.ndarray) -> float:
    """Modified Hausdorff distance [m] (Dubuisson and Jain 1994)."""
    d_pt, d_tp = nearest_distances(pred, target), nearest_distances(target, pred)
    if d_pt.size == 0 and d_tp.size == 0:
        return 0.0
    if d_pt.size == 0 or d_tp.size == 0:
        return math.inf
    return max(_mean(d_pt), _mean(d_tp))


def f_score(pred: np.ndarray, target: np.ndarray, threshold: float) -> tuple[float, float, float]:
    """``(F, precision, recall)`` at ``threshold`` metres (a distance ``<= threshold`` counts)."""
    if not threshold > 0:
        raise SettingsError(f"threshold must be positive, got {threshold}")
    d_pt, d_tp = nearest_distances(pred, target), nearest_distances(target, pred)
    precision = _mean(d_pt <= threshold)
    recall = _mean(d_tp <= threshold)
    return _f(precision, recall), precision, recall


def _f(p: float, r: float) -> float:
    if math.isnan(p) or math.isnan(r):
        return 0.0 if (math.isnan(p) != math.isnan(r)) else math.nan
    return 2 * p * r / (p + r) if p + r > 0 else 0.0


def occupancy_scores(pred: np.ndarray, target: np.ndarray,
                     valid: np.ndarray | None = None) -> tuple[float, float, float]:
    """``(IoU, precision, recall)`` of two occupancy images of the same shape.

    Parameters
    ----------
    pred, target
        Images (any shape, equal); a cell is occupied where the value is > 0.5 (booleans and
        0/1 occupancy channels both work).
    valid
        bool mask of the cells to score (e.g. :attr:`BevProjector.valid`); default all.
    """
    a, b = np.asarray(pred), np.asarray(target)
    if a.shape != b.shape:
        raise SettingsError(f"occupancy images differ in shape: {a.shape} and {b.shape}")
    a, b = a > 0.5, b > 0.5
    if valid is not None:
        a, b = a[valid], b[valid]
    tp = int(np.sum(a & b))
    na, nb, union = int(a.sum()), int(b.sum()), int(np.sum(a | b))
    return (tp / union if union else math.nan, tp / na if na else math.nan,
            tp / nb if nb else math.nan)


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
