"""Built-in scenes: an indoor corridor, an outdoor courtyard, a mine tunnel and a long
self-similar hallway.

Each is a scene description in the JSON schema of :func:`.scene.scene_from_dict` (so
``coloradar simulate --scene corridor --write-scene corridor.json`` gives a file to edit). All
are closed or bounded so that the rig's looping path never leaves them, whatever the duration.
Reflectivities are backscatter coefficients at normal incidence for 77 GHz (painted
plasterboard and concrete ~0.05–0.2, rock ~0.2–0.3, metal ~0.5–1).
"""

from __future__ import annotations

import copy

from ..errors import ColoradarError
from .scene import Scene, scene_from_dict

__all__ = ["SCENES", "builtin_scene", "builtin_scene_dict"]


def _corridor() -> dict:
    lights = [{"position": [x, 0.0, 2.75], "rcs": 0.1, "name": f"light{i}"}
              for i, x in enumerate(range(-9, 10, 3))]
    handles = [{"position": [x, 1.17, 1.0], "rcs": 0.05, "name": f"door_handle{i}"}
               for i, x in enumerate((-4.0, 0.5, 4.5))]
    cabinets = [{"center": [x, -1.0, 0.95], "size": [0.9, 0.4, 1.9], "reflectivity": 0.6,
                 "lidar_reflectivity": 0.6, "edge_rcs": 0.05, "name": f"cabinet{i}"}
                for i, x in enumerate((-5.0, 1.5, 5.5))]
    pillars = [{"center": [x, 1.05, 1.4], "size": [0.4, 0.3, 2.8], "reflectivity": 0.15,
                "edge_rcs": 0.03, "name": f"pillar{i}"} for i, x in enumerate((-8.0, 8.0))]
    return {
        "name": "corridor",
        "description": "Indoor corridor 20 m x 2.4 m x 2.8 m with metal cabinets, pillars, "
                       "ceiling lights and a person walking up and down.",
        "spacing": 0.3,
        "seed": 1,
        "rig_path": {"type": "ellipse", "center": [0.0, -0.15, 1.1], "radii": [7.0, 0.25],
                     "speed": 1.0, "ramp": 0.5},
        "rooms": [{"min": [-10, -1.2, 0], "max": [10, 1.2, 2.8], "reflectivity": 0.08,
                   "floor_reflectivity": 0.05, "lidar_reflectivity": 0.5, "name": "corridor"}],
        "boxes": cabinets + pillars,
        "reflectors": lights + handles,
        "objects": [{"kind": "person", "name": "walker",
                     "path": {"type": "line", "start": [-6, 0.8, 0], "end": [6, 0.8, 0],
                              "speed": 1.3}}],
    }


def _courtyard() -> dict:
    posts = [(5.0, -1.0), (-5.0, 1.0), (0.0, 7.0), (0.0, -7.0), (10.0, 6.0), (-10.0, -6.0)]
    boxes = [{"center": [x, y, 2.0], "size": [0.25, 0.25, 4.0], "reflectivity": 0.4,
              "edge_rcs": 0.05, "name": f"post{i}"} for i, (x, y) in enumerate(posts)]
    boxes += [
        {"center": [-10.0, 0.0, 0.75], "size": [1.8, 4.5, 1.5], "reflectivity": 1.0,
         "lidar_reflectivity": 0.7, "edge_rcs": 0.3, "name": "parked_car"},
        {"center": [0.0, -11.5, 0.25], "size": [1.8, 0.5, 0.5], "reflectivity": 0.3,
         "name": "bench0"},
        {"center": [13.5, 10.5, 0.3], "size": [1.5, 1.5, 0.6], "reflectivity": 0.15,
         "name": "planter0"},
        {"center": [-13.5, 10.5, 0.3], "size": [1.5, 1.5, 0.6], "reflectivity": 0.15,
         "name": "planter1"},
        {"center": [13.0, -9.0, 0.6], "size": [1.2, 2.5, 1.2], "yaw_deg": 30,
         "reflectivity": 0.8, "edge_rcs": 0.1, "name": "bike_shed"},
    ]
    lamps = [{"position": [x, y, 4.1], "rcs": 0.2, "name": f"lamp{i}"}
             for i, (x, y) in enumerate(posts)]
    return {
        "name": "courtyard",
        "description": "Outdoor courtyard 30 m x 24 m between 8 m building walls (no roof), "
                       "with lamp posts, a parked car, benches and two people walking.",
        "spacing": 0.45,
        "seed": 2,
        "rig_path": {"type": "ellipse", "center": [0.0, 0.0, 1.1], "radii": [8.0, 5.0],
                     "speed": 1.2, "ramp": 0.5},
        "rooms": [{"min": [-15, -12, 0], "max": [15, 12, 8], "ceiling": False,
                   "reflectivity": 0.15, "floor_reflectivity": 0.03, "lidar_reflectivity": 0.4,
                   "name": "courtyard"}],
        "boxes": boxes,
        "reflectors": lamps,
        "objects": [
            {"kind": "person", "name": "crossing",
             "path": {"type": "line", "start": [-4, -2, 0], "end": [4, 2, 0], "speed": 1.4}},
            {"kind": "person", "name": "stroller",
             "path": {"type": "ellipse", "center": [0, 0, 0], "radii": [12.0, 9.5],
                      "speed": 1.1, "clockwise": True, "phase_deg": 200}},
        ],
    }


def _mine() -> dict:
    boxes = []
    for i, x in enumerate(range(-13, 14, 3)):
        boxes += [
            {"center": [x, -1.875, 1.65], "size": [0.25, 0.25, 3.3], "reflectivity": 0.3,
             "edge_rcs": 0.05, "name": f"set{i}:post_l"},
            {"center": [x, 1.875, 1.65], "size": [0.25, 0.25, 3.3], "reflectivity": 0.3,
             "edge_rcs": 0.05, "name": f"set{i}:post_r"},
            {"center": [x, 0.0, 3.375], "size": [0.3, 3.5, 0.25], "reflectivity": 0.3,
             "edge_rcs": 0.02, "name": f"set{i}:cap"},
        ]
    boxes += [
        {"center": [0.0, 1.0, 2.9], "size": [29.0, 0.5, 0.5], "reflectivity": 0.8,
         "lidar_reflectivity": 0.6, "edge_rcs": 0.0, "name": "vent_duct"},
        {"center": [-6.0, -1.5, 0.3], "size": [1.2, 0.7, 0.6], "yaw_deg": 15,
         "reflectivity": 0.3, "name": "rock_pile0"},
        {"center": [7.5, -1.55, 0.25], "size": [1.5, 0.6, 0.5], "yaw_deg": -10,
         "reflectivity": 0.3, "name": "rock_pile1"},
    ]
    flanges = [{"position": [x, -1.9, 2.2], "rcs": 0.15, "name": f"pipe_flange{i}"}
               for i, x in enumerate(range(-14, 15, 4))]
    return {
        "name": "mine",
        "description": "Mine tunnel 30 m x 4 m x 3.5 m with timber sets every 3 m, a "
                       "ventilation duct, rock piles, pipe flanges and a cart moving through.",
        "spacing": 0.3,
        "seed": 3,
        "rig_path": {"type": "ellipse", "center": [0.0, 0.6, 1.1], "radii": [11.0, 0.25],
                     "speed": 0.9, "ramp": 0.5},
        "rooms": [{"min": [-15, -2, 0], "max": [15, 2, 3.5], "reflectivity": 0.25,
                   "floor_reflectivity": 0.1, "lidar_reflectivity": 0.25, "name": "tunnel"}],
        "boxes": boxes,
        "reflectors": flanges,
        "objects": [
            {"kind": "box", "name": "cart", "size": [2.5, 1.2, 1.5], "rcs": 0.3,
             "reflectivity": 0.8, "lidar_reflectivity": 0.5,
             "path": {"type": "line", "start": [-11, -0.5, 0], "end": [11, -0.5, 0],
                      "speed": 0.8, "phase_deg": 180}},
        ],
    }


def _hallway() -> dict:
    """A long corridor whose every 4 m look alike: the test of false loop closures."""
    bay = range(-18, 19, 4)
    boxes = [{"center": [x, s * 1.4, 1.05], "size": [1.0, 0.1, 2.1], "reflectivity": 0.5,
              "lidar_reflectivity": 0.5, "edge_rcs": 0.05, "name": f"door{i}{'lr'[s > 0]}"}
             for i, x in enumerate(bay) for s in (-1, 1)]
    boxes += [{"center": [x + 2.0, s * 1.3, 1.4], "size": [0.3, 0.2, 2.8], "reflectivity": 0.2,
               "edge_rcs": 0.03, "name": f"pilaster{i}{'lr'[s > 0]}"}
              for i, x in enumerate(bay[:-1]) for s in (-1, 1)]
    lights = [{"position": [x, 0.0, 2.75], "rcs": 0.1, "name": f"light{i}"}
              for i, x in enumerate(bay)]
    handles = [{"position": [x + 0.35, s * 1.33, 1.0], "rcs": 0.05, "name": f"handle{i}{'lr'[s > 0]}"}
               for i, x in enumerate(bay) for s in (-1, 1)]
    return {
        "name": "hallway",
        "description": "Long self-similar corridor 40 m x 3 m x 2.8 m: a door on each side, a "
                       "ceiling light and a pilaster every 4 m, and a person walking; the rig "
                       "walks it up and down (a closed path: --laps).",
        "spacing": 0.3,
        "seed": 4,
        "rig_path": {"type": "ellipse", "center": [0.0, 0.0, 1.1], "radii": [17.0, 0.3],
                     "speed": 1.2, "ramp": 0.5},
        "rooms": [{"min": [-20, -1.5, 0], "max": [20, 1.5, 2.8], "reflectivity": 0.08,
                   "floor_reflectivity": 0.05, "lidar_reflectivity": 0.5, "name": "hallway"}],
        "boxes": boxes,
        "reflectors": lights + handles,
        "objects": [{"kind": "person", "name": "walker",
                     "path": {"type": "line", "start": [-15, -0.9, 0], "end": [15, -0.9, 0],
                              "speed": 1.1}}],
    }


SCENES = {"corridor": _corridor, "courtyard": _courtyard, "mine": _mine, "hallway": _hallway}
"""Names of the built-in scenes."""


def builtin_scene_dict(name: str) -> dict:
    """The JSON description of a built-in scene (a fresh copy)."""
    if name not in SCENES:
        raise ColoradarError(f"unknown scene {name!r}; built-in scenes: {', '.join(SCENES)} "
                             "(or give a .json scene file)")
    return copy.deepcopy(SCENES[name]())


def builtin_scene(name: str) -> Scene:
    """A built-in :class:`~coloradar.sim.scene.Scene` by name."""
    return scene_from_dict(builtin_scene_dict(name), f"built-in scene {name!r}")
