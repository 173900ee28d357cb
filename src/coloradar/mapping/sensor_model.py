"""The inverse sensor model of a point cloud: one frame's returns → occupancy evidence.

A return at range ``r`` in direction ``u`` is evidence that something occupies the place it
names, blurred by what the sensor cannot tell apart, and evidence that nothing occupies the
ray in front of it:

- **Occupancy, spread by the return's uncertainty.** The return's position is a Gaussian with
  standard deviations ``σ_r`` along the ray and ``r·σ_az``, ``r·σ_el`` across it. ``σ_r`` is
  half a range bin; an angle's standard deviation (in its sine) is the array's resolution
  ``2/N`` (``N`` distinct virtual positions along that axis) over ``1.6·√(2·SNR)`` (the
  Cramér–Rao-like rule the simulator and SLAM's submaps use), never below a floor (the
  calibration's and the detector's errors, which the SNR does not show). Each voxel near the
  return gets the Gaussian's mass in it, ``m_v ≈ V·N(c_v; p, Σ + V^{2/3}/12·I)`` (the voxel's
  own extent added as a variance), and the frame's evidence about the voxel is
  ``logit(½ + P_v·(p_hit − ½))`` with ``P_v = min(1, Σ m_v)`` over the frame's returns. A near
  return, precise, puts most of its mass in one voxel; a far one spreads it thin, so that many
  near views outweigh one far view of the same wall.
- **Free space along the ray**, from the sensor to ``r − (2σ_r + voxel)``: ``logit(p_miss)``
  once per voxel per frame, except in voxels the frame itself puts a return in (a hit wins).

A voxel reaches :attr:`~.voxels.OccupancySettings.p_occupied` only with the evidence of more
than one frame, and a ghost or a noise tail in open space is outvoted by the rays of other
frames that pass through it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SettingsError
from ..geometry.mapping import voxel_downsample
from .voxels import OccupancySettings, local_unique_keys, logit, voxel_keys

__all__ = ["PointSensorModel", "angle_std_floor", "hit_evidence", "lidar_sensor_model",
           "merge_evidence", "point_evidence", "radar_sensor_model", "ray_keys"]

_DEG = math.pi / 180.0


@dataclass(frozen=True)
class PointSensorModel:
    """What one sensor's returns tell (lengths in metres, angles in radians).

    Attributes
    ----------
    range_std
        Standard deviation of a return's range.
    azimuth_resolution, elevation_resolution
        The array's resolution in the sine of each angle (``2/N``); 0 for a sensor whose
        angle error is its floor alone (a lidar).
    min_azimuth_std, min_elevation_std
        Floors of the angle errors.
    snr_db
        The SNR [dB] of every return; None: the cloud's 4th column (intensity) is its SNR in
        dB, clipped to ``snr_clip_db``.
    snr_clip_db
        ``(low, high)`` [dB].
    min_range, max_range
        Returns outside are left out (the rig itself; beyond the unambiguous range).
    max_spread
        Voxels each way of a return's own that its occupancy reaches (the Gaussian's tails
        beyond are dropped; bounds the work per return).
    thin
        Keep one return per voxel (sensor frame) of a frame: a lidar's 65,536 points a scan
        say no more about a voxel map than one per voxel does.
    """

    range_std: float
    azimuth_resolution: float
    elevation_resolution: float
    min_azimuth_std: float = 1.0 * _DEG
    min_elevation_std: float = 2.0 * _DEG
    snr_db: float | None = None
    snr_clip_db: tuple[float, float] = (5.0, 40.0)
    min_range: float = 0.3
    max_range: float = 20.0
    max_spread: int = 2
    thin: bool = False

    def __post_init__(self) -> None:
        for name in ("range_std", "min_azimuth_std", "min_elevation_std"):
            if not getattr(self, name) > 0:
                raise SettingsError(f"PointSensorModel.{name} must be > 0")
        if not 0 <= self.min_range < self.max_range:
            raise SettingsError("PointSensorModel: expected 0 <= min_range < max_range, got "
                                f"{self.min_range} and {self.max_range}")
        if self.max_spread < 0:
            raise SettingsError("PointSensorModel.max_spread must be >= 0")

    def angle_std(self, cloud: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """float64 ``(N,)`` twice: each return's azimuth and elevation standard deviation
        [rad] (module docstring)."""
        n = cloud.shape[0]
        if self.snr_db is not None or cloud.shape[1] < 4:
            snr_db = np.full(n, 20.0 if self.snr_db is None else self.snr_db)
        else:
            snr_db = np.nan_to_num(cloud[:, 3].astype(np.float64), nan=self.snr_clip_db[0])
        snr = 10.0 ** (np.clip(snr_db, *self.snr_clip_db) / 10.0)
        k = 1.0 / (1.6 * np.sqrt(2.0 * snr))
        az = np.maximum(np.arcsin(np.minimum(self.azimuth_resolution * k, 1.0)),
                        self.min_azimuth_std)
        el = np.maximum(np.arcsin(np.minimum(self.elevation_resolution * k, 1.0)),
                        self.min_elevation_std)
        return az, el


def angle_std_floor(resolution: float, cap: float) -> float:
    """The floor of a radar's angle error [rad] for an array that resolves ``resolution``
    (in the sine of the angle, ``2/N``): 0.4 of the resolution as an angle, at most ``cap``.

    A return's angle is a peak on a grid of directions, and the calibration's phase errors
    move it by a share of the beam: both scale with the beamwidth. The factor was chosen on
    the mapping tuning runs (``benchmarks/mc_mapping.py``, seeds 101–103) from floors of
    0.25–1° for the cascade (86 azimuth positions: 0.53°, where 1° thickened the walls of
    its heatmap maps by a cell); the cap keeps the single chip's 1° in azimuth (8 positions:
    0.4 of its 14° beam would blur every return) and 2° in elevation.
    """
    return float(min(cap, 0.4 * math.asin(min(1.0, resolution))))


def radar_sensor_model(radar_calib, *, min_azimuth_std: float | None = None,
                       min_elevation_std: float | None = None, snr_db: float | None = None,
                       max_range: float | None = None) -> PointSensorModel:
    """The :class:`PointSensorModel` of a radar from its calibration
    (:class:`coloradar.calib.RadarCalib`): half a range bin, the virtual array's resolution,
    the unambiguous range (or ``max_range``); the angle floors [rad] (None:
    :func:`angle_std_floor` of the array's resolution, at most 1° in azimuth and 2° in
    elevation)."""
    w = radar_calib.waveform
    v = radar_calib.antenna.virtual.unique_positions
    n_az = max(2, len(np.unique(v[:, 0])))
    n_el = max(2, len(np.unique(v[:, 1])))
    if min_azimuth_std is None:
        min_azimuth_std = angle_std_floor(2.0 / n_az, 1.0 * _DEG)
    if min_elevation_std is None:
        min_elevation_std = angle_std_floor(2.0 / n_el, 2.0 * _DEG)
    return PointSensorModel(range_std=w.range_bin_width / 2, azimuth_resolution=2.0 / n_az,
                            elevation_resolution=2.0 / n_el, min_azimuth_std=min_azimuth_std,
                            min_elevation_std=min_elevation_std, snr_db=snr_db,
                            max_range=float(max_range or w.max_range))


def lidar_sensor_model(max_range: float = 15.0) -> PointSensorModel:
    """A lidar's model (Ouster OS1-64: about 3 cm in range, 0.2° in angle), for the
    reference maps radar maps are scored against."""
    return PointSensorModel(range_std=0.03, azimuth_resolution=0.0, elevation_resolution=0.0,
                            min_azimuth_std=0.2 * _DEG, min_elevation_std=0.2 * _DEG,
                            snr_db=30.0, min_range=0.5, max_range=max_range, max_spread=1,
                            thin=True)


def _ray_basis(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit vectors along each ray, across it in azimuth and across it in elevation."""
    r = np.linalg.norm(p, axis=1, keepdims=True)
    e_r = p / r
    h = np.hypot(e_r[:, 0], e_r[:, 1])[:, None]
    e_az = np.column_stack([-e_r[:, 1], e_r[:, 0], np.zeros(len(p))]) / np.maximum(h, 1e-9)
    e_el = np.cross(e_r, e_az)
    return e_r, e_az, e_el


def point_evidence(cloud: np.ndarray, rotation: np.ndarray, translation: np.ndarray,
                   model: PointSensorModel, settings: OccupancySettings
                   ) -> tuple[np.ndarray, np.ndarray]:
    """One frame's occupancy and free-space evidence (module docstring).

    Parameters
    ----------
    cloud
        float ``(N, ≥3)``: x y z [m] (and intensity), sensor frame.
    rotation, translation
        ``world_T_sensor``: float ``(3, 3)`` and ``(3,)``.
    model
        The sensor.
    settings
        The map's voxel and probabilities.

    Returns
    -------
    keys : numpy.ndarray
        int64 ``(K,)``, distinct.
    delta : numpy.ndarray
        float32 ``(K,)``: log-odds to add (> 0 occupied, < 0 free).
    """
    c = np.asarray(cloud, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] < 3:
        raise SettingsError(f"expected a cloud of shape (N, >=3), got {c.shape}")
    c = c[np.all(np.isfinite(c[:, :3]), axis=1)]
    r = np.linalg.norm(c[:, :3], axis=1)
    c, r = c[(r >= model.min_range) & (r <= model.max_range)], r[(r >= model.min_range)
                                                                   & (r <= model.max_range)]
    if c.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.float32)
    if model.thin:
        c = voxel_downsample(c, settings.voxel, reduce="first")
        r = np.linalg.norm(c[:, :3], axis=1)
    rot, t = np.asarray(rotation, np.float64), np.asarray(translation, np.float64)
    hit_keys, l_hit = hit_evidence(c, rot, t, model, settings)
    end = r - (2 * model.range_std + settings.voxel)
    free = ray_keys(t, c[:, :3] @ rot.T + t, end / r, settings.voxel)
    free = free[~np.isin(free, hit_keys, assume_unique=True)]
    keys = np.concatenate([hit_keys, free])
    delta = np.concatenate([l_hit, np.full(free.size, logit(settings.p_miss))])
    return keys, delta.astype(np.float32)


def hit_evidence(cloud: np.ndarray, rotation: np.ndarray, translation: np.ndarray,
                 model: PointSensorModel, settings: OccupancySettings
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The occupancy half of :func:`point_evidence`: distinct voxel keys near the returns of
    float ``(N, ≥3)`` ``cloud`` (sensor frame, inside the model's ranges; column 3 the SNR
    [dB] when the model reads it) and the log-odds each gets, float64 ``(K,)`` > 0."""
    c = np.asarray(cloud, np.float64)
    if c.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    r = np.linalg.norm(c[:, :3], axis=1)
    keys, mass = _spread(c, r, rotation, translation, model, settings.voxel)
    keys, p_v = merge_evidence(keys, mass, np.add)
    q = 0.5 + np.minimum(p_v, 1.0) * (settings.p_hit - 0.5)
    return keys, np.log(q / (1.0 - q))


def _spread(c: np.ndarray, r: np.ndarray, rot: np.ndarray, t: np.ndarray,
            model: PointSensorModel, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Keys of the voxels near each return and the Gaussian mass each gets (not merged)."""
    s_az, s_el = model.angle_std(c)
    box = voxel ** 2 / 12.0                             # a voxel's own extent, as a variance
    sd = np.sqrt(np.column_stack([np.full(r.size, model.range_std ** 2),
                                  (r * s_az) ** 2, (r * s_el) ** 2]) + box)   # (N, 3)
    n = int(min(model.max_spread, math.ceil(2.5 * float(sd.max()) / voxel)))
    o = np.arange(-n, n + 1)
    offs = np.stack(np.meshgrid(o, o, o, indexing="ij"), axis=-1).reshape(-1, 3)
    pw = c[:, :3] @ rot.T + t                                           # world frame
    base = np.floor(pw / voxel)
    centres = (base[:, None, :] + offs[None, :, :] + 0.5) * voxel       # (N, O, 3)
    d = (centres - pw[:, None, :]) @ rot                                # sensor axes
    e = _ray_basis(c[:, :3])
    z2 = sum((np.einsum("nok,nk->no", d, e[i]) / sd[:, i:i + 1]) ** 2 for i in range(3))
    norm = voxel ** 3 / ((2 * math.pi) ** 1.5 * np.prod(sd, axis=1))
    mass = np.exp(-0.5 * z2) * norm[:, None]
    keys = voxel_keys(centres.reshape(-1, 3), voxel)
    keep = mass.reshape(-1) > 1e-3
    return keys[keep], mass.reshape(-1)[keep]


def merge_evidence(keys: np.ndarray, values: np.ndarray, how: np.ufunc
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Distinct keys and their values combined with ``how`` (``np.add`` or ``np.maximum``)."""
    if keys.size == 0:
        return keys.astype(np.int64), values.astype(np.float64)
    u, inv = np.unique(keys, return_inverse=True)
    inv = inv.reshape(-1)
    if how is np.add:
        return u, np.bincount(inv, weights=values, minlength=u.size)
    out = np.full(u.size, -np.inf)
    how.at(out, inv, values)
    return u, out


def ray_keys(origin: np.ndarray, ends: np.ndarray, fraction: np.ndarray, voxel: float
             ) -> np.ndarray:
    """int64, distinct: the voxels the rays from ``origin`` to ``ends`` cross, from the
    origin to ``fraction`` of the way (sampled every half voxel; ``fraction`` ≤ 0: none).

    Parameters
    ----------
    origin
        float ``(3,)`` [m].
    ends
        float ``(N, 3)`` [m].
    fraction
        float ``(N,)``.
    voxel
        Voxel edge [m].
    """
    v = np.asarray(ends, np.float64) - origin
    length = np.linalg.norm(v, axis=1) * np.clip(fraction, 0.0, 1.0)
    step = voxel / 2.0
    n = np.floor(length / step).astype(np.int64)
    total = int(n.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    ray = np.repeat(np.arange(n.size), n)
    first = np.cumsum(n) - n
    k = np.arange(total) - np.repeat(first, n)                  # sample index along its ray
    unit = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
    pts = origin + unit[ray] * ((k + 0.5) * step)[:, None]
    return local_unique_keys(pts, voxel)
