"""What holds the single chip's odometry on the foreign runs: heading from the gyro, height from
the radar (issue 42).

    nice python benchmarks/foreign_heading.py [RUN.zip ...] [--calib DIR] [--window 20]

For each run (default: ``../shared/foreign/*.zip``, calibration ``../shared/reference/
coloradar_calib``) three trajectories, each scored against the run's ground truth every 10 s
(heading error [deg], horizontal and vertical position error [m]) and at the end (ATE after
SE(3) alignment and final error, % of distance):

- **default**: ``coloradar odometry RUN --radar single_chip``;
- **gyro bias removed**: the same filter on a view of the run whose gyro has its bias, slow
  variation included, taken out. The bias is read against the ground truth: over each ``--window`` s, the
  gyro integrated from the true attitude is compared with the true attitude at the window's
  end, and the first-order bias that explains the difference is solved for
  (``δ = Σ_k R(t_k→end) b Δt_k``, the body's own rotation within the window included). What the
  filter then still gets wrong is not the bias (nor its walk);
- **dead reckoning with the true attitude** (``--estimator dead-reckoning --orientation
  groundtruth --model 3d``): what the radar's velocities alone carry, heading error 0 by
  construction.

A radar-inertial filter does not observe heading: the radar measures velocity in the body
frame, the accelerometer specific force in the body frame, and neither changes when the world
turns about gravity. Its heading error is the gyro's bias error integrated: the bias read at a
2 s rest (uncertain by the gyro's white noise over 2 s) plus the bias's walk in motion.

Printed beside them, from the run's own samples:

- **the rest**: the gyro's mean z rate over the rest at the start (until 0.1 s before the
  ground truth first moves), its standard error (sample std / √n), how many of those it
  lies from the bias read against the truth over the first span; and what one standard
  error of the bias leaves at the end across the path, ``σ_b · |∫ (t − t_rest) ẑ × v dt|``
  [m] (a heading error growing linearly turns each later stretch of the path);
- **a mounting off by ±``--pitch`` degrees** (default 0.3°, the Monte Carlo's 1σ per axis):
  the default filter on the same run, its calibration's single-chip rotation turned about
  the radar's y axis (pitch), with the yaw-only refinement (default) and with every axis
  refined (``--extrinsic-rotation-axes all``): the final height error against the calibrated
  run's.
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

import coloradar as cr
from coloradar.calib import Extrinsic
from coloradar.geometry import trajectory_from_groundtruth
from coloradar.odometry import RioConfig, read_tum
from coloradar.odometry.metrics import absolute_trajectory_error, final_position_error
from coloradar.odometry.pipeline import OdometryJob, ego_velocity_config, run_odometry

SHARED = Path(__file__).resolve().parents[2] / "shared"


def gyro_bias_against_truth(seq, window: float) -> tuple[np.ndarray, np.ndarray]:
    """The gyro's bias [rad/s, IMU axes] over consecutive ``window``-second spans, read against
    the ground truth (module docstring): span centres [s] ``(M,)`` and biases ``(M, 3)``."""
    imu, gt = seq.imu, seq.groundtruth
    i_R_b = Rotation.from_matrix(seq.calib.transforms["imu"].matrix()[:3, :3])
    t_imu = np.asarray(imu.timestamps, np.float64)
    inside = np.flatnonzero((t_imu >= gt.timestamps[0]) & (t_imu <= gt.timestamps[-1]))
    world_R_imu = Slerp(gt.timestamps, Rotation.from_quat(gt.quaternions))(t_imu[inside]) * i_R_b
    rates = np.asarray(imu.angular_rates, np.float64)[inside]
    dt = np.diff(t_imu[inside], append=t_imu[inside][-1])
    centres, biases = [], []
    for a in np.arange(t_imu[inside[0]], t_imu[inside[-1]] - window, window):
        sel = np.flatnonzero((t_imu[inside] >= a) & (t_imu[inside] < a + window))
        steps = Rotation.from_rotvec(rates[sel] * dt[sel, None])
        cum = [Rotation.identity()]
        for s in steps:                               # body rotation since the span's start
            cum.append(cum[-1] * s)
        end = cum[-1]
        last = min(sel[-1] + 1, len(world_R_imu) - 1)
        delta = (world_R_imu[last].inv() * world_R_imu[sel[0]] * end).as_rotvec()
        a_mat = sum((end.inv() * cum[k + 1]).as_matrix() * dt[sel[k]] for k in range(len(sel)))
        centres.append(a + window / 2)
        biases.append(np.linalg.solve(a_mat, delta))
    return np.asarray(centres), np.asarray(biases)


class _Imu:
    """The run's IMU with other angular rates."""

    def __init__(self, imu, data: np.ndarray) -> None:
        self._imu, self.data = imu, data

    @property
    def angular_rates(self) -> np.ndarray:
        return self.data[:, 3:]

    def __getattr__(self, name: str):
        return getattr(self._imu, name)


class _Run:
    """A view of a run whose IMU or calibration is replaced (nothing is written)."""

    def __init__(self, seq, imu: _Imu | None = None, calib=None) -> None:
        self._seq = seq
        self.imu = imu if imu is not None else seq.imu
        self.calib = calib if calib is not None else seq.calib

    def __getattr__(self, name: str):
        return getattr(self._seq, name)


def without_bias(seq, window: float):
    """A view of ``seq`` whose gyro has its bias, as read against the ground truth, removed."""
    centres, biases = gyro_bias_against_truth(seq, window)
    t = np.asarray(seq.imu.timestamps, np.float64)
    bias = np.column_stack([np.interp(t, centres, biases[:, k]) for k in range(3)])
    data = np.array(seq.imu.data, dtype=np.float64, copy=True)
    data[:, 3:] -= bias
    return _Run(seq, _Imu(seq.imu, data)), biases


def pitched(seq, degrees: float):
    """A view of ``seq`` whose calibration has the single chip turned by ``degrees`` about
    its own y axis (a mounting pitched against the calibration)."""
    tf = dict(seq.calib.transforms)
    e = tf["single_chip"]
    rot = Rotation.from_quat(e.quaternion) * Rotation.from_euler("y", degrees, degrees=True)
    tf["single_chip"] = Extrinsic(e.translation, rot.as_quat())
    return _Run(seq, calib=replace(seq.calib, transforms=tf))


def rest_reading(seq, gt) -> tuple[float, float, float, float]:
    """The rest at the start (until 0.1 s before the ground truth first moves): its length [s],
    the gyro's mean z rate and its standard error [rad/s, IMU axes], and the end-of-run offset
    across the path [m] that one standard error of the bias leaves (module docstring)."""
    t = gt.timestamps
    speed = np.linalg.norm(np.gradient(gt.translations, t, axis=0), axis=1)
    # The rest ends 0.1 s before the truth first moves (0.1 mm/s): the rig turns before its
    # 10 Hz poses show it.
    t_rest = t[int(np.argmax(speed > 1e-4))] - 0.1
    t_imu = np.asarray(seq.imu.timestamps, np.float64)
    z = np.asarray(seq.imu.angular_rates, np.float64)[(t_imu >= t[0]) & (t_imu < t_rest), 2]
    se = float(z.std(ddof=1) / np.sqrt(z.size))
    v = np.gradient(gt.translations, t, axis=0)
    moving = t >= t_rest
    dt = np.gradient(t)[moving]
    # ∫ (t − t_rest) ẑ × v dt: the end offset per rad/s of bias error.
    lever = ((t[moving] - t_rest)[:, None] * np.column_stack(
        [-v[moving, 1], v[moving, 0]]) * dt[:, None]).sum(axis=0)
    return float(t_rest - t[0]), float(z.mean()), se, float(se * np.linalg.norm(lever))


def _final_height(traj, gt) -> float:
    """The estimate's height error at the end [m], its first pose put on the truth's."""
    t = traj.timestamps[(traj.timestamps >= gt.start) & (traj.timestamps <= gt.end)]
    e, g = traj.interpolate(t).matrices(), gt.interpolate(t).matrices()
    end = g[0] @ np.linalg.inv(e[0]) @ e[-1]
    return float(end[2, 3] - g[-1][2, 3])


def mounting_table(seq, gt, pitch: float) -> None:
    """The default's final height error with the single chip's calibration pitched by
    ``±pitch`` degrees, yaw-only and all-axes refinement (module docstring)."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, deg in enumerate((0.0, pitch, -pitch)):
            view = pitched(seq, deg) if deg else seq
            cells = []
            for axes in ("auto", "all"):
                rio = replace(RioConfig(), extrinsic_rotation_axes=axes)
                d = Path(tmp) / f"{k}_{axes}"
                run_odometry(view, d, job=OdometryJob(radar="single_chip", rio_config=rio))
                cells.append(_final_height(read_tum(d / "trajectory.txt"), gt))
            rows.append((deg, *cells))
    print("  final height error [m], the calibration's single chip pitched: "
          "(pitch: yaw refined | every axis refined) " + "; ".join(
              f"{d:+.1f}°: {a:+.3f} | {b:+.3f}" for d, a, b in rows))


def errors(traj, gt, step: float = 10.0) -> list[tuple[float, float, float, float]]:
    """``(t, heading err [deg], horizontal err [m], vertical err [m])`` averaged over each
    ``step`` seconds."""
    t = traj.timestamps[(traj.timestamps >= gt.start) & (traj.timestamps <= gt.end)]
    e, g = traj.interpolate(t), gt.interpolate(t)
    r_e = Rotation.from_matrix(e.matrices()[:, :3, :3])
    r_g = Rotation.from_matrix(g.matrices()[:, :3, :3])
    yaw = np.degrees((r_e * r_g.inv()).as_rotvec()[:, 2])
    d = e.translations - g.translations
    rows = []
    for a in np.arange(0.0, t[-1] - t[0], step):
        s = (t - t[0] >= a) & (t - t[0] < a + step)
        rows.append((a, float(yaw[s].mean()), float(np.linalg.norm(d[s, :2], axis=1).mean()),
                     float(d[s, 2].mean())))
    return rows


def run_one(path: Path, calib: Path, window: float, pitch: float = 0.3) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seq = cr.open_sequence(path, calib=calib)
        gt = trajectory_from_groundtruth(seq)
        unbiased, biases = without_bias(seq, window)
        radar = seq.calib.radar("single_chip")
        out = {}
        with tempfile.TemporaryDirectory() as tmp:
            for name, s, job in (
                    ("default", seq, OdometryJob(radar="single_chip")),
                    ("gyro bias removed", unbiased, OdometryJob(radar="single_chip")),
                    ("DR, true attitude", seq, OdometryJob(
                        radar="single_chip", estimator="dead-reckoning",
                        orientation="groundtruth",
                        config=ego_velocity_config(radar, planar=False)))):
                d = Path(tmp) / name.replace(" ", "_").replace(",", "")
                run_odometry(s, d, job=job)
                out[name] = read_tum(d / "trajectory.txt")
    z = np.degrees(biases[:, 2])
    print(f"\n{path.name}: gyro z bias over {window:g} s spans, read against the ground truth: "
          f"{z.min():+.4f} to {z.max():+.4f} deg/s (first span {z[0]:+.4f})")
    print("  t [s] | " + " | ".join(f"{n:>27s}" for n in out))
    print("        | " + " | ".join(f"{'yaw deg  horiz m  vert m':>27s}" for _ in out))
    table = {n: errors(tr, gt) for n, tr in out.items()}
    for i, row in enumerate(next(iter(table.values()))):
        print(f"  {row[0]:5.0f} | " + " | ".join(
            f"{v[i][1]:+7.3f}  {v[i][2]:7.3f}  {v[i][3]:+6.3f}" for v in table.values()))
    print("  ATE / final % | " + " | ".join(
        f"{absolute_trajectory_error(tr, gt).rmse_percent:.3f} / "
        f"{final_position_error(tr, gt).percent:.3f}" for tr in out.values()))
    rest, mean, se, across = rest_reading(seq, gt)
    print(f"  rest {rest:.1f} s: gyro z {np.degrees(mean):+.4f} ± {np.degrees(se):.4f} deg/s, "
          f"{(mean - biases[0, 2]) / se:+.1f} standard errors from the first span's bias; "
          f"one standard error leaves {across:.2f} m across the path at the end "
          f"({100 * across / final_position_error(out['default'], gt).path_length:.2f} %)")
    if pitch:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mounting_table(seq, gt, pitch)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="*", type=Path)
    ap.add_argument("--calib", type=Path, default=SHARED / "reference" / "coloradar_calib")
    ap.add_argument("--window", type=float, default=20.0, help="bias span [s]")
    ap.add_argument("--pitch", type=float, default=0.3,
                    help="mounting error to try [deg] (0: skip)")
    args = ap.parse_args()
    runs = args.runs or sorted((SHARED / "foreign").glob("*.zip"))
    if not runs:
        raise SystemExit(f"no runs given and none in {SHARED / 'foreign'}")
    for p in runs:
        run_one(p, args.calib, args.window, args.pitch)


if __name__ == "__main__":
    main()
