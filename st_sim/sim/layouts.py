"""Synthetic layouts that need no data: a four-way crossing, a bidirectional corridor and a bottleneck."""

from __future__ import annotations

import numpy as np

from st_sim.sim.layout import Layout, Region, rasterise

GATE_DEPTH_M = 1.5  # depth of the entry/exit strips at the open ends of a layout [m]
MARGIN_M = 0.5  # raster margin around the walls [m]


def _box(xmin: float, ymin: float, xmax: float, ymax: float) -> np.ndarray:
    """(4, 2) counter-clockwise rectangle [m]."""
    return np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], dtype=np.float64)


def _build(name: str, free_polygon_m: np.ndarray, entries: list[Region], exits: list[Region],
           ego_start_m: tuple[float, float], ego_goal_m: tuple[float, float]) -> Layout:
    lo, hi = free_polygon_m.min(axis=0) - MARGIN_M, free_polygon_m.max(axis=0) + MARGIN_M
    bounds_m = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    scene, walls_m = rasterise(name, free_polygon_m, bounds_m)
    return Layout(name=name, walls_m=walls_m, entries=entries, exits=exits, bounds_m=bounds_m,
                  scene=scene, ego_start_m=np.array(ego_start_m), ego_goal_m=np.array(ego_goal_m))


def corridor(length_m: float = 20.0, width_m: float = 8.0) -> Layout:
    """Closed corridor with a gate strip at each end; pedestrians walk to the opposite end (two flows)."""
    gates = [Region("west", _box(0.0, 0.0, GATE_DEPTH_M, width_m)),
             Region("east", _box(length_m - GATE_DEPTH_M, 0.0, length_m, width_m))]
    return _build("corridor", _box(0.0, 0.0, length_m, width_m), gates, gates,
                  (GATE_DEPTH_M + 1.0, width_m / 2), (length_m - GATE_DEPTH_M - 1.0, width_m / 2))


def crossing(size_m: float = 20.0, arm_width_m: float = 6.0) -> Layout:
    """Two corridors crossing at right angles (a plus sign); pedestrians go from any arm to any other."""
    a, b, s = (size_m - arm_width_m) / 2, (size_m + arm_width_m) / 2, size_m
    plus = np.array([[a, 0], [b, 0], [b, a], [s, a], [s, b], [b, b], [b, s], [a, s], [a, b], [0, b], [0, a], [a, a]],
                    dtype=np.float64)
    d = GATE_DEPTH_M
    gates = [Region("south", _box(a, 0, b, d)), Region("east", _box(s - d, a, s, b)),
             Region("north", _box(a, s - d, b, s)), Region("west", _box(0, a, d, b))]
    return _build("crossing", plus, gates, gates, (s / 2, d + 1.0), (s / 2, s - d - 1.0))


def bottleneck(room_m: float = 8.5, wall_m: float = 1.0, height_m: float = 8.0, door_m: float = 1.2) -> Layout:
    """Two rooms joined by a door in a thick wall; everybody walks from the west room to the east room."""
    x1, x2, x3 = room_m, room_m + wall_m, 2 * room_m + wall_m
    y1, y2 = (height_m - door_m) / 2, (height_m + door_m) / 2
    free = np.array([[0, 0], [x1, 0], [x1, y1], [x2, y1], [x2, 0], [x3, 0], [x3, height_m], [x2, height_m],
                     [x2, y2], [x1, y2], [x1, height_m], [0, height_m]], dtype=np.float64)
    west = Region("west", _box(0.0, 0.0, GATE_DEPTH_M, height_m))
    east = Region("east", _box(x3 - GATE_DEPTH_M, 0.0, x3, height_m))
    return _build("bottleneck", free, [west], [east], (GATE_DEPTH_M + 1.0, height_m / 2),
                  (x3 - GATE_DEPTH_M - 1.0, height_m / 2))


SYNTHETIC = {"corridor": corridor, "crossing": crossing, "bottleneck": bottleneck}


def make_layout(name: str) -> Layout:
    """A layout by name: "corridor", "crossing", "bottleneck", or an ETH/UCY scene ("zara1", ...).

    Real scenes read their map from the data root (``replays.load_scene``).
    """
    if name in SYNTHETIC:
        return SYNTHETIC[name]()
    from replays.scenes import SCENE_NAMES, load_scene
    from st_sim.sim.map_walls import layout_from_scene

    if name not in SCENE_NAMES:
        raise KeyError(f"unknown layout {name!r}; expected one of {', '.join([*SYNTHETIC, *SCENE_NAMES])}")
    return layout_from_scene(load_scene(name))
