"""Pictures that fit their data (issue 41, items 9 and 10): a long thin trajectory is drawn
along / across its main direction, not as a line in an empty square; the RPE's two units get two
axes; an evaluation of a SLAM folder says SLAM."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from scipy.spatial.transform import Rotation

from coloradar.geometry import Trajectory
from coloradar.odometry.evaluation import evaluate_trajectory
from coloradar.odometry.plot import evaluation_figure, top_view_frame


def hallway(heading_deg: float, noise: float = 0.0, seed: int = 0) -> Trajectory:
    """40 m there and back along a hallway 1.3 m wide, heading ``heading_deg`` in the world."""
    t = np.linspace(0.0, 80.0, 801)
    s = np.where(t < 40.0, t, 80.0 - t)                       # along, m
    a = 0.65 * np.sin(2 * np.pi * t / 13.0)                   # across, m
    h = np.radians(heading_deg)
    xy = np.stack([s * np.cos(h) - a * np.sin(h), s * np.sin(h) + a * np.cos(h)], axis=1)
    xy = xy + noise * np.random.default_rng(seed).standard_normal(xy.shape)
    p = np.column_stack([xy, np.zeros(len(t))])
    return Trajectory(t, p, Rotation.from_euler("z", np.full((len(t), 1), h)), name="hallway")


def test_the_top_view_frame_is_the_paths_own():
    rot, _c, ratio = top_view_frame(hallway(63.0).translations[:, :2])
    along = np.degrees(np.arctan2(rot[0, 1], rot[0, 0]))
    assert abs(along - 63.0) < 2.0 and ratio > 20


@pytest.mark.parametrize("heading", [90.0, 30.0])
def test_a_hallway_evaluation_is_drawn_along_and_across(heading):
    ref = hallway(heading)
    est = hallway(heading, noise=0.05, seed=1)
    ev = evaluate_trajectory(est, ref, info={"run_name": "hallway_run0", "radar": "single_chip",
                                             "estimator": "slam"})
    fig = evaluation_figure(ev)
    fig.canvas.draw()
    top = fig.axes[0]
    lo, hi = top.get_ylim()
    # across: the 1.3 m hallway (and its noise) fills the axis, not a ±30 m square
    assert hi - lo < 4.0, (lo, hi)
    assert "along" in top.get_xlabel()
    # RPE: two axes, the rotation's bars on their own (they vanished beside the %)
    rpe = next(a for a in fig.axes if a.get_title() == "RPE")
    twins = [a for a in fig.axes if a is not rpe and a.bbox.bounds == rpe.bbox.bounds]
    assert len(twins) == 1 and "deg/m" in twins[0].get_ylabel()
    assert "SLAM" in fig._suptitle.get_text() and "odometry" not in fig._suptitle.get_text()


def test_a_slam_picture_of_a_hallway_fills_the_figure():
    pytest.importorskip("gtsam")              # the slam package's own import (its extra)
    from coloradar.slam.plot import slam_figure
    from coloradar.slam.system import SlamResult

    ref = hallway(90.0)
    pts = np.column_stack([np.zeros(200), np.linspace(0, 40, 200), np.zeros(200),
                           np.full(200, 5.0), np.ones(200)])
    pts[:, 0] = np.where(np.arange(200) % 2, 1.0, -1.0)      # the walls, x = ±1 m
    res = SlamResult(odometry=ref, trajectory=ref, keyframes=np.zeros(0, dtype=np.int64),
                     keyframe_odometry=None, keyframe_poses=None, loops=[],
                     map_points=pts.astype(np.float32), frontend=None,  # type: ignore[arg-type]
                     submap_points=np.zeros((0, 3)))
    fig = slam_figure(res, groundtruth=ref)
    fig.canvas.draw()
    ax = fig.axes[0]
    lo, hi = ax.get_ylim()
    assert hi - lo < 6.0 and "along" in ax.get_xlabel()      # the strip fills the axes
    w, h = fig.get_size_inches()
    assert w / h > 1.8                                        # a wide, low picture
