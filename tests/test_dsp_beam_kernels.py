"""The compiled per-detection beam kernels (numba engine) against brute-force definitions.

Each kernel is checked against the sum it computes written out directly (explicit steering
vectors, complex128, no shared code), and the whole point cloud of the numba engine against
the numpy engine on simulated frames (the numpy path builds full steering matrices and runs
the Newton steps in numpy).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from coloradar.calib import preset_radar
from coloradar.dsp import RadarProcessor
from coloradar.dsp.detection import ResolveStage
from coloradar.dsp.heatmap import available_engines
from coloradar.sim import synthesize_adc

pytestmark = pytest.mark.skipif("numba" not in available_engines(),
                                reason="the beam kernels need numba (pip install coloradar[accel])")

RADARS = ("cascade", "single_chip")


def _proc(name: str) -> RadarProcessor:
    proc = RadarProcessor(preset_radar(name), engine="numba")
    assert proc.detector.beams.tables is not None
    return proc


def _steering(proc: RadarProcessor, uy: np.ndarray, uz: np.ndarray) -> np.ndarray:
    """exp(+jπρ(s_az p_az u_y + s_el p_el u_z)), complex128 (M, P), from the definition."""
    g = proc.detection_grid
    ph = np.pi * g.rho * (g.azimuth_sign * g.az_pos[:, None] * uy[None, :]
                          + g.elevation_sign * g.el_pos[:, None] * uz[None, :])
    return np.exp(1j * ph)


def _cascade_calib():
    """The release's cascade calibration where the reference files are here, else the preset."""
    from _synth import REFERENCE_CALIB
    from coloradar.calib import load_calibration

    if not REFERENCE_CALIB.is_dir():
        return preset_radar("cascade")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                 # the real files' known defects
        return load_calibration(REFERENCE_CALIB).radar("cascade")


def _random_directions(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    uy = rng.uniform(-0.8, 0.8, n)
    uz = rng.uniform(-0.5, 0.5, n)
    return uy, uz


@pytest.mark.parametrize("name", RADARS)
def test_steering_columns_match_the_definition(name):
    proc = _proc(name)
    uy, uz = _random_directions(np.random.default_rng(0), 50)
    got = proc.detector.beams.steer(uy, uz, np.full(50, 5.0))
    assert got.dtype == np.complex64 and got.shape == (proc.detection_grid.num_elements, 50)
    np.testing.assert_allclose(got, _steering(proc, uy, uz), atol=2e-6)


@pytest.mark.parametrize("name", RADARS)
def test_newton_refinement_finds_the_source_direction(name):
    """A noiseless source off the grid: the refined direction is the source's, the power the
    source's |a|² (the numpy path's float32 sums stop about 1e-5 from it)."""
    proc = _proc(name)
    rng = np.random.default_rng(1)
    n = 40
    uy, uz = _random_directions(rng, n)
    amp = rng.uniform(1.0, 3.0, n) * np.exp(2j * np.pi * rng.random(n))
    x = (amp[None, :] * np.conj(_steering(proc, uy, uz))).T.astype(np.complex64)   # (P, M)
    g = proc.detection_grid
    du, dz = 0.3 * 2.0 / (g.num_az * g.rho), 0.3 * 2.0 / (g.num_el * g.rho)
    start_y = uy + rng.uniform(-du, du, n)
    start_z = uz + rng.uniform(-dz, dz, n)
    out = np.empty((3, n))
    step = (2.0 / (g.num_az * g.rho), 2.0 / (g.num_el * g.rho))
    kb = proc.detector.beams.tables
    kb["k"].newton_refine(x, kb["ca"], kb["cb"], kb["az"], kb["el"], start_y, start_z, step[0],
                          step[1], 6, True, out[0], out[1], out[2])
    np.testing.assert_allclose(out[0], uy, atol=1e-5)
    np.testing.assert_allclose(out[1], uz, atol=1e-4)
    np.testing.assert_allclose(out[2], np.abs(amp) ** 2, rtol=1e-5)


@pytest.mark.parametrize("name", RADARS)
def test_elevation_search_matches_a_brute_force_scan(name):
    """Strongest elevation bin of the beam along each vector's azimuth, by explicit beams on
    the detection grid's elevation sines (invisible directions excluded)."""
    proc = _proc(name)
    rng = np.random.default_rng(2)
    n = 30
    uy, uz = _random_directions(rng, n)
    x = (np.conj(_steering(proc, uy, uz)).T
         + 0.05 * (rng.standard_normal((n, proc.detection_grid.num_elements))
                   + 1j * rng.standard_normal((n, proc.detection_grid.num_elements))))
    x = x.astype(np.complex64)
    got_uz, got_p = proc.detector.beams.elevation_search(x, uy, np.full(n, 5.0))
    g = proc.detection_grid
    m = g.num_elements
    for i in range(n):
        beams = np.array([abs(x[i] @ _steering(proc, uy[i:i + 1], np.array([s]))[:, 0]) ** 2
                          if uy[i] ** 2 + s * s <= 1 else 0.0 for s in g.el_sines]) / m**2
        ie = int(np.argmax(beams))
        assert got_p[i] == pytest.approx(beams[ie], rel=1e-5)
        # the log-parabola moves the peak by at most half a bin from the grid's best
        bin_width = 2.0 / (g.num_el * g.rho)
        assert abs(got_uz[i] - g.el_sines[ie]) <= 0.5 * bin_width + 1e-9


@pytest.mark.parametrize("name", RADARS)
def test_beam_neighbourhood_matches_the_definition(name):
    """Beam power at a direction in the 3 × 3 range–Doppler cells around a cell, with the TDM
    phase of each (unwrapped) Doppler bin and an alias phase, against explicit sums over the
    first pair of every unique element."""
    calib = preset_radar(name)
    proc = _proc(name)
    rng = np.random.default_rng(3)
    adc = synthesize_adc(calib, [[4.0, 1.0, 0.3], [6.0, -2.0, 0.0]], [[0.4, 0, 0], [-0.3, 0, 0]],
                         3e3, noise_std=10.0, rng=4)
    rcube = proc.cube.range_cube(adc, extra=True)
    nr = proc.num_range_bins
    raw = proc.cube.doppler(rcube[..., :nr], compensate=False)
    nxt = proc.cube.doppler(rcube[..., nr:], compensate=False)
    ntx, _, nd, _ = raw.shape
    d = np.array([0, nd - 1, nd // 2, 3, 5])                    # both Doppler edges
    r = np.array([10, 20, nr - 1, 0, nr - 1])                   # both range edges
    alias = rng.integers(-1, 2, d.size)
    uy, uz = _random_directions(rng, d.size)
    steer = _steering(proc, uy, uz)
    got = proc.detector.guard.beam_neighbourhood(raw, d, r, alias, steer.astype(np.complex64), nxt)
    first = calib.antenna.virtual.first_pair
    m = first.shape[0]
    t = np.arange(ntx)
    for p in range(d.size):
        for i, dd in enumerate((d[p] - 1, d[p], d[p] + 1)):
            ph = np.exp(-2j * np.pi * t * ((dd - nd // 2) / (nd * ntx) + alias[p] / ntx))
            for k, rr in enumerate((r[p] - 1, r[p], r[p] + 1)):
                if rr >= nr:
                    cell = nxt[:, :, dd % nd, 0]
                else:
                    cell = raw[:, :, dd % nd, min(max(rr, 0), nr - 1)]
                v = np.array([cell[a, b] * ph[a] for a, b in first])
                want = abs(v @ steer[:, p]) ** 2 / m**2
                assert got[p, i, k] == pytest.approx(want, rel=1e-5, abs=1e-9 * want + 1e-12)


def _check_engines_agree(fast, ref, synth, calib, rng, seed, k, ranges, max_az):
    """``k`` targets (two at one range and range rate, mirrored in azimuth) synthesised by
    ``synth``: both engines give the same points to float32 rounding (sub-millimetre)."""
    rng_m = rng.uniform(*ranges, k)
    az = rng.uniform(-max_az, max_az, k)
    el = rng.uniform(-0.2, 0.2, k)
    pos = rng_m[:, None] * np.column_stack([np.cos(el) * np.cos(az),
                                            np.cos(el) * np.sin(az), np.sin(el)])
    pos[1] = pos[0] * [1, -1, 1]                                  # same range, mirrored azimuth
    vel = rng.uniform(-0.5, 0.5, (k, 1)) * pos / rng_m[:, None]
    vel[1] = vel[0] * [1, -1, 1]
    adc = synth(calib, pos, vel, 200.0 * rng_m**2, noise_std=10.0, rng=seed)
    a, b = fast.pointcloud(adc), ref.pointcloud(adc)
    assert len(a) == len(b) >= k - 1
    np.testing.assert_allclose(a[:, :3], b[:, :3], atol=1e-3)
    np.testing.assert_allclose(a[:, 3], b[:, 3], rtol=2e-3)
    np.testing.assert_allclose(a[:, 4], b[:, 4], atol=1e-4)


@pytest.mark.parametrize("name", RADARS)
def test_point_clouds_of_both_engines_agree(name):
    """Simulated frames with several targets (two in one range–Doppler cell): the numba
    engine's points are the numpy engine's to float32 rounding (sub-millimetre)."""
    calib = preset_radar(name)
    rng = np.random.default_rng(5)
    fast, ref = RadarProcessor(calib, engine="numba"), RadarProcessor(calib, engine="numpy")
    for f in range(3):
        k = 6
        _check_engines_agree(fast, ref, synthesize_adc, calib, rng, f, k, (2.0, 8.0), 1.0)


@pytest.mark.parametrize("name", RADARS)
def test_point_clouds_of_both_engines_agree_with_focusing(name):
    """Near-field focusing on (the compiled kernels get the focusing phases on their inputs
    and outputs, the numpy path multiplies full steering matrices): exact spherical-wave
    frames (tests/_synth.py) of close targets, two in one range–Doppler cell, give the same
    points on both engines to float32 rounding."""
    from _synth import exact_adc

    calib = preset_radar(name)
    rng = np.random.default_rng(11)
    fast = RadarProcessor(calib, engine="numba", near_field=True)
    ref = RadarProcessor(calib, engine="numpy", near_field=True)
    assert fast.detector.beams.focus and ref.detector.beams.focus
    for f in range(2):
        k = 5
        _check_engines_agree(fast, ref, exact_adc, calib, rng, f, k, (1.5, 5.0), 0.9)


def _focused_bound_case(seed: int, near: bool):
    """The focused secondary bound's inputs on the cascade (relative focusing on the
    calibration's reflector where there is one), random vectors, directions and ranges."""
    calib = _cascade_calib()
    proc = RadarProcessor(calib, engine="numba", near_field=True)
    assert proc.detector.beams.focus and proc.detector.beams.near_terms is not None
    rng = np.random.default_rng(seed)
    g = proc.detection_grid
    m, n_cells, per = g.num_elements, 6, 4
    p = n_cells * per
    # each cell: one vector, its primary direction first, then secondaries
    xc = (rng.normal(size=(n_cells, m)) + 1j * rng.normal(size=(n_cells, m))).astype(np.complex64)
    x = np.repeat(xc, per, axis=0)
    primary = np.tile(np.r_[True, np.zeros(per - 1, bool)], n_cells)
    uy = rng.uniform(-1.0, 1.0, p)
    uy[::7] = rng.choice([-0.999, 0.0, 0.98], uy[::7].size)     # disc edge and boresight
    uz_p = rng.uniform(-0.6, 0.6, p)
    rho = (rng.uniform(0.3, 3.0, p) if near else rng.uniform(10.0, 40.0, p))
    rho = np.repeat(rho[::per], per)                            # one range per cell
    wp = proc.detector.beams.steer(uy[primary], uz_p[primary], rho[primary])
    lead = (np.cumsum(primary) - 1).astype(np.int64)
    return proc, x, wp, lead, uy, rho


@pytest.mark.parametrize("near", [True, False])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_focused_secondary_bound_holds_at_every_elevation(seed, near):
    """The bounds of the focused residual beam power never fall below the exact residual
    ``|Σ_m r_m w_m(u)|²/M²`` (``r`` the vector less the primary's fit, ``w`` the focused
    weights, complex128, focusing phases from NearField.focus) over a fine grid of
    elevations: the visible ones at the azimuth and the ones beyond its edge the elevation
    search can return (scaled onto the disc, as focus_sines does). Both bounds: the row sums
    with the focusing's slack, and Cauchy–Schwarz (written where it already fails a test)."""
    from coloradar.dsp.array import sines_to_unit

    proc, x, wp, lead, uy, rho = _focused_bound_case(seed, near)
    kb = proc.detector.beams.tables
    g = proc.detection_grid
    ne = g.num_el
    half = 1.0 / (ne * g.rho)
    u_grid = 2.0 * half * max(ne // 2 + 0.5, ne - 0.5 - ne // 2)
    sq, cyy, cyz, czz, ref = proc.detector.beams.near_terms
    ty2, it = np.unique(proc.detector.beams.near.tx[:, 1] ** 2, return_inverse=True)
    ry2, ir = np.unique(proc.detector.beams.near.rx[:, 1] ** 2, return_inverse=True)

    def kernel(floor: float) -> tuple[np.ndarray, np.ndarray]:
        bound, top = np.empty((2, uy.size))
        kb["k"].secondary_bound_focused(
            x, wp, lead, uy.astype(np.float64), rho, np.full(uy.size, floor), 0.0, kb["ca"],
            kb["az"], kb["row"], int(kb["row"].max()) + 1, sq, cyy, cyz, czz, ref, ty2,
            it.astype(np.int64), ry2, ir.astype(np.int64), proc.detector.beams.near.wavenumber, u_grid,
            half, bound, top)
        return bound, top

    bound, top = kernel(0.0)           # nothing passes a test at 0: the row-sum bound
    bound_cs, _ = kernel(np.inf)       # every peak below the floor: the Cauchy–Schwarz one
    m = g.num_elements
    wf = wp.astype(np.complex128)[:, lead]                      # (M, P) primary weights
    s_f = np.einsum("pm,mp->p", x.astype(np.complex128), wf) / m
    np.testing.assert_allclose(top, np.abs(s_f) ** 2, rtol=1e-5)
    r = x - s_f[:, None] * np.conj(wf.T)                         # (P, M)
    zm = np.sqrt(np.clip(1.0 - uy**2, 0.0, None))
    worst = 0.0
    for k in range(uy.size):
        u_max = min(u_grid, zm[k] + half) if uy[k] ** 2 <= 1 else u_grid
        uz = np.linspace(-u_max, u_max, 4001)
        uyk = np.full(uz.size, uy[k])
        # focusing as the processor's weights: directions beyond the disc scaled onto it
        foc = proc.detector.beams.near.focus(sines_to_unit(uyk, uz), np.full(uz.size, rho[k]))
        w = _steering(proc, uyk, uz) * foc.astype(np.complex128)
        exact = np.abs(r[k] @ w) ** 2 / m**2
        assert exact.max() <= bound[k], (k, exact.max(), bound[k])
        assert exact.max() <= bound_cs[k], (k, exact.max(), bound_cs[k])
        worst = max(worst, exact.max() / bound[k])
    assert worst > 0.05          # (a bound, not a blanket: some secondary comes close)


def test_peak_grouping_helpers_match_numpy_references():
    """The processor's grouping of peaks by cell gives what ``np.unique`` and ``np.r_`` give,
    on sorted and unsorted cells, with and without repeats, and empty."""
    from coloradar.dsp.detection._common import firsts as _firsts
    from coloradar.dsp.detection._common import groups as _groups

    rng = np.random.default_rng(3)
    cases = [np.zeros(0, dtype=np.int64), np.array([4]), np.array([2, 2, 2])]
    cases += [np.sort(rng.integers(0, n, n)) for n in (2, 5, 40)]
    cases += [rng.integers(0, 6, 12) for _ in range(3)]              # not sorted
    for ci in cases:
        np.testing.assert_array_equal(_firsts(ci), np.r_[True, ci[1:] != ci[:-1]])
        np.testing.assert_array_equal(_firsts(ci, end=True),
                                      np.r_[True, ci[1:] != ci[:-1], True])
        _, inv, cnt = np.unique(ci, return_inverse=True, return_counts=True)
        cell_of, count = _groups(ci)
        np.testing.assert_array_equal(cell_of, inv.reshape(-1))
        np.testing.assert_array_equal(count, cnt)


@pytest.mark.parametrize("rows", [True, False])
def test_compiled_focusing_matches_the_fresnel_phase_of_each_antenna_pair(rows):
    """The compiled focusing (one phasor per TX and per RX position) multiplies each
    element by ``exp(−jk/(2ρ)·(|t|² − (t·u)² + |r|² − (r·u)²) + jk·(|t|² + |r|²)/(2R0))``,
    written here from the antenna pairs (complex128), for directions inside and beyond the
    visible disc (scaled onto its edge) and both layouts of the vectors."""
    calib = _cascade_calib()
    proc = RadarProcessor(calib, engine="numba", near_field=True)
    assert proc.detector.beams.focus_tables is not None
    rng = np.random.default_rng(4)
    k = 40
    uy, uz = rng.uniform(-1.0, 1.0, k), rng.uniform(-0.9, 0.9, k)     # some beyond the disc
    rho = rng.uniform(0.4, 30.0, k)
    m = proc.detection_grid.num_elements
    x = (rng.normal(size=(k, m)) + 1j * rng.normal(size=(k, m))).astype(np.complex64)
    s = np.sqrt(uy**2 + uz**2)
    scale = np.where(s > 1.0, 1.0 / s, 1.0)
    u = np.column_stack([np.sqrt(np.clip(1 - s**2, 0, None)), uy * scale, uz * scale])
    t, r, kw = proc.detector.beams.near.tx, proc.detector.beams.near.rx, proc.detector.beams.near.wavenumber
    bracket = ((t**2).sum(1)[None] - (u @ t.T) ** 2 + (r**2).sum(1)[None] - (u @ r.T) ** 2)
    phase = -kw / (2 * rho[:, None]) * bracket                          # (K, M)
    r0 = calib.near_field_reference
    if r0 is not None:
        phase += kw * ((t**2).sum(1) + (r**2).sum(1))[None] / (2 * r0)
    want = x.astype(np.complex128) * np.exp(1j * phase)
    x0 = x.copy()
    got = proc.detector.beams.focused(x if rows else np.ascontiguousarray(x.T), uy, uz, rho, rows=rows)
    assert got.dtype == np.complex64
    np.testing.assert_allclose(got if rows else got.T, want, rtol=0, atol=5e-5 * np.abs(x).max())
    # the input is left as it was unless asked otherwise
    np.testing.assert_array_equal(x, x0)


def test_compiled_peak_grouping_matches_the_numpy_grouping():
    """The compiled peak grouping gives the numpy grouping's mask on random maps: ties
    (integer powers), untested cells (+inf noise), with and without the bin after the last,
    and the small shapes where wrapping and mirroring meet (one or two bins per axis)."""
    from coloradar.dsp import _kernels
    from coloradar.dsp.detection.cfar_stage import STRONG_NEIGHBOUR
    from coloradar.dsp.detection.cfar_stage import group_peaks as _group_peaks

    rng = np.random.default_rng(8)
    shapes = [(16, 64), (1, 5), (2, 2), (5, 1), (3, 2), (64, 128)]
    checked = 0
    for nd, nr in shapes:
        for trial in range(6):
            stat = rng.integers(0, 6, (nd, nr)).astype(np.float64) ** 3   # ties and peaks
            noise = np.where(rng.random((nd, nr)) < 0.2, np.inf, rng.uniform(0.5, 30, (nd, nr)))
            mask = rng.random((nd, nr)) < 0.6
            nxt = rng.integers(0, 6, nd).astype(np.float64) ** 3 if trial % 2 else None
            want = _group_peaks(stat, mask.copy(), noise, nxt)
            got = np.empty((nd, nr), dtype=bool)
            _kernels.group_peaks(stat, mask, noise, np.zeros(0) if nxt is None else nxt,
                                 STRONG_NEIGHBOUR, got)
            np.testing.assert_array_equal(got, want)
            checked += int(want.sum())
    assert checked > 100                                   # the cases keep cells to compare


def test_compiled_channel_noise_picks_the_same_median_cell():
    """The compiled median of each channel's noise cells is numpy's selection, to the bit:
    exponential noise of different powers per channel, maps with zeros and repeated values,
    the subsampled and the full cell sets, and a NaN (which the compiled path hands back to
    numpy rather than order wrongly)."""
    from coloradar.dsp import _kernels
    from coloradar.dsp.detect import channel_noise

    rng = np.random.default_rng(2)
    cases = [((192, 16, 128), 3), ((12, 128, 64), 2), ((5, 4, 10), 0), ((3, 2, 5), 7),
             ((4, 64, 256), 5)]
    for shape, first in cases:
        p = (rng.exponential(size=shape) * rng.uniform(0.1, 9, (shape[0], 1, 1))
             ).astype(np.float32)
        p[0, :, ::3] = 0.0                                       # zeros and ties
        p[1] = np.round(p[1])
        want = channel_noise(p, first)
        got = channel_noise(p, first, engine="numba")
        np.testing.assert_array_equal(got, want)
        # (and the compiled selection makes it, not numpy's taking over on a refusal: the
        # kernel alone gives each row's k-th value)
        flat = p.reshape(shape[0], -1)
        k = flat.shape[1] // 3
        out = np.empty(shape[0], dtype=np.int32)
        assert _kernels.median_bits(flat, np.arange(flat.shape[1]), k, out)
        np.testing.assert_array_equal(out.view(np.float32), np.sort(flat, axis=1)[:, k])
        # the median of an exponential is ln 2 times its mean: sig2 estimates the mean
        if shape[1] * shape[2] > 1000:
            assert np.all(np.abs(got[2:] / (p[2:].mean(axis=(1, 2))) - 1) < 0.25)
    p[0, 0, 5] = np.nan
    np.testing.assert_array_equal(channel_noise(p, 5, engine="numba"), channel_noise(p, 5))


def test_compiled_azimuth_peaks_match_numpy():
    """The compiled azimuth peak search returns numpy's peaks in numpy's order (strongest
    first within a profile, ties in bin order), with ties, an absolute floor, an infinite
    relative threshold (one peak a profile) and empty input."""
    from coloradar.dsp import _kernels
    from coloradar.dsp.angle import azimuth_peaks

    rng = np.random.default_rng(6)
    total = 0
    for k, a in ((40, 64), (7, 256), (1, 5), (0, 16), (12, 3)):
        for rel in (0.05, 0.3, np.inf):
            prof = rng.integers(0, 9, (k, a)).astype(np.float32) ** 2    # ties
            prof[: k // 2] = rng.exponential(size=(k // 2, a)).astype(np.float32)
            floor = rng.uniform(0, 20, k)
            wk, wa = azimuth_peaks(prof, rel, floor)
            ck, ca_ = np.empty((2, prof.size), dtype=np.int64)
            n = _kernels.azimuth_peaks(prof, rel, floor, ck, ca_)
            np.testing.assert_array_equal(ck[:n], wk)
            np.testing.assert_array_equal(ca_[:n], wa)
            total += n
    assert total > 200
    # a NaN bin (NaN in the frame): numpy's argmax stops at it, and so does the kernel
    prof = rng.exponential(size=(6, 32)).astype(np.float32)
    prof[1, 7] = prof[3, 0] = prof[4, 31] = np.nan
    floor = np.zeros(6)
    wk, wa = azimuth_peaks(prof, 0.1, floor)
    ck, ca_ = np.empty((2, prof.size), dtype=np.int64)
    n = _kernels.azimuth_peaks(prof, 0.1, floor, ck, ca_)
    np.testing.assert_array_equal(ck[:n], wk)
    np.testing.assert_array_equal(ca_[:n], wa)


@pytest.mark.parametrize("name,focus", [("cascade", False), ("cascade", True),
                                        ("single_chip", False)])
def test_compiled_joint_refinement_is_the_numpy_loop(name, focus, monkeypatch):
    """Cells with several sources (pairs sharing range and range rate): the compiled joint
    refinement keeps the same sources at the same directions as the numpy loop it replaces
    (the same kernels inside: bit-equal), with powers equal to 1 ulp (numba's |z| is hypot,
    numpy's its own)."""
    from _synth import REFERENCE_CALIB
    if focus and not REFERENCE_CALIB.is_dir():
        # Focusing needs the release's near-field phases; the preset has none.
        pytest.skip(f"the release's calibration not at {REFERENCE_CALIB}")
    from _synth import exact_adc

    calib = _cascade_calib() if name == "cascade" else preset_radar(name)
    proc = RadarProcessor(calib, engine="numba", near_field=focus)
    rng = np.random.default_rng(12)
    multi = 0
    for f in range(3):
        k = 6
        rng_m = rng.uniform(2.0, 7.0, k)
        az, el = rng.uniform(-1.0, 1.0, k), rng.uniform(-0.2, 0.2, k)
        pos = rng_m[:, None] * np.column_stack([np.cos(el) * np.cos(az),
                                                np.cos(el) * np.sin(az), np.sin(el)])
        pos[1::2] = pos[0::2] * [1, -1, 1]                         # pairs in one cell
        vel = rng.uniform(-0.5, 0.5, (k, 1)) * pos / rng_m[:, None]
        vel[1::2] = vel[0::2] * [1, -1, 1]
        synth = exact_adc if focus else synthesize_adc
        adc = synth(calib, pos, vel, 200.0 * rng_m**2, noise_std=10.0, rng=f)
        got = proc.detect(adc)
        monkeypatch.setattr(ResolveStage, "COMPILED_JOINT", False)
        want = proc.detect(adc)
        monkeypatch.setattr(ResolveStage, "COMPILED_JOINT", True)
        cells = np.stack([want.range_bin, want.doppler_bin], axis=1)
        multi += len(cells) - len(np.unique(cells, axis=0))
        for field in ("range_bin", "doppler_bin", "azimuth", "elevation", "range", "xyz"):
            np.testing.assert_array_equal(getattr(got, field), getattr(want, field))
        np.testing.assert_allclose(got.intensity, want.intensity, rtol=1e-14, atol=0)
    assert multi >= 2                                  # cells with two points were compared


def test_joint_amplitudes_of_two_sources_in_one_direction():
    """Two peaks of a cell with the same weights (a singular Gram matrix): both engines give
    finite amplitudes whose fit is the cell's least-squares projection, where they used to
    raise (ZeroDivisionError compiled, LinAlgError in numpy)."""
    from coloradar.dsp import _kernels

    proc_n = RadarProcessor(preset_radar("cascade"), engine="numba")
    proc_p = RadarProcessor(preset_radar("cascade"), engine="numpy")
    rng = np.random.default_rng(3)
    uy, uz = np.array([0.2, 0.2, -0.4]), np.array([0.1, 0.1, 0.0])   # peaks 0 and 1 alike
    w = proc_n.detector.beams.steer(uy, uz, np.full(3, 5.0))
    m = w.shape[0]
    xc = (rng.normal(size=m) + 1j * rng.normal(size=m)).astype(np.complex64)
    x = np.repeat(xc[None], 3, axis=0)
    a = np.conj(w).astype(np.complex128)                              # (M, 3) sources
    proj = a[:, [0, 2]] @ np.linalg.lstsq(a[:, [0, 2]], xc.astype(np.complex128), rcond=None)[0]
    amps = np.empty(3, dtype=np.complex128)
    _kernels.joint_amplitudes(x, w, np.array([0, 3]), amps)
    for got in (amps, proc_p.detector.resolve.joint_amplitudes(x, w, np.zeros(3, dtype=np.int64),
                                                np.arange(3))):
        assert np.all(np.isfinite(got))
        np.testing.assert_allclose(a @ got, proj, rtol=0, atol=1e-4 * np.abs(proj).max())
