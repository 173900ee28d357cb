"""Simulated loops: a run of ``laps_duration`` brings the rig back to where it started."""

from __future__ import annotations

import numpy as np
import pytest

from coloradar.errors import SettingsError
from coloradar.sim import builtin_scene, make_trajectory
from coloradar.sim.point_runs import laps_duration
from coloradar.sim.rest import RestStart


@pytest.mark.parametrize("scene", ["corridor", "courtyard", "hallway"])
@pytest.mark.parametrize("laps", [1.0, 2.0])
def test_laps_bring_the_rig_back_to_its_start(scene, laps):
    sc = builtin_scene(scene)
    traj = RestStart(make_trajectory(sc.rig_path, "smooth", 3), 2.0)
    t_end = laps_duration(sc, laps, rest=2.0)
    start, end = traj.state(np.array([0.0, t_end])).position
    # The path's own point comes back exactly; the smooth profile's perturbations (a few cm)
    # and the ease-in ramp's approximation remain.
    assert np.linalg.norm(end - start) < 0.15, (end, start)
    half = traj.state(np.array([laps_duration(sc, laps - 0.5, rest=2.0)])).position[0]
    assert np.linalg.norm(half - start) > 0.4      # half a lap away, it is elsewhere


def test_laps_refuse_nonsense():
    with pytest.raises(SettingsError):
        laps_duration("corridor", 0.0)
