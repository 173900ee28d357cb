"""Scenes: static structure, moving objects and the rig's nominal path.

Static structure is a set of finite rectangles (walls, floors, ceilings, box faces) that the
lidar ray-casts against and that are sampled as radar point scatterers, plus isolated point
reflectors (lamps, pipes, signs). Moving objects (people, carts) carry their own scatterers and
a box the lidar sees, and follow an analytic path (:mod:`.paths`).

Radar scattering model (per scatterer k, in ADC counts at 1 m before the ``1/R²`` falloff)::

    a_k = A_radar · s_k · g_k(θ) · e^{jϕ_k}

with ``s_k = sqrt(ρ·dA)`` for a surface sample (ρ: the surface's backscatter coefficient at
normal incidence, dA: the area the sample stands for) or ``sqrt(σ)`` for a point reflector (σ
its RCS [m²]), ``g_k(θ) = |cos θ|`` the incidence-angle falloff of a diffuse surface (1 for
point reflectors), ``ϕ_k`` a fixed random phase (speckle) and ``A_radar`` the radar's gain.

Scenes are plain JSON files (``docs/simulator.md``); :func:`scene_from_dict` builds one,
:meth:`Scene.to_dict` writes it back.
"""

from __future__ import annotations

import json
import os
import re
import zlib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path as FsPath

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import ColoradarError, MissingDataError, SettingsError
from ..formats.source import read_file_text
from .paths import Path, path_from_dict
from .raycast import RectArrays

__all__ = [
    "Box",
    "MovingObject",
    "Rect",
    "Reflector",
    "Scatterers",
    "Scene",
    "load_scene",
    "scene_from_dict",
]


def _unit(v, what: str) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(3)
    n = np.linalg.norm(v)
    if not n > 0:
        raise SettingsError(f"{what}: zero-length direction")
    return v / n


@dataclass(frozen=True, eq=False)
class Rect:
    """A finite flat rectangle.

    Attributes
    ----------
    center
        ``(3,)`` [m].
    u, v
        ``(3,)`` orthonormal in-plane axes (``v`` is orthogonalised against ``u``).
    size
        ``(2,)`` full lengths along ``u`` and ``v`` [m].
    reflectivity
        Radar backscatter coefficient ρ at normal incidence [m²/m²] (concrete ≈ 0.05–0.2,
        metal ≈ 0.3–1).
    lidar_reflectivity
        Fraction of the lidar's light returned, in [0, 1].
    one_sided
        True for faces of a solid (seen only from the side their normal ``u × v`` points to).
    name
        For the scene file and the truth file.
    """

    center: np.ndarray
    u: np.ndarray
    v: np.ndarray
    size: np.ndarray
    reflectivity: float = 0.1
    lidar_reflectivity: float = 0.4
    one_sided: bool = False
    name: str = ""

    def __post_init__(self) -> None:
        u = _unit(self.u, f"rect {self.name!r} u")
        v = np.asarray(self.v, dtype=np.float64).reshape(3)
        v = _unit(v - (v @ u) * u, f"rect {self.name!r} v")
        object.__setattr__(self, "center", np.asarray(self.center, dtype=np.float64).reshape(3))
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "v", v)
        object.__setattr__(self, "size", np.asarray(self.size, dtype=np.float64).reshape(2))
        if np.any(self.size <= 0):
            raise SettingsError(f"rect {self.name!r}: size must be positive")

    @property
    def normal(self) -> np.ndarray:
        return np.cross(self.u, self.v)

    def to_dict(self) -> dict:
        return {"center": self.center.tolist(), "u": self.u.tolist(), "v": self.v.tolist(),
                "size": self.size.tolist(), "reflectivity": self.reflectivity,
                "lidar_reflectivity": self.lidar_reflectivity, "one_sided": self.one_sided,
                "name": self.name}


@dataclass(frozen=True, eq=False)
class Box:
    """A solid box standing upright, turned by ``yaw`` about z.

    Attributes
    ----------
    center
        ``(3,)`` [m].
    size
        ``(3,)`` full lengths along its own x, y, z [m].
    yaw
        [rad].
    reflectivity, lidar_reflectivity
        As for :class:`Rect`.
    edge_rcs
        RCS [m²] of each point sampled along its vertical edges (edges and corners are strong
        radar reflectors); 0 for none.
    name
        Label.
    """

    center: np.ndarray
    size: np.ndarray
    yaw: float = 0.0
    reflectivity: float = 0.2
    lidar_reflectivity: float = 0.5
    edge_rcs: float = 0.02
    name: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", np.asarray(self.center, dtype=np.float64).reshape(3))
        object.__setattr__(self, "size", np.asarray(self.size, dtype=np.float64).reshape(3))
        if np.any(self.size <= 0):
            raise SettingsError(f"box {self.name!r}: size must be positive")

    def faces(self) -> list[Rect]:
        """The six faces, normals pointing out (the bottom one left out when on the floor)."""
        rot = Rotation.from_euler("z", self.yaw).as_matrix()
        ex, ey, ez = rot[:, 0], rot[:, 1], rot[:, 2]
        hx, hy, hz = self.size / 2
        c = self.center
        spec = [  # (normal axis, offset, u, v, size)
            (ex, hx, ey, ez, (2 * hy, 2 * hz)), (-ex, hx, -ey, ez, (2 * hy, 2 * hz)),
            (ey, hy, -ex, ez, (2 * hx, 2 * hz)), (-ey, hy, ex, ez, (2 * hx, 2 * hz)),
            (ez, hz, ex, ey, (2 * hx, 2 * hy)), (-ez, hz, ey, ex, (2 * hy, 2 * hx)),
        ]
        faces = []
        for i, (n, off, u, v, size) in enumerate(spec):
            if i == 5 and c[2] - hz <= 0.01:
                continue  # resting on the floor: its bottom is never seen
            faces.append(Rect(c + n * off, u, v, np.array(size), self.reflectivity,
                              self.lidar_reflectivity, True, f"{self.name}:face{i}"))
        return faces

    def vertical_edges(self) -> np.ndarray:
        """float64 ``(4, 2, 3)``: bottom and top end of the four vertical edges [m]."""
        rot = Rotation.from_euler("z", self.yaw).as_matrix()
        hx, hy, hz = self.size / 2
        corners = np.array([[sx * hx, sy * hy] for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))])
        xy = corners @ rot[:2, :2].T + self.center[:2]
        lo = np.column_stack([xy, np.full(4, self.center[2] - hz)])
        hi = np.column_stack([xy, np.full(4, self.center[2] + hz)])
        return np.stack([lo, hi], axis=1)

    def to_dict(self) -> dict:
        return {"center": self.center.tolist(), "size": self.size.tolist(),
                "yaw_deg": float(np.degrees(self.yaw)), "reflectivity": self.reflectivity,
                "lidar_reflectivity": self.lidar_reflectivity, "edge_rcs": self.edge_rcs,
                "name": self.name}


@dataclass(frozen=True, eq=False)
class Reflector:
    """An isolated point scatterer (lamp, pipe flange, sign post), seen from every direction."""

    position: np.ndarray
    rcs: float = 0.1
    name: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "position",
                           np.asarray(self.position, dtype=np.float64).reshape(3))

    def to_dict(self) -> dict:
        return {"position": self.position.tolist(), "rcs": self.rcs, "name": self.name}


@dataclass(frozen=True, eq=False)
class Scatterers:
    """Point scatterers in some frame, at one or more times.

    Attributes
    ----------
    position
        float64 ``(..., K, 3)`` [m].
    velocity
        float64 ``(..., K, 3)`` [m/s] (zeros for static structure).
    normal
        float64 ``(..., K, 3)``: unit surface normal, or zeros for an isotropic scatterer.
    one_sided
        bool ``(K,)``: seen only from the side the normal points to.
    strength
        float64 ``(K,)``: ``sqrt(ρ·dA)`` or ``sqrt(σ)`` [m].
    phase
        float64 ``(K,)``: fixed speckle phase [rad].
    ident
        int64 ``(K,)``: a scene-wide identifier (static ones 0..; object ones offset).
    """

    position: np.ndarray
    velocity: np.ndarray
    normal: np.ndarray
    one_sided: np.ndarray
    strength: np.ndarray
    phase: np.ndarray
    ident: np.ndarray

    def __len__(self) -> int:
        return int(self.strength.size)


# A walking person in its own frame (x forward, y left, z up, origin between the feet):
# (x, y, z, normal axis (0 none, ±1 ±x, ±2 ±y), swing amplitude [m] along x, swing phase, rcs)
_PERSON_POINTS = np.array([
    # torso front / back / sides
    (0.14, 0.1, 1.05, 1, 0, 0, 0.06), (0.14, -0.1, 1.05, 1, 0, 0, 0.06),
    (0.14, 0.1, 1.35, 1, 0, 0, 0.06), (0.14, -0.1, 1.35, 1, 0, 0, 0.06),
    (-0.14, 0.1, 1.05, -1, 0, 0, 0.06), (-0.14, -0.1, 1.05, -1, 0, 0, 0.06),
    (-0.14, 0.1, 1.35, -1, 0, 0, 0.06), (-0.14, -0.1, 1.35, -1, 0, 0, 0.06),
    (0.0, 0.2, 1.2, 2, 0, 0, 0.04), (0.0, -0.2, 1.2, -2, 0, 0, 0.04),
    # head
    (0.0, 0.0, 1.62, 0, 0, 0, 0.04),
    # arms: elbow and hand, opposite to the leg on the same side
    (0.0, 0.24, 1.1, 0, 0.10, np.pi, 0.02), (0.0, 0.26, 0.85, 0, 0.25, np.pi, 0.03),
    (0.0, -0.24, 1.1, 0, 0.10, 0, 0.02), (0.0, -0.26, 0.85, 0, 0.25, 0, 0.03),
    # legs: knee, shin and foot
    (0.05, 0.1, 0.5, 0, 0.15, 0, 0.04), (0.02, 0.1, 0.25, 0, 0.25, 0, 0.03),
    (0.0, 0.1, 0.08, 0, 0.35, 0, 0.02),
    (0.05, -0.1, 0.5, 0, 0.15, np.pi, 0.04), (0.02, -0.1, 0.25, 0, 0.25, np.pi, 0.03),
    (0.0, -0.1, 0.08, 0, 0.35, np.pi, 0.02),
])


@dataclass(frozen=True, eq=False)
class MovingObject:
    """An object that moves along an analytic path.

    Attributes
    ----------
    kind
        ``"person"`` (walking: torso, head, swinging arms and legs — micro-Doppler) or
        ``"box"`` (a rigid cart or vehicle sampled like a static box).
    path
        Its path; the position is the object's ground point, the heading its x axis.
    size
        ``(3,)`` depth (along the heading), width, height [m]: the box the lidar sees.
    rcs
        Person: total RCS [m²] (split over its points). Box: RCS of each edge point.
    reflectivity, lidar_reflectivity
        For box faces.
    gait_frequency
        Stride frequency of a person [Hz] (one swing period of a limb).
    name
        Label.
    """

    kind: str
    path: Path
    size: np.ndarray = field(default_factory=lambda: np.array([0.3, 0.5, 1.75]))
    rcs: float = 1.0
    reflectivity: float = 0.3
    lidar_reflectivity: float = 0.3
    gait_frequency: float = 0.9
    name: str = ""

    def __post_init__(self) -> None:
        if self.kind not in ("person", "box"):
            raise SettingsError(f"object {self.name!r}: kind must be 'person' or 'box', "
                                f"got {self.kind!r}")
        object.__setattr__(self, "size", np.asarray(self.size, dtype=np.float64).reshape(3))

    @cached_property
    def _local(self) -> dict[str, np.ndarray]:
        """Scatterers in the object's frame (and their swing), sampled once."""
        if self.kind == "person":
            p = _PERSON_POINTS
            axis = p[:, 3].astype(int)
            normal = np.zeros((len(p), 3))
            normal[np.abs(axis) == 1, 0] = np.sign(axis[np.abs(axis) == 1])
            normal[np.abs(axis) == 2, 1] = np.sign(axis[np.abs(axis) == 2])
            scale = self.size[2] / 1.75
            rcs = p[:, 6] * self.rcs / p[:, 6].sum()
            return {"pos": p[:, :3] * [1, 1, scale], "normal": normal, "swing": p[:, 4],
                    "swing_phase": p[:, 5], "strength": np.sqrt(rcs)}
        box = Box(np.array([0, 0, self.size[2] / 2]), self.size, 0.0, self.reflectivity,
                  self.lidar_reflectivity, self.rcs, self.name)
        s = _sample_rects(box.faces(), 0.3, np.random.default_rng(0))
        e = _sample_edges([box], 0.3)
        pos = np.vstack([s["pos"], e["pos"]])
        return {"pos": pos, "normal": np.vstack([s["normal"], e["normal"]]),
                "swing": np.zeros(len(pos)), "swing_phase": np.zeros(len(pos)),
                "strength": np.concatenate([s["strength"], e["strength"]])}

    @property
    def num_scatterers(self) -> int:
        return len(self._local["pos"])

    def scatterers(self, t: np.ndarray, ident_offset: int = 0) -> Scatterers:
        """The object's scatterers at times ``t`` (``(T,)`` [s]): arrays ``(T, K, ...)``, world."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        ps = self.path.sample(t)
        loc = self._local
        moving = float(np.linalg.norm(ps.velocity, axis=1).max(initial=0.0)) > 0
        w = 2 * np.pi * self.gait_frequency if moving else 0.0
        arg = w * t[:, None] + loc["swing_phase"][None, :]                       # (T, K)
        local = np.broadcast_to(loc["pos"], (t.size, *loc["pos"].shape)).copy()
        local[..., 0] += loc["swing"] * np.sin(arg)
        local_vel = np.zeros_like(local)
        local_vel[..., 0] = loc["swing"] * w * np.cos(arg)
        rot = Rotation.from_euler("z", ps.heading[:, None])
        mats = rot.as_matrix()                                                   # (T, 3, 3)
        r_world = np.einsum("tij,tkj->tki", mats, local)
        # Rigid rotation about z at the heading rate, plus the limbs' own swing.
        omega = np.zeros((t.size, 3))
        omega[:, 2] = ps.heading_rate
        vel = (ps.velocity[:, None, :] + np.einsum("tij,tkj->tki", mats, local_vel)
               + np.cross(omega[:, None, :], r_world))
        normal = np.einsum("tij,tkj->tki", mats, np.broadcast_to(loc["normal"], local.shape))
        k = len(loc["pos"])
        return Scatterers(ps.position[:, None, :] + r_world, vel, normal,
                          np.linalg.norm(loc["normal"], axis=1) > 0, loc["strength"],
                          _speckle_phases(k, f"{self.kind}:{self.name}"),
                          ident_offset + np.arange(k))

    def rects(self, t: np.ndarray, owner: int) -> RectArrays:
        """The object's box faces at times ``t``: geometry ``(T, 5, ...)``."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        ps = self.path.sample(t)
        faces = Box(np.array([0, 0, self.size[2] / 2]), self.size, 0.0).faces()
        rot = Rotation.from_euler("z", ps.heading[:, None]).as_matrix()                  # (T, 3, 3)

        def world(vecs, offset=None):
            out = np.einsum("tij,mj->tmi", rot, vecs)
            return out + offset[:, None, :] if offset is not None else out

        c = world(np.array([f.center for f in faces]), ps.position)
        m = len(faces)
        return RectArrays(c, world(np.array([f.u for f in faces])),
                          world(np.array([f.v for f in faces])),
                          world(np.array([f.normal for f in faces])),
                          np.broadcast_to(np.array([f.size / 2 for f in faces]),
                                          (t.size, m, 2)).copy(),
                          np.full(m, self.lidar_reflectivity), np.full(m, owner, dtype=np.int64))

    def to_dict(self) -> dict:
        return {"kind": self.kind, "path": self.path.to_dict(), "size": self.size.tolist(),
                "rcs": self.rcs, "reflectivity": self.reflectivity,
                "lidar_reflectivity": self.lidar_reflectivity,
                "gait_frequency": self.gait_frequency, "name": self.name}


def _speckle_phases(n: int, key: str) -> np.ndarray:
    # A stable seed from the object's label: the same object keeps its phases from run to run.
    return np.random.default_rng(zlib.crc32(key.encode())).uniform(0, 2 * np.pi, n)


def _sample_rects(rects: list[Rect], spacing: float, rng: np.random.Generator) -> dict:
    """Jittered grid samples of rectangles: one scatterer per cell of about ``spacing``²."""
    pos, normal, strength, one_sided = [], [], [], []
    for r in rects:
        nu = max(1, int(np.ceil(r.size[0] / spacing)))
        nv = max(1, int(np.ceil(r.size[1] / spacing)))
        cu, cv = r.size[0] / nu, r.size[1] / nv
        iu, iv = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
        # Jitter within the cell breaks the grid's regularity (no grating lobes in the data).
        a = (iu.ravel() + 0.5 + rng.uniform(-0.4, 0.4, iu.size)) * cu - r.size[0] / 2
        b = (iv.ravel() + 0.5 + rng.uniform(-0.4, 0.4, iv.size)) * cv - r.size[1] / 2
        pos.append(r.center + a[:, None] * r.u + b[:, None] * r.v)
        normal.append(np.broadcast_to(r.normal, (a.size, 3)))
        strength.append(np.full(a.size, np.sqrt(r.reflectivity * cu * cv)))
        one_sided.append(np.full(a.size, r.one_sided))
    if not pos:
        return {"pos": np.zeros((0, 3)), "normal": np.zeros((0, 3)), "strength": np.zeros(0),
                "one_sided": np.zeros(0, bool)}
    return {"pos": np.vstack(pos), "normal": np.vstack(normal),
            "strength": np.concatenate(strength), "one_sided": np.concatenate(one_sided)}


def _sample_edges(boxes: list[Box], spacing: float) -> dict:
    pos, strength = [], []
    for b in boxes:
        if b.edge_rcs <= 0:
            continue
        ends = b.vertical_edges()
        n = max(2, int(np.ceil(b.size[2] / spacing)) + 1)
        f = np.linspace(0.02, 0.98, n)
        for lo, hi in ends:
            pos.append(lo + f[:, None] * (hi - lo))
            strength.append(np.full(n, np.sqrt(b.edge_rcs)))
    if not pos:
        return {"pos": np.zeros((0, 3)), "normal": np.zeros((0, 3)), "strength": np.zeros(0)}
    p = np.vstack(pos)
    return {"pos": p, "normal": np.zeros_like(p), "strength": np.concatenate(strength)}


@dataclass(frozen=True, eq=False)
class Scene:
    """A simulated environment.

    Attributes
    ----------
    name, description
        Labels (the name goes into the run's name).
    rig_path
        The rig's nominal path (:mod:`.paths`).
    rects
        Two-sided static rectangles (walls, floor, ceiling).
    boxes
        Solid static boxes (cabinets, pillars, parked cars, timber sets).
    reflectors
        Isolated point reflectors.
    objects
        Moving objects.
    spacing
        Radar scatterer spacing on surfaces [m].
    seed
        Seed of the scatterer sampling (jitter and speckle phases): part of the scene.
    """

    name: str
    rig_path: Path
    rects: tuple[Rect, ...] = ()
    boxes: tuple[Box, ...] = ()
    reflectors: tuple[Reflector, ...] = ()
    objects: tuple[MovingObject, ...] = ()
    spacing: float = 0.3
    seed: int = 1
    description: str = ""

    @cached_property
    def static_rects(self) -> list[Rect]:
        """All static rectangles: the scene's own plus every box face."""
        out = list(self.rects)
        for b in self.boxes:
            out.extend(b.faces())
        return out

    @cached_property
    def static_rect_arrays(self) -> RectArrays:
        """:attr:`static_rects` as arrays (group size 1), owner -1."""
        rs = self.static_rects
        if not rs:
            return RectArrays.empty()
        return RectArrays(np.array([r.center for r in rs])[None], np.array([r.u for r in rs])[None],
                          np.array([r.v for r in rs])[None], np.array([r.normal for r in rs])[None],
                          np.array([r.size / 2 for r in rs])[None],
                          np.array([r.lidar_reflectivity for r in rs]),
                          np.full(len(rs), -1, dtype=np.int64))

    @cached_property
    def static_scatterers(self) -> Scatterers:
        """Radar scatterers of the static structure, world frame, sampled once per scene."""
        rng = np.random.default_rng(self.seed)
        s = _sample_rects(self.static_rects, self.spacing, rng)
        e = _sample_edges(list(self.boxes), self.spacing)
        refl = self.reflectors
        pos = np.vstack([s["pos"], e["pos"], np.array([r.position for r in refl]).reshape(-1, 3)])
        n_iso = len(e["pos"]) + len(refl)
        normal = np.vstack([s["normal"], np.zeros((n_iso, 3))])
        strength = np.concatenate([s["strength"], e["strength"],
                                   np.sqrt([r.rcs for r in refl])])
        one_sided = np.concatenate([s["one_sided"], np.zeros(n_iso, bool)])
        k = len(pos)
        return Scatterers(pos, np.zeros_like(pos), normal, one_sided, strength,
                          rng.uniform(0, 2 * np.pi, k), np.arange(k))

    def object_ident_offsets(self) -> list[int]:
        """First scatterer identifier of each moving object (after the static ones)."""
        offs, cur = [], len(self.static_scatterers)
        for o in self.objects:
            offs.append(cur)
            cur += o.num_scatterers
        return offs

    def object_scatterers(self, t: float) -> Scatterers:
        """All moving objects' scatterers at time ``t`` [s], world frame, ``(K, ...)``."""
        parts = [o.scatterers(np.array([t]), off)
                 for o, off in zip(self.objects, self.object_ident_offsets(), strict=True)]
        if not parts:
            z = np.zeros((0, 3))
            return Scatterers(z, z, z, np.zeros(0, bool), np.zeros(0), np.zeros(0),
                              np.zeros(0, dtype=np.int64))

        def cat(name: str, per_time: bool) -> np.ndarray:
            # Per-time arrays are (1, K, 3) for the single time asked for.
            return np.concatenate([getattr(p, name)[0] if per_time else getattr(p, name)
                                   for p in parts])

        return Scatterers(cat("position", True), cat("velocity", True), cat("normal", True),
                          cat("one_sided", False), cat("strength", False), cat("phase", False),
                          cat("ident", False))

    def rect_arrays(self, t: np.ndarray) -> RectArrays:
        """Static rectangles plus the moving objects' boxes at times ``t`` (one group per time)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        parts = [self.static_rect_arrays]
        parts += [o.rects(t, i) for i, o in enumerate(self.objects)]
        return RectArrays.concatenate(parts)

    def to_dict(self) -> dict:
        """The scene as a JSON-ready dict (rooms expanded to rectangles)."""
        return {"name": self.name, "description": self.description, "spacing": self.spacing,
                "seed": self.seed, "rig_path": self.rig_path.to_dict(),
                "rects": [r.to_dict() for r in self.rects],
                "boxes": [b.to_dict() for b in self.boxes],
                "reflectors": [r.to_dict() for r in self.reflectors],
                "objects": [o.to_dict() for o in self.objects]}

    def to_json(self) -> str:
        """The scene file text: :meth:`to_dict` as JSON, number lists kept on one line."""
        text = json.dumps(self.to_dict(), indent=1)
        return re.sub(r"\[[^\[\]{}\"]*\]", lambda m: "[" + " ".join(m.group(0)[1:-1].split()) + "]",
                      text) + "\n"


def _room_rects(d: dict, where: str) -> list[Rect]:
    """Inner faces of an axis-aligned room ``{"min": [...], "max": [...]}``."""
    lo = np.asarray(d["min"], dtype=np.float64)
    hi = np.asarray(d["max"], dtype=np.float64)
    if lo.shape != (3,) or hi.shape != (3,) or np.any(hi <= lo):
        raise SettingsError(f"{where}: 'min' and 'max' must be 3 numbers each, max > min")
    c, s = (lo + hi) / 2, hi - lo
    rho = float(d.get("reflectivity", 0.1))
    lid = float(d.get("lidar_reflectivity", 0.4))
    rho_floor = float(d.get("floor_reflectivity", rho))
    name = d.get("name", "room")
    ex, ey, ez = np.eye(3)
    out = []
    if d.get("floor", True):
        out.append(Rect(np.array([c[0], c[1], lo[2]]), ex, ey, np.array([s[0], s[1]]), rho_floor, lid,
                        name=f"{name}:floor"))
    if d.get("ceiling", True):
        out.append(Rect(np.array([c[0], c[1], hi[2]]), ex, ey, np.array([s[0], s[1]]), rho, lid,
                        name=f"{name}:ceiling"))
    if d.get("walls", True):
        out += [Rect(np.array([lo[0], c[1], c[2]]), ey, ez, np.array([s[1], s[2]]), rho, lid,
                     name=f"{name}:wall-x"),
                Rect(np.array([hi[0], c[1], c[2]]), ey, ez, np.array([s[1], s[2]]), rho, lid,
                     name=f"{name}:wall+x"),
                Rect(np.array([c[0], lo[1], c[2]]), ex, ez, np.array([s[0], s[2]]), rho, lid,
                     name=f"{name}:wall-y"),
                Rect(np.array([c[0], hi[1], c[2]]), ex, ez, np.array([s[0], s[2]]), rho, lid,
                     name=f"{name}:wall+y")]
    return out


def scene_from_dict(d: dict, source: str = "<scene>") -> Scene:
    """Build a :class:`Scene` from its JSON description (``docs/simulator.md``).

    Raises :class:`~coloradar.errors.ColoradarError` naming ``source`` and the bad entry.
    """
    try:
        if "rig_path" not in d:
            raise SettingsError("missing 'rig_path'")
        rects: list[Rect] = []
        for i, room in enumerate(d.get("rooms", [])):
            rects += _room_rects(room, f"rooms[{i}]")
        for i, r in enumerate(d.get("rects", [])):
            try:
                rects.append(Rect(r["center"], r["u"], r["v"], r["size"],
                                  float(r.get("reflectivity", 0.1)),
                                  float(r.get("lidar_reflectivity", 0.4)),
                                  bool(r.get("one_sided", False)), r.get("name", f"rect{i}")))
            except (KeyError, TypeError, ValueError) as exc:
                raise SettingsError(f"rects[{i}]: {exc}") from None
        boxes = []
        for i, b in enumerate(d.get("boxes", [])):
            try:
                boxes.append(Box(b["center"], b["size"], np.radians(float(b.get("yaw_deg", 0))),
                                 float(b.get("reflectivity", 0.2)),
                                 float(b.get("lidar_reflectivity", 0.5)),
                                 float(b.get("edge_rcs", 0.02)), b.get("name", f"box{i}")))
            except (KeyError, TypeError, ValueError) as exc:
                raise SettingsError(f"boxes[{i}]: {exc}") from None
        refl = []
        for i, r in enumerate(d.get("reflectors", [])):
            try:
                refl.append(Reflector(r["position"], float(r.get("rcs", 0.1)),
                                      r.get("name", f"reflector{i}")))
            except (KeyError, TypeError, ValueError) as exc:
                raise SettingsError(f"reflectors[{i}]: {exc}") from None
        objs = []
        for i, o in enumerate(d.get("objects", [])):
            try:
                objs.append(MovingObject(o.get("kind", "person"),
                                         path_from_dict(o["path"], f"objects[{i}].path"),
                                         np.asarray(o.get("size", [0.3, 0.5, 1.75]), float),
                                         float(o.get("rcs", 1.0)),
                                         float(o.get("reflectivity", 0.3)),
                                         float(o.get("lidar_reflectivity", 0.3)),
                                         float(o.get("gait_frequency", 0.9)),
                                         o.get("name", f"object{i}")))
            except (KeyError, TypeError, ValueError) as exc:
                raise SettingsError(f"objects[{i}]: {exc}") from None
        spacing = float(d.get("spacing", 0.3))
        if not 0.02 <= spacing <= 5:
            raise SettingsError(f"spacing {spacing} m is outside 0.02..5 m")
        return Scene(str(d.get("name", "custom")), path_from_dict(d["rig_path"], "rig_path"),
                     tuple(rects), tuple(boxes), tuple(refl), tuple(objs), spacing,
                     int(d.get("seed", 1)), str(d.get("description", "")))
    except (ValueError, TypeError, AttributeError) as exc:
        raise ColoradarError(f"{source}: bad scene description: {exc}") from None


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Read a scene from a JSON file."""
    p = FsPath(path)
    try:
        d = json.loads(read_file_text(p))
    except MissingDataError:
        raise MissingDataError(f"{p}: no such scene file") from None
    except json.JSONDecodeError as exc:
        raise ColoradarError(f"{p}: not valid JSON ({exc})") from None
    if not isinstance(d, dict):
        raise ColoradarError(f"{p}: a scene file holds one JSON object")
    return scene_from_dict(d, str(p))
