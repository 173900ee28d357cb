"""Finding the azimuth/elevation sign convention from a sensor's own point clouds."""

from __future__ import annotations

import numpy as np
import pytest

from coloradar.calib import preset_radar
from coloradar.dsp import match_sign_convention
from coloradar.sim import synthesize_adc


def scene(seed):
    """Four targets at distinct ranges, well off boresight in azimuth and elevation."""
    g = np.random.default_rng(seed)
    r = np.array([2.5, 3.7, 5.1, 6.4]) + g.uniform(-0.2, 0.2, 4)
    az = np.deg2rad(g.choice([-1, 1], 4) * g.uniform(20, 45, 4))
    el = np.deg2rad(g.choice([-1, 1], 4) * g.uniform(10, 25, 4))
    pos = r[:, None] * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
    vel = g.uniform(-1.0, 1.0, (4, 1)) * pos / r[:, None]
    return pos, vel


@pytest.mark.parametrize("truth", [(1, 1), (-1, 1), (1, -1), (-1, -1)])
def test_mirrored_sensor_is_recognised(truth):
    calib = preset_radar("single_chip")
    frames, clouds = [], []
    for seed in range(3):
        pos, vel = scene(seed)
        frames.append(synthesize_adc(calib, pos, vel, 300.0 * np.linalg.norm(pos, axis=1) ** 2,
                                     noise_std=10.0, rng=seed, azimuth_sign=truth[0],
                                     elevation_sign=truth[1]))
        # the sensor's own cloud: the true points (plus a spurious one it saw and we did not)
        clouds.append(np.vstack([pos, [[1.0, -4.0, 0.5]]]))
    match = match_sign_convention(calib, frames, clouds)
    assert (match.azimuth_sign, match.elevation_sign) == truth, match.scores
    assert match.margin > 0.1
    assert set(match.scores) == {(1, 1), (1, -1), (-1, 1), (-1, -1)}


def test_frame_count_mismatch_is_an_error():
    calib = preset_radar("single_chip")
    with pytest.raises(ValueError, match="one cloud per frame"):
        match_sign_convention(calib, [np.zeros(calib.frame_shape, np.complex64)], [])
