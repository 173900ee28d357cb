"""Evaluation of an odometry output folder against its run's ground truth.

:func:`evaluate_odometry` reads ``trajectory.txt`` (and ``ego_velocity.csv`` when present) of a
folder written by :func:`~coloradar.odometry.run_odometry` (or any TUM trajectory of the rig's
base frame), opens the run named in ``odometry.json`` (or the one given), and computes the
ego-velocity error (against the ground-truth velocity of the radar origin in the radar frame,
:func:`~coloradar.geometry.rig_velocity`), the ATE after alignment, the position error at the
end, the RPE over fixed distances and the KITTI-style drift (:mod:`.metrics`), and the RIO
literature's figures: the ATE after position + yaw alignment and the relative error over 25,
50, 75 and 100 m as rpg_trajectory_evaluation computes them.
:func:`write_evaluation` writes ``evaluation.json``, ``evaluation.txt`` (the printed table),
``groundtruth.txt`` (the ground truth interpolated at the estimate's timestamps, TUM, so that
``evo`` associates every pose) and, with matplotlib installed, ``evaluation.png``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..errors import FormatError, MissingDataError, OutputExistsError
from ..formats.atomic import atomic_write_text, make_output_dir
from ..formats.source import read_file_text
from ..geometry import Trajectory, trajectory_from_groundtruth
from .metrics import (
    DRIFT_LENGTHS,
    RPG_LENGTHS,
    Align,
    ATEResult,
    Evaluation,
    RPEPairing,
    RPEResult,
    absolute_trajectory_error,
    final_position_error,
    relative_pose_error,
    rpg_relative_error,
    trajectory_drift,
    velocity_errors,
)
from .pipeline import INFO_FILE, TRAJECTORY_FILE, VELOCITY_FILE
from .tum import read_tum, write_tum
from .velocity_track import EgoVelocityTrack, read_velocity_table

__all__ = [
    "EVALUATION_FILES",
    "Evaluation",
    "evaluate_odometry",
    "evaluate_trajectory",
    "evaluation_dict",
    "format_evaluation",
    "write_evaluation",
]

EVALUATION_FILES = ("evaluation.json", "evaluation.txt", "groundtruth.txt", "evaluation.png")


def evaluate_trajectory(estimate: Trajectory, reference: Trajectory, *,
                        track: EgoVelocityTrack | None = None, calib=None,
                        align: Align = "se3", distances: tuple[float, ...] = (1.0, 2.0, 5.0),
                        max_gap: float | None = 1.0, info: dict | None = None,
                        rpe_pairing: RPEPairing = "every_pose",
                        drift_lengths: tuple[float, ...] = DRIFT_LENGTHS) -> Evaluation:
    """ATE, final error, RPE, drift, the RIO literature's figures and (with ``track`` and
    ``calib``) ego-velocity errors.

    The RIO literature's figures are the ATE after ``posyaw`` alignment and the relative error
    over :data:`~coloradar.odometry.metrics.RPG_LENGTHS` as rpg_trajectory_evaluation computes
    it (:func:`~coloradar.odometry.metrics.rpg_relative_error`).

    Parameters
    ----------
    estimate, reference
        ``world_T_base(t)`` estimated and true.
    track
        Ego-velocities (radar frame) to compare with the ground-truth radar velocity.
    calib
        The rig calibration (the radar's extrinsic), needed with ``track``.
    align, distances, max_gap
        See :func:`~coloradar.odometry.absolute_trajectory_error` and
        :func:`~coloradar.odometry.relative_pose_error`.
    rpe_pairing
        The RPE's pose pairs (``pairing`` of :func:`~coloradar.odometry.relative_pose_error`;
        ``"evo"`` gives the pairs of ``evo_rpe -d D -u m``).
    drift_lengths
        Segment lengths [m] of the KITTI-style drift
        (:func:`~coloradar.odometry.metrics.trajectory_drift`).
    info
        Extra fields for :attr:`Evaluation.info`.
    """
    ate = absolute_trajectory_error(estimate, reference, align=align, max_gap=max_gap)
    final = final_position_error(estimate, reference, max_gap=max_gap)
    rpe = relative_pose_error(estimate, reference, distances, max_gap=max_gap,
                              pairing=rpe_pairing)
    drift = trajectory_drift(estimate, reference, drift_lengths, max_gap=max_gap)
    posyaw = ate if align == "posyaw" else absolute_trajectory_error(
        estimate, reference, align="posyaw", max_gap=max_gap)
    rpg = rpg_relative_error(estimate, reference, RPG_LENGTHS, max_gap=max_gap)
    vel = None
    if track is not None and calib is not None:
        vel = velocity_errors(track, reference, calib)
    meta = {"align": align, "distances": [float(d) for d in distances],
            "rpe_pairing": rpe_pairing, "drift_lengths": [float(d) for d in drift_lengths],
            "rpg_lengths": list(RPG_LENGTHS), **(info or {})}
    return Evaluation(estimate, reference, ate, rpe, vel, track, meta, drift, final, posyaw, rpg)


def _calib_for(info: dict, calib):
    if calib is not None:
        return calib
    stored = str(info.get("calib") or "")
    if stored and stored != "preset":
        path = Path(stored.split(".zip:")[0] + ".zip") if ".zip:" in stored else Path(stored)
        if path.exists():
            return path
    return None


def evaluate_odometry(folder: str | os.PathLike[str], run: str | os.PathLike[str] | None = None,
                      *, calib=None, align: Align = "se3",
                      distances: tuple[float, ...] = (1.0, 2.0, 5.0),
                      max_gap: float | None = 1.0,
                      rpe_pairing: RPEPairing = "every_pose",
                      drift_lengths: tuple[float, ...] = DRIFT_LENGTHS) -> Evaluation:
    """Evaluate an odometry output folder against its run's ground truth.

    Parameters
    ----------
    folder
        Holds ``trajectory.txt`` (TUM), optionally ``ego_velocity.csv`` and ``odometry.json``.
    run
        The run (folder or zip); default: the one recorded in ``odometry.json``.
    calib
        Calibration (object or path); default: the one the odometry used, else the one found
        beside the run.
    align, distances, max_gap, rpe_pairing, drift_lengths
        See :func:`evaluate_trajectory`.

    Returns
    -------
    Evaluation
    """
    from ..dataset import open_sequence

    folder = Path(folder)
    info: dict = {}
    info_path = folder / INFO_FILE
    if info_path.exists():
        try:
            info = json.loads(read_file_text(info_path))
        except json.JSONDecodeError as exc:
            raise FormatError(f"{info_path}: expected the JSON object 'coloradar odometry' "
                              f"writes ({exc})") from None
        if not isinstance(info, dict):
            raise FormatError(f"{info_path}: expected a JSON object, found "
                              f"{type(info).__name__}")
    run = run if run is not None else info.get("run")
    if not run:
        raise MissingDataError(f"{folder}: no {INFO_FILE} naming the run; give the run "
                               "(--run RUN)")
    if not (folder / TRAJECTORY_FILE).is_file():
        raise MissingDataError(f"{folder}: no {TRAJECTORY_FILE} (a TUM trajectory); run "
                               "'coloradar odometry RUN --out DIR' first")
    seq = open_sequence(run, calib=_calib_for(info, calib))
    if "groundtruth" not in seq.available():
        raise MissingDataError(f"{seq.location}: the run has no ground truth to evaluate against")
    reference = trajectory_from_groundtruth(seq)
    estimate = read_tum(folder / TRAJECTORY_FILE)
    track = read_velocity_table(folder / VELOCITY_FILE) if (folder / VELOCITY_FILE).is_file() \
        else None
    meta = {k: info[k] for k in ("radar", "source", "estimator", "orientation", "fuse")
            if k in info}
    meta.update(run=str(run), run_name=seq.name, folder=str(folder))
    return evaluate_trajectory(estimate, reference, track=track, calib=seq.calib, align=align,
                               distances=distances, max_gap=max_gap, info=meta,
                               rpe_pairing=rpe_pairing, drift_lengths=drift_lengths)


def _f(x: float) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


def _ate_dict(a: ATEResult, align: str) -> dict:
    return {"align": align, "poses": int(a.errors.size),
            "rmse_m": _f(a.rmse), "mean_m": _f(a.mean), "median_m": _f(a.median),
            "std_m": _f(a.std), "max_m": _f(a.max), "rotation_rmse_deg": _f(a.rotation_rmse),
            "path_length_m": _f(a.path_length), "rmse_percent_of_path": _f(a.rmse_percent),
            "scale": _f(a.alignment.scale)}


def _rpg_dict(r: RPEResult) -> dict:
    """One length of the rpg relative error: pairs and rpg's statistics (null without pairs)."""
    st = r.statistics()
    return {"distance_m": r.distance, "pairs": r.pairs,
            **{f"{k}_{s}": _f(v) for k, stats in st.items() for s, v in stats.items()}}


def evaluation_dict(ev: Evaluation) -> dict:
    """The evaluation's figures as a JSON-compatible dict (NaN written as null).

    ``ate_posyaw`` (the ATE after position + yaw alignment, keys as ``ate``) and
    ``rpg_relative`` (one entry per length: ``distance_m``, ``pairs``, and
    ``translation_percent_*`` [%], ``yaw_deg_*`` [deg] for ``rmse``, ``mean``, ``median``,
    ``std``, ``min``, ``max``: rpg_trajectory_evaluation's ``rel_trans_perc`` and ``rel_yaw``
    statistics) are the RIO literature's figures.
    """
    out: dict = {"info": ev.info, "ate": _ate_dict(ev.ate, ev.info.get("align", "se3"))}
    out["rpe"] = [{"distance_m": r.distance, "pairs": r.pairs,
                   "translation_percent": _f(r.translation_percent),
                   "rotation_deg_per_m": _f(r.rotation_deg_per_m),
                   "translation_rmse_m": _f(r.translation_rmse),
                   "rotation_rmse_deg": _f(r.rotation_rmse)} for r in ev.rpe]
    if ev.final is not None:
        out["final_error"] = {"error_m": _f(ev.final.error), "percent_of_path": _f(ev.final.percent),
                              "path_length_m": _f(ev.final.path_length)}
    if ev.drift is not None:
        out["drift"] = {"lengths_m": list(ev.drift.lengths), "segments": ev.drift.pairs,
                        "translation_percent": _f(ev.drift.translation_percent),
                        "rotation_deg_per_m": _f(ev.drift.rotation_deg_per_m)}
    if ev.ate_posyaw is not None:
        out["ate_posyaw"] = _ate_dict(ev.ate_posyaw, "posyaw")
    if ev.rpg_relative is not None:
        out["rpg_relative"] = [_rpg_dict(r) for r in ev.rpg_relative]
    if ev.velocity is not None:
        v = ev.velocity
        out["ego_velocity"] = {
            "frames": v.frames_total, "failed": v.frames_failed, "compared": int(v.timestamps.size),
            "rmse_m_s": _f(v.rmse), "rmse_axes_m_s": [_f(x) for x in v.rmse_axes],
            "mean_speed_m_s": _f(v.mean_speed)}
    return out


def _method(info: dict) -> str:
    """What made the estimate: the EKF has no separate attitude source (it integrates the IMU
    itself), dead reckoning names its attitude; files written before the EKF existed (no
    ``estimator``) were dead reckoning."""
    est, att = info.get("estimator"), info.get("orientation")
    if est is not None and est != "dead-reckoning":
        fused = [str(r) for r in info.get("fuse") or []]
        return f"estimator {est}" + (f" (fused {', '.join(fused)})" if fused else "")
    parts = [f"estimator {est}" if est else "", f"attitude {att}" if att else ""]
    return " · ".join(x for x in parts if x)


def format_evaluation(ev: Evaluation) -> str:
    """A plain-text table of the evaluation (what ``coloradar evaluate`` prints)."""
    i = ev.info
    head = " · ".join(x for x in (
        f"run {i['run_name']}" if "run_name" in i else "",
        f"{i['radar']} radar" if "radar" in i else "",
        f"source {i['source']}" if "source" in i else "",
        _method(i)) if x)
    lines = [head] if head else []
    rows: list[tuple[str, str]] = []
    if ev.velocity is not None:
        v = ev.velocity
        ax = ", ".join(f"{c} {x:.3f}" for c, x in zip("xyz", v.rmse_axes, strict=True))
        rows.append(("ego-velocity RMSE", f"{v.rmse:.3f} m/s  ({ax})  over "
                     f"{v.timestamps.size} frames; {v.frames_failed} of {v.frames_total} "
                     f"failed; mean speed {v.mean_speed:.2f} m/s"))
    a = ev.ate
    al = i.get("align", "se3")
    scale = f", scale {a.alignment.scale:.4f}" if al == "sim3" else ""
    rows.append((f"ATE RMSE ({al}{scale})",
                 f"{a.rmse:.3f} m = {a.rmse_percent:.2f} % of {a.path_length:.1f} m  "
                 f"(mean {a.mean:.3f}, median {a.median:.3f}, max {a.max:.3f} m; "
                 f"{a.errors.size} poses)"))
    rows.append(("ATE rotation RMSE", f"{a.rotation_rmse:.2f} deg"))
    if ev.ate_posyaw is not None and al != "posyaw":
        p = ev.ate_posyaw
        rows.append(("ATE RMSE (posyaw)",
                     f"{p.rmse:.3f} m = {p.rmse_percent:.2f} % of {p.path_length:.1f} m  "
                     f"(mean {p.mean:.3f}, median {p.median:.3f}, max {p.max:.3f} m)"))
    if ev.final is not None:
        rows.append(("final position error", f"{ev.final.error:.3f} m = {ev.final.percent:.2f} % "
                     "of the distance (first poses coincide)"))
    if ev.drift is not None:
        d = ev.drift
        lengths = ", ".join(f"{x:g}" for x in d.lengths)
        rows.append(("drift (KITTI-style)", f"{d.translation_percent:.2f} %, "
                     f"{d.rotation_deg_per_m:.3f} deg/m over {d.pairs} segments of {lengths} m"))
    w = max(len(r[0]) for r in rows)
    lines += [f"{k:<{w}}  {val}" for k, val in rows]
    lines.append("")
    lines.append(f"{'RPE over':>10} {'pairs':>7} {'trans [%]':>10} {'rot [deg/m]':>12} "
                 f"{'trans RMSE [m]':>15} {'rot RMSE [deg]':>15}")
    for r in ev.rpe:
        lines.append(f"{r.distance:>8.1f} m {r.pairs:>7d} {r.translation_percent:>10.2f} "
                     f"{r.rotation_deg_per_m:>12.3f} {r.translation_rmse:>15.3f} "
                     f"{r.rotation_rmse:>15.2f}")
    if ev.rpg_relative:
        lines += ["", *_format_rpg(ev.rpg_relative, ev.ate.path_length)]
    return "\n".join(lines) + "\n"


def _format_rpg(results: list[RPEResult], path: float) -> list[str]:
    """The relative-error table of rpg_trajectory_evaluation: mean, median, RMSE of the
    translation error [% of d] and of the yaw error [deg] per length; n/a without pairs (one
    line when no length has any)."""
    if not any(r.pairs for r in results):
        lengths = ", ".join(f"{r.distance:g}" for r in results)
        return [f"RE (rpg) over {lengths} m: n/a (no pose pairs on {path:.1f} m of path)"]
    out = [f"{'RE (rpg) over':>13} {'pairs':>7} {'trans mean [%]':>15} {'median':>7} "
           f"{'RMSE':>7} {'yaw mean [deg]':>15} {'median':>7} {'RMSE':>7}"]
    for r in results:
        st = r.statistics()
        cells = [st[k][s] for k in ("translation_percent", "yaw_deg")
                 for s in ("mean", "median", "rmse")]
        c = ["n/a" if not np.isfinite(x) else f"{x:.2f}" for x in cells]
        out.append(f"{r.distance:>11g} m {r.pairs:>7d} {c[0]:>15} {c[1]:>7} {c[2]:>7} "
                   f"{c[3]:>15} {c[4]:>7} {c[5]:>7}")
    return out


def write_evaluation(ev: Evaluation, folder: str | os.PathLike[str], *, plot: bool = True,
                     overwrite: bool = False) -> list[Path]:
    """Write ``evaluation.json``, ``evaluation.txt``, ``groundtruth.txt`` and (with ``plot`` and
    matplotlib installed) ``evaluation.png`` into ``folder``; returns the paths written.

    Raises :class:`~coloradar.OutputExistsError` when any exists and not ``overwrite``.
    """
    folder = Path(folder)
    names = list(EVALUATION_FILES if plot else EVALUATION_FILES[:3])
    existing = [n for n in names if (folder / n).exists()]
    if existing and not overwrite:
        raise OutputExistsError(f"{folder}: holds {', '.join(existing)} already; pass "
                                "overwrite=True (--overwrite) to replace them")
    make_output_dir(folder)
    written = []
    atomic_write_text(folder / names[0], json.dumps(evaluation_dict(ev), indent=2) + "\n")
    atomic_write_text(folder / names[1], format_evaluation(ev))
    written += [folder / names[0], folder / names[1]]
    # The ground truth at the estimate's own timestamps (the poses the ATE used): evo
    # associates poses by timestamp, and the raw 10 Hz ground truth shares none with a radar
    # frame's time.
    gt = ev.ate.reference
    run_name = ev.info.get("run_name", "the run")
    written.append(write_tum(folder / names[2], gt, overwrite=True, comments=[
        f"ground truth world_T_base of {run_name}, interpolated (linear, SLERP) at the "
        "estimate's timestamps"]))
    if plot:
        try:
            from .plot import plot_evaluation
        except ImportError:
            return written
        written.append(plot_evaluation(ev, folder / names[3], overwrite=True))
    return written
