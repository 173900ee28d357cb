"""The clean-room odometry ladder (issue 42) over several seeds: figures per rung and method.

    nice python benchmarks/ladder_odometry.py [--seeds 5] [--duration 40] [--verbose]

Runs come from ``tests/_ladder.py`` (a generator written from first principles, not
:mod:`coloradar.sim`): per rung (cumulative: white noise, turn-on biases, bias walks,
direction noise, ghosts and a mover, a 15 ms time offset) the run of
``_ladder.ladder_spec(rung, seed)`` (walk on odd rungs, vehicle on even ones; the IMU 0.2 m
from the base origin on rungs 3 and 4). Methods:

- ``default``: ``RioConfig()`` with the single chip's default ego-velocity settings (the
  Doppler-point update 3-D, the per-frame ego-velocities planar);
- ``3d``: ``RioConfig(doppler=DopplerConfig(planar=False), extrinsic_rotation_axes="yaw")``
  with ``ego_velocity_config(..., planar=False)`` (``--model 3d``: the per-frame
  ego-velocities 3-D as well);
- ``planar``: ``--model planar``, the default before issue 42 (``DopplerConfig(planar=None)``:
  the Doppler-point update planar for the single chip, its ``v_z`` held near 0), its point
  noise measured since;
- ``loose``: ``RioConfig(update="ego-velocity")`` with the default ego-velocities;
- ``loose 3d``: the ``3d`` filter with ``update="ego-velocity"`` and the 3-D ego-velocities
  (what the ladder's loosely coupled check compares with once the default is that variant);
- ``DR true 3d``: the 3-D ego-velocities integrated with the true attitude (the reference).

Figures: ATE after SE(3) alignment and final error, % of distance (median and worst over the
seeds), and per filter how many seeds break the ladder's two checks
(``tests/test_odometry_ladder.py``: ATE ≤ 1.5 × DR's + 0.02, ATE ≤ + 0.02 that of the same
filter with the loosely coupled update: ``loose`` for ``default``, ``loose 3d`` for ``3d``).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import _ladder as lad
from coloradar.odometry import (
    DopplerConfig,
    RioConfig,
    absolute_trajectory_error,
    ego_velocity_config,
    estimate_ego_velocities,
    radar_inertial_odometry,
    rio_odometry,
)
from coloradar.odometry.metrics import final_position_error

SLACK, DR_FACTOR = 0.02, 1.5
LOOSE = {"default": "loose", "3d": "loose 3d", "planar": "loose"}


def _score(traj, gt) -> tuple[float, float]:
    return (absolute_trajectory_error(traj, gt).rmse_percent,
            final_position_error(traj, gt).percent)


def evaluate(run: lad.LadderRun) -> dict[str, tuple[float, float]]:
    """Per method (ATE %, final %)."""
    radar = run.calib.radar(lad.RADAR)
    track = estimate_ego_velocities(run.clouds, run.frame_t, ego_velocity_config(radar),
                                    frame=lad.RADAR)
    track_3d = estimate_ego_velocities(run.clouds, run.frame_t,
                                       ego_velocity_config(radar, planar=False), frame=lad.RADAR)
    variant = RioConfig(doppler=DopplerConfig(planar=False), extrinsic_rotation_axes="yaw")
    out = {}
    for name, cfg, tr, pts in (("default", RioConfig(), track, [run.clouds]),
                               ("3d", variant, track_3d, [run.clouds]),
                               ("planar", RioConfig(doppler=DopplerConfig(planar=None)), track,
                                [run.clouds]),
                               ("loose", RioConfig(update="ego-velocity"), track, None),
                               ("loose 3d", dataclasses.replace(variant, update="ego-velocity"),
                                track_3d, None)):
        res = rio_odometry([tr], run.calib, run.imu_t, run.imu, config=cfg,
                           initial_pose=run.gt, points=pts)
        out[name] = _score(res.trajectory, run.gt)
    dr = radar_inertial_odometry(track_3d, run.calib, orientation="groundtruth",
                                 groundtruth=run.gt, radar=lad.RADAR)
    out["DR true 3d"] = _score(dr, run.gt)
    return out


def _breaks(res: dict[str, tuple[float, float]], name: str) -> tuple[bool, bool]:
    """Whether filter ``name`` breaks the DR check and the loosely coupled check."""
    ate = res[name][0]
    return (ate > DR_FACTOR * res["DR true 3d"][0] + SLACK, ate > res[LOOSE[name]][0] + SLACK)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--rungs", default="1,2,3,4,5,6")
    ap.add_argument("--verbose", action="store_true")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    print(f"{args.seeds} seeds, {args.duration:g} s runs; ATE % / final % of distance, "
          "median (worst); breaks: seeds failing the DR check / the loose check")
    for rung in (int(r) for r in args.rungs.split(",")):
        rows = []
        for seed in range(args.seeds):
            run = lad.make_run(lad.ladder_spec(rung, seed, args.duration))
            res = evaluate(run)
            rows.append(res)
            if args.verbose:
                cells = " ".join(f"{m} {v[0]:.3f}/{v[1]:.3f}" for m, v in res.items())
                print(f"  rung {rung} seed {seed} {run.spec.motion:<7} {run.distance:5.1f} m "
                      f"{cells}", flush=True)
        spec = lad.ladder_spec(rung)
        where = "IMU at origin" if spec.imu_at_origin else "IMU 0.2 m off"
        print(f"\nrung {rung} ({lad.RUNG_NAMES[rung]}; {spec.motion}, {where})")
        for m in rows[0]:
            a = np.array([r[m][0] for r in rows])
            f = np.array([r[m][1] for r in rows])
            extra = ""
            if m in LOOSE:
                b = np.array([_breaks(r, m) for r in rows])
                extra = f"   breaks {b[:, 0].sum()}/{len(rows)} DR, {b[:, 1].sum()}/{len(rows)} loose"
            print(f"  {m:<11} ATE {np.median(a):.3f} ({a.max():.3f})   final {np.median(f):.3f} "
                  f"({f.max():.3f}){extra}", flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
