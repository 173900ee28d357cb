"""Beam-steered Doppler refinement (``ProcessingSettings.beam_doppler``) on extended surfaces.

A corridor of random point scatterers (floor 0.8 m below the radar, ceiling 1.6 m above,
walls 1 m to each side) is synthesized with :func:`coloradar.sim.synthesize_adc` for a radar
moving straight ahead beyond v_max. Every static scatterer's range rate is ``−d·v``, so the
detections' velocity fitted by plain least squares (inliers chosen with the true velocity, no
RANSAC) must match the true one. Refining the Doppler on the channel-summed power mixes all
the range rates of a range–Doppler cell and biases ``v_z`` by the floor/ceiling asymmetry.
"""

from __future__ import annotations

import numpy as np
import pytest

from _synth import matched
from coloradar.calib import preset_radar
from coloradar.dsp import ProcessingSettings, RadarProcessor
from coloradar.sim import synthesize_adc

SPEED = 2.5                                                # m/s; cascade v_max is 1.76 m/s


def corridor(rng: np.random.Generator, n: int = 400) -> np.ndarray:
    x = rng.uniform(0.8, 8.0, n)
    side = rng.integers(0, 4, n)
    y = np.where(side < 2, rng.uniform(-1.0, 1.0, n), np.where(side == 2, -1.0, 1.0))
    z = np.where(side == 0, -0.8, np.where(side == 1, 1.6, rng.uniform(-0.8, 1.6, n)))
    return np.column_stack([x, y, z])


@pytest.fixture(scope="module")
def frames():
    cal = matched(preset_radar("cascade"))          # a perfect board: its phases are known
    rng = np.random.default_rng(1)
    out = []
    for f in range(8):
        pos = corridor(rng)
        amp = 300.0 * rng.rayleigh(1.0, len(pos)) * np.exp(2j * np.pi * rng.random(len(pos)))
        vel = np.tile([-SPEED, 0.0, 0.0], (len(pos), 1))     # scatterers relative to the radar
        out.append(synthesize_adc(cal, pos, vel, amp, noise_std=20.0, rng=f, precision="single"))
    return cal, out


def fitted_errors(cal, adcs, **settings) -> np.ndarray:
    # The simulator's far-field model measures directions from the radar origin, without the
    # parallax of the array's phase centre (4 cm on the cascade) that real points carry.
    proc = RadarProcessor(cal, ProcessingSettings(phase_centre=False, **settings))
    v = np.array([SPEED, 0.0, 0.0])
    errors = []
    for adc in adcs:
        det = proc.detect(adc)
        d = det.xyz / det.range[:, None]
        inl = np.abs(det.range_rate + d @ v) < 0.25          # static and correctly unwrapped
        assert inl.sum() >= 15 and inl.mean() > 0.8
        fit = np.linalg.lstsq(-d[inl], det.range_rate[inl], rcond=None)[0]
        errors.append(fit - v)
    return np.array(errors)


def test_beam_doppler_removes_the_vertical_bias_of_surface_detections(frames):
    cal, adcs = frames
    e = fitted_errors(cal, adcs)
    assert np.sqrt(np.mean(np.sum(e**2, axis=1))) < 0.03, e
    assert abs(e[:, 2].mean()) < 0.015, e
    # Negative control: the power-map refinement is pulled towards the mixed range rates of
    # each cell (about +0.05 m/s in v_z here, whatever the speed).
    e_off = fitted_errors(cal, adcs, beam_doppler=False)
    assert e_off[:, 2].mean() > 0.03, e_off


def test_beam_doppler_keeps_isolated_targets_exact():
    """A single target: both refinements agree with the physical range rate."""
    cal = matched(preset_radar("cascade"))          # a perfect board: its phases are known
    vbin = cal.waveform.velocity_bin_width
    for i, (az, el, vr) in enumerate([(25.0, 10.0, -2.5), (-40.0, -15.0, 1.2), (5.0, 0.0, 3.3)]):
        a, e = np.radians(az), np.radians(el)
        u = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        adc = synthesize_adc(cal, (3.0 * u)[None], (vr * u)[None], 3600.0, noise_std=20.0, rng=i)
        for beam in (True, False):
            det = RadarProcessor(cal, ProcessingSettings(beam_doppler=beam)).detect(adc)
            k = int(np.argmax(det.snr))
            assert abs(det.range_rate[k] - vr) < 0.05 * vbin, (beam, det.range_rate[k], vr)
