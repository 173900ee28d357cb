"""The learning view: synchronisation against brute-force references, splits, numpy and torch."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from coloradar import ColoradarError, DataWarning, open_dataset
from coloradar.formats import parse_poses, parse_timestamps
from coloradar.learning import SyncedSamples, collate_numpy, collate_torch, split_runs, torch_dataset
from coloradar.sim.run import simulate_run


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("learn")
    # Lidar scans are the slow part to simulate: only the first run has them.
    simulate_run(root, duration=1.0, seed=1, sensors=["single_chip", "lidar", "groundtruth"])
    for seed in (2, 3):
        simulate_run(root, duration=1.0, seed=seed, sensors=["single_chip", "groundtruth"],
                     heatmaps=False)
    return root


RUN1 = "11_21_2026_sim_corridor_run1"


def _gt(run_path):
    """Ground truth read straight from the files (not through the dataset API)."""
    t = parse_timestamps((run_path / "groundtruth" / "timestamps.txt").read_text())
    p = parse_poses((run_path / "groundtruth" / "groundtruth_poses.txt").read_text())
    return t, p


def _pose_at(t_gt, p_gt, t):
    """world_T_base at t by a linear search and a two-knot interpolation (4x4)."""
    j = max(i for i in range(t_gt.size - 1) if t_gt[i] <= t)
    a = (t - t_gt[j]) / (t_gt[j + 1] - t_gt[j])
    m = np.eye(4)
    m[:3, 3] = (1 - a) * p_gt[j, :3] + a * p_gt[j + 1, :3]
    m[:3, :3] = Slerp([0.0, 1.0], Rotation.from_quat(p_gt[j:j + 2, 3:]))([a]).as_matrix()[0]
    return m, (t_gt[j], t_gt[j + 1])


def test_samples_are_synchronised(root):
    ds = open_dataset(root)
    view = SyncedSamples(ds, radar="single_chip", products=("heatmap", "points"), lidar=True,
                         runs=[RUN1])
    assert len(view) >= 9 and view.runs == [RUN1]
    calib = ds.calib
    b_r, b_l = calib.transforms["single_chip"].matrix(), calib.transforms["lidar"].matrix()
    cache = {}
    for i in range(len(view)):
        s = view[i]
        run_path = ds.path(s["run"])
        if s["run"] not in cache:
            lid_t = parse_timestamps((run_path / "lidar" / "timestamps.txt").read_text())
            pc_t = parse_timestamps(
                (run_path / "single_chip" / "pointclouds" / "timestamps.txt").read_text())
            cache[s["run"]] = (*_gt(run_path), lid_t, pc_t)
        t_gt, p_gt, lid_t, pc_t = cache[s["run"]]
        t = s["radar_time"]
        # the pose is the ground truth at the radar time, from knots one ground-truth period apart
        want, knots = _pose_at(t_gt, p_gt, t)
        assert np.array_equal(s["pose_knots"], knots)
        assert knots[0] <= t <= knots[1]
        assert knots[1] - knots[0] <= np.max(np.diff(t_gt))
        assert np.allclose(s["world_T_base"], want, atol=1e-9)
        assert np.allclose(s["world_T_radar"], want @ b_r, atol=1e-9)
        # the lidar scan is the nearest one, within half a lidar period
        j = int(np.argmin(np.abs(lid_t - t)))
        assert s["lidar_time"] == lid_t[j]
        assert abs(lid_t[j] - t) <= 0.5 * np.median(np.diff(lid_t))
        w_l, _ = _pose_at(t_gt, p_gt, s["lidar_time"])
        assert np.allclose(s["radar_T_lidar"], np.linalg.inv(want @ b_r) @ (w_l @ b_l), atol=1e-9)
        # heatmap and points of the same frame
        assert s["heatmap"].shape == (*calib.single_chip.heatmap_shape, 2)
        assert s["points"].dtype == np.float32 and s["points"].shape[1] == 5
        # the points are the shipped cloud nearest the heatmap's time (same radar frame)
        assert s["points_time"] == pc_t[int(np.argmin(np.abs(pc_t - t)))]
        assert abs(s["points_time"] - t) <= 0.05
    assert np.array_equal(view.radar_times(), [view[i]["radar_time"] for i in range(len(view))])


def test_pose_sync_over_a_dataset_root(root):
    view = SyncedSamples(root, radar="single_chip", products=("points",), lidar=False)
    assert view.runs == sorted(view.runs) and len(view.runs) == 3
    for i in range(len(view)):
        s = view[i]
        t_gt, p_gt = _gt(root / s["run"])
        want, knots = _pose_at(t_gt, p_gt, s["radar_time"])
        assert knots[0] <= s["radar_time"] <= knots[1] and knots[1] - knots[0] <= np.max(np.diff(t_gt))
        assert np.allclose(s["world_T_base"], want, atol=1e-9)


def test_split_by_run_is_stable_and_disjoint(root):
    names = [f"run{i}" for i in range(40)]
    a, b = split_runs(names, seed=4), split_runs(list(reversed(names)), seed=4)
    assert a == b and list(a) == ["train", "val", "test"]
    assert sorted(r for part in a.values() for r in part) == sorted(names)
    assert split_runs(names, seed=5) != a
    # Adding runs moves no other run: every old run keeps its part.
    bigger = split_runs([*names, "new_a", "new_b", "2_28_2021_outdoors_run9"], seed=4)
    for part, runs in a.items():
        assert set(runs) <= set(bigger[part])

    view = SyncedSamples(root, radar="single_chip", products=("points",), lidar=False)
    parts = view.split({"train": 2, "test": 1}, seed=0)
    assert set(parts["train"].runs).isdisjoint(parts["test"].runs)
    assert len(parts["train"]) + len(parts["test"]) == len(view)
    assert view.split({"train": 2, "test": 1}, seed=0)["test"].runs == parts["test"].runs


def test_a_one_run_dataset_keeps_and_says_its_empty_parts(root):
    with pytest.warns(DataWarning, match="no run fell into"):
        parts = split_runs(["only_run"], seed=0)
    assert set(parts) == {"train", "val", "test"}
    assert sum(len(v) for v in parts.values()) == 1
    view = SyncedSamples(root, radar="single_chip", products=("points",), lidar=False, runs=[RUN1])
    with pytest.warns(DataWarning):
        views = view.split(seed=0)
    assert set(views) == {"train", "val", "test"}
    assert sorted(len(v) for v in views.values()) == [0, 0, len(view)]


def test_collate_numpy_keeps_variable_clouds(root):
    view = SyncedSamples(root, radar="single_chip", products=("points",), runs=[RUN1])
    batch = [view[i] for i in range(3)]
    out = collate_numpy(batch)
    counts = [b["points"].shape[0] for b in batch]
    assert out["points"].shape == (sum(counts), 5)
    assert np.array_equal(out["points_counts"], counts)
    assert np.array_equal(out["points"][out["points_batch"] == 1], batch[1]["points"])
    assert out["world_T_base"].shape == (3, 4, 4) and out["run"] == [b["run"] for b in batch]


def test_missing_products_and_runs_are_clear_errors(root):
    with pytest.raises(ColoradarError, match="cascade"):
        SyncedSamples(root, radar="cascade")
    with pytest.raises(ColoradarError, match="no run named nope"):
        SyncedSamples(root, radar="single_chip", products=("points",), runs=["nope"])


def test_torch_dataset_absent(monkeypatch, root):
    monkeypatch.setitem(sys.modules, "torch", None)
    view = SyncedSamples(root, radar="single_chip", products=("points",), lidar=False)
    with pytest.raises(ColoradarError, match="PyTorch"):
        torch_dataset(view)


def test_torch_dataset_and_collate(root):
    torch = pytest.importorskip("torch", reason="torch is optional (not installed)")
    from torch.utils.data import DataLoader, Dataset

    view = SyncedSamples(root, radar="single_chip", products=("points",), lidar=True, runs=[RUN1])
    ds = torch_dataset(view)
    assert isinstance(ds, Dataset) and len(ds) == len(view)
    s = ds[2]
    assert isinstance(s["points"], torch.Tensor) and s["points"].dtype == torch.float32
    assert np.array_equal(s["points"].numpy(), view[2]["points"])
    loader = DataLoader(ds, batch_size=4, shuffle=False, collate_fn=collate_torch)
    batch = next(iter(loader))
    counts = [view[i]["points"].shape[0] for i in range(4)]
    assert batch["points"].shape == (sum(counts), 5)
    assert batch["points_counts"].tolist() == counts
    assert batch["lidar_batch"].max().item() == 3
    assert batch["world_T_base"].dtype == torch.float64 and batch["world_T_base"].shape == (4, 4, 4)
    assert torch.equal(batch["points"][batch["points_batch"] == 3], torch.from_numpy(view[3]["points"]))


def test_views_pickle_for_spawned_workers(root):
    """DataLoader workers under spawn receive the dataset pickled: samples must survive it."""
    import pickle

    view = SyncedSamples(root, radar="single_chip", products=("heatmap", "bev"), lidar=True,
                         targets=True, runs=[RUN1])
    before = view[1]   # builds the run's map and the BEV tables, which are not pickled
    again = pickle.loads(pickle.dumps(view))
    after = again[1]
    assert list(after) == list(before)
    for k, v in before.items():
        assert np.array_equal(after[k], v, equal_nan=True) if isinstance(v, np.ndarray) else after[k] == v


def test_named_splits_are_sourced_and_resolve_to_dated_run_names():
    from coloradar.dataset.splits import named_split, named_splits, resolve_runs

    for name in named_splits():
        s = named_split(name)
        assert "https://" in s.source and s.note
        runs = [r for part in s.parts.values() for r in part]
        assert len(runs) == len(set(runs))        # parts are disjoint
    s = named_split("rmap2023")
    assert "ec_hallways_run0" in s.parts["test"] and "ec_hallways_run1" in s.parts["train"]
    have = ["12_21_2020_ec_hallways_run0", "12_21_2020_ec_hallways_run1", "ec_hallways_run10",
            "2_28_2021_outdoors_run0"]
    got = resolve_runs(["ec_hallways_run0", "ec_hallways_run1", "outdoors_run0", "aspen_run0",
                        "ec_hallways_run10"], have)
    assert got == {"ec_hallways_run0": "12_21_2020_ec_hallways_run0",
                   "ec_hallways_run1": "12_21_2020_ec_hallways_run1",
                   "outdoors_run0": "2_28_2021_outdoors_run0", "aspen_run0": None,
                   "ec_hallways_run10": "ec_hallways_run10"}
    with pytest.raises(ColoradarError, match="several"):
        resolve_runs(["x_run0"], ["1_1_2020_x_run0", "2_2_2021_x_run0"])
