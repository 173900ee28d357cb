"""Learning views: polar and BEV images against brute-force loops over the heatmap / the points."""

from __future__ import annotations

import numpy as np
import pytest

from coloradar import ColoradarError
from coloradar.calib import HeatmapConfig
from coloradar.learning import BevGrid, BevProjector, lidar_bev, lidar_polar, point_bins, radar_polar

N_EL, N_AZ, N_R, DR = 4, 12, 24, 0.25
# Uniform direction sines (as an FFT grid has), not reaching ±1.
EL_S = (np.arange(N_EL) - (N_EL - 1) / 2) * 0.2
AZ_S = (np.arange(N_AZ) - (N_AZ - 1) / 2) * 0.15
CFG = HeatmapConfig(N_R, N_EL, N_AZ, DR, np.arcsin(AZ_S), np.arcsin(EL_S))
# Cell centres never on a bin edge (y = 0 is the edge between the two middle azimuth bins).
GRID = BevGrid(x_min=0.0, x_max=6.2, y_min=-5.03, y_max=4.97, cell=0.2, z_min=-1.0, z_max=1.0)


def _heatmap(seed):
    rng = np.random.default_rng(seed)
    hm = np.empty((N_EL, N_AZ, N_R, 2), dtype=np.float32)
    hm[..., 0] = rng.exponential(1.0, (N_EL, N_AZ, N_R))
    hm[..., 1] = rng.uniform(-2, 2, (N_EL, N_AZ, N_R))
    return hm


def _nearest(value, centres):
    """Index of the centre within half a spacing of ``value`` (uniform centres), else None."""
    step = centres[1] - centres[0]
    best = min(range(len(centres)), key=lambda i: abs(value - centres[i]))
    return best if abs(value - centres[best]) <= step / 2 else None


def test_polar_image_is_the_elevation_max_and_its_rate():
    hm = _heatmap(0)
    img = radar_polar(hm, CFG, "max")
    assert img.shape == (2, N_R, N_AZ) and img.dtype == np.float32
    for k in range(N_R):
        for j in range(N_AZ):
            e = max(range(N_EL), key=lambda e: hm[e, j, k, 0])
            assert img[0, k, j] == pytest.approx(10 * np.log10(hm[e, j, k, 0]), abs=1e-4)
            assert img[1, k, j] == hm[e, j, k, 1]
    mean = radar_polar(hm, CFG, "mean")
    w = hm[:, 3, 7, 0].astype(np.float64)
    assert mean[0, 7, 3] == pytest.approx(10 * np.log10(w.mean()), abs=1e-4)
    assert mean[1, 7, 3] == pytest.approx((w * hm[:, 3, 7, 1]).sum() / w.sum(), abs=1e-5)


@pytest.mark.parametrize("reduce", ["max", "mean"])
def test_bev_cells_against_a_brute_force_loop_over_the_heatmap(reduce):
    hm = _heatmap(1)
    img = BevProjector(CFG, GRID)(hm, reduce=reduce)
    nx, ny = GRID.shape
    assert img.shape == (2, nx, ny)
    ranges = np.arange(N_R) * DR
    checked = 0
    for i in range(0, nx, 2):
        for j in range(0, ny, 2):
            x = GRID.x_min + (i + 0.5) * GRID.cell
            y = GRID.y_min + (j + 0.5) * GRID.cell
            rho = np.hypot(x, y)
            vals = []   # (intensity, rate) of the heatmap cell each elevation row sees here
            for e in range(N_EL):
                r = rho / np.sqrt(1 - EL_S[e] ** 2)
                a = _nearest(y / r, AZ_S)
                k = _nearest(r, ranges)
                if a is not None and k is not None:
                    vals.append((float(hm[e, a, k, 0]), float(hm[e, a, k, 1])))
            if not vals:
                assert np.isnan(img[:, i, j]).all()
                continue
            checked += 1
            p = np.array(vals)
            if reduce == "max":
                want_i, want_v = p[np.argmax(p[:, 0])]
            else:
                want_i, want_v = p[:, 0].mean(), (p[:, 0] * p[:, 1]).sum() / p[:, 0].sum()
            assert img[0, i, j] == pytest.approx(10 * np.log10(want_i), abs=1e-4)
            assert img[1, i, j] == pytest.approx(want_v, abs=1e-5)
    assert checked > 100


def test_lidar_images_against_brute_force_binning():
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(-1, 7, 400), rng.uniform(-6, 6, 400),
                           rng.uniform(-1.5, 1.5, 400), rng.uniform(0, 100, 400)]).astype(np.float32)
    bev = lidar_bev(pts, GRID)
    nx, ny = GRID.shape
    want = np.zeros((3, nx, ny))
    for x, y, z, inten in pts.astype(np.float64):
        i = int(np.floor((x - GRID.x_min) / GRID.cell))
        j = int(np.floor((y - GRID.y_min) / GRID.cell))
        if 0 <= i < nx and 0 <= j < ny and GRID.z_min <= z <= GRID.z_max:
            first = want[0, i, j] == 0
            want[0, i, j] = 1
            want[1, i, j] = z if first else max(want[1, i, j], z)
            want[2, i, j] = inten if first else max(want[2, i, j], inten)
    assert np.allclose(bev, want, atol=1e-5)

    polar = lidar_polar(pts, CFG)
    ranges = np.arange(N_R) * DR
    want = np.zeros((3, N_R, N_AZ))
    for x, y, z, inten in pts.astype(np.float64):
        r = np.sqrt(x * x + y * y + z * z)
        a, e, k = _nearest(y / r, AZ_S), _nearest(z / r, EL_S), _nearest(r, ranges)
        if x < 0 or a is None or e is None or k is None:
            continue
        first = want[0, k, a] == 0
        want[0, k, a] = 1
        want[1, k, a] = z if first else max(want[1, k, a], z)
        want[2, k, a] = inten if first else max(want[2, k, a], inten)
    assert np.allclose(polar, want, atol=1e-5)


def test_point_bins_place_a_bin_centre_in_its_own_bin_and_align_radar_with_lidar():
    e, a, k = 2, 8, 15
    direction = np.array([np.sqrt(1 - AZ_S[a] ** 2 - EL_S[e] ** 2), AZ_S[a], EL_S[e]])
    p = (k * DR * direction)[None]
    assert [int(b[0]) for b in point_bins(p, CFG)] == [e, a, k]
    # A heatmap with one hot bin: its polar image peaks where the lidar image of that bin's
    # centre is occupied.
    hm = np.zeros((N_EL, N_AZ, N_R, 2), dtype=np.float32)
    hm[e, a, k, 0] = 1.0
    radar = radar_polar(hm, CFG, range_rate=False)[0]
    lidar = lidar_polar(p, CFG)[0]
    assert np.unravel_index(np.argmax(radar), radar.shape) == tuple(np.argwhere(lidar)[0])


def test_grid_checks_and_default_grid():
    with pytest.raises(ColoradarError, match="whole number"):
        BevGrid(x_max=1.05, cell=0.1)
    with pytest.raises(ColoradarError):
        BevGrid(cell=0)
    g = BevGrid.for_radar(CFG, cell=0.25)
    assert g.x_max >= (N_R - 0.5) * DR and g.y_min == -g.y_max
    assert BevProjector(CFG, g).valid.any()
    with pytest.raises(ColoradarError, match="shape"):
        radar_polar(np.zeros((2, 2, 2, 2), np.float32), CFG)
