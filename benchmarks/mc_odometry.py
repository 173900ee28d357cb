"""Monte Carlo of radar-inertial odometry over independent simulated runs (issue 25).

    nice python benchmarks/mc_odometry.py [--runs 20] [--seed0 0] [--duration 60 120]
                                          [--configs single,cascade,both] [--motions ...]

Each run is drawn at the detection level (:mod:`coloradar.sim.doppler_clouds`): an analytic
rig trajectory (``handheld``: walking gait with pitch, roll and heave, ~1.4 m/s; ``vehicle``:
~2.1 m/s with slow pitch of a few degrees and tens of centimetres of heave) on a random
elliptic loop, a 3DM-GX5-25-class IMU (:mod:`coloradar.sim.imu`) whose bias random walks are
1–10× the datasheet-derived densities and whose turn-on biases are 1–2× the datasheet's, a rest
of 0–2 s at the start (none in a third of the runs), each radar mounted 0.3° (1σ per axis) off
its calibrated rotation, and per radar clouds of
``points`` detections with direction noise and 10–20 % ghosts and movers:

- single chip: 10 Hz, 10–40 points, azimuth 2–4°, elevation 3–6° of noise, elevations centred
  2–8° above boresight, range rates folded at its 2.45 m/s;
- cascade: 5 Hz, 40–120 points, azimuth 0.5–1.5°, elevation 1–2.5°.

Methods per run: the filter with the tightly coupled Doppler-point update (the default; every
radar's points in 3-D), the filter with the RANSAC ego-velocity update (``--update
ego-velocity``, the loosely coupled baseline), the filter with the single chip planar
(``planar``: ``--model planar``, ``DopplerConfig(planar=None)``, the default before issue
42, its point noise measured since), dead reckoning
with the gyro attitude and with the ground-truth attitude (the
reference of what the radar alone carries). Figures: ATE (SE(3)-aligned RMSE) and final
error (first poses put on the truth's) as % of the distance; and, for the filter, the mean
NEES of position, velocity and attitude per degree of freedom over the output poses.

Seeds: reported runs use ``--seed0`` 0 (runs 0..N−1; 3–10 s runs ``--seed0 500 --duration 3
10``); choices were made on the tuning runs (``--tuning``: seeds 1001–1016, 90 s, and for the
filter's bias walks 1001–1048; 3–10 s:
``--seed0 600 --duration 3 10``; never reported). ``--imu-prior 2 5`` runs the filter
with twice the default's turn-on bias std and five times its bias walks (docs/odometry.md).
``--oracle turn-on,bias,mount`` tells every method truths a real run does not have (the IMU's
turn-on biases or whole bias tracks taken out of its samples, the radars' true mountings in
the calibration): bounds that show which error limits the estimates, never the default's
figures. ``--write-dataset DIR`` also writes each run's single-chip stream as a dataset run, for
``coloradar benchmark DIR --radar single_chip`` (docs/odometry.md).
Runs are cached under ``/tmp/coloradar_mc`` (``--cache``).
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import pickle
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from coloradar.calib import Calibration, Extrinsic, preset_calibration
from coloradar.geometry import Trajectory
from coloradar.odometry import (
    RioConfig,
    absolute_trajectory_error,
    estimate_ego_velocities,
    radar_inertial_odometry,
    rio_odometry,
)
from coloradar.odometry.metrics import final_position_error
from coloradar.odometry.pipeline import ego_velocity_config
from coloradar.sim.doppler_clouds import CloudModel, simulate_clouds
from coloradar.sim.imu import GX5_25, simulate_imu
from coloradar.sim.paths import EllipsePath
from coloradar.sim.point_runs import PointRun, write_point_run
from coloradar.sim.rest import RestStart
from coloradar.sim.trajectory import make_trajectory

_DEG = np.pi / 180
RATES = {"single_chip": 10.0, "cascade": 5.0}
EXTRINSIC_STD = 0.3 * _DEG
"""How far each radar's true mounting is from the calibration's, per axis (1σ) [rad]."""


@dataclass
class SimRun:
    """One simulated run: IMU, per radar the frame times and clouds, the truth."""

    seed: int
    motion: str
    duration: float
    imu_t: np.ndarray
    imu: np.ndarray
    frames: dict
    gt: Trajectory
    imu_velocity: np.ndarray      # world velocity of the IMU origin at the gt times
    note: str


def _models(rng: np.random.Generator) -> dict[str, CloudModel]:
    mover = rng.uniform(0.0, 0.08)
    ghost = rng.uniform(0.10, 0.20) - mover
    ghost = max(ghost, 0.05)
    sc = CloudModel(points=(10, 40), range_rate_std=rng.uniform(0.03, 0.08),
                    azimuth_std=rng.uniform(2, 4) * _DEG, elevation_std=rng.uniform(3, 6) * _DEG,
                    elevation_mean=rng.uniform(2, 8) * _DEG, ghost_fraction=ghost,
                    mover_fraction=mover, max_velocity=2.45)
    ca = CloudModel(points=(40, 120), range_rate_std=rng.uniform(0.03, 0.06),
                    azimuth_std=rng.uniform(0.5, 1.5) * _DEG,
                    elevation_std=rng.uniform(1, 2.5) * _DEG,
                    elevation_mean=rng.uniform(0, 6) * _DEG, ghost_fraction=ghost,
                    mover_fraction=mover, azimuth_fov=70 * _DEG)
    return {"single_chip": sc, "cascade": ca}


MOTION_KEYS = {"handheld": 0, "vehicle": 1, "ramps": 2}
"""Each motion's second seed word (runs of one seed differ between motions)."""


def _draw_rig(seed: int, motion: str, duration: float, base_T_imu: np.ndarray
              ) -> tuple[RestStart, np.ndarray, np.ndarray, np.ndarray, np.random.Generator, str]:
    """The run's trajectory, IMU times, samples and bias tracks ``(N, 6)``, the generator that
    draws the rest of it and a note (one order of draws, shared by :func:`make_run` and the
    oracles)."""
    ss = np.random.SeedSequence([seed, MOTION_KEYS[motion]])
    rng = np.random.default_rng(ss)
    a = rng.uniform(8, 15)
    path = EllipsePath(np.array([0.0, 0.0, 1.0]), (a, rng.uniform(4, a)), 1.4,
                       orientation=rng.uniform(0, 2 * np.pi), ramp=0.5)
    inner = make_trajectory(path, motion, rng)
    rest = 0.0 if rng.random() < 1 / 3 else rng.uniform(0.3, 2.0)
    traj = RestStart(inner, rest, 1.0) if rest > 0 else inner
    walk = rng.uniform(1, 10)
    turn = rng.uniform(1, 2)
    model = replace(GX5_25, accel_bias_walk=GX5_25.accel_bias_walk * walk,
                    gyro_bias_walk=GX5_25.gyro_bias_walk * walk,
                    accel_bias=GX5_25.accel_bias * turn, gyro_bias=GX5_25.gyro_bias * turn)
    imu_t = np.arange(0.0, duration, 1 / 300)
    imu, ab, gb = simulate_imu(traj, base_T_imu, imu_t, model, rng)  # type: ignore[arg-type]
    note = f"walk x{walk:.1f} turn-on x{turn:.1f} rest {rest:.1f}s"
    return traj, imu_t, imu, np.hstack([ab, gb]), rng, note


def mount_errors(seed: int) -> dict[str, np.ndarray]:
    """Per radar, the rotation vector [rad] by which it truly sits off its calibrated mounting
    (drawn from a generator of its own, so that everything else stays as it was)."""
    mount = np.random.default_rng([seed, 99])
    return {radar: mount.normal(0, EXTRINSIC_STD, 3) for radar in RATES}


def make_run(seed: int, motion: str, duration: float) -> SimRun:
    """Draw run ``seed`` (every random choice from ``SeedSequence([seed, motion])``)."""
    calib = preset_calibration()
    base_T_imu = calib.transforms["imu"].matrix()
    traj, imu_t, imu, _, rng, rig_note = _draw_rig(seed, motion, duration, base_T_imu)
    models = _models(rng)
    frames = {}
    mounts = mount_errors(seed)
    for radar, rate in RATES.items():
        t = np.arange(rng.uniform(0.0, 1 / rate), duration - 0.05, 1 / rate)
        b_T_r = calib.transforms[radar].matrix()
        b_T_r[:3, :3] = b_T_r[:3, :3] @ Rotation.from_rotvec(mounts[radar]).as_matrix()
        clouds, _ = simulate_clouds(traj, b_T_r, t, models[radar], rng)
        frames[radar] = (t, clouds)
    tg = np.arange(0.0, duration, 0.01)
    st = traj.state(tg)
    gt = Trajectory(tg, st.position, st.rotation, "groundtruth")
    w_world = st.rotation.apply(st.angular_velocity)
    v_imu = st.velocity + np.cross(w_world, st.rotation.apply(
        np.tile(base_T_imu[:3, 3], (tg.size, 1))))
    sc = models["single_chip"]
    note = (f"{rig_note}; single chip az "
            f"{sc.azimuth_std / _DEG:.1f} el {sc.elevation_std / _DEG:.1f} deg, ghosts "
            f"{sc.ghost_fraction:.2f} movers {sc.mover_fraction:.2f}")
    return SimRun(seed, motion, duration, imu_t, imu, frames, gt, v_imu, note)


def cached_run(cache: Path, seed: int, motion: str, duration: float) -> SimRun:
    """:func:`make_run`, kept on disk under ``cache``."""
    key = hashlib.sha1(f"{seed}-{motion}-{duration}-v2".encode()).hexdigest()[:16]
    f = cache / f"{motion}_{seed}_{duration:g}_{key}.pkl"
    if f.exists():
        with f.open("rb") as fh:
            return pickle.load(fh)
    run = make_run(seed, motion, duration)
    cache.mkdir(parents=True, exist_ok=True)
    tmp = f.with_suffix(".tmp")
    with tmp.open("wb") as fh:
        pickle.dump(run, fh)
    tmp.replace(f)
    return run


def _nees(res, run: SimRun) -> np.ndarray:
    """Mean NEES per degree of freedom of position, velocity and attitude over the poses."""
    traj = res.trajectory
    t = traj.timestamps
    p_gt, r_gt = run.gt.interpolate_arrays(t)
    e_p = traj.translations - p_gt
    e_th = (r_gt * traj.rotations.inv()).as_rotvec()
    v_gt = np.column_stack([np.interp(t, run.gt.timestamps, run.imu_velocity[:, i])
                            for i in range(3)])
    e_v = res.velocity - v_gt
    out = []
    for e, c in ((e_p, res.covariance[:, :3, :3]), (e_v, res.velocity_covariance),
                 (e_th, res.covariance[:, 3:, 3:])):
        c = c + np.eye(3) * 1e-12
        q = np.einsum("ni,nij,nj->n", e, np.linalg.inv(c), e)
        # Skip the first second: the anchor pins the start (covariance ~0).
        out.append(float(np.mean(q[t > t[0] + 1.0])) / 3)
    return np.array(out)


def _score(traj: Trajectory, gt: Trajectory) -> tuple[float, float, float]:
    """ATE %, final %, and the final vertical error % of the distance."""
    fin = final_position_error(traj, gt)
    p_gt = gt.interpolate_arrays(traj.timestamps[[0, -1]])[0]
    dz = (traj.translations[-1, 2] - traj.translations[0, 2]) - (p_gt[1, 2] - p_gt[0, 2])
    return (absolute_trajectory_error(traj, gt).rmse_percent, fin.percent,
            100.0 * abs(dz) / fin.path_length)


# "planar": `--model planar` (the default before issue 42, its point noise measured since), the
# Doppler-point update planar for the single chip (its v_z held near 0) and 3-D for the cascade;
# run beside the default (3-D for every radar).


def imu_prior(turn_on: float = 1.0, walk: float = 1.0) -> RioConfig:
    """The default filter with its turn-on bias uncertainties and bias-walk densities scaled
    (``--imu-prior``; 1, 1: the default's, the datasheet's turn-on biases and three times its
    derived walks)."""
    d = RioConfig()
    return replace(d, accel_bias_std=d.accel_bias_std * turn_on,
                   gyro_bias_std=d.gyro_bias_std * turn_on,
                   accel_bias_walk=d.accel_bias_walk * walk,
                   gyro_bias_walk=d.gyro_bias_walk * walk)


ORACLES = ("turn-on", "bias", "gyro-bias", "accel-bias", "mount")
"""What ``--oracle`` can tell every method that it is not told in a real run: the IMU's
turn-on biases (removed from its samples), its whole bias tracks (turn-on and walk; or the
gyro's alone, or the accelerometer's alone), the radars' true mountings (in the calibration)."""


@functools.lru_cache(maxsize=2)
def _bias_tracks(seed: int, motion: str, duration: float) -> np.ndarray:
    """The run's IMU bias tracks ``(N, 6)``, drawn again (once per run: every configuration
    of a run is told the same)."""
    base_T_imu = preset_calibration().transforms["imu"].matrix()
    return _draw_rig(seed, motion, duration, base_T_imu)[3]


def told(run: SimRun, oracle: frozenset[str] = frozenset()) -> tuple[np.ndarray, Calibration]:
    """The IMU samples and the calibration the methods get, with the truths in ``oracle``
    (:data:`ORACLES`) given away: the bounds that show what limits the estimates."""
    imu, calib = run.imu, preset_calibration()
    if oracle & {"turn-on", "bias", "gyro-bias", "accel-bias"}:
        bias = _bias_tracks(run.seed, run.motion, run.duration)
        known = np.zeros_like(bias)
        if "turn-on" in oracle:
            known[:] = bias[:1]
        for name, cols in (("accel-bias", slice(0, 3)), ("gyro-bias", slice(3, 6)),
                           ("bias", slice(0, 6))):
            if name in oracle:
                known[:, cols] = bias[:, cols]
        imu = imu - known
    if "mount" in oracle:
        tf = dict(calib.transforms)
        for radar, rv in mount_errors(run.seed).items():
            rot = Rotation.from_quat(tf[radar].quaternion) * Rotation.from_rotvec(rv)
            tf[radar] = Extrinsic(tf[radar].translation, rot.as_quat())
        calib = replace(calib, transforms=tf)
    return imu, calib


def evaluate(run: SimRun, radars: tuple[str, ...], base: RioConfig | None = None,
             oracle: frozenset[str] = frozenset()) -> dict[str, tuple]:
    """Per method: (ATE %, final %, NEES p/v/θ per dof or NaN, seconds, final vertical %);
    the filters with the settings ``base`` (default :class:`RioConfig`) and either update,
    the filter with the single chip planar; every method told the truths
    in ``oracle`` (:func:`told`)."""
    base = base or RioConfig()
    imu, calib = told(run, oracle)
    tracks, clouds = [], []
    for r in radars:
        t, cl = run.frames[r]
        cfg = ego_velocity_config(calib.radar(r))
        tracks.append(estimate_ego_velocities(cl, t, cfg, frame=r))
        clouds.append(cl)
    out: dict[str, tuple] = {}
    for name, rcfg, pts in (("doppler", replace(base, update="doppler"), clouds),
                            ("ego-velocity", replace(base, update="ego-velocity"), None),
                            ("planar", replace(base, doppler=replace(base.doppler, planar=None)), clouds)):
        t0 = time.perf_counter()
        res = rio_odometry(tracks, calib, run.imu_t, imu, config=rcfg, initial_pose=run.gt,
                           points=pts)
        dt = time.perf_counter() - t0
        a, f, z = _score(res.trajectory, run.gt)
        out[name] = (a, f, _nees(res, run), dt, z)
    t, cl = run.frames[radars[0]]
    track3 = estimate_ego_velocities(cl, t, ego_velocity_config(calib.radar(radars[0]),
                                                                planar=False), frame=radars[0])
    for att, tr in (("imu", tracks[0]), ("groundtruth", tracks[0]), ("gt 3d", track3)):
        dr = radar_inertial_odometry(tr, calib, orientation="imu" if att == "imu" else
                                     "groundtruth", imu_timestamps=run.imu_t,
                                     imu_rates=imu[:, 3:], groundtruth=run.gt,
                                     radar=radars[0])
        a, f, z = _score(dr, run.gt)
        out[f"DR {att}"] = (a, f, np.full(3, np.nan), 0.0, z)
    return out


def write_dataset(run: SimRun, root: Path) -> Path:
    """Write the run's single-chip stream (its clouds, IMU, ground truth; the calibration the
    methods get) as a dataset run ``root/mc_<motion>_<seed>`` that ``coloradar benchmark``
    reads. Only the single chip: the dataset has no cascade point-cloud stream."""
    t0 = 1.6e9                                      # a Unix-like start, as the dataset's
    t, clouds = run.frames["single_chip"]
    gt = Trajectory(run.gt.timestamps + t0, run.gt.translations, run.gt.rotations,
                    "groundtruth")
    pr = PointRun("single_chip", t + t0, list(clouds), run.imu_t + t0, run.imu, gt,
                  preset_calibration(), np.zeros((0, 3), np.float32), None, None)
    return write_point_run(pr, root, f"mc_{run.motion}_{run.seed}")


CONFIGS = {"single": ("single_chip",), "cascade": ("cascade",),
           "both": ("single_chip", "cascade")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--seed0", type=int, default=0)
    ap.add_argument("--duration", type=float, nargs=2, default=(60.0, 120.0))
    ap.add_argument("--configs", default="single,cascade,both")
    ap.add_argument("--motions", default="handheld,vehicle,ramps")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/coloradar_mc"))
    ap.add_argument("--verbose", action="store_true")
    ap.add_argument("--tuning", action="store_true",
                    help="the tuning runs: seeds 1001.. (--runs of them), 90 s, handheld on "
                         "even seeds and vehicle on odd ones (never reported)")
    ap.add_argument("--imu-prior", type=float, nargs=2, default=(1.0, 1.0),
                    metavar=("TURN_ON", "WALK"),
                    help="scale the filter's turn-on bias std and bias-walk densities")
    ap.add_argument("--oracle", default="", metavar="TRUTHS",
                    help="comma-separated truths every method is told (bounds, never the "
                         f"default's figures): {', '.join(ORACLES)}")
    ap.add_argument("--write-dataset", type=Path, metavar="DIR",
                    help="also write each run's single-chip stream as a dataset run under DIR "
                         "(for `coloradar benchmark DIR --radar single_chip`)")
    ap.add_argument("--plot", type=Path, metavar="PNG",
                    help="also draw the final errors per configuration and method (matplotlib)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    motions = args.motions.split(",")
    results: dict[str, list] = {c: [] for c in args.configs.split(",")}
    base = imu_prior(*args.imu_prior)
    oracle = frozenset(o for o in args.oracle.split(",") if o)
    if oracle - set(ORACLES):
        ap.error(f"--oracle: unknown {sorted(oracle - set(ORACLES))}; choose from {ORACLES}")
    for i in range(args.runs):
        seed = args.seed0 + i
        motion = motions[i % len(motions)]
        dur = float(np.random.default_rng([seed, 7]).uniform(*args.duration))
        if args.tuning:
            seed, motion, dur = 1001 + i, ("handheld", "vehicle")[(1001 + i) % 2], 90.0
        run = cached_run(args.cache, seed, motion, round(dur, 1))
        if args.write_dataset:
            write_dataset(run, args.write_dataset)
        rest = "rest 0.0s" not in run.note
        for c in results:
            res = evaluate(run, CONFIGS[c], base, oracle)
            res["_rest"] = rest
            res["_motion"] = motion
            results[c].append(res)
            if args.verbose:
                cells = " ".join(f"{m} {v[0]:.2f}/{v[1]:.2f}" for m, v in res.items()
                                 if not m.startswith("_"))
                print(f"{c:<8} seed {seed:>4} {motion:<8} {dur:5.1f}s {cells} | {run.note}",
                      flush=True)
    for c, rows in results.items():
        _summary(f"{c}: {len(rows)} runs", rows)
        _summary(f"{c}, the runs with a rest", [r for r in rows if r["_rest"]])
        for motion in motions:
            _summary(f"{c}, {motion}", [r for r in rows if r["_motion"] == motion])
    if args.plot:
        _plot(results, args.plot)


def _summary(title: str, rows: list[dict]) -> None:
    """Worst and median ATE, final and vertical error per method over ``rows``."""
    if not rows:
        return
    print(f"\n{title} ({len(rows)}), % of distance (worst / median)")
    for m in (k for k in rows[0] if not k.startswith("_")):
        a = np.array([r[m][0] for r in rows])
        f = np.array([r[m][1] for r in rows])
        z = np.array([r[m][4] for r in rows])
        nees = np.array([r[m][2] for r in rows])
        sec = np.array([r[m][3] for r in rows])
        extra = "" if np.isnan(nees).all() else (
            "  NEES/dof p {:.2f} v {:.2f} att {:.2f}".format(*np.median(nees, axis=0))
            + f"  {sec.sum():.1f} s")
        print(f"  {m:<14} ATE {a.max():5.2f} / {np.median(a):5.2f}   final {f.max():5.2f} / "
              f"{np.median(f):5.2f}   vertical {z.max():5.2f} / {np.median(z):5.2f}{extra}")
    d = np.array([r["doppler"][1] for r in rows])
    lo = np.array([r["ego-velocity"][1] for r in rows])
    dr = np.array([r["DR imu"][1] for r in rows])
    print(f"  doppler final worse than DR imu in {(d > dr).sum()}, than ego-velocity in "
          f"{(d > lo).sum()} of {len(rows)} runs")


def _plot(results: dict[str, list], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(4.5 * len(results), 4), squeeze=False)
    for ax, (c, rows) in zip(axes[0], results.items(), strict=True):
        methods = [m for m in rows[0] if not m.startswith("_")]
        ax.boxplot([[r[m][1] for r in rows] for m in methods], whis=(0, 100))
        ax.set_xticks(range(1, len(methods) + 1), methods, rotation=30, fontsize=8)
        ax.set_title(f"{c} ({len(rows)} runs)")
        ax.set_ylabel("final error [% of distance]")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
