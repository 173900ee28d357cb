"""``coloradar calibrate coupling RUN --out FILE``: a radar's antenna coupling estimated from a
run's own ADC frames, written as a ``coupling_calib.txt`` (docs/calibration.md); ``calibrate
phase`` is in :mod:`.calibrate_phase`."""

from __future__ import annotations

import argparse
import os
import warnings

import numpy as np

from ..calib import (
    Calibration,
    load_calibration,
    with_coupling,
    with_phase_calibration,
    write_coupling_calib,
)
from ..dataset import open_dataset, open_sequence
from ..errors import DataWarning, MissingDataError
from ..geometry import rig_velocity, trajectory_from_groundtruth
from ..progress import Progress
from ._common import (
    add_file_output_args,
    add_quiet_arg,
    add_run_out_radar_args,
    calibration_run,
    non_negative_float,
    positive_int,
)

FEW_FRAMES = 20
"""Below this many frames the static scene can hardly be told from the coupling: said."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="measure a radar calibration from a run's own data",
                       description="Measure a calibration from a run's own data.")
    what = p.add_subparsers(dest="what", metavar="WHAT", required=True)
    c = what.add_parser(
        "coupling", help="estimate a radar's antenna coupling (coupling_calib.txt) from a run",
        description="Estimate each virtual channel's antenna coupling (the static near-range "
                    "leakage that every chirp carries) from a run's ADC frames, and write it as "
                    "a coupling_calib.txt: the release's single-chip file has TX 2's block all "
                    "zeros. Per frame the static part of the chirps is taken; frames are "
                    "combined per channel and range bin by a trimmed mean about the median, "
                    "which leaves out the scene's returns as long as the rig moves (a rig "
                    "standing still, or an object carried with it, looks like coupling). Use "
                    "the file with 'coloradar process --coupling FILE'. Never writes into the "
                    "dataset.")
    add_run_out_radar_args(c, "coupling_calib.txt")
    c.add_argument("--statistic", choices=("trimmed", "median", "mean"), default="trimmed",
                   help="how frames are combined (default: trimmed; mean is not robust to "
                        "targets)")
    c.add_argument("--max-frames", type=positive_int, default=600, metavar="N",
                   help="use at most N frames, spread evenly over the run (default 600)")
    c.add_argument("--min-speed", type=non_negative_float, default=0.1, metavar="M_PER_S",
                   help="leave out frames in which the radar moves slower than this by the "
                        "run's ground truth: a scene that stands still looks like coupling "
                        "(default 0.1 m/s; 0: every frame)")
    add_file_output_args(c)
    add_quiet_arg(c)
    c.set_defaults(func=run)
    from .calibrate_phase import register_phase
    register_phase(what)


def moving_frames(seq, radar: str, times: np.ndarray, min_speed: float) -> np.ndarray:
    """bool ``(N,)``: frames at ``times`` in which the radar's origin moves at least
    ``min_speed`` [m/s] by the run's ground truth (all True with ``min_speed`` 0, or with a
    warning when the run has no ground truth)."""
    t = np.asarray(times, dtype=np.float64)
    if min_speed <= 0:
        return np.ones(t.size, dtype=bool)
    try:
        traj = trajectory_from_groundtruth(seq)
    except MissingDataError:
        warnings.warn(f"{seq.name}: no ground truth: every frame is used, whether the rig moves "
                      "or not", DataWarning, stacklevel=2)
        return np.ones(t.size, dtype=bool)
    ok = traj.covers(t)
    speed = np.zeros(t.size)
    if ok.any():
        v = rig_velocity(traj, t[ok], calib=seq.calib, sensor=radar)
        speed[ok] = np.linalg.norm(v.linear, axis=1)
    return speed >= min_speed


def _frames(stream, positions: list[int]):
    for k in positions:
        frame = stream.read_or_skip(k)
        if frame is not None:
            yield frame


def run(args: argparse.Namespace) -> int:
    from ..dsp.coupling_estimate import estimate_coupling  # dsp is heavy: only when run

    out, seq, rc, stream = calibration_run(args)
    n = len(stream)
    moving = np.flatnonzero(moving_frames(seq, args.radar, stream.timestamps, args.min_speed))
    if moving.size == 0:
        raise MissingDataError(f"{seq.name}: the radar moves slower than {args.min_speed:g} m/s "
                               "in every frame (by the ground truth); the coupling cannot be "
                               "told from the scene (lower --min-speed to use them anyway)")
    pick = np.linspace(0, moving.size - 1, min(moving.size, args.max_frames)).round()
    positions = [int(k) for k in moving[np.unique(pick.astype(int))]]
    prog = Progress(len(positions), f"{args.radar} coupling", enabled=not args.quiet)
    with prog:
        est = estimate_coupling(_frames(stream, positions), rc, statistic=args.statistic,
                                progress=prog, total=len(positions))
    if est.frames < FEW_FRAMES:
        warnings.warn(f"{seq.name}: only {est.frames} {args.radar} frames: the scene's static "
                      "returns can hardly be told from the coupling", DataWarning, stacklevel=2)
    write_coupling_calib(out, est.coupling, overwrite=args.overwrite)
    if not args.quiet:
        still = f" ({n - moving.size} left out: slower than {args.min_speed:g} m/s)" \
            if moving.size < n else ""
        print(f"{out}: {args.radar} coupling from {est.frames} of {n} frames of {seq.name}"
              f"{still}")
        for line in summary(est.coupling.data, est.standard_error, rc.coupling):
            print(line)
    return 0


def summary(data: np.ndarray, standard_error: np.ndarray, released) -> list[str]:
    """One line per TX: the estimate's peak, its expected error, and how it compares with the
    calibration the run came with."""
    lines = []
    for t in range(data.shape[0]):
        peak = float(np.abs(data[t]).max())
        err = float(standard_error[t].max()) / peak if peak > 0 else float("nan")
        text = f"  TX {t}: peak {peak:.4g} counts, standard error <= {100 * err:.2g} % of it"
        if released is not None and released.data.shape == data.shape:
            ref = released.data[t]
            if not np.any(ref):
                text += "; the run's calibration holds zeros for it"
            else:
                diff = np.linalg.norm(data[t] - ref) / np.linalg.norm(ref)
                text += f"; differs from the run's calibration by {100 * diff:.3g} %"
        lines.append(text)
    return lines


def coupling_calibration(path: str | os.PathLike[str], calib: str | None,
                         coupling: str | os.PathLike[str] | None, radar: str | None = None,
                         phase: str | os.PathLike[str] | None = None) -> Calibration:
    """``coloradar process --coupling FILE --phase-calib FILE``: the calibration of ``path`` (a
    run or a dataset root; ``calib`` overrides it) with the radar of each file's size taking
    its coupling or phase calibration; ``radar`` (the one radar processed, None for both) must
    be that radar, else a ``CalibrationError`` (a file the processed radar would silently not
    use)."""
    if calib is not None:
        base = load_calibration(calib)
    else:
        try:
            base = open_sequence(path).calib
        except MissingDataError:
            base = open_dataset(path).calib
    if coupling is not None:
        base = with_coupling(base, coupling, radar)
    if phase is not None:
        base = with_phase_calibration(base, phase, radar)
    return base
