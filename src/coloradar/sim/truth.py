"""The truth file of a simulated run (``<run>/truth/truth.npz``) and its reader.

Keys (N_r = frames of radar r, T = ground-truth samples; times are Unix seconds, float64):

- ``world_T_start`` ``(4, 4)``: the scene (world) pose of the ground truth's start frame, so
  ``world_T_base(t) = world_T_start @ groundtruth(t)``; the world frame is z up.
- ``rig_timestamps`` ``(T,)`` and ``rig_pose_world`` ``(T, 7)`` (x y z qx qy qz qw of
  ``world_T_base``), ``rig_velocity_world`` ``(T, 3)``, ``rig_angular_velocity_base``
  ``(T, 3)``, ``rig_acceleration_world`` ``(T, 3)``: the exact rig state at the ground-truth
  times.
- ``static_position`` ``(K, 3)``, ``static_strength`` ``(K,)``: static scatterers (world);
  scatterer identifiers ``0..K-1``; ``object_ident_offset`` ``(O,)``: first identifier of each
  moving object's scatterers.
- ``object_names`` ``(O,)``; ``object_position`` ``(O, T, 3)``, ``object_velocity``
  ``(O, T, 3)``, ``object_heading`` ``(O, T)``: object tracks (ground point) at the rig times.
- per radar ``r`` in ``cascade``, ``single_chip``: ``r/timestamps`` ``(N_r,)``,
  ``r/world_T_radar`` ``(N_r, 4, 4)``, ``r/velocity`` and ``r/angular_velocity`` ``(N_r, 3)``
  (the radar's own linear and angular velocity in its frame, what ego-velocity estimation
  recovers), and the scatterers it saw: ``r/offsets`` ``(N_r + 1,)`` indexing the
  concatenated ``r/target_ident``, ``r/target_position`` (radar frame at the frame start [m]),
  ``r/target_velocity`` (relative velocity, radar frame), ``r/target_range_rate``,
  ``r/target_amplitude`` (``|a|/R²`` per ADC sample [counts]); ``r/coupling`` complex64
  ``(tx, rx, sample)``: the coupling the frames carry, as its unwindowed, unnormalised FFT over
  samples (the first bins are what ``coupling_calib.txt`` holds).
- ``imu_accel_bias``, ``imu_gyro_bias`` ``(3,)``.
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import MissingDataError
from ..formats.atomic import atomic_write_bytes

__all__ = ["SimTruth", "load_truth", "match_detections", "save_truth"]

TRUTH_FILE = "truth/truth.npz"


def save_truth(path: str | os.PathLike[str], arrays: dict[str, np.ndarray]) -> None:
    """Write the truth arrays atomically as a compressed ``.npz``."""
    buf = io.BytesIO()
    # numpy's stubs type **kwds as if a key could hit the ``allow_pickle`` flag (numpy >= 2.1).
    named: dict[str, Any] = dict(arrays)
    np.savez_compressed(buf, **named)
    atomic_write_bytes(path, buf.getvalue())


class SimTruth:
    """Read access to a simulated run's truth file.

    Parameters
    ----------
    path
        The run folder or the ``truth.npz`` file.

    Examples
    --------
    >>> truth = load_truth("out/11_21_2026_sim_corridor_run0")
    >>> t = truth.targets("cascade", 0)            # what the cascade saw in frame 0
    >>> t["position"].shape, truth.radar_velocity("cascade").shape
    """

    def __init__(self, path: str | os.PathLike[str]):
        p = Path(path)
        if p.is_dir():
            p = p / TRUTH_FILE
        if not p.is_file():
            raise MissingDataError(f"{p}: no truth file (only simulated runs have one)")
        with np.load(p, allow_pickle=False) as z:
            self._data = {k: z[k] for k in z.files}
        self.path = p

    def __getitem__(self, key: str) -> np.ndarray:
        try:
            return self._data[key]
        except KeyError:
            raise MissingDataError(f"{self.path}: no {key!r} in the truth file") from None

    def keys(self) -> list[str]:
        """Names of the stored arrays."""
        return sorted(self._data)

    def radar_timestamps(self, radar: str) -> np.ndarray:
        """float64 ``(N,)``: the radar's frame timestamps [s]."""
        return self[f"{radar}/timestamps"]

    def radar_velocity(self, radar: str) -> np.ndarray:
        """float64 ``(N, 3)``: the radar's velocity in its own frame per frame [m/s]."""
        return self[f"{radar}/velocity"]

    def radar_angular_velocity(self, radar: str) -> np.ndarray:
        """float64 ``(N, 3)``: the radar's angular velocity in its own frame [rad/s]."""
        return self[f"{radar}/angular_velocity"]

    def targets(self, radar: str, frame: int) -> dict[str, np.ndarray]:
        """What ``radar`` saw in ``frame``: ``ident``, ``position`` ``(K, 3)``, ``velocity``,
        ``range_rate``, ``amplitude`` (radar frame at the frame start)."""
        off = self[f"{radar}/offsets"]
        if not 0 <= frame < len(off) - 1:
            raise MissingDataError(f"{self.path}: {radar} has {len(off) - 1} frames, "
                                   f"not {frame}")
        sl = slice(int(off[frame]), int(off[frame + 1]))
        return {k: self[f"{radar}/target_{k}"][sl]
                for k in ("ident", "position", "velocity", "range_rate", "amplitude")}


def load_truth(path: str | os.PathLike[str]) -> SimTruth:
    """Open a simulated run's truth file (see :class:`SimTruth` and the module docstring)."""
    return SimTruth(path)


def match_detections(points: np.ndarray, truth_position: np.ndarray,
                     truth_range_rate: np.ndarray | None = None, *, radius: float = 0.3,
                     rate_tolerance: float | None = None,
                     max_velocity: float | None = None) -> dict[str, float]:
    """How well radar detections match the scatterers the radar saw.

    Parameters
    ----------
    points
        float ``(N, >=3)``: detections in the radar frame (x y z […, range_rate in column 4]).
    truth_position
        float ``(K, 3)``: the frame's truth scatterers, same frame (:meth:`SimTruth.targets`).
    truth_range_rate
        float ``(K,)`` [m/s]; with ``rate_tolerance``, a match must also agree in range rate.
    radius
        A detection matches when a truth scatterer lies within this distance [m].
    rate_tolerance
        Range-rate tolerance [m/s] (None: position only).
    max_velocity
        Unambiguous velocity [m/s]: range rates are compared modulo ``2·max_velocity``.

    Returns
    -------
    dict
        ``detections`` (N), ``matched`` (within ``radius``), ``matched_rate`` (within
        ``radius`` of a scatterer whose range rate agrees), ``median_distance`` [m] and
        ``median_rate_error`` [m/s] of the detections that match in position (NaN when none).
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    out = {"detections": float(n), "matched": 0.0, "matched_rate": 0.0,
           "median_distance": float("nan"), "median_rate_error": float("nan")}
    if n == 0 or len(truth_position) == 0:
        return out
    tree = cKDTree(np.asarray(truth_position, dtype=np.float64))
    dist, nearest = tree.query(pts[:, :3])
    close = dist <= radius
    out["matched"] = float(close.sum())
    if close.any():
        out["median_distance"] = float(np.median(dist[close]))
    if truth_range_rate is not None and pts.shape[1] >= 5:
        rr = np.asarray(truth_range_rate, dtype=np.float64)

        def rate_error(det_rate, idx):
            e = det_rate - rr[idx]
            if max_velocity:
                e = (e + max_velocity) % (2 * max_velocity) - max_velocity
            return np.abs(e)

        if close.any():
            out["median_rate_error"] = float(np.median(rate_error(pts[close, 4],
                                                                  nearest[close])))
        if rate_tolerance is not None:
            # Any scatterer within the radius whose range rate agrees counts.
            ok = 0
            for i, cand in enumerate(tree.query_ball_point(pts[:, :3], radius)):
                if cand and np.any(rate_error(np.full(len(cand), pts[i, 4]),
                                              np.asarray(cand)) <= rate_tolerance):
                    ok += 1
            out["matched_rate"] = float(ok)
    return out
