"""Lidar targets: the voxel map against a brute-force set, the per-frame cut against ray-cast
truth on a simulated scene."""

from __future__ import annotations

import numpy as np
import pytest

from coloradar import open_sequence
from coloradar.dsp.array import sines_to_unit
from coloradar.geometry import sensor_to_base, trajectory_from_groundtruth
from coloradar.learning import TargetSettings, VoxelMap, build_voxel_map, frame_target, prepare_cut
from coloradar.sim.raycast import cast_rays
from coloradar.sim.run import simulate_run
from coloradar.sim.scene import scene_from_dict
from coloradar.sim.scenes import builtin_scene_dict
from coloradar.sim.truth import load_truth


def test_voxel_map_against_a_brute_force_set():
    rng = np.random.default_rng(0)
    scans = [np.column_stack([rng.uniform(-3, 3, (500, 3)), rng.uniform(0, 10, 500)])
             for _ in range(6)]
    vmap = VoxelMap(0.5, flush_every=300)   # small batches: the merge path runs several times
    want: dict[tuple[int, int, int], list] = {}
    for s in scans:
        vmap.add(s)
        seen: dict[tuple[int, int, int], list[float]] = {}
        for p in s:
            seen.setdefault(tuple(int(v) for v in np.floor(p[:3] / 0.5)), []).append(p[3])
        for key, inten in seen.items():
            want.setdefault(key, []).append(np.mean(inten))
    centres, hits, inten = vmap.voxels()
    got = {tuple(int(v) for v in np.floor(c / 0.5)): (h, i)
           for c, h, i in zip(centres, hits, inten, strict=True)}
    assert set(got) == set(want)
    for key, vals in want.items():
        assert got[key][0] == len(vals)
        assert got[key][1] == pytest.approx(np.mean(vals))
    assert np.allclose(centres, (np.floor(centres / 0.5) + 0.5) * 0.5)
    # Memory follows the occupied voxels, not the scans: the same scan again adds no voxel.
    n = len(vmap)
    vmap.add(scans[0])
    assert len(vmap) == n
    again = vmap.voxels()[1]
    first = {tuple(int(v) for v in np.floor(p[:3] / 0.5)) for p in scans[0]}
    gained = [tuple(int(v) for v in np.floor(c / 0.5)) in first for c in centres]
    assert np.array_equal(again - hits, np.array(gained, dtype=int))


def _rect_distance(points, rects):
    """Distance from every point (world) to the nearest scene rectangle, by the closed form."""
    c, u, v, n, h = (a[0] for a in (rects.center, rects.u, rects.v, rects.normal, rects.half_size))
    d = points[:, None, :] - c[None]
    du = np.abs(np.einsum("pmk,mk->pm", d, u)) - h[None, :, 0]
    dv = np.abs(np.einsum("pmk,mk->pm", d, v)) - h[None, :, 1]
    dn = np.einsum("pmk,mk->pm", d, n)
    return np.sqrt(dn**2 + np.maximum(du, 0) ** 2 + np.maximum(dv, 0) ** 2).min(axis=1)


@pytest.fixture(scope="module")
def static_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("targets")
    d = builtin_scene_dict("corridor")
    d["objects"] = []    # a static scene: the map and the truth describe the same surfaces
    scene = scene_from_dict(d)
    res = simulate_run(root, scene=scene, duration=1.5, seed=4, sensors=["lidar", "groundtruth"],
                       heatmaps=False)
    return scene, res.run_path


@pytest.mark.parametrize("radar", ["single_chip", "cascade"])
def test_frame_target_against_ray_cast_truth(static_run, radar):
    scene, run_path = static_run
    seq = open_sequence(run_path)
    st = TargetSettings(voxel_size=0.1)
    cut = prepare_cut(build_voxel_map(seq, st))
    cfg = seq.calib.radar(radar).heatmap
    traj = trajectory_from_groundtruth(seq)
    scene_T_world = load_truth(run_path)["world_T_start"]
    rects = scene.static_rect_arrays
    reach = (cfg.num_range_bins - 0.5) * cfg.range_bin_width
    base_T_radar = sensor_to_base(seq.calib, radar).matrix()
    for t in traj.start + np.array([0.3, 1.1]):
        world_T_radar = traj.at(t).matrix() @ base_T_radar
        tgt = frame_target(cut, world_T_radar, cfg)
        assert tgt.dtype == np.float32 and tgt.shape[1] == 4 and len(tgt) > 200
        # Every target point lies in the field of view and range (the radar frame's geometry).
        r = np.linalg.norm(tgt[:, :3], axis=1)
        assert np.all(r <= reach) and np.all(tgt[:, 0] > 0)
        s_az, s_el = np.sin(cfg.azimuth_bins), np.sin(cfg.elevation_bins)
        assert np.all(np.abs(tgt[:, 1] / r) <= np.abs(s_az).max() + np.diff(s_az).max())
        assert np.all(np.abs(tgt[:, 2] / r) <= np.abs(s_el).max() + np.diff(s_el).max())
        # ... and on a surface of the scene (voxel half-diagonal + 3 sigma of lidar noise).
        scene_T_radar = scene_T_world @ world_T_radar
        pts = tgt[:, :3].astype(np.float64) @ scene_T_radar[:3, :3].T + scene_T_radar[:3, 3]
        assert np.quantile(_rect_distance(pts, rects), 0.99) <= 0.087 + 0.05
        # Truth: rays from the radar across its azimuth span, near its horizontal plane (where
        # the lidar saw the walls all along), that hit a surface between 1.5 m and its range.
        az = np.linspace(s_az.min(), s_az.max(), 90)
        el = np.sin(np.radians([-4.0, 0.0, 4.0]))
        dirs_r = sines_to_unit(*np.meshgrid(az, el)).reshape(-1, 3)
        dirs = dirs_r @ scene_T_radar[:3, :3].T
        dist, _ = cast_rays(scene_T_radar[None, None, :3, 3], dirs[None], rects)
        dist = dist[0]
        ok = np.isfinite(dist) & (dist >= 1.5) & (dist <= reach - 0.2)
        hits_radar = dirs_r[ok] * dist[ok, None]
        assert ok.sum() > 100
        from scipy.spatial import cKDTree

        near = cKDTree(tgt[:, :3]).query(hits_radar)[0]
        assert np.mean(near <= 0.15) >= 0.95     # recall of the visible surfaces


def test_target_settings_are_checked():
    with pytest.raises(ValueError):
        TargetSettings(voxel_size=0)
    with pytest.raises(ValueError):
        TargetSettings(lidar_min_range=5, lidar_max_range=1)
