"""Vectorised ray casting against finite rectangles (every wall, floor and box face of a scene).

A rectangle has a centre ``c``, orthonormal in-plane axes ``u``, ``v``, half sizes
``(h_u, h_v)`` and normal ``n = u × v``. A ray ``o + t·d`` meets its plane at
``t = (c − o)·n / (d·n)``; it hits the rectangle when ``|(o + t d − c)·u| ≤ h_u`` and likewise
for ``v``. All rays are tested against all rectangles at once with matrix products (no loop
per ray or per rectangle), in blocks of rays to bound memory.

Many rays against static structure (a lidar scan, a radar's occlusion test) take a faster
path: rays are sorted into azimuth sectors around their origins, and each rectangle is tested
only against the rays of the sectors it spans as seen from there (all sectors when it lies
under or over the origins, like a floor). The result is the same; the work drops from
``rays × rectangles`` to about ``rays × (rectangles around the sensor)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..errors import SettingsError

__all__ = ["RectArrays", "cast_rays"]


@dataclass(frozen=True, eq=False)
class RectArrays:
    """M rectangles as arrays, optionally one geometry per ray group (for moving objects).

    Attributes
    ----------
    center, u, v, normal
        float64 ``(G, M, 3)`` with ``G`` = 1 (static) or the number of ray groups [m].
    half_size
        float64 ``(G, M, 2)`` [m].
    lidar_reflectivity
        float64 ``(M,)`` in [0, 1].
    owner
        int64 ``(M,)``: -1 for static structure, else the index of the moving object.
    """

    center: np.ndarray
    u: np.ndarray
    v: np.ndarray
    normal: np.ndarray
    half_size: np.ndarray
    lidar_reflectivity: np.ndarray
    owner: np.ndarray

    @property
    def count(self) -> int:
        return int(self.center.shape[-2])

    @staticmethod
    def empty() -> RectArrays:
        z3 = np.zeros((1, 0, 3))
        return RectArrays(z3, z3, z3, z3, np.zeros((1, 0, 2)), np.zeros(0),
                          np.zeros(0, dtype=np.int64))

    @staticmethod
    def concatenate(parts: list[RectArrays]) -> RectArrays:
        """Stack rectangle sets along M (their group sizes must be 1 or equal)."""
        parts = [p for p in parts if p.count]
        if not parts:
            return RectArrays.empty()
        g = max(p.center.shape[0] for p in parts)

        def cat(name):
            return np.concatenate([np.broadcast_to(getattr(p, name),
                                                   (g, *getattr(p, name).shape[1:]))
                                   for p in parts], axis=1)

        return RectArrays(cat("center"), cat("u"), cat("v"), cat("normal"), cat("half_size"),
                          np.concatenate([p.lidar_reflectivity for p in parts]),
                          np.concatenate([p.owner for p in parts]))

    def group(self, sl: slice) -> RectArrays:
        """The rectangles of a range of ray groups (static sets are returned unchanged)."""
        if self.center.shape[0] == 1:
            return self
        return RectArrays(self.center[sl], self.u[sl], self.v[sl], self.normal[sl],
                          self.half_size[sl], self.lidar_reflectivity, self.owner)


def cast_rays(origins: np.ndarray, directions: np.ndarray, rects: RectArrays,
              t_min: float = 1e-6, block: int = 8192, method: Literal["auto", "sectors", "dense"] = "auto"
              ) -> tuple[np.ndarray, np.ndarray]:
    """First hit of every ray.

    Parameters
    ----------
    origins
        float ``(G, 1, 3)`` or ``(G, B, 3)``: ray origins, one per group or per ray [m].
    directions
        float ``(G, B, 3)``: unit ray directions.
    rects
        The rectangles; group size 1 or ``G``.
    t_min
        Hits closer than this are ignored [m].
    block
        Rays per block (memory bound: about ``block·M·8`` bytes per temporary).
    method
        ``"dense"`` (every ray against every rectangle), ``"sectors"`` (static rectangles
        only) or ``"auto"`` (sectors for many rays against static rectangles).

    Returns
    -------
    distance : numpy.ndarray
        float64 ``(G, B)``: distance to the first hit along the ray [m], ``inf`` for none.
    index : numpy.ndarray
        int64 ``(G, B)``: index of the rectangle hit, -1 for none.
    """
    if method not in ("auto", "sectors", "dense"):   # an unknown name would mean "dense"
        raise SettingsError(f"cast_rays: method must be 'auto', 'sectors' or 'dense', got {method!r}")
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    g_count, b_count = d.shape[:2]
    dist = np.full((g_count, b_count), np.inf)
    index = np.full((g_count, b_count), -1, dtype=np.int64)
    if rects.count == 0 or d.size == 0:
        return dist, index
    static = rects.center.shape[0] == 1
    if method == "sectors" and not static:
        raise SettingsError("cast_rays: the sector method needs static rectangles")
    if method == "sectors" or (method == "auto" and static and d.size // 3 >= 512
                               and rects.count >= 8):
        oo = np.broadcast_to(o, d.shape).reshape(-1, 3)
        dd, ii = _cast_sectors(oo, d.reshape(-1, 3), rects, t_min)
        return dd.reshape(g_count, b_count), ii.reshape(g_count, b_count)
    step = max(1, block // max(b_count, 1))
    for g0 in range(0, g_count, step):
        sl = slice(g0, g0 + step)
        r = rects.group(sl)
        n_t = np.swapaxes(r.normal, -1, -2)                   # (g, 3, M)
        u_t = np.swapaxes(r.u, -1, -2)
        v_t = np.swapaxes(r.v, -1, -2)
        oc = o[sl]
        dd = d[sl]
        c_n = np.einsum("gmk,gmk->gm", r.center, r.normal)[:, None, :]
        c_u = np.einsum("gmk,gmk->gm", r.center, r.u)[:, None, :]
        c_v = np.einsum("gmk,gmk->gm", r.center, r.v)[:, None, :]
        dn = dd @ n_t                                          # (g, B, M)
        # A ray parallel to a plane gives t = ±inf (or NaN) and in-plane offsets of inf·0 = NaN:
        # no hit, since NaN fails every comparison below.
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (c_n - oc @ n_t) / dn
            pu = (oc @ u_t - c_u) + t * (dd @ u_t)
            pv = (oc @ v_t - c_v) + t * (dd @ v_t)
        hit = ((t > t_min) & (np.abs(pu) <= r.half_size[:, None, :, 0])
               & (np.abs(pv) <= r.half_size[:, None, :, 1]))
        t = np.where(hit, t, np.inf)
        k = np.argmin(t, axis=-1)
        best = np.take_along_axis(t, k[..., None], axis=-1)[..., 0]
        dist[sl] = best
        index[sl] = np.where(np.isfinite(best), k, -1)
    return dist, index


_SECTORS = 256


def _azimuth_spans(center: np.ndarray, radius: float, rects: RectArrays
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Azimuth interval of every rectangle seen from anywhere within ``radius`` of ``center``.

    Returns ``(start, width, full)``: start angle and width [rad] of the interval, and True
    where the rectangle's footprint comes within ``radius`` of ``center`` horizontally (it may
    then be seen at any azimuth).
    """
    c, u, v = rects.center[0], rects.u[0], rects.v[0]
    h = rects.half_size[0]
    signs = np.array([(-1, -1), (1, -1), (1, 1), (-1, 1)], dtype=np.float64)
    corners = (c[:, None, :] + signs[None, :, 0, None] * h[:, None, 0, None] * u[:, None, :]
               + signs[None, :, 1, None] * h[:, None, 1, None] * v[:, None, :])   # (M, 4, 3)
    xy = corners[..., :2] - center[:2]                                            # (M, 4, 2)
    # Horizontal distance from the centre to the footprint (a parallelogram, maybe flat).
    a, b = xy, np.roll(xy, -1, axis=1)
    e = b - a
    t = np.clip(np.einsum("mkj,mkj->mk", -a, e) / np.maximum(np.einsum("mkj,mkj->mk", e, e),
                                                            1e-18), 0, 1)
    edge_dist = np.linalg.norm(a + t[..., None] * e, axis=-1).min(axis=1)
    cross = a[..., 0] * e[..., 1] - a[..., 1] * e[..., 0]
    inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
    full = inside | (edge_dist <= radius + 1e-9)
    ang = np.sort(np.arctan2(xy[..., 1], xy[..., 0]), axis=1)                    # (M, 4)
    gaps = np.diff(np.concatenate([ang, ang[:, :1] + 2 * np.pi], axis=1), axis=1)
    k = np.argmax(gaps, axis=1)
    rows = np.arange(len(ang))
    start = ang[rows, (k + 1) % 4]
    width = 2 * np.pi - gaps[rows, k]
    margin = np.arcsin(np.clip(radius / np.maximum(edge_dist, 1e-12), 0, 1))
    return start - margin, width + 2 * margin, full


def _cast_sectors(o: np.ndarray, d: np.ndarray, rects: RectArrays,
                  t_min: float) -> tuple[np.ndarray, np.ndarray]:
    """First hits of rays ``(N, 3)`` against static rectangles, by azimuth sectors."""
    n = len(d)
    center = o.mean(axis=0)
    radius = float(np.linalg.norm(o - center, axis=1).max())
    az = np.arctan2(d[:, 1], d[:, 0])
    sector = np.minimum(((az + np.pi) / (2 * np.pi) * _SECTORS).astype(np.int64), _SECTORS - 1)
    order = np.argsort(sector, kind="stable")
    bounds = np.searchsorted(sector[order], np.arange(_SECTORS + 1))
    os_, ds = o[order], d[order]
    best = np.full(n, np.inf)
    best_i = np.full(n, -1, dtype=np.int64)
    start, width, full = _azimuth_spans(center, radius, rects)
    c, u, v, nrm = rects.center[0], rects.u[0], rects.v[0], rects.normal[0]
    h = rects.half_size[0]
    scale = _SECTORS / (2 * np.pi)
    for m in range(rects.count):
        if full[m] or width[m] >= 2 * np.pi - 2 / scale:
            spans = [(0, n)]
        else:
            s0 = int(np.floor((start[m] + np.pi) * scale)) - 1
            s1 = int(np.floor((start[m] + width[m] + np.pi) * scale)) + 1
            if s0 < 0:
                spans = [(bounds[s0 % _SECTORS], n), (0, bounds[min(s1 + 1, _SECTORS)])]
            elif s1 >= _SECTORS:
                spans = [(bounds[s0], n), (0, bounds[(s1 + 1) % _SECTORS])]
            else:
                spans = [(bounds[s0], bounds[s1 + 1])]
        for a0, a1 in spans:
            if a1 <= a0:
                continue
            oo, dd = os_[a0:a1], ds[a0:a1]
            dn = dd @ nrm[m]
            q = oo - c[m]
            with np.errstate(divide="ignore", invalid="ignore"):   # parallel rays: NaN, no hit
                t = ((c[m] - oo) @ nrm[m]) / dn
                pu = q @ u[m] + t * (dd @ u[m])
                pv = q @ v[m] + t * (dd @ v[m])
            hit = (t > t_min) & (np.abs(pu) <= h[m, 0]) & (np.abs(pv) <= h[m, 1])
            closer = hit & (t < best[a0:a1])
            if closer.any():
                best[a0:a1] = np.where(closer, t, best[a0:a1])
                best_i[a0:a1] = np.where(closer, m, best_i[a0:a1])
    dist = np.empty(n)
    idx = np.empty(n, dtype=np.int64)
    dist[order] = best
    idx[order] = best_i
    return dist, idx
