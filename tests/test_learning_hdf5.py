"""One HDF5 file per run: round trip against the folder view, atomic writes, the CLI commands."""

from __future__ import annotations

import json

import numpy as np
import pytest

from coloradar import ColoradarError, OutputExistsError, open_sequence
from coloradar.cli.main import main
from coloradar.learning import BevGrid, SyncedSamples, TargetSettings, ViewOptions
from coloradar.sim.run import simulate_run

h5py = pytest.importorskip("h5py", reason="h5py is the optional 'hdf5' extra")

from coloradar.interop.hdf5 import H5Run, export_hdf5  # noqa: E402

OPTS = dict(radar="single_chip", products=("heatmap", "points", "polar", "bev"), lidar=True,
            targets=True, target_settings=TargetSettings(voxel_size=0.2),
            views=ViewOptions(grid=BevGrid(0.0, 8.0, -6.0, 6.0, 0.2)))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("h5")
    return simulate_run(root, duration=0.8, seed=2, sensors=["single_chip", "lidar", "groundtruth"]).run_path


def _same(a, b):
    assert list(a) == list(b)
    for k in a:
        x, y = a[k], b[k]
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, k
            assert np.array_equal(x, y, equal_nan=True), k
        else:
            assert type(x) is type(y) and x == y, k


def test_round_trip_equals_the_source_samples(run, tmp_path):
    out = tmp_path / "run.h5"
    res = export_hdf5(run, out, compression="gzip", **OPTS)
    folder = SyncedSamples(run, **OPTS)
    back = SyncedSamples(out)
    assert res.frames == len(folder) == len(back) >= 5 and res.bytes == out.stat().st_size
    assert back.products == folder.products and back.grid == folder.grid
    assert np.array_equal(back.radar_times(), folder.radar_times())
    for i in range(len(folder)):
        _same(folder[i], back[i])
    # A subset of what the file holds: only those keys.
    only = SyncedSamples(out, products=("bev",), lidar=False, targets=False)
    assert set(only[0]) == {"run", "radar_frame", "frame_id", "radar_time", "bev", "world_T_base",
                            "pose_knots", "world_T_radar"}
    with pytest.raises(ColoradarError, match="no radar cascade"):
        SyncedSamples(out, radar="cascade")
    # Attributes: the grid, the heatmap grid and the calibration.
    seq = open_sequence(run)
    h = H5Run(out)
    cfg = seq.single_chip.heatmap_config
    assert np.array_equal(h.config.azimuth_bins, cfg.azimuth_bins)
    cal = h.calibration()
    assert np.allclose(cal.transforms["single_chip"].matrix(),
                       seq.calib.transforms["single_chip"].matrix())
    with h5py.File(out) as f:
        assert f["heatmap"].chunks == (1, *cfg.shape, 2) and f["heatmap"].compression == "gzip"
        assert json.loads(f.attrs["views"])["grid"]["cell"] == 0.2


def test_written_atomically_and_never_over_a_file(run, tmp_path):
    out = tmp_path / "x.h5"
    out.write_text("mine")
    with pytest.raises(OutputExistsError):
        export_hdf5(run, out, radar="single_chip", targets=False)
    assert out.read_text() == "mine"

    def boom(done, total):
        if done == 2:
            raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError):
        export_hdf5(run, tmp_path / "y.h5", radar="single_chip", targets=False, progress=boom)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.h5"]   # no partial file left
    with pytest.raises(ColoradarError, match=r"not a coloradar-learning file|not an HDF5"):
        SyncedSamples(out)


def test_cli_export_and_score(run, tmp_path, capsys):
    out = tmp_path / "r.h5"
    assert main(["export", str(run), str(out), "--format", "hdf5", "--radar", "single_chip",
                 "--products", "bev", "--cell", "0.2", "--voxel-size", "0.2", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "hdf5" in text and "lidar_target" in text and "KiB/frame" in text
    view = SyncedSamples(out)
    preds = tmp_path / "preds"
    preds.mkdir()
    for i in range(len(view)):
        s = view[i]
        np.save(preds / f"{s['frame_id']:06d}.npy", s["lidar_target"][:, :3])
    report = tmp_path / "score.json"
    assert main(["score", str(preds), str(out), "--out", str(report), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "Chamfer distance          0.000 m" in text and "F-score @ 0.2 m        1.000" in text
    data = json.loads(report.read_text())
    assert data["mean"]["bev_iou"] == 1.0 and len(data["frames"]) == len(view)
    # The same predictions shifted by 0.5 m: worse on every score, scored against the run folder.
    shifted = tmp_path / "shifted"
    shifted.mkdir()
    for p in preds.iterdir():
        np.save(shifted / p.name, np.load(p) + np.array([0.5, 0.0, 0.0]))
    assert main(["score", str(shifted), str(run), "--radar", "single_chip", "--voxel-size", "0.2",
                 "--out", str(tmp_path / "s2.json"), "--quiet"]) == 0
    worse = json.loads((tmp_path / "s2.json").read_text())["mean"]
    assert worse["chamfer"] > 0.1 and worse["f_score"] < 0.9 and worse["bev_iou"] < 0.5
    assert main(["score", str(tmp_path / "nothing"), str(out), "--quiet"]) == 1


def test_torch_loader_with_spawned_workers(run, tmp_path):
    torch = pytest.importorskip("torch", reason="torch is optional (not installed)")
    from torch.utils.data import DataLoader

    from coloradar.learning import collate_torch, torch_dataset

    out = tmp_path / "t.h5"
    export_hdf5(run, out, radar="single_chip", products=("bev", "points"),
                views=ViewOptions(grid=BevGrid(0.0, 8.0, -6.0, 6.0, 0.2)),
                target_settings=TargetSettings(voxel_size=0.2))
    view = SyncedSamples(out)
    loader = DataLoader(torch_dataset(view), batch_size=2, num_workers=2,
                        multiprocessing_context="spawn", collate_fn=collate_torch)
    batches = list(loader)
    assert sum(b["bev"].shape[0] for b in batches) == len(view)
    first = batches[0]
    assert torch.equal(first["bev"][1].nan_to_num(), torch.from_numpy(view[1]["bev"]).nan_to_num())
    assert first["lidar_target_counts"].tolist() == [len(view[i]["lidar_target"]) for i in range(2)]
