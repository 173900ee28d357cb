"""Metrics against brute-force pairwise distances and counts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coloradar import ColoradarError
from coloradar.learning import (
    BevGrid,
    chamfer_distance,
    f_score,
    mean_scores,
    modified_hausdorff,
    occupancy_scores,
    score_clouds,
)


def _pairwise(a, b):
    """Full distance matrix by broadcasting (no tree)."""
    return np.sqrt(((a[:, None, :3].astype(np.float64) - b[None, :, :3]) ** 2).sum(-1))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_point_metrics_against_brute_force_pairwise_distances(seed):
    rng = np.random.default_rng(seed)
    pred = rng.normal(0, 2, (int(rng.integers(20, 200)), 5)).astype(np.float32)
    target = rng.normal(0.3, 2, (int(rng.integers(20, 200)), 4)).astype(np.float32)
    d = _pairwise(pred, target)
    d_pt, d_tp = d.min(axis=1), d.min(axis=0)
    assert chamfer_distance(pred, target) == pytest.approx(d_pt.mean() + d_tp.mean(), rel=1e-9)
    assert chamfer_distance(pred, target, squared=True) == pytest.approx(
        (d_pt**2).mean() + (d_tp**2).mean(), rel=1e-9)
    assert modified_hausdorff(pred, target) == pytest.approx(max(d_pt.mean(), d_tp.mean()), rel=1e-9)
    tau = 0.5
    p = sum(1 for v in d_pt if v <= tau) / len(d_pt)
    r = sum(1 for v in d_tp if v <= tau) / len(d_tp)
    f, fp, fr = f_score(pred, target, tau)
    assert (fp, fr) == (pytest.approx(p), pytest.approx(r))
    assert f == pytest.approx(2 * p * r / (p + r) if p + r else 0.0)
    s = score_clouds(pred, target, tau)
    assert s.chamfer == pytest.approx(d_pt.mean() + d_tp.mean())
    assert math.isnan(s.bev_iou) and (s.num_pred, s.num_target) == (len(pred), len(target))


def test_identical_clouds_and_empty_sets():
    pts = np.random.default_rng(3).normal(size=(50, 3))
    assert chamfer_distance(pts, pts) == 0.0 and modified_hausdorff(pts, pts) == 0.0
    assert f_score(pts, pts, 0.01)[0] == 1.0
    empty = np.zeros((0, 3))
    assert chamfer_distance(empty, pts) == math.inf and chamfer_distance(empty, empty) == 0.0
    f, p, r = f_score(empty, pts, 0.1)
    assert f == 0.0 and math.isnan(p) and r == 0.0
    with pytest.raises(ColoradarError):
        f_score(pts, pts, 0.0)
    with pytest.raises(ColoradarError):
        chamfer_distance(np.zeros((3, 2)), pts)


def test_occupancy_scores_against_counts():
    rng = np.random.default_rng(4)
    a, b = rng.random((30, 40)) > 0.7, rng.random((30, 40)) > 0.6
    valid = rng.random((30, 40)) > 0.2
    iou, p, r = occupancy_scores(a, b, valid)
    tp = fp = fn = 0
    for i in range(30):
        for j in range(40):
            if valid[i, j]:
                tp += a[i, j] and b[i, j]
                fp += a[i, j] and not b[i, j]
                fn += b[i, j] and not a[i, j]
    assert iou == pytest.approx(tp / (tp + fp + fn))
    assert p == pytest.approx(tp / (tp + fp)) and r == pytest.approx(tp / (tp + fn))
    # Clouds on a BEV grid: cells hit by both / either.
    g = BevGrid(0.0, 4.0, -2.0, 2.0, 0.5, -1.0, 1.0)
    pred = np.array([[0.1, 0.1, 0], [1.2, -1.9, 0.2], [3.9, 1.9, 0]])
    tgt = np.array([[0.2, 0.3, 0], [1.3, -1.6, 0], [2.0, 0.1, 0], [2.1, 0.2, 0.5]])
    s = score_clouds(pred, tgt, 0.3, g)
    # cells: pred {(0,4), (2,0), (7,7)}; target {(0,4), (2,0), (4,4)}
    assert (s.bev_iou, s.bev_precision, s.bev_recall) == pytest.approx((2 / 4, 2 / 3, 2 / 3))
    means = mean_scores([s, s])
    assert means["bev_iou"] == pytest.approx(0.5)
