"""The two engines against one contract (:data:`coloradar.dsp.engines.CONTRACTS`): one table of
cases, each running a stage method on the numba and the numpy engine with the same inputs and
comparing the results within the contract's tolerance. Each case names the kernels it must call
on the numba engine, and a spy checks that it did, so that the table covers every kernel.

The numpy side is the definition (tests/test_dsp_beam_kernels.py checks it against brute-force
loops and formulas); a compiled kernel that drifts from it fails here.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from coloradar.calib import preset_radar
from coloradar.dsp import RadarProcessor
from coloradar.dsp.engines import CONTRACTS
from coloradar.sim import synthesize_adc

pytest.importorskip("numba")


def _frame(calib, seed: int, k: int = 6) -> np.ndarray:
    """``k`` targets, two of them in one range–Doppler cell (mirrored in azimuth)."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(2.0, 8.0, k)
    az, el = rng.uniform(-1.0, 1.0, k), rng.uniform(-0.2, 0.2, k)
    pos = r[:, None] * np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                        np.sin(el)])
    pos[1] = pos[0] * [1, -1, 1]
    vel = rng.uniform(-0.5, 0.5, (k, 1)) * pos / r[:, None]
    vel[1] = vel[0] * [1, -1, 1]
    return synthesize_adc(calib, pos, vel, 200.0 * r**2, noise_std=10.0, rng=seed)


class Pair:
    """The same radar and settings on both engines, and one frame."""

    def __init__(self, name: str, **settings: Any) -> None:
        self.calib = preset_radar(name)
        self.fast = RadarProcessor(self.calib, engine="numba", **settings)
        self.ref = RadarProcessor(self.calib, engine="numpy", **settings)
        self.adc = _frame(self.calib, 3)
        nr = self.ref.num_range_bins
        rcube = self.ref.cube.range_cube(self.adc, extra=True)
        self.rd = self.ref.cube.doppler(rcube[..., :nr], compensate=False)
        self.rd_next = self.ref.cube.doppler(rcube[..., nr:], compensate=False)


def _directions(p: Pair, n: int = 40, seed: int = 1):
    g = np.random.default_rng(seed)
    m = p.ref.detection_grid.num_elements
    uy, uz = g.uniform(-0.7, 0.7, n), g.uniform(-0.3, 0.3, n)
    x = (g.standard_normal((n, m)) + 1j * g.standard_normal((n, m))).astype(np.complex64)
    return x, uy, uz, g.uniform(2.0, 8.0, n)


def _both(p: Pair, fn: Callable[[RadarProcessor], Any]) -> tuple[Any, Any]:
    return fn(p.fast), fn(p.ref)


def case_range_cube(p):
    return _both(p, lambda q: q.cube.range_cube(p.adc, extra=True))


def case_statistic(p):
    return _both(p, lambda q: q.detector.cfar.statistic(p.rd)[0])


def case_channel_noise(p):
    from coloradar.dsp.detect import channel_noise

    ntx, nrx, nd, nr = p.rd.shape
    mag2 = (np.abs(p.rd) ** 2).astype(np.float32).reshape(ntx * nrx, nd, nr)
    return _both(p, lambda q: channel_noise(mag2, 3, engine=q.cube.engine))


def case_group(p):
    stat, _, looks, _ = p.ref.detector.cfar.statistic(p.rd)
    mask, noise = p.ref.detector.cfar.cfar_mask(stat, looks)
    nxt = p.ref.detector.cfar.exclude_row(np.abs(p.rd_next[..., 0]).reshape(
        -1, p.rd.shape[2]) ** 2, p.rd.shape[2])
    return _both(p, lambda q: q.detector.cfar.group(stat, mask, noise, nxt))


def case_heatmap(p):
    return _both(p, lambda q: q.heatmap(p.adc)[..., 0])


def case_heatmap_any_grid(p):
    """A grid of 96 azimuth bins (no power of two: the chunked kernels, not the planar one)."""
    from coloradar.dsp import angle_grid, heatmap_from_elements

    w, h = p.calib.waveform, p.calib.heatmap
    grid = angle_grid(p.calib.antenna, w.center_frequency, h.num_elevation_bins, 96, 1, 1)
    rd = p.ref.range_doppler(p.adc)
    ntx, nrx = rd.shape[:2]
    first = p.calib.antenna.virtual.first_pair
    elements = rd.reshape(ntx * nrx, *rd.shape[2:])[first[:, 0] * nrx + first[:, 1]]
    return _both(p, lambda q: heatmap_from_elements(elements, grid, q.velocities,
                                                    engine=q.cube.engine)[..., 0])


def case_steer(p):
    _, uy, uz, rho = _directions(p)
    return _both(p, lambda q: q.detector.beams.steer(uy, uz, rho))


def case_focused(p):
    x, uy, uz, rho = _directions(p)
    return _both(p, lambda q: q.detector.beams.focused(x, uy, uz, rho))


def case_newton(p):
    x, uy, uz, rho = _directions(p)
    # vectors of one source each, near the start directions: a well-defined peak
    w = p.ref.detector.beams.steer(uy + 0.01, uz - 0.01, rho)
    x = (np.conj(w.T) * 3.0 + 0.1 * x).astype(np.complex64)
    return _both(p, lambda q: np.stack(q.detector.beams.newton(x, uy, uz, rho)))


def case_elevation_search(p):
    x, uy, _, rho = _directions(p)
    return _both(p, lambda q: np.stack(q.detector.beams.elevation_search(x, uy, rho)))


def case_azimuth_peaks(p):
    g = np.random.default_rng(4)
    prof = g.exponential(1.0, (50, p.ref.detection_grid.num_az)).astype(np.float32)
    floor = np.full(50, 2.0)
    return _both(p, lambda q: np.stack(q.detector.beams.azimuth_peaks(prof, 0.1, floor)))


def case_beam_neighbourhood(p):
    g = np.random.default_rng(5)
    nd, nr = p.rd.shape[2:]
    d, r = g.integers(0, nd, 30), g.integers(0, nr, 30)
    alias = g.integers(-1, 2, 30)
    _, uy, uz, rho = _directions(p, 30)
    steer = p.ref.detector.beams.steer(uy, uz, rho).astype(np.complex64)
    return _both(p, lambda q: q.detector.guard.beam_neighbourhood(p.rd, d, r, alias, steer,
                                                                 p.rd_next))


def case_joint_amplitudes(p):
    x, _, _, rho = _directions(p, 4)
    x = np.repeat(x, 3, axis=0)                       # each peak carries its cell's vector
    uy = np.tile([-0.5, 0.0, 0.5], 4)                  # three well-separated sources per cell
    uz = np.tile([0.0, 0.1, -0.1], 4)
    w = p.ref.detector.beams.steer(uy, uz, np.repeat(rho, 3)).astype(np.complex64)
    cell_of = np.repeat(np.arange(4), 3)
    rank = np.tile(np.arange(3), 4)
    return _both(p, lambda q: q.detector.resolve.joint_amplitudes(x, w, cell_of, rank))


def case_alias_choice(p):
    g = np.random.default_rng(6)
    d = g.integers(0, p.rd.shape[2], 40)
    r = g.integers(5, p.rd.shape[3], 40)
    vecs = p.rd[:, :, d, r] * p.ref.cube.tdm_at(d)
    k = (d - p.rd.shape[2] // 2).astype(np.float64)
    noise = np.full(40, 1e-3 * float(np.median(np.abs(vecs) ** 2)))
    return _both(p, lambda q: q.detector.alias.choose(vecs, k, noise)[0])


def case_points(p):
    """Several frames' points (several sources per cell): positions and intensities."""
    out = []
    for q in (p.fast, p.ref):
        pts = [q.pointcloud(_frame(p.calib, s)) for s in range(3)]
        out.append(np.concatenate(pts))
    return out[0], out[1]


# name → (case, radar and settings, kernels it must call on the numba engine, tolerance from)
CASES: dict[str, tuple[Callable, tuple[str, dict], tuple[str, ...], str]] = {
    "range cube": (case_range_cube, ("cascade", {}), ("prepare_chirps",), "prepare_chirps"),
    "statistic": (case_statistic, ("cascade", {}), ("power",), "power"),
    "channel noise": (case_channel_noise, ("cascade", {}), ("median_bits",), "median_bits"),
    "peak grouping": (case_group, ("cascade", {}), ("group_peaks",), "group_peaks"),
    "heatmap, cascade": (case_heatmap, ("cascade", {}),
                         ("prepare_chirps", "peak_over_doppler_planar"),
                         "peak_over_doppler_planar"),
    "heatmap, 96 azimuth bins": (case_heatmap_any_grid, ("cascade", {}),
                                 ("gather_rows", "peak_over_doppler"), "peak_over_doppler"),
    "steering, focused": (case_steer, ("cascade", {"near_field": True}),
                          ("steer_columns", "focus_multiply"), "steer_columns"),
    "focusing": (case_focused, ("cascade", {"near_field": True}), ("focus_multiply",),
                 "focus_multiply"),
    "Newton": (case_newton, ("cascade", {}), ("newton_refine",), "newton_refine"),
    "elevation search": (case_elevation_search, ("cascade", {}), ("elevation_search",),
                         "elevation_search"),
    "azimuth peaks": (case_azimuth_peaks, ("cascade", {}), ("azimuth_peaks",),
                      "azimuth_peaks"),
    "beam neighbourhood": (case_beam_neighbourhood, ("cascade", {}), ("beam_neighbourhood",),
                           "beam_neighbourhood"),
    "joint amplitudes": (case_joint_amplitudes, ("cascade", {}), ("joint_amplitudes",),
                         "joint_amplitudes"),
    "alias choice": (case_alias_choice, ("single_chip", {}), ("source_pairs",),
                     "source_pairs"),
    "points": (case_points, ("cascade", {}),
               ("secondary_residual", "secondary_bound", "joint_round", "joint_residuals",
                "joint_powers"), "joint_round"),
    "points, focused": (case_points, ("cascade", {"near_field": True}),
                        ("secondary_bound_focused", "joint_round"), "joint_round"),
}

_PAIRS: dict[tuple[str, str], Pair] = {}


def _pair(radar: str, settings: dict) -> Pair:
    key = (radar, repr(sorted(settings.items())))
    if key not in _PAIRS:
        _PAIRS[key] = Pair(radar, **settings)
    return _PAIRS[key]


def test_every_kernel_has_a_contract_and_a_case():
    from coloradar.dsp import _kernels

    kernels = set(_kernels.__all__) - {"CACHE_PROBLEM", "LANES"}
    assert set(CONTRACTS) == kernels
    covered = {k for _, _, called, _ in CASES.values() for k in called}
    assert covered == kernels


@pytest.mark.parametrize("name", list(CASES))
def test_engines_meet_the_kernel_contract(name, monkeypatch):
    from coloradar.dsp import _kernels, heatmap

    case, (radar, settings), must_call, contract = CASES[name]
    p = _pair(radar, settings)
    calls: Counter[str] = Counter()
    for k in must_call:
        real = getattr(_kernels, k)

        def spy(*args: Any, _k: str = k, _real: Any = real) -> Any:
            calls[_k] += 1
            return _real(*args)

        monkeypatch.setattr(_kernels, k, spy)
        if k == "peak_over_doppler":                 # (heatmap.py keeps it once loaded)
            monkeypatch.setattr(heatmap, "_KERNEL", spy)
    fast, ref = case(p)
    assert set(calls) == set(must_call), f"not called: {set(must_call) - set(calls)}"
    fast, ref = np.asarray(fast), np.asarray(ref)
    assert fast.shape == ref.shape
    rtol = CONTRACTS[contract].rtol
    if rtol == 0.0:
        np.testing.assert_array_equal(fast, ref)
    elif name.startswith("points"):
        assert len(ref) > 10
        np.testing.assert_allclose(fast[:, :3], ref[:, :3], atol=1e-3)    # sub-millimetre
        np.testing.assert_allclose(fast[:, 3], ref[:, 3], rtol=2e-3)
        np.testing.assert_allclose(fast[:, 4], ref[:, 4], atol=1e-4)
    else:
        scale = float(np.max(np.abs(ref))) or 1.0
        np.testing.assert_allclose(fast, ref, rtol=rtol, atol=rtol * scale)
