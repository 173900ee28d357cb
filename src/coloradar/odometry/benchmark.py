"""``coloradar benchmark``: estimators run on many runs, evaluated, one table.

Every method is evaluated the same way (:func:`~coloradar.odometry.evaluate_trajectory`, the
ground truth interpolated at the estimate's timestamps) so that methods compare on equal terms:

- ``coloradar`` (or ``coloradar-<estimator>``): :func:`~coloradar.odometry.run_odometry` on the
  run, timed;
- a folder of TUM files, one per run (``<DIR>/<run>.txt`` or ``<DIR>/<run>/trajectory.txt``, with
  ``<DIR>/<run>/ego_velocity.csv`` when present): someone else's method, run elsewhere;
- a Python callable ``module:function`` (or ``path/to/file.py:function``) taking a
  :class:`coloradar.Sequence` and returning a :class:`~coloradar.geometry.Trajectory`
  (``world_T_base``), or a ``(trajectory, EgoVelocityTrack)`` pair, or an object with
  ``trajectory`` (and ``track``) attributes: timed like ours;
- a function ``fn(run_path, out_dir, settings) -> TUM path`` (:func:`function_method`,
  :func:`function_methods`): a higher layer's estimator (SLAM) added as a method without this
  module knowing it; ``settings`` are the benchmark's odometry options.

Beside the project's figures, every row carries the RIO literature's (rpg_trajectory_evaluation,
as x_rio, DeRO and 4DRadarSLAM report them): the ATE after position + yaw alignment
(``ate_posyaw_*``) and the mean relative translation error [% of d] and yaw error [deg] over
25, 50, 75 and 100 m (``re<d>_percent``, ``re<d>_yaw_deg``; empty where the run is shorter;
the summary row pools every segment of every run, as rpg's ``overall_odometry_errors`` does).

The filter's rows carry its **consistency**: the mean NEES per degree of freedom of the base
position and attitude against the ground truth (``nees_position``, ``nees_attitude``; 1 for a
consistent filter), from the per-pose covariance of ``odometry.json``.

Each (method, run) pair is a task of a :mod:`coloradar.batch` executor (local process pool or
Dask cluster). Its outputs go to ``OUT/<method>/<run>/`` (the estimate, ``evaluation.json``,
``evaluation.txt``, ``groundtruth.txt``) and its row to ``OUT/<method>/<run>/row.json``, written
last: a rerun with the same settings keeps the rows it finds and runs the rest. The table goes
to ``OUT/benchmark.txt``, ``OUT/benchmark.csv`` and ``OUT/benchmark.json``. A run that fails is
a row with its error, never the end of the benchmark.
"""

from __future__ import annotations

import csv
import dataclasses
import importlib
import importlib.util
import inspect
import io
import json
import math
import os
import re
import shutil
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..errors import (
    ColoradarError,
    FormatError,
    MissingDataError,
    OutputExistsError,
    SettingsError,
)
from ..formats.atomic import atomic_write_text, make_output_dir
from ..formats.source import read_file_text
from ..geometry import Trajectory, trajectory_from_groundtruth
from .evaluation import evaluate_trajectory, evaluation_dict, write_evaluation
from .metrics import ALIGNMENTS, DRIFT_LENGTHS, RPE_PAIRINGS, RPG_LENGTHS
from .pipeline import TRAJECTORY_FILE, VELOCITY_FILE, OdometryJob, run_odometry
from .tum import read_tum, write_tum
from .velocity_track import EgoVelocityTrack, read_velocity_table, write_velocity_table

__all__ = [
    "BENCHMARK_FILES",
    "BenchmarkJob",
    "BenchmarkResult",
    "Method",
    "benchmark",
    "builtin_method",
    "callable_method",
    "format_table",
    "function_method",
    "function_methods",
    "table_csv",
    "tum_method",
]

BENCHMARK_FILES = ("benchmark.txt", "benchmark.csv", "benchmark.json")
SETTINGS_FILE = "benchmark_settings.json"
ROW_FILE = "row.json"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")

#: Columns of the CSV file, in order (``run`` is ``overall`` on a method's summary row); the
#: RIO literature's figures (posyaw ATE, rpg relative errors) come last.
CSV_COLUMNS = ("run", "method", "status", "ate_rmse_m", "ate_rmse_percent", "final_error_m",
               "final_error_percent", "drift_percent", "rotation_drift_deg_per_m",
               "ego_velocity_rmse_m_s", "frames_per_s", "real_time_factor", "poses",
               "path_length_m", "estimator_s", "nees_position", "nees_attitude", "error",
               "ate_posyaw_m", "ate_posyaw_percent",
               "re25_percent", "re25_yaw_deg", "re50_percent", "re50_yaw_deg",
               "re75_percent", "re75_yaw_deg", "re100_percent", "re100_yaw_deg")
_RE_COLUMNS = {d: (f"re{d:g}_percent", f"re{d:g}_yaw_deg") for d in RPG_LENGTHS}


@dataclass(frozen=True)
class Method:
    """One method of a benchmark.

    Attributes
    ----------
    name
        Its name in the table and its output folder (letters, digits, ``. _ + -``).
    kind
        ``"coloradar"`` (our :func:`~coloradar.odometry.run_odometry`), ``"tum"`` (a folder of
        TUM files) or ``"callable"`` (``module:function``).
    spec
        The estimator name (``"coloradar"``; None: its default), the folder (``"tum"``) or the
        ``module:function`` text (``"callable"``).
    """

    name: str
    kind: str
    spec: str | None = None

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise SettingsError(f"method name {self.name!r}: use letters, digits and . _ + - "
                                "(it names an output folder)")
        if self.kind not in ("coloradar", "tum", "callable", "function"):
            raise SettingsError(f"method kind must be coloradar, tum, callable or function, "
                                f"got {self.kind!r}")


def builtin_method(estimator: str | None = None, name: str | None = None) -> Method:
    """Our odometry; ``estimator`` is passed to :func:`run_odometry` only when given."""
    return Method(name or ("coloradar" if estimator is None else f"coloradar-{estimator}"),
                  "coloradar", estimator)


def tum_method(folder: str | os.PathLike[str], name: str | None = None) -> Method:
    """A folder of TUM trajectories, ``<run>.txt`` or ``<run>/trajectory.txt`` per run."""
    path = Path(folder)
    if not path.is_dir():
        raise MissingDataError(f"{path}: folder of estimates not found (expected <run>.txt or "
                               "<run>/trajectory.txt per run, TUM format)")
    return Method(name or path.resolve().name, "tum", str(path.resolve()))


def _load_callable(spec: str) -> Callable[..., Any]:
    """``module:function`` or ``path/to/file.py:function`` → the function."""
    mod, sep, attr = spec.rpartition(":")
    if not sep or not mod or not attr:
        raise SettingsError(f"expected module:function or file.py:function, got {spec!r}")
    try:
        if mod.endswith(".py") or os.sep in mod or "/" in mod:
            path = Path(mod).resolve()
            if not path.is_file():
                raise MissingDataError(f"{path}: Python file of method {spec!r} not found")
            key = f"_coloradar_method_{abs(hash(str(path)))}"
            module = sys.modules.get(key)
            if module is None:
                loader = importlib.util.spec_from_file_location(key, path)
                if loader is None or loader.loader is None:
                    raise SettingsError(f"{path}: not a Python module")
                module = importlib.util.module_from_spec(loader)
                sys.modules[key] = module
                loader.loader.exec_module(module)
        else:
            if os.getcwd() not in sys.path:
                # As `python -m` would: a module beside the user is found.
                sys.path.append(os.getcwd())
            module = importlib.import_module(mod)
    except ImportError as exc:
        raise SettingsError(f"method {spec!r}: cannot import {mod} ({exc})") from None
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise SettingsError(f"method {spec!r}: {mod} has no function {attr!r}")
    return fn


def callable_method(spec: str, name: str | None = None) -> Method:
    """A Python function ``module:function`` (checked now: it must import)."""
    _load_callable(spec)
    return Method(name or spec.rpartition(":")[2], "callable", spec)


def function_method(fn: Callable[[str, Path, dict], str | os.PathLike[str]],
                    name: str | None = None) -> Method:
    """A method computed by ``fn(run_path, out_dir, settings)``, which writes its estimate
    (TUM, ``world_T_base``) and returns the file's path; ``settings`` is the benchmark's
    odometry options (a dict). ``fn`` must be a module-level function (workers import it)."""
    mod, qual = getattr(fn, "__module__", None), getattr(fn, "__qualname__", "")
    if not mod or not qual or "<" in qual:
        raise SettingsError(f"method {name or fn!r}: a module-level function is needed (worker "
                            "processes import it by name)")
    return Method(name or qual, "function", f"{mod}:{qual}")


def function_methods(functions: dict[str, Callable[[str, Path, dict],
                                                   str | os.PathLike[str]]]) -> list[Method]:
    """:func:`function_method` for each ``name → function`` of a mapping."""
    return [function_method(fn, name) for name, fn in functions.items()]


def _nees(est: Trajectory, reference: Trajectory, folder: Path) -> tuple[float | None, ...]:
    """Mean NEES per dof of the base position and attitude over the estimate's poses, from the
    per-pose covariance of the filter's ``odometry.json`` (None when it has none)."""
    info_path = folder / "odometry.json"
    if not info_path.is_file():
        return None, None
    poses = json.loads(read_file_text(info_path)).get("rio", {}).get("poses", {})
    upper = poses.get("covariance_upper")
    if not upper or len(upper) != len(est):
        return None, None
    cov = np.zeros((len(est), 6, 6))
    iu = np.triu_indices(6)
    cov[:, iu[0], iu[1]] = np.asarray(upper, dtype=np.float64)
    cov = cov + np.triu(cov, 1).transpose(0, 2, 1)
    inside = reference.covers(est.timestamps)
    # The first second is left out: the output is anchored there (covariance ~0).
    inside &= est.timestamps > est.timestamps[0] + 1.0
    if inside.sum() < 2:
        return None, None
    p_ref, r_ref = reference.interpolate_arrays(est.timestamps[inside])
    e_p = est.translations[inside] - p_ref
    e_r = (r_ref * est.rotations[np.flatnonzero(inside)].inv()).as_rotvec()
    out = []
    for e, c in ((e_p, cov[inside, :3, :3]), (e_r, cov[inside, 3:, 3:])):
        c = c + np.eye(3) * 1e-12
        out.append(float(np.mean(np.einsum("ni,nij,nj->n", e, np.linalg.inv(c), e))) / 3)
    return out[0], out[1]


def _run_function(task: _Task, folder: Path) -> tuple[Trajectory, EgoVelocityTrack | None]:
    """A :func:`function_method`'s estimate for the task's run."""
    m = task.method
    fn = _load_callable(m.spec or "")
    path = Path(fn(task.path, folder, dict(task.odometry)))
    if not path.is_file():
        raise MissingDataError(f"method {m.name}: {path}: no estimate written (expected a TUM "
                               "file)")
    est = read_tum(path)
    if path.resolve() != (folder / TRAJECTORY_FILE).resolve():
        write_tum(folder / TRAJECTORY_FILE, est, overwrite=True,
                  comments=[f"run {task.run}, method {m.name} ({m.spec})"])
    vel = folder / VELOCITY_FILE
    return est, read_velocity_table(vel) if vel.is_file() else None


@dataclass(frozen=True)
class _Task:
    method: Method
    run: str
    path: str | None          # None: the run is not in the dataset
    out: str
    calib: str | None
    odometry: dict
    evaluation: dict


def _estimate_from_tum(method: Method, run: str) -> tuple[Trajectory, EgoVelocityTrack | None]:
    root = Path(method.spec or "")
    flat, nested = root / f"{run}.txt", root / run / TRAJECTORY_FILE
    path = flat if flat.is_file() else nested
    if not path.is_file():
        raise MissingDataError(f"{root}: no estimate for run {run} (expected {flat.name} or "
                               f"{run}/{TRAJECTORY_FILE})")
    vel = root / run / VELOCITY_FILE
    return read_tum(path), read_velocity_table(vel) if vel.is_file() else None


def _unpack(result: Any, spec: str) -> tuple[Trajectory, EgoVelocityTrack | None]:
    traj, track = result, None
    if isinstance(result, tuple) and len(result) == 2:
        traj, track = result
    elif hasattr(result, "trajectory"):
        traj, track = result.trajectory, getattr(result, "track", None)
    if not isinstance(traj, Trajectory):
        raise ColoradarError(f"method {spec}: returned {type(traj).__name__}, expected a "
                             "coloradar.geometry.Trajectory (world_T_base)")
    if track is not None and not isinstance(track, EgoVelocityTrack):
        track = None
    return traj, track


def _clear(folder: Path) -> None:
    # Only what this benchmark writes into its own per-run folder.
    for name in (ROW_FILE, TRAJECTORY_FILE, VELOCITY_FILE, "odometry.json", "evaluation.json",
                 "evaluation.txt", "groundtruth.txt", "evaluation.png"):
        (folder / name).unlink(missing_ok=True)


def _f(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def run_task(task: _Task) -> dict:
    """One (method, run): estimate, evaluate, write the run's folder; returns its row.

    Module-level so that process and cluster workers can run it. Raises on failure (the
    executor reports it).
    """
    from ..dataset import open_sequence

    if task.path is None:
        raise MissingDataError(f"run {task.run} is not in the dataset")
    folder = Path(task.out)
    make_output_dir(folder)
    _clear(folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # data warnings: the parent has shown them
        seq = open_sequence(task.path, calib=task.calib)
    if "groundtruth" not in seq.available():
        raise MissingDataError(f"{seq.location}: the run has no ground truth")
    m = task.method
    seconds: float | None = None
    est: Trajectory
    track: EgoVelocityTrack | None
    if m.kind == "coloradar":
        opts = dict(task.odometry)
        if m.spec is not None:
            opts["estimator"] = m.spec
        t0 = time.perf_counter()
        out = run_odometry(seq, folder, overwrite=True, **opts)
        seconds = time.perf_counter() - t0
        est, track = out.trajectory, out.track
    elif m.kind == "callable":
        fn = _load_callable(m.spec or "")
        t0 = time.perf_counter()
        est, track = _unpack(fn(seq), m.spec or "")
        seconds = time.perf_counter() - t0
        write_tum(folder / TRAJECTORY_FILE, est, overwrite=True,
                  comments=[f"run {task.run}, method {m.name} ({m.spec})"])
        if track is not None:
            write_velocity_table(folder / VELOCITY_FILE, track, overwrite=True)
    elif m.kind == "function":
        t0 = time.perf_counter()
        est, track = _run_function(task, folder)
        seconds = time.perf_counter() - t0
    else:
        est, track = _estimate_from_tum(m, task.run)
    reference = trajectory_from_groundtruth(seq)
    nees_p, nees_r = _nees(est, reference, folder) if m.kind == "coloradar" else (None, None)
    ev_opts = dict(task.evaluation)
    ev = evaluate_trajectory(
        est, reference, track=track, calib=seq.calib, align=ev_opts["align"],
        distances=tuple(ev_opts["distances"]), rpe_pairing=ev_opts["rpe_pairing"],
        drift_lengths=tuple(ev_opts["drift_lengths"]), max_gap=ev_opts["max_gap"],
        info={"run_name": task.run, "method": m.name})
    write_evaluation(ev, folder, plot=False, overwrite=True)
    d = evaluation_dict(ev)
    drift = ev.drift
    assert drift is not None and ev.final is not None
    vel = ev.velocity
    span = float(est.timestamps[-1] - est.timestamps[0]) if len(est) > 1 else 0.0
    row = {
        "run": task.run, "method": m.name, "status": "ok",
        "ate_rmse_m": d["ate"]["rmse_m"], "ate_rmse_percent": d["ate"]["rmse_percent_of_path"],
        "final_error_m": _f(ev.final.error), "final_error_percent": _f(ev.final.percent),
        "drift_percent": _f(drift.translation_percent),
        "rotation_drift_deg_per_m": _f(drift.rotation_deg_per_m),
        "ego_velocity_rmse_m_s": _f(vel.rmse) if vel is not None and vel.timestamps.size
        else None,
        "frames_per_s": _f(len(est) / seconds) if seconds else None,
        "real_time_factor": _f(span / seconds) if seconds else None,
        "poses": len(est), "path_length_m": _f(ev.ate.path_length),
        "estimator_s": _f(seconds), "nees_position": _f(nees_p), "nees_attitude": _f(nees_r),
        "error": "",
        # Sums for the pooled figures of the summary row.
        "drift_segments": drift.pairs,
        "drift_translation_sum": float(drift.translation_ratios.sum()),
        "drift_rotation_sum": float(drift.rotation_ratios.sum()),
        "velocity_frames": int(vel.timestamps.size) if vel is not None else 0,
        "velocity_sq_sum": float(np.sum(vel.errors ** 2)) if vel is not None else 0.0,
        "rpe": d["rpe"],
        "ate_posyaw_m": d["ate_posyaw"]["rmse_m"],
        "ate_posyaw_percent": d["ate_posyaw"]["rmse_percent_of_path"],
        **_re_cells(d["rpg_relative"]),
        "rpg_relative": d["rpg_relative"],
    }
    atomic_write_text(folder / ROW_FILE, json.dumps(row, indent=2) + "\n")
    return row


def _re_cells(rpg: list[dict]) -> dict[str, float | None]:
    """The ``re<d>_percent`` and ``re<d>_yaw_deg`` cells (means; None without pairs) from
    :func:`~coloradar.odometry.evaluation_dict`'s ``rpg_relative``."""
    out: dict[str, float | None] = {}
    for e in rpg:
        if e["distance_m"] in _RE_COLUMNS:
            pct, yaw = _RE_COLUMNS[e["distance_m"]]
            out[pct], out[yaw] = e["translation_percent_mean"], e["yaw_deg_mean"]
    return out


def _pooled_re(ok: list[dict]) -> dict[str, float | None]:
    """Summary ``re<d>_*`` cells: means over every segment of every run (rpg's
    ``overall_odometry_errors`` pools the errors of all datasets); rows written before these
    figures existed have no ``rpg_relative`` and count for nothing."""
    out: dict[str, float | None] = {}
    for d, (pct, yaw) in _RE_COLUMNS.items():
        entries = [e for r in ok for e in r.get("rpg_relative") or []
                   if e["distance_m"] == d and e["pairs"]]
        n = sum(e["pairs"] for e in entries)
        out[pct] = sum(e["pairs"] * e["translation_percent_mean"] for e in entries) / n \
            if n else None
        out[yaw] = sum(e["pairs"] * e["yaw_deg_mean"] for e in entries) / n if n else None
    return out


def _failed_row(method: str, run: str, error: str) -> dict:
    return {"run": run, "method": method, "status": "failed", "error": error}


def _summary(method: str, rows: list[dict], n_runs: int) -> dict:
    """The method's overall row: means of per-run ATE (both alignments) and final error, drift
    pooled over all segments of all runs (KITTI), the rpg relative errors pooled likewise,
    ego-velocity RMSE over all frames, poses / estimator time."""
    ok = [r for r in rows if r["status"] == "ok"]

    def mean(key: str) -> float | None:
        v = [r[key] for r in ok if r.get(key) is not None]
        return float(np.mean(v)) if v else None

    seg = sum(r["drift_segments"] for r in ok)
    frames = sum(r["velocity_frames"] for r in ok)
    timed = [r for r in ok if r.get("estimator_s")]
    secs = sum(r["estimator_s"] for r in timed)
    span = sum(r["real_time_factor"] * r["estimator_s"] for r in timed)
    return {
        "run": "overall", "method": method,
        "status": f"{len(ok)}/{n_runs} ok",
        "ate_rmse_m": mean("ate_rmse_m"), "ate_rmse_percent": mean("ate_rmse_percent"),
        "final_error_m": mean("final_error_m"), "final_error_percent": mean("final_error_percent"),
        "drift_percent": 100.0 * sum(r["drift_translation_sum"] for r in ok) / seg if seg
        else None,
        "rotation_drift_deg_per_m": sum(r["drift_rotation_sum"] for r in ok) / seg if seg
        else None,
        "ego_velocity_rmse_m_s": math.sqrt(sum(r["velocity_sq_sum"] for r in ok) / frames)
        if frames else None,
        "frames_per_s": sum(r["poses"] for r in timed) / secs if secs else None,
        "real_time_factor": span / secs if secs else None,
        "poses": sum(r["poses"] for r in ok),
        "path_length_m": sum(r["path_length_m"] or 0.0 for r in ok),
        "estimator_s": secs if timed else None,
        "nees_position": mean("nees_position"), "nees_attitude": mean("nees_attitude"),
        "error": "",
        "ate_posyaw_m": mean("ate_posyaw_m"), "ate_posyaw_percent": mean("ate_posyaw_percent"),
        **_pooled_re(ok),
    }


@dataclass
class BenchmarkResult:
    """What :func:`benchmark` computed.

    Attributes
    ----------
    rows
        One dict per (run, method), in run then method order (keys :data:`CSV_COLUMNS`, and
        ``rpe`` and ``rpg_relative`` per length).
    overall
        One summary dict per method (``run == "overall"``).
    settings
        Methods, runs, odometry and evaluation settings.
    files
        The table files written.
    reused
        Rows taken from an earlier, interrupted or finished, benchmark with the same settings.
    """

    rows: list[dict]
    overall: list[dict]
    settings: dict
    files: list[Path] = field(default_factory=list)
    reused: int = 0

    @property
    def failures(self) -> list[dict]:
        """The rows that failed."""
        return [r for r in self.rows if r["status"] != "ok"]

    @property
    def ok(self) -> bool:
        """Every run of every method evaluated."""
        return not self.failures

    def to_json(self) -> dict:
        """The JSON of ``benchmark.json``."""
        return {"coloradar_version": __version__, "settings": self.settings,
                "overall": self.overall,
                "runs": [{k: v for k, v in r.items() if not k.startswith(("drift_segments",
                          "drift_translation_sum", "drift_rotation_sum", "velocity_"))}
                         for r in self.rows]}


def _cell(x: Any, fmt: str) -> str:
    return "-" if x is None else format(x, fmt)


def format_table(result: BenchmarkResult) -> str:
    """The plain-text table (``benchmark.txt``, what ``coloradar benchmark`` prints)."""
    s = result.settings
    head = ["run", "method", "ATE [m]", "ATE [%]", "final [%]", "drift [%]", "rot [deg/m]",
            "vel RMSE [m/s]", "frames/s", "NEES p", "NEES att"]
    fmts = ["", "", ".3f", ".2f", ".2f", ".2f", ".3f", ".3f", ".0f", ".2f", ".2f"]
    keys = ["run", "method", "ate_rmse_m", "ate_rmse_percent", "final_error_percent",
            "drift_percent", "rotation_drift_deg_per_m", "ego_velocity_rmse_m_s",
            "frames_per_s", "nees_position", "nees_attitude"]

    def cells(r: dict) -> list[str]:
        if r["status"] == "failed":
            return [r["run"], r["method"], "failed: " + r["error"].splitlines()[0][:90]]
        c = [str(r[k]) if not f else _cell(r.get(k), f) for k, f in zip(keys, fmts,
                                                                         strict=True)]
        if r["run"] == "overall":
            c[0] = f"overall ({r['status']})"
        return c

    runs = [cells(r) for r in result.rows]
    overall = [cells(r) for r in result.overall]
    body = runs + overall
    widths = [max([len(h)] + [len(b[i]) for b in body if len(b) == len(head)])
              for i, h in enumerate(head)]
    widths[0] = max([widths[0]] + [len(b[0]) for b in body])
    widths[1] = max([widths[1]] + [len(b[1]) for b in body])

    def line(cells: list[str]) -> str:
        if len(cells) < len(head):   # a failed run: its message spans the figures
            return f"{cells[0]:<{widths[0]}}  {cells[1]:<{widths[1]}}  {cells[2]}"
        return "  ".join(c.ljust(w) if i < 2 else c.rjust(w)
                         for i, (c, w) in enumerate(zip(cells, widths, strict=True)))

    ev = s["evaluation"]
    lengths = ", ".join(f"{x:g}" for x in ev["drift_lengths"])
    rule = line(["-" * w for w in widths])
    out = [f"ATE: RMSE after {ev['align']} alignment; final: end-point error with the first "
           f"poses coincident; drift: KITTI-style over segments of {lengths} m; NEES: the "
           "filter's mean normalised error of position and attitude per dof (consistent: ~1)",
           line(head), rule, *map(line, runs), rule, *map(line, overall)]
    n_ok = len(result.rows) - len(result.failures)
    out.append(f"{n_ok} of {len(result.rows)} run evaluations ok")
    return "\n".join(out) + "\n"


def table_csv(result: BenchmarkResult) -> str:
    """The CSV text (``benchmark.csv``): :data:`CSV_COLUMNS`, one row per run and method, then
    one ``overall`` row per method; empty cells where a figure does not apply."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for r in [*result.rows, *result.overall]:
        w.writerow(["" if r.get(k) is None else (repr(r[k]) if isinstance(r[k], float)
                                                  else r[k]) for k in CSV_COLUMNS])
    return buf.getvalue()


def _dataset_runs(dataset: Path, out: Path) -> dict[str, Path]:
    from ..dataset.dataset import find_runs, is_run_folder

    if not dataset.exists():
        raise MissingDataError(f"{dataset}: no such dataset folder or run")
    if dataset.suffix == ".zip" or is_run_folder(dataset):
        return {dataset.name.removesuffix(".zip"): dataset}
    out_r = out.resolve()
    found = {n: p for n, p in find_runs(dataset).items()
             if not (p.resolve() == out_r or out_r in p.resolve().parents)}
    if not found:
        raise MissingDataError(f"{dataset}: no runs (run folders or run .zip files) in this "
                               "folder")
    return found


def choose_runs(available: Sequence[str], runs: str | Sequence[str] | None = None,
                split: str | None = None) -> list[str]:
    """The run names a benchmark uses: ``runs`` patterns (:func:`coloradar.dataset.splits.
    select_runs`) or a named split ``NAME`` / ``NAME:PART`` (every part when none is named);
    a split's runs are matched to the dataset's names (:func:`coloradar.dataset.splits.
    resolve_runs`: published lists often drop the date prefix), and those the dataset lacks are
    kept under the source's name (they become failed rows)."""
    from ..dataset.splits import named_split, resolve_runs, select_runs

    if split is None:
        return select_runs(available, runs)
    if runs is not None:
        raise SettingsError("give runs or a split, not both")
    name, _, part = split.partition(":")
    ns = named_split(name)
    if part:
        if part not in ns.parts:
            raise SettingsError(f"split {name} has no part {part!r}; parts: "
                                f"{', '.join(ns.parts)}")
        chosen = list(ns.parts[part])
    else:
        chosen = [r for p in ns.parts.values() for r in p]
    matched = resolve_runs(chosen, available)
    return sorted(dict.fromkeys(matched[r] or r for r in chosen))


def _check_odometry_options(methods: Sequence[Method], odometry: dict) -> None:
    sig = inspect.signature(run_odometry).parameters
    # run_odometry takes OdometryJob's fields as keywords (**options).
    params = {f.name for f in dataclasses.fields(OdometryJob)} \
        if any(p.kind is p.VAR_KEYWORD for p in sig.values()) else set(sig)
    bad = [k for k in odometry if k not in params or k in ("overwrite", "progress",
                                                           "estimator")]
    if bad:
        raise SettingsError(f"run_odometry takes no option {', '.join(bad)}")
    if any(m.kind == "coloradar" and m.spec is not None for m in methods) \
            and "estimator" not in params:
        raise SettingsError("this version of coloradar odometry has one estimator; drop the "
                            "estimator choice")


@dataclass(frozen=True, eq=False)
class BenchmarkJob:
    """Options of :func:`benchmark` (each also a keyword of it); see its parameters."""

    methods: Sequence[Method] | None = None
    runs: str | Sequence[str] | None = None
    split: str | None = None
    calib: str | os.PathLike[str] | None = None
    odometry: dict | None = None
    align: str = "se3"
    distances: Sequence[float] = (1.0, 2.0, 5.0)
    drift_lengths: Sequence[float] = DRIFT_LENGTHS
    rpe_pairing: str = "every_pose"
    max_gap: float | None = 1.0
    executor: Any = None
    jobs: int | None = 1
    overwrite: bool = False
    progress: bool = True

    @classmethod
    def of(cls, job: BenchmarkJob | None = None, **options: Any) -> BenchmarkJob:
        """``job`` (default: the defaults) with ``options`` replaced."""
        names = {f.name for f in dataclasses.fields(cls)}
        bad = sorted(set(options) - names)
        if bad:
            raise SettingsError(f"benchmark: unknown option(s) {', '.join(bad)}")
        return dataclasses.replace(job or cls(), **options)


def benchmark(dataset: str | os.PathLike[str], out: str | os.PathLike[str], *,
              job: BenchmarkJob | None = None, **options: Any) -> BenchmarkResult:
    """Run and evaluate methods on the runs of a dataset; write the table to ``out``.

    Parameters
    ----------
    dataset
        A dataset root (run folders / zips and ``calib/``), or one run.
    out
        Output folder: ``<method>/<run>/`` per task, ``benchmark.txt``, ``benchmark.csv``,
        ``benchmark.json``.
    job, **options
        :class:`BenchmarkJob`, or its fields as keywords:
    methods
        Default: ``[builtin_method()]`` (our odometry with its default estimator).
    runs, split
        Run name patterns, or a named split ``NAME[:PART]`` (:func:`choose_runs`).
    calib
        Calibration folder or zip; None: found beside each run.
    odometry
        Keyword arguments for :func:`~coloradar.odometry.run_odometry` (``radar``,
        ``source``, ``orientation``, ``seed``…), the same for every run.
    align, distances, drift_lengths, rpe_pairing, max_gap
        As for :func:`~coloradar.odometry.evaluate_trajectory`.
    executor
        A :mod:`coloradar.batch` executor; None: ``make_executor(jobs)`` (closed at the end).
    jobs
        Local worker processes when no executor is given (1: this process; None: all cores).
    overwrite
        Redo every task; otherwise an earlier benchmark in ``out`` made with the same settings
        is resumed (its finished rows kept) and one made otherwise is refused.
    progress
        A progress line on stderr.

    Returns
    -------
    BenchmarkResult
        Failed runs are rows with ``status == "failed"`` and their ``error``.
    """
    from ..batch.executors import TaskError, make_executor
    from ..progress import Progress

    j = BenchmarkJob.of(job, **options)
    out_p = Path(out)
    methods = list(j.methods or [builtin_method()])
    names = [m.name for m in methods]
    if len(set(names)) != len(names):
        raise SettingsError(f"two methods share a name: {', '.join(names)}; name them "
                            "(NAME=…)")
    if j.align not in ALIGNMENTS:
        raise SettingsError(f"align must be one of {', '.join(ALIGNMENTS)}, got {j.align!r}")
    if j.rpe_pairing not in RPE_PAIRINGS:
        raise SettingsError(f"rpe_pairing must be one of {', '.join(RPE_PAIRINGS)}, got "
                            f"{j.rpe_pairing!r}")
    if any(not d > 0 for d in [*j.distances, *j.drift_lengths]) or not j.drift_lengths:
        raise SettingsError("segment lengths must be positive (and at least one drift length)")
    odo = dict(j.odometry or {})
    _check_odometry_options(methods, odo)
    found = _dataset_runs(Path(dataset), out_p)
    chosen = choose_runs(list(found), j.runs, j.split)
    evaluation = {"align": j.align, "distances": [float(d) for d in j.distances],
                  "drift_lengths": [float(d) for d in j.drift_lengths],
                  "rpe_pairing": j.rpe_pairing, "max_gap": j.max_gap}
    settings = {"dataset": str(Path(dataset).resolve()), "runs": chosen, "split": j.split,
                "methods": [asdict(m) for m in methods], "odometry": odo,
                "evaluation": evaluation, "calib": None if j.calib is None else str(j.calib)}
    _claim_output(out_p, settings, j.overwrite)

    tasks: list[_Task] = []
    rows: dict[tuple[str, str], dict] = {}
    reused = 0
    for run in chosen:
        for m in methods:
            folder = out_p / m.name / run
            row_path = folder / ROW_FILE
            if not j.overwrite and row_path.is_file():
                try:
                    rows[(run, m.name)] = json.loads(read_file_text(row_path))
                    reused += 1
                    continue
                except (json.JSONDecodeError, FormatError):
                    pass   # a damaged row is redone
            p = found.get(run)
            tasks.append(_Task(m, run, None if p is None else str(p), str(folder),
                               None if j.calib is None else str(j.calib), odo, evaluation))
    bar = Progress(len(tasks), desc=f"benchmark {len(methods)} method(s) × {len(chosen)} runs",
                   unit="runs", enabled=j.progress and bool(tasks))
    ex = j.executor
    try:
        if tasks:
            if ex is None:
                ex = make_executor(min(j.jobs or os.cpu_count() or 1, len(tasks)))
            for task, res in ex.imap_unordered(run_task, tasks, errors="return"):
                if isinstance(res, TaskError):
                    rows[(task.run, task.method.name)] = _failed_row(
                        task.method.name, task.run, f"{res.error}: {res.message}")
                    bar.update(1, failed=1)
                else:
                    rows[(task.run, task.method.name)] = res
                    bar.update(1)
    finally:
        bar.close()
        if ex is not None and j.executor is None:
            ex.close()
    ordered = [rows[(run, m.name)] for run in chosen for m in methods]
    overall = [_summary(m.name, [r for r in ordered if r["method"] == m.name], len(chosen))
               for m in methods]
    result = BenchmarkResult(ordered, overall, settings, reused=reused)
    make_output_dir(out_p)
    texts = (format_table(result), table_csv(result),
             json.dumps(result.to_json(), indent=2) + "\n")
    for name, text in zip(BENCHMARK_FILES, texts, strict=True):
        atomic_write_text(out_p / name, text)
        result.files.append(out_p / name)
    return result


def _claim_output(out: Path, settings: dict, overwrite: bool) -> None:
    """Record the settings in ``out``; refuse output of other settings unless ``overwrite``."""
    marker = out / SETTINGS_FILE
    if marker.is_file():
        try:
            stored = json.loads(read_file_text(marker))
        except json.JSONDecodeError:
            stored = None
        if stored != json.loads(json.dumps(settings)) and not overwrite:
            raise OutputExistsError(f"{out}: holds a benchmark made with other settings "
                                    f"({marker.name}); pass overwrite=True (--overwrite) to "
                                    "redo it, or choose another folder")
    elif out.is_dir() and any(out.iterdir()) and not overwrite:
        raise OutputExistsError(f"{out}: not empty and not a benchmark folder; choose another "
                                "folder or pass overwrite=True (--overwrite)")
    if overwrite and marker.is_file():
        # Only our own per-method folders go: ``out`` may hold other things of the user's.
        try:
            old = json.loads(read_file_text(marker))
            old_names = [m["name"] for m in old.get("methods", [])]
        except (json.JSONDecodeError, AttributeError, KeyError, TypeError):
            old_names = []
        for name in old_names:
            if _NAME.match(str(name)) and (out / name).is_dir():
                shutil.rmtree(out / name)
    make_output_dir(out)
    atomic_write_text(marker, json.dumps(settings, indent=2) + "\n")
