"""Distances between point sets and map-quality scores: one implementation for the package.

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
* **Occupancy IoU / precision / recall** of two boolean images (optionally only over the
  cells where the radar can see), and **voxel IoU** of two clouds: the occupied voxels of a
  regular grid (voxel ``k`` covers ``[k·s, (k+1)·s)`` on each axis), intersection over union.

Empty sets: a distance to an empty set is ``inf``; a ratio with a zero denominator is ``nan``
(F is 0 when precision and recall are both 0 or one of them is undefined for an empty set
against a non-empty one).

``coloradar.learning.metrics`` re-exports these for the learning scores;
:func:`score_map` is what ``coloradar slam`` and ``coloradar score-map`` report for a map.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import SettingsError

__all__ = ["MapScores", "chamfer_distance", "f_score", "format_map_scores", "modified_hausdorff",
           "nearest_distances", "occupancy_scores", "score_map", "voxel_iou"]


def xyz_points(points: np.ndarray, what: str) -> np.ndarray:
    """float64 ``(N, 3)``: the finite x y z rows of ``(N, ≥3)`` points (``what`` names them in
    the error raised for any other shape)."""
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] < 3:
        raise SettingsError(f"{what}: expected points of shape (N, >=3), got {p.shape}")
    p = p[:, :3].astype(np.float64)
    return p[np.all(np.isfinite(p), axis=1)]


def nearest_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """float64 ``(len(a),)``: distance from every point of ``a`` to the nearest point of ``b``
    (``inf`` when ``b`` is empty). Points are ``(N, ≥3)``; only x y z are used."""
    pa, pb = xyz_points(a, "a"), xyz_points(b, "b")
    if pb.shape[0] == 0:
        return np.full(pa.shape[0], np.inf)
    if pa.shape[0] == 0:
        return np.zeros(0)
    return cKDTree(pb).query(pa, k=1)[0]


def mean_or_nan(d: np.ndarray) -> float:
    """Mean of ``d``, ``nan`` when empty."""
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
    return mean_or_nan(d_pt) + mean_or_nan(d_tp)


def modified_hausdorff(pred: np.ndarray, target: np.ndarray) -> float:
    """Modified Hausdorff distance [m] (Dubuisson and Jain 1994)."""
    d_pt, d_tp = nearest_distances(pred, target), nearest_distances(target, pred)
    if d_pt.size == 0 and d_tp.size == 0:
        return 0.0
    if d_pt.size == 0 or d_tp.size == 0:
        return math.inf
    return max(mean_or_nan(d_pt), mean_or_nan(d_tp))


def f_from(p: float, r: float) -> float:
    """F-score of a precision and a recall (``nan`` handling of the module docstring)."""
    if math.isnan(p) or math.isnan(r):
        return 0.0 if (math.isnan(p) != math.isnan(r)) else math.nan
    return 2 * p * r / (p + r) if p + r > 0 else 0.0


def f_score(pred: np.ndarray, target: np.ndarray, threshold: float) -> tuple[float, float, float]:
    """``(F, precision, recall)`` at ``threshold`` metres (a distance ``<= threshold`` counts)."""
    if not threshold > 0:
        raise SettingsError(f"threshold must be positive, got {threshold}")
    d_pt, d_tp = nearest_distances(pred, target), nearest_distances(target, pred)
    precision = mean_or_nan(d_pt <= threshold)
    recall = mean_or_nan(d_tp <= threshold)
    return f_from(precision, recall), precision, recall


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


def voxel_iou(pred: np.ndarray, target: np.ndarray, voxel: float) -> float:
    """Intersection over union of the voxels (edge ``voxel`` [m], grid anchored at the origin)
    that the two clouds occupy; ``nan`` when both are empty."""
    if not voxel > 0:
        raise SettingsError(f"voxel must be positive, got {voxel}")
    keys = []
    for p in (xyz_points(pred, "prediction"), xyz_points(target, "target")):
        k = np.floor(p / voxel).astype(np.int64)
        keys.append(np.unique(k, axis=0) if k.shape[0] else np.zeros((0, 3), np.int64))
    both = np.concatenate(keys)
    if both.shape[0] == 0:
        return math.nan
    _, counts = np.unique(both, axis=0, return_counts=True)
    # Each cloud's keys are unique, so a key seen twice is in both.
    return float(np.sum(counts == 2) / counts.size)


@dataclass(frozen=True)
class MapScores:
    """A map against a reference cloud (distances in metres).

    Attributes
    ----------
    chamfer
        Chamfer distance (sum of the two mean nearest-neighbour distances).
    precision, recall, f_score
        At ``threshold``: share of map points within it of the reference, share of reference
        points within it of the map, their harmonic mean.
    voxel_iou
        IoU of the occupied voxels of edge ``voxel``.
    median_error
        Median distance from a map point to the reference.
    threshold, voxel
        The settings.
    num_map, num_reference
        Points compared.
    """

    chamfer: float
    precision: float
    recall: float
    f_score: float
    voxel_iou: float
    median_error: float
    threshold: float
    voxel: float
    num_map: int
    num_reference: int

    def to_dict(self) -> dict[str, float | int | None]:
        """JSON-compatible (non-finite values as None)."""
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in asdict(self).items()}


def score_map(pred: np.ndarray, reference: np.ndarray, *, threshold: float = 0.25,
              voxel: float = 0.25) -> MapScores:
    """Chamfer, precision / recall / F-score at ``threshold`` and voxel IoU of a map.

    Parameters
    ----------
    pred, reference
        float ``(N, ≥3)`` and ``(M, ≥3)`` in one frame [m] (e.g. a radar map and the lidar map
        built with ground truth).
    threshold
        Distance of the precision / recall / F-score [m].
    voxel
        Voxel edge of the IoU [m].
    """
    if not threshold > 0:
        raise SettingsError(f"threshold must be positive, got {threshold}")
    p, t = xyz_points(pred, "map"), xyz_points(reference, "reference")
    d_pt, d_tp = nearest_distances(p, t), nearest_distances(t, p)
    if p.shape[0] == 0 and t.shape[0] == 0:
        cd = 0.0
    elif p.shape[0] == 0 or t.shape[0] == 0:
        cd = math.inf
    else:
        cd = mean_or_nan(d_pt) + mean_or_nan(d_tp)
    prec, rec = mean_or_nan(d_pt <= threshold), mean_or_nan(d_tp <= threshold)
    med = float(np.median(d_pt)) if d_pt.size else math.nan
    return MapScores(cd, prec, rec, f_from(prec, rec), voxel_iou(p, t, voxel), med,
                     float(threshold), float(voxel), int(p.shape[0]), int(t.shape[0]))


def format_map_scores(s: MapScores, title: str = "") -> str:
    """The scores as a short table (the style of ``coloradar evaluate``)."""
    lines = [title] if title else []
    lines += [
        f"map points            {s.num_map:,}  (reference {s.num_reference:,})",
        f"Chamfer distance      {s.chamfer:.3f} m",
        f"precision @ {s.threshold:.2f} m   {100 * s.precision:.1f} %  (map points near the reference)",
        f"recall @ {s.threshold:.2f} m      {100 * s.recall:.1f} %  (reference points near the map)",
        f"F-score @ {s.threshold:.2f} m     {100 * s.f_score:.1f} %",
        f"voxel IoU ({s.voxel:.2f} m)    {100 * s.voxel_iou:.1f} %",
        f"median map error      {s.median_error:.3f} m",
    ]
    return "\n".join(lines) + "\n"
