"""The fast heatmap engine against the definition written out with explicit steering vectors."""

from __future__ import annotations

import numpy as np
import pytest

from coloradar.calib import format_heatmap_cfg, parse_heatmap_cfg, preset_radar, shipped_angle_bins
from coloradar.dsp import RadarProcessor, angle_grid, combine_channels, heatmap_from_elements

C0 = 299_792_458.0


def brute_force_heatmap(calib, elements, velocities, sa, se):
    """max over Doppler of |Σ_m U_m exp(+jπρ(s_a p_m u_y + s_e q_m u_z))|² / M², loop over bins."""
    w, h = calib.waveform, calib.heatmap
    fc = w.start_frequency + w.slope * (w.adc_start_time + w.num_samples / (2 * w.sample_rate))
    rho = fc / calib.antenna.design_frequency
    pos = calib.antenna.virtual.unique_positions          # (M, 2) az, el
    m = pos.shape[0]
    ne, na = h.num_elevation_bins, h.num_azimuth_bins
    uz = 2.0 * (np.arange(ne) - ne // 2) / (ne * rho)
    uy = 2.0 * (np.arange(na) - na // 2) / (na * rho)
    out = np.zeros((ne, na, elements.shape[2], 2))
    for ie in range(ne):
        for ia in range(na):
            steer = np.exp(1j * np.pi * rho * (sa * pos[:, 0] * uy[ia] + se * pos[:, 1] * uz[ie]))
            spec = np.abs(np.einsum("m,mdr->dr", steer, elements)) ** 2 / m**2   # (Nd, Nr)
            d = spec.argmax(axis=0)
            out[ie, ia, :, 0] = spec[d, np.arange(spec.shape[1])]
            out[ie, ia, :, 1] = velocities[d]
    return out


ENGINES = ["numpy", "numba"]


def _engine_or_skip(engine):
    from coloradar.dsp.heatmap import available_engines
    if engine not in available_engines():
        pytest.skip(f"heatmap engine {engine!r} needs numba (pip install coloradar[accel])")


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", ["cascade", "single_chip"])
@pytest.mark.parametrize("signs", [(1, 1), (-1, 1), (1, -1)])
def test_engine_matches_definition(name, signs, engine):
    _engine_or_skip(engine)
    calib = preset_radar(name)
    w, h = calib.waveform, calib.heatmap
    g = np.random.default_rng(1)
    m = calib.antenna.virtual.num_unique
    nd, nr = w.num_chirps, 3
    elements = (g.standard_normal((m, nd, nr)) + 1j * g.standard_normal((m, nd, nr))).astype(
        np.complex64)
    vel = np.linspace(-2.0, 2.0, nd, endpoint=False)
    grid = angle_grid(calib.antenna, w.center_frequency, h.num_elevation_bins,
                      h.num_azimuth_bins, *signs)
    # small chunks: several chunks per call, the last one partial
    fast = heatmap_from_elements(elements, grid, vel, chunk_size=1 << 14, engine=engine)
    ref = brute_force_heatmap(calib, elements.astype(np.complex128), vel, *signs)
    # numpy packs the Doppler bin into 4-7 mantissa bits (2^-16 relative); numba is exact
    np.testing.assert_allclose(fast[..., 0], ref[..., 0], rtol=2e-4 if engine == "numpy" else 2e-5)
    # The Doppler bin of the peak may differ only where two bins are equal to float32 accuracy.
    same = fast[..., 1] == ref[..., 1]
    assert same.mean() > 0.999


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize(("num_el", "num_az"), [(8, 32), (2, 32), (8, 24)])
def test_engine_on_another_layout(engine, num_el, num_az):
    """Three elevation rows (0, 2, 3) and, with 2 bins, an aperture wider than the grid: the
    kernel's general paths (not the two radars' specialised ones) against explicit steering.
    24 azimuth bins (not a power of two) take the numba engine's FFT-call path."""
    _engine_or_skip(engine)
    from coloradar.calib import AntennaConfig
    rx = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    tx = np.array([[0.0, 0.0], [4.0, 2.0], [1.0, 3.0], [6.0, 0.0]])
    ant = AntennaConfig(77e9, rx, tx)
    grid = angle_grid(ant, 78e9, num_el, num_az)
    assert (grid.n_el == num_el) == (num_el == 8)
    g = np.random.default_rng(4)
    m, nd, nr = grid.num_elements, 7, 19   # 19 range bins: a full block of 16 and a partial one; odd nd
    elements = (g.standard_normal((m, nd, nr)) + 1j * g.standard_normal((m, nd, nr))).astype(
        np.complex64)
    vel = np.arange(nd) - 4.0
    fast = heatmap_from_elements(elements, grid, vel, chunk_size=1 << 10, engine=engine)
    pos = ant.virtual.unique_positions
    ref = np.zeros_like(fast, dtype=np.float64)
    for ie, uz in enumerate(grid.el_sines):
        for ia, uy in enumerate(grid.az_sines):
            steer = np.exp(1j * np.pi * grid.rho * (pos[:, 0] * uy + pos[:, 1] * uz))
            spec = np.abs(np.einsum("m,mdr->dr", steer, elements.astype(complex))) ** 2 / m**2
            d = spec.argmax(axis=0)
            ref[ie, ia, :, 0] = spec[d, np.arange(nr)]
            ref[ie, ia, :, 1] = vel[d]
    np.testing.assert_allclose(fast[..., 0], ref[..., 0], rtol=2e-4 if engine == "numpy" else 2e-5)
    assert np.mean(fast[..., 1] == ref[..., 1]) > 0.99


@pytest.mark.parametrize("name", ["cascade", "single_chip"])
def test_engines_agree_on_a_processed_frame(name):
    """Full processor on a simulated frame: the engines give the same heatmap."""
    _engine_or_skip("numba")
    from coloradar.sim import synthesize_adc
    calib = preset_radar(name)
    g = np.random.default_rng(3)
    pos = np.array([[4.0, 1.0, 0.3], [7.0, -2.0, -0.5], [2.5, 0.2, 0.0]])
    vel = 0.5 * calib.waveform.max_velocity * pos / np.linalg.norm(pos, axis=1)[:, None]
    adc = synthesize_adc(calib, pos, vel, 300.0 * np.sum(pos**2, axis=1), noise_std=20.0, rng=g)
    a = RadarProcessor(calib, engine="numpy").heatmap(adc)
    b = RadarProcessor(calib, engine="numba").heatmap(adc)
    np.testing.assert_allclose(b[..., 0], a[..., 0], rtol=5e-5, atol=1e-6 * a[..., 0].max())
    assert np.mean(a[..., 1] == b[..., 1]) > 0.999


def test_unknown_engine_is_refused():
    with pytest.raises(ValueError, match="engine"):
        RadarProcessor(preset_radar("single_chip"), engine="gpu")


def test_combine_channels_average_is_the_mean_of_coincident_pairs():
    calib = preset_radar("cascade")
    v = calib.antenna.virtual
    g = np.random.default_rng(2)
    cube = g.standard_normal((*calib.frame_shape[:2], 5)) + 0j
    avg = combine_channels(cube, v, "average")
    first = combine_channels(cube, v, "first")
    for u in range(v.num_unique):
        pairs = [(t, r) for t in range(v.index.shape[0]) for r in range(v.index.shape[1])
                 if np.allclose(v.positions[t, r], v.unique_positions[u])]
        np.testing.assert_allclose(avg[u], np.mean([cube[p] for p in pairs], axis=0))
        np.testing.assert_allclose(first[u], cube[pairs[0]])


@pytest.mark.parametrize("name", ["cascade", "single_chip"])
def test_heatmap_config_angles_and_file_round_trip(name):
    calib = preset_radar(name)
    cfg = RadarProcessor(calib).heatmap_config()
    w = calib.waveform
    fc = w.start_frequency + w.slope * (w.adc_start_time + w.num_samples / (2 * w.sample_rate))
    rho = fc / calib.antenna.design_frequency
    for got, n in ((cfg.azimuth_bins, cfg.num_azimuth_bins),
                   (cfg.elevation_bins, cfg.num_elevation_bins)):
        np.testing.assert_allclose(got, np.arcsin((2.0 * np.arange(n) / n - 1.0) / rho))
        # the shipped labels are half a bin off and use another carrier: never equal ours
        assert np.max(np.abs(got - shipped_angle_bins(n))) > 0.3 * np.pi / n
    back = parse_heatmap_cfg(format_heatmap_cfg(cfg))
    np.testing.assert_array_equal(back.azimuth_bins, cfg.azimuth_bins)
    np.testing.assert_array_equal(back.elevation_bins, cfg.elevation_bins)
    assert back.range_bin_width == cfg.range_bin_width


def test_bin_directions_are_the_physical_unit_vectors():
    calib = preset_radar("cascade")
    grid = RadarProcessor(calib).grid
    d = grid.directions()
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0)
    az, el = grid.azimuth_angles, grid.elevation_angles
    row0 = d[grid.num_el // 2]                                    # the el = 0 row
    np.testing.assert_allclose(row0, np.stack([np.cos(az), np.sin(az), 0 * az], -1), atol=1e-12)
    np.testing.assert_allclose(d[:, grid.num_az // 2, 2], np.sin(el))
    # off the el = 0 plane the azimuth axis holds cos(el)·sin(az): y is the same in every row
    # of the visible region; bins outside it (u_y² + u_z² > 1) are put on the x = 0 plane
    visible = np.sin(az[80]) ** 2 + np.sin(el) ** 2 <= 1
    assert 0 < (~visible).sum() < 3
    np.testing.assert_allclose(d[visible, 80, 1], np.sin(az[80]))
    np.testing.assert_allclose(d[~visible, 80, 0], 0.0)


@pytest.mark.parametrize("settings", [{}, {"dc_removal": False}, {"range_fft_size": 512},
                                      {"coupling_domain": "calibrated", "range_window": "none"}])
def test_compiled_range_pass_equals_numpy(settings):
    """Coupling, DC removal, calibration and windows in one compiled pass = the numpy passes."""
    _engine_or_skip("numba")
    from dataclasses import replace

    from coloradar.calib import CouplingCalib, PhaseFrequencyCalib
    calib = preset_radar("cascade")
    w = calib.waveform
    g = np.random.default_rng(5)
    shape = (w.num_tx, w.num_rx)
    nb = calib.heatmap.num_range_bins
    coupling = CouplingCalib(2e3 * np.exp(-np.arange(nb) / 2.0)
                             * (g.standard_normal((*shape, nb)) + 1j), w.num_chirps)
    pf = PhaseFrequencyCalib(51 + 0.3 * g.standard_normal(shape),
                             np.exp(2j * np.pi * g.random(shape)), w.slope, w.sample_rate)
    calib = replace(calib, coupling=coupling, phase_frequency=pf)
    adc = (g.standard_normal(calib.frame_shape) + 1j * g.standard_normal(calib.frame_shape)
           + 30.0).astype(np.complex64) * 100
    a = RadarProcessor(calib, engine="numpy", **settings).range_doppler(adc)
    b = RadarProcessor(calib, engine="numba", **settings).range_doppler(adc)
    assert b.shape == a.shape and b.dtype == np.complex64
    np.testing.assert_allclose(b, a, rtol=0, atol=2e-5 * np.abs(a).max())


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("num_az", [32, 24])
def test_doppler_phase_is_applied_per_channel_and_bin(engine, num_az):
    """``doppler_phase`` (the TDM compensation the processor hands over) equals multiplying
    the channels first, through a channel map, on the planar (32) and FFT-call (24) paths."""
    _engine_or_skip(engine)
    from coloradar.calib import AntennaConfig
    rx = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    tx = np.array([[0.0, 0.0], [4.0, 2.0], [1.0, 3.0], [6.0, 0.0]])
    grid = angle_grid(AntennaConfig(77e9, rx, tx), 78e9, 8, num_az)
    g = np.random.default_rng(8)
    m, nd, nr = grid.num_elements, 8, 7
    cube = (g.standard_normal((m + 3, nd, nr)) + 1j * g.standard_normal((m + 3, nd, nr))).astype(
        np.complex64)
    channels = g.permutation(m + 3)[:m]
    phase = np.exp(2j * np.pi * g.random((m + 3, nd))).astype(np.complex64)
    vel = np.arange(nd) - 4.0
    got = heatmap_from_elements(cube, grid, vel, engine=engine, channels=channels,
                                doppler_phase=phase)
    want = heatmap_from_elements((cube * phase[:, :, None])[channels], grid, vel, engine=engine)
    np.testing.assert_allclose(got[..., 0], want[..., 0], rtol=1e-5)
    assert np.mean(got[..., 1] == want[..., 1]) > 0.99
