"""The static-world Doppler test of radar points (``coloradar.mapping.static_gate``).

References written here: the range rate of a static point seen from a moving sensor,
``ṙ = −uᵀv``, computed point by point in a loop; a person walking beside the rig, whose points
a map of the static world must not keep. (The sensor's velocity is
:func:`coloradar.geometry.rig_velocity`'s, tested in ``test_geometry.py``.)
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from coloradar.errors import SettingsError
from coloradar.mapping import (
    OCCUPIED,
    UNKNOWN,
    OccupancyMap,
    OccupancySettings,
    PointSensorModel,
    StaticGate,
    StaticTest,
    frame_evidence,
    occupancy_from_frames,
    static_frames,
    static_mask,
)


def test_the_mask_is_the_static_range_rate_test_point_by_point():
    rng = np.random.default_rng(0)
    v = np.array([1.2, -0.3, 0.1])
    xyz = rng.normal(0, 4, (200, 3))
    rates = rng.uniform(-3, 3, 200)
    cloud = np.column_stack([xyz, np.ones(200), rates])
    gate = StaticGate(floor=0.1, direction_std_deg=3.0)
    bin_width, vmax = 0.2, 2.5
    got = static_mask(cloud, v, gate, bin_width, vmax)
    tol = max(0.1, 0.75 * bin_width) + 2 * math.hypot(*v) * math.sin(math.radians(3.0))
    for i in range(200):
        u = xyz[i] / math.sqrt(float(xyz[i] @ xyz[i]))
        expected = -float(u @ v)                 # a static point's range rate
        d = rates[i] - expected
        d = (d + vmax) % (2 * vmax) - vmax       # folded at ±v_max
        assert got[i] == (abs(d) <= tol), i
    assert 0 < got.sum() < 200


def test_a_folded_static_point_passes_and_a_cloud_without_rates_is_refused():
    v = np.array([3.0, 0.0, 0.0])                # faster than v_max: the rate folds
    cloud = np.array([[5.0, 0.0, 0.0, 1.0, -3.0 + 2 * 2.0]])
    assert static_mask(cloud, v, StaticGate(), 0.0, 2.0)[0]
    assert not static_mask(cloud, v, StaticGate(), 0.0, None)[0]
    with pytest.raises(SettingsError, match="range rates"):
        static_mask(np.zeros((3, 4)), v, StaticGate())
    with pytest.raises(SettingsError):
        StaticGate(floor=0.0)


def test_a_person_walking_beside_the_rig_leaves_no_trail_in_the_map():
    # The rig walks along +y at 1 m/s looking along +x at a wall 5 m away; a person walks
    # with it, 2 m out and 1.5 m ahead, at the same speed. The person's points sit still in
    # the sensor's frame with range rate 0; a static point there would approach at
    # -uᵀv = -0.6 m/s.
    rng = np.random.default_rng(3)
    model = PointSensorModel(range_std=0.05, azimuth_resolution=0.1, elevation_resolution=0.5,
                             max_range=10.0)
    s = OccupancySettings()
    times = np.arange(0, 8, 0.1)
    v_sensor = np.array([0.0, 1.0, 0.0])
    clouds = []
    for t0 in times:
        yw = rng.uniform(-3, 3, 25) + t0
        wall = np.column_stack([np.full(25, 5.0), yw - t0, rng.uniform(-0.3, 0.3, 25)])
        u = wall / np.linalg.norm(wall, axis=1, keepdims=True)
        wall_rates = -(u @ v_sensor)
        person = np.array([2.0, 1.5, 0.0]) + rng.normal(0, 0.03, (4, 3))
        cloud = np.vstack([np.column_stack([wall, np.full(25, 20.0), wall_rates]),
                           np.column_stack([person, np.full(4, 20.0), np.zeros(4)])])
        clouds.append(cloud.astype(np.float32))
    rot = np.tile(np.eye(3), (times.size, 1, 1))
    trans = np.column_stack([np.zeros_like(times), times, np.zeros_like(times)])
    ev = frame_evidence(model, s)

    def person_voxels(m: OccupancyMap) -> int:
        occ = m.occupied()
        return int(np.sum(np.abs(occ[:, 0] - 2.0) < 0.5))

    plain = occupancy_from_frames(clouds, rot, trans, ev, s)
    gated = occupancy_from_frames(static_frames(clouds, np.tile(v_sensor, (times.size, 1)),
                                                StaticTest(StaticGate(), 0.04, 2.5)),
                                  rot, trans, ev, s)
    assert person_voxels(plain) > 10               # without the test: a trail along y
    assert person_voxels(gated) == 0
    wall_gated = gated.occupied()
    assert wall_gated.shape[0] > 50 and np.all(np.abs(wall_gated[:, 0] - 5.0) < 0.3)


def test_a_frame_whose_range_rates_are_not_a_static_worlds_is_kept_whole_and_counted():
    # A bag imported without a Doppler field: every range rate 0 while the rig moves.
    rng = np.random.default_rng(5)
    xyz = np.column_stack([rng.uniform(2, 8, 40), rng.uniform(-3, 3, 40), rng.uniform(-1, 1, 40)])
    zeros = np.column_stack([xyz, np.ones(40), np.zeros(40)])
    v = np.array([1.5, 0.0, 0.0])
    test = StaticTest(StaticGate(), 0.04, 2.5)
    assert static_mask(zeros, v, StaticGate(), 0.04, 2.5).mean() < 0.3   # the bare test
    assert test(zeros, v).all()                                          # kept whole
    u = xyz / np.linalg.norm(xyz, axis=1, keepdims=True)
    good = np.column_stack([xyz, np.ones(40), -(u @ v)])
    good[:5, 4] += 1.0                                                   # five movers
    keep = test(good, v)
    assert keep.sum() == 35 and not keep[:5].any()
    assert test.summary() == {"frames": 2, "frames_kept_whole": 1, "points": 80,
                              "points_dropped": 5}
    assert "kept 1 of 2 frames whole" in (test.warning() or "")
    # at rest nothing is kept whole: movers are all a still rig's points can fail on
    rest = StaticTest(StaticGate())
    moving_things = np.column_stack([xyz, np.ones(40), np.full(40, 0.8)])
    assert not rest(moving_things, np.zeros(3)).any() and rest.warning() is None


def test_heatmap_returns_of_a_mover_are_left_out_with_the_sensors_velocity():
    from coloradar.calib import HeatmapConfig
    from coloradar.mapping import HeatmapModel, heatmap_evidence

    # One elevation row, 9 beams; a static target at (2 m, beam 4) and a mover at (3 m, beam 6)
    # whose range rate is 0 while the rig moves forward at 1 m/s.
    nr, na = 40, 9
    az = np.linspace(-0.4, 0.4, na)
    cfg = HeatmapConfig(num_range_bins=nr, num_elevation_bins=1, num_azimuth_bins=na,
                        range_bin_width=0.1, azimuth_bins=az, elevation_bins=np.zeros(1))
    pm = PointSensorModel(range_std=0.05, azimuth_resolution=0.25, elevation_resolution=1.0)
    s = OccupancySettings(voxel=0.1)
    v = np.array([1.0, 0.0, 0.0])
    rng = np.random.default_rng(2)
    h = np.zeros((1, na, nr, 2), np.float32)
    h[..., 0] = rng.exponential(1.0, (32, 1, na, nr)).max(axis=0)
    h[0, 4, 20, 0], h[0, 4, 20, 1] = 1000.0, -math.cos(az[4]) * 1.0     # static: -u·v
    h[0, 6, 30, 0], h[0, 6, 30, 1] = 1000.0, 0.0                         # the mover
    static_pt = np.array([[2.0 * math.cos(az[4]), 2.0 * math.sin(az[4]), 0.0]])
    mover_pt = np.array([[3.0 * math.cos(az[6]), 3.0 * math.sin(az[6]), 0.0]])

    def occupied_after(model, velocity):
        m = OccupancyMap(s)
        for _ in range(5):
            m.integrate(*heatmap_evidence(h, np.eye(3), np.zeros(3), model, s, velocity))
        return m.state(static_pt)[0], m.state(mover_pt)[0]

    test = StaticTest(StaticGate(), 0.04, 2.5, min_points=1)
    gated = HeatmapModel(cfg, pm, stride=1, static_test=test)
    assert occupied_after(gated, v) == (OCCUPIED, UNKNOWN)
    assert test.summary()["points_dropped"] == 5
    assert occupied_after(gated, None) == (OCCUPIED, OCCUPIED)        # no velocity, no test
    assert occupied_after(HeatmapModel(cfg, pm, stride=1), v) == (OCCUPIED, OCCUPIED)
