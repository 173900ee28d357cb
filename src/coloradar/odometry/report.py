"""A short ego-velocity summary of a run (used by ``coloradar demo``)."""

from __future__ import annotations

import numpy as np

from ..errors import MissingDataError
from ..geometry import trajectory_from_groundtruth
from .metrics import velocity_errors
from .pipeline import default_source, run_ego_velocity

__all__ = ["ego_velocity_report"]


def _default_radar(seq) -> str:
    have = seq.available()
    for radar in ("cascade", "single_chip"):
        if any(f"{radar}/{k}" in have for k in ("adc", "pointclouds", "heatmaps")):
            return radar
    raise MissingDataError(f"{seq.location}: no radar data in this run")


def ego_velocity_report(seq, radar: str | None = None, source: str | None = None, *,
                        max_frames: int | None = 20, stride: int = 1, seed: int = 0) -> dict:
    """Ego-velocity of the first frames of a run, compared with the ground truth if present.

    Parameters
    ----------
    seq
        A :class:`coloradar.Sequence`.
    radar
        Default: the cascade when the run has its data, else the single chip.
    source
        Default: :func:`~coloradar.odometry.pipeline.default_source`.
    max_frames, stride
        Frames used (None: all).
    seed
        RANSAC seed.

    Returns
    -------
    dict
        ``radar``, ``source``, ``frames``, ``frames_ok``, ``median_points``,
        ``median_inliers``, ``mean_speed_m_s`` (estimated), and with ground truth
        ``rmse_m_s`` and ``rmse_axes_m_s``; ``track`` (the
        :class:`~coloradar.odometry.EgoVelocityTrack`) and ``text`` (a one-line summary).
    """
    radar = radar or _default_radar(seq)
    source = source or default_source(seq, radar)
    track = run_ego_velocity(seq, radar, source, stride=stride, max_frames=max_frames, seed=seed)
    ok = track.ok
    speed = np.linalg.norm(track.velocity[ok], axis=1)
    rep: dict = {
        "radar": radar, "source": source, "frames": len(track), "frames_ok": int(ok.sum()),
        "median_points": float(np.median(track.num_points)) if len(track) else 0.0,
        "median_inliers": float(np.median(track.num_inliers[ok])) if ok.any() else 0.0,
        "mean_speed_m_s": float(speed.mean()) if speed.size else float("nan"),
        "track": track,
    }
    text = (f"ego-velocity ({radar}, {source}): {rep['frames_ok']}/{rep['frames']} frames "
            f"estimated, median {rep['median_inliers']:.0f} static of "
            f"{rep['median_points']:.0f} points, mean speed {rep['mean_speed_m_s']:.2f} m/s")
    if "groundtruth" in seq.available() and ok.any():
        gt = trajectory_from_groundtruth(seq)
        ve = velocity_errors(track, gt, seq.calib, radar)
        if ve.timestamps.size:
            rep["rmse_m_s"] = ve.rmse
            rep["rmse_axes_m_s"] = [float(x) for x in ve.rmse_axes]
            text += (f"; RMSE against ground truth {ve.rmse:.3f} m/s (x "
                     f"{ve.rmse_axes[0]:.3f}, y {ve.rmse_axes[1]:.3f}, z {ve.rmse_axes[2]:.3f})")
    rep["text"] = text
    return rep
