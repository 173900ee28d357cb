"""Random trajectories shared by the trajectory-metric tests."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from coloradar.geometry import Trajectory

T0 = 1_608_580_000.0


def wander(n: int = 300, seed: int = 3) -> Trajectory:
    """A random walk at 10 Hz with uneven steps (no two path lengths tie) and turning attitude."""
    rng = np.random.default_rng(seed)
    t = T0 + np.arange(n) * 0.1
    steps = rng.uniform(0.02, 0.25, (n, 1)) * rng.normal(size=(n, 3))
    steps[0] = 0.0
    rot = Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0))
    return Trajectory(t, np.cumsum(steps, axis=0), rot, "reference")
