"""The simulator's radar frames, processed by coloradar.dsp, show targets where they are."""

from __future__ import annotations

import numpy as np
import pytest

from coloradar import dsp
from coloradar.formats import decode_adc, encode_adc
from coloradar.sim.radar import RADAR_MODELS, RadarTargets, radar_frame
from coloradar.sim.run import simulated_calibration


@pytest.fixture(scope="module")
def rig():
    return simulated_calibration(board_seed=2021)


# (range [m], azimuth [deg], elevation [deg], range rate [m/s])
TARGETS = [(4.2, 25.0, 8.0, 0.6), (2.5, -40.0, -5.0, -0.9), (6.0, 5.0, 0.0, 0.3)]


@pytest.mark.parametrize("radar", ["cascade", "single_chip"])
@pytest.mark.parametrize("target", TARGETS)
def test_one_scatterer_peaks_where_it_is(rig, radar, target):
    calib, coupling = rig
    rc = calib.radar(radar)
    r, az_d, el_d, vr = target
    az, el = np.radians(az_d), np.radians(el_d)
    u = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    # A 0.1 m² reflector, with everything a real frame has: the cascade's channel errors,
    # coupling, thermal noise, int16 rounding.
    model = RADAR_MODELS[radar]
    t = RadarTargets((r * u)[None], (vr * u)[None], np.array([model.gain * np.sqrt(0.1) + 0j]),
                     np.array([0]))
    frame = radar_frame(rc, model, t, channel_errors=rc.phase_frequency,
                        coupling_adc=coupling[radar], rng=np.random.default_rng(1))
    adc = decode_adc(encode_adc(frame), rc.frame_shape)
    proc = dsp.RadarProcessor(rc)
    cfg = proc.heatmap_config()
    # The simulator wrote the processor's own true-angle grid into the calibration.
    np.testing.assert_allclose(rc.heatmap.azimuth_bins, cfg.azimuth_bins)
    hm = proc.heatmap(adc)
    # Below 0.3 m lives what is left of the coupling after its removal.
    near = cfg.range_bins < 0.3
    ie, ia, ir = np.unravel_index(np.argmax(np.where(near, 0, hm[..., 0])), hm.shape[:3])
    w = rc.waveform
    assert abs(cfg.range_bins[ir] - r) <= cfg.range_bin_width
    # Azimuth bins measure asin(cos(el)·sin(az)) (exact in the el = 0 plane).
    az_axis = np.arcsin(np.cos(el) * np.sin(az))
    step_az = np.max(np.diff(cfg.azimuth_bins)[max(ia - 1, 0):ia + 1])
    assert abs(cfg.azimuth_bins[ia] - az_axis) <= step_az
    step_el = np.max(np.diff(cfg.elevation_bins)[max(ie - 1, 0):ie + 1])
    assert abs(cfg.elevation_bins[ie] - el) <= 1.5 * step_el
    assert abs(hm[ie, ia, ir, 1] - vr) <= w.velocity_bin_width
    # The point cloud has a detection at the scatterer, with its range rate.
    pts = proc.pointcloud(adc)
    d = np.linalg.norm(pts[:, :3] - r * u, axis=1)
    k = np.argmin(d)
    assert d[k] < 0.06 * r + 0.1
    assert abs(pts[k, 4] - vr) <= w.velocity_bin_width
