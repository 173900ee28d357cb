"""RPE pairs and ATE/RPE figures of coloradar against evo itself.

    python benchmarks/check_evo_parity.py --evo-python /tmp/evo-venv/bin/python [--cases 6]

evo is not a dependency of coloradar: install it into a separate environment
(``python -m venv /tmp/evo-venv && /tmp/evo-venv/bin/pip install evo``) and name its
interpreter. For random drifting trajectories (ground truth at 10 Hz, the estimate at other
times), the script writes the estimate and the ``groundtruth.txt`` of
:func:`coloradar.odometry.write_evaluation` (the ground truth at the estimate's timestamps), lets
evo associate them by timestamp and pick its pairs (``filters.filter_pairs_by_path``,
consecutive and ``all_pairs``), and compares with ``--rpe-pairing evo`` / ``evo_all_pairs``:
same index pairs, same RPE RMSE [m], same SE(3)-aligned APE RMSE. Exit code 1 on a difference.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from coloradar.geometry import Trajectory
from coloradar.odometry import (
    associate_trajectories,
    evaluate_trajectory,
    relative_pose_error,
    write_evaluation,
    write_tum,
)

DISTANCES = (0.5, 1.0, 2.0, 3.0)

# Run by evo's interpreter: evo's own association, pairs and metrics, as JSON.
EVO_SIDE = r"""
import json, sys
from evo.tools import file_interface
from evo.core import sync, metrics, filters
gt, est, distances = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
def load():
    return sync.associate_trajectories(file_interface.read_tum_trajectory_file(gt),
                                       file_interface.read_tum_trajectory_file(est))
out = {}
for d in distances:
    for all_pairs in (False, True):
        ref, e = load()
        pairs = filters.filter_pairs_by_path(e.poses_se3, d, d * 0.1, all_pairs)
        rpe = metrics.RPE(metrics.PoseRelation.translation_part, d, metrics.Unit.meters, 0.1,
                          all_pairs)
        rpe.process_data((ref, e))
        out[f"{d} {all_pairs}"] = {"pairs": [[int(i), int(j)] for i, j in pairs],
                                   "rmse": rpe.get_statistic(metrics.StatisticsType.rmse)}
ref, e = load()
e.align(ref)
ape = metrics.APE(metrics.PoseRelation.translation_part)
ape.process_data((ref, e))
out["ape"] = ape.get_statistic(metrics.StatisticsType.rmse)
print(json.dumps(out))
"""


def _case(seed: int) -> tuple[Trajectory, Trajectory]:
    rng = np.random.default_rng(seed)
    n = 400
    t = 1_608_580_000.0 + np.arange(n) * 0.1 + rng.uniform(0, 0.01, n)
    steps = rng.uniform(0.02, 0.2, (n, 1)) * rng.normal(size=(n, 3))
    steps[0] = 0.0
    rot = Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0))
    ref = Trajectory(t, np.cumsum(steps, axis=0), rot, "reference")
    te = np.sort(rng.uniform(t[2], t[-3], 250))
    truth = ref.interpolate(te)
    walk = np.cumsum(rng.normal(scale=0.01, size=(te.size, 3)), axis=0)
    att = Rotation.from_rotvec(rng.normal(scale=0.01, size=(te.size, 3)))
    return ref, Trajectory(te, truth.translations + walk, att * truth.rotations, "estimate")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--evo-python", required=True, help="a Python interpreter with evo")
    ap.add_argument("--cases", type=int, default=6, help="random trajectories (default 6)")
    args = ap.parse_args()
    bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.cases):
            ref, est = _case(seed)
            folder = Path(tmp) / f"case{seed}"
            ev = evaluate_trajectory(est, ref)
            write_evaluation(ev, folder, plot=False)
            write_tum(folder / "trajectory.txt", est)
            evo = json.loads(subprocess.run(
                [args.evo_python, "-c", EVO_SIDE, str(folder / "groundtruth.txt"),
                 str(folder / "trajectory.txt"), json.dumps(DISTANCES)],
                check=True, capture_output=True, text=True).stdout)
            ok_ape = abs(evo["ape"] - ev.ate.rmse) <= 1e-9 * max(1.0, ev.ate.rmse)
            bad += not ok_ape
            print(f"case {seed}: APE RMSE evo {evo['ape']:.9f} m, coloradar {ev.ate.rmse:.9f} m")
            assoc, _ = associate_trajectories(est, ref)
            for d in DISTANCES:
                for all_pairs in (False, True):
                    pairing = "evo_all_pairs" if all_pairs else "evo"
                    (res,) = relative_pose_error(est, ref, [d], pairing=pairing)
                    ours = [[int(np.searchsorted(assoc.timestamps, a)),
                             int(np.searchsorted(assoc.timestamps, b))]
                            for a, b in zip(res.start_times, res.end_times, strict=True)]
                    theirs = evo[f"{d} {all_pairs}"]
                    same = ours == theirs["pairs"] and abs(
                        theirs["rmse"] - res.translation_rmse) <= 1e-9
                    bad += not same
                    print(f"  d = {d} m {pairing:<13} pairs evo {len(theirs['pairs']):>3}, "
                          f"coloradar {len(ours):>3}; RMSE evo {theirs['rmse']:.9f}, coloradar "
                          f"{res.translation_rmse:.9f} m  {'same' if same else 'DIFFERENT'}")
    print("all the same" if not bad else f"{bad} differences")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
