"""TDM-MIMO Doppler phase compensation."""

from __future__ import annotations

import numpy as np
import pytest

from coloradar.calib import preset_radar
from coloradar.dsp import RadarProcessor, compensate_tdm, doppler_fft, range_fft, tdm_phase
from coloradar.sim import slow_times, synthesize_adc


@pytest.mark.parametrize("name", ["cascade", "single_chip"])
@pytest.mark.parametrize("k", [-7, 3, 6])
def test_boresight_mover_is_in_phase_on_every_channel_after_compensation(name, k):
    """A boresight target has no geometric phase across the array; what is left after the
    Doppler FFT is the TDM slot delay t·Tc, which the compensation must remove exactly."""
    calib = preset_radar(name)
    w = calib.waveform
    # radial velocity whose Doppler is exactly bin k: 2v/λ · Ntx·Tc = k/Nc
    v = k / w.num_chirps * w.wavelength / (2.0 * w.tdm_period)
    r = 60 * w.range_bin_width
    adc = synthesize_adc(calib, [[r, 0.0, 0.0]], [[v, 0.0, 0.0]], 1.0)
    rd = doppler_fft(range_fft(adc, "none"), "none")
    cell = (slice(None), slice(None), w.num_chirps // 2 + k, 60)
    raw = rd[cell]
    # before: TX slot t lags by the Doppler phase over t·Tc (docs/conventions.md §3 timing)
    t_slot = slow_times(calib)[:, 0]
    expected = np.exp(2j * np.pi * (2 * v / w.wavelength) * t_slot)
    np.testing.assert_allclose(raw / raw[0, 0], np.broadcast_to(expected[:, None], raw.shape),
                               atol=1e-4)
    after = compensate_tdm(rd)[cell]
    np.testing.assert_allclose(after / after[0, 0], 1.0, atol=1e-4)


def test_tdm_phase_formula():
    ph = tdm_phase(4, np.array([-2.5, 0.0, 1.0]), 16)
    t = np.arange(4)[:, None]
    np.testing.assert_allclose(ph, np.exp(-2j * np.pi * t * np.array([-2.5, 0.0, 1.0]) / 64),
                               rtol=1e-6)


def test_without_compensation_fast_targets_move_in_angle():
    calib = preset_radar("single_chip")
    w = calib.waveform
    el = np.deg2rad(15.0)
    u = np.array([np.cos(el), 0.0, np.sin(el)])
    adc = synthesize_adc(calib, 4.0 * u[None], 0.9 * w.max_velocity * u[None], 16.0)
    cfg = RadarProcessor(calib).heatmap_config()
    for comp, ok in ((True, True), (False, False)):
        hm = RadarProcessor(calib, tdm_compensation=comp).heatmap(adc)
        e, _, _ = np.unravel_index(np.argmax(hm[..., 0]), hm.shape[:3])
        err = abs(cfg.elevation_bins[e] - el)
        assert (err < np.deg2rad(6.0)) == ok, (comp, np.rad2deg(cfg.elevation_bins[e]))


def test_overlap_pairs_match_a_brute_force_search():
    from coloradar.dsp.tdm import overlap_pairs

    for name in ("cascade", "single_chip"):
        calib = preset_radar(name)
        pos = calib.antenna.virtual.positions                  # (tx, rx, 2)
        ntx, nrx = pos.shape[:2]
        want = set()
        for a in range(ntx * nrx):
            for b in range(a):
                ta, tb = divmod(a, nrx)[0], divmod(b, nrx)[0]
                if ta != tb and np.allclose(pos[divmod(a, nrx)], pos[divmod(b, nrx)]):
                    want.add((a, b))
        op = overlap_pairs(calib.antenna.virtual)
        got = {(max(a, b), min(a, b)) for a, b in zip(op.a, op.b, strict=True)}
        assert got == want
        np.testing.assert_array_equal(op.slot_difference, op.a // nrx - op.b // nrx)
    assert len(overlap_pairs(preset_radar("cascade").antenna.virtual)) == 58


def test_alias_scores_peak_at_the_true_alias():
    """Channels of a target at true Doppler k + m·n after compensation at k: TX t keeps the
    phase 2π·m·t/Ntx (the formula of the module notes); the pair score is 1 at m only."""
    from coloradar.dsp.tdm import alias_hypotheses, alias_phase, overlap_pairs

    calib = preset_radar("cascade")
    w = calib.waveform
    ntx = w.num_tx
    op = overlap_pairs(calib.antenna.virtual)
    hyps = alias_hypotheses(ntx, w.max_velocity, 100.0)
    assert len(hyps) == ntx and len(set((hyps % ntx).tolist())) == ntx
    g = np.random.default_rng(0)
    geo = np.exp(1j * g.uniform(-np.pi, np.pi, calib.antenna.virtual.num_unique))
    for m in (-2, -1, 1, 3):
        t = np.arange(ntx)[:, None]
        x = geo[calib.antenna.virtual.index] * np.exp(2j * np.pi * m * t / ntx)   # (tx, rx)
        s = op.scores(x.reshape(1, -1), hyps)[0]
        assert hyps[np.argmax(s)] == m and s.max() == pytest.approx(1.0)
        fixed = x * alias_phase(ntx, np.array(m))[:, None]
        np.testing.assert_allclose(fixed, geo[calib.antenna.virtual.index], atol=1e-6)
    assert alias_hypotheses(ntx, w.max_velocity, 0.0).tolist() == [0]
    assert alias_hypotheses(ntx, w.max_velocity, 5.0).tolist() == [0, 1, -1]
