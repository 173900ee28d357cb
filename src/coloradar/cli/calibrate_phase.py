"""``coloradar calibrate phase RUN --out FILE``: a radar's per-channel phases and gains measured
from a run's own ADC frames, written as a ``phase_frequency_calib.txt`` (docs/calibration.md)."""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from ..calib import write_phase_frequency_calib
from ..errors import DataWarning, MissingDataError
from ..geometry import rig_velocity, trajectory_from_groundtruth
from ..progress import Progress
from ._common import (
    add_file_output_args,
    add_quiet_arg,
    add_run_out_radar_args,
    calibration_run,
    positive_float,
    positive_int,
)


def register_phase(what: argparse._SubParsersAction) -> None:
    """The ``phase`` sub-command of ``coloradar calibrate``."""
    c = what.add_parser(
        "phase", help="measure a radar's per-channel phases and gains from a run",
        description="Measure each virtual channel's phase and gain (relative to TX 0, RX 0) "
                    "from a run's ADC frames, and write them as a phase_frequency_calib.txt "
                    "(the release's format; the channels' delays kept from the run's "
                    "calibration, or measured first when it has none). Strong cells of many "
                    "frames are each fitted with one scatterer; the gains and the cells' "
                    "directions are found in turn, cells that one scatterer does not explain "
                    "left out. Frames in which the "
                    "radar moves faster than --max-speed by the ground truth are left out, so "
                    "that the static scene's Doppler is not aliased. A linear phase ramp "
                    "across the array (a direction offset) cannot be measured without a target "
                    "in a known direction; it is fixed as docs/calibration.md says. Use the "
                    "file with 'coloradar process --phase-calib FILE'. Never writes into the "
                    "dataset.")
    add_run_out_radar_args(c, "phase_frequency_calib.txt")
    c.add_argument("--max-frames", type=positive_int, default=200, metavar="N",
                   help="use at most N frames, spread evenly over the run (default 200)")
    c.add_argument("--max-speed", type=positive_float, metavar="M_PER_S",
                   help="leave out frames in which the radar moves faster than this by the "
                        "run's ground truth (default: 0.9 v_max, below which no static "
                        "scatterer's Doppler aliases)")
    add_file_output_args(c)
    add_quiet_arg(c)
    c.set_defaults(func=run_phase)


def radar_velocities(seq, radar: str, times: np.ndarray) -> np.ndarray:
    """float64 ``(N, 3)``: the radar's velocity in its own frame at ``times`` by the run's
    ground truth [m/s]; NaN where the ground truth does not cover a time, all NaN (with a
    warning) for a run without one."""
    t = np.asarray(times, dtype=np.float64)
    out = np.full((t.size, 3), np.nan)
    try:
        traj = trajectory_from_groundtruth(seq)
    except MissingDataError:
        if t.size > 1:
            warnings.warn(f"{seq.name}: no ground truth: every frame is used (frames in which "
                          "the radar moved faster than v_max alias the static scene and are "
                          "left out only as far as they are a minority), and the azimuth "
                          "offset is fixed by the receivers, not the Doppler", DataWarning,
                          stacklevel=2)
        return out
    ok = traj.covers(t)
    if ok.any():
        out[ok] = rig_velocity(traj, t[ok], calib=seq.calib, sensor=radar).linear
    return out


class _Picked:
    """Frames ``positions`` of an ADC stream, read when indexed (None: unreadable)."""

    def __init__(self, stream, positions: list[int]) -> None:
        self.stream, self.positions = stream, positions

    def __len__(self) -> int:
        return len(self.positions)

    def __getitem__(self, i: int) -> np.ndarray | None:
        return self.stream.read_or_skip(self.positions[i])


def run_phase(args: argparse.Namespace) -> int:
    from ..dsp.phase_estimate import (  # dsp is heavy: only when run
        estimate_phase_calibration,
        estimation_passes,
    )

    out, seq, rc, stream = calibration_run(args)
    n = len(stream)
    limit = args.max_speed if args.max_speed is not None else 0.9 * rc.waveform.max_velocity
    vel = radar_velocities(seq, args.radar, stream.timestamps)
    speed = np.linalg.norm(vel, axis=1)
    unknown = np.all(np.isnan(vel))
    slow = np.flatnonzero(unknown | (speed <= limit))
    if slow.size == 0:
        raise MissingDataError(f"{seq.name}: the radar moves faster than {limit:.2f} m/s in "
                               "every frame (by the ground truth): the static scene's Doppler "
                               "may alias (raise --max-speed to use them anyway)")
    pick = np.linspace(0, slow.size - 1, min(slow.size, args.max_frames)).round()
    positions = [int(k) for k in slow[np.unique(pick.astype(int))]]
    frames = _Picked(stream, positions)
    passes = estimation_passes(rc)
    prog = Progress(passes * len(positions), f"{args.radar} phase", unit="frame passes",
                    enabled=not args.quiet)
    with prog:
        est = estimate_phase_calibration(frames, rc, progress=prog.update,
                                         velocities=None if unknown else vel[positions])
    write_phase_frequency_calib(out, est.calibration, overwrite=args.overwrite)
    if not args.quiet:
        fit = est.fit
        print(f"{out}: {args.radar} channel phases from {fit.used.sum()} of {est.cells} cells "
              f"in {est.frames} of {n} frames of {seq.name}")
        print(f"  one-scatterer fit: median {100 * np.median(fit.residual[fit.used]):.2g} % of "
              "a used cell's power left")
        if est.delay is not None:
            print(f"  channel delays: {np.ptp(est.delay):.3f} range bins from first to last "
                  "(measured: the run has no calibration)")
        base = "relative to the run's calibration" if rc.phase_frequency is not None else \
            "uncalibrated board"
        tx, std = est.tx_phase_deg(), fit.phase_std_deg
        for t in range(tx.size):
            print(f"  TX {t}: phase {tx[t]:+7.1f} deg from TX 0 ({base}); per channel "
                  f"+-{float(std[t].max()):.1f} deg (noise)")
    return 0
