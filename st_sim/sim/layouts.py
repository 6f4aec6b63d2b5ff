"""Synthetic layouts that need no data: a four-way crossing, a bidirectional corridor, a bottleneck, a corner
and a periodic (wrap-around) corridor for the fundamental diagram; for the scripted encounters
(``st_sim.sim.encounters``), an open plaza and a doorway.

Every size is checked (finite, inside the stated range; ValueError naming the parameter otherwise), and the
raster refuses layouts beyond the memory budget (``checks.MEMORY_BUDGET_BYTES``). A layout whose gaps are too
narrow for a pedestrian is refused when a ``CrowdSim`` is built on it (no route from an entry to an exit).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from replays.scenes import Scene
from st_sim.sim.checks import Bounds, check_value
from st_sim.sim.layout import Layout, Period, Region, rasterise

GATE_DEPTH_M = 1.5  # depth of the entry/exit strips at the open ends of a layout [m]
MARGIN_M = 0.5  # raster margin around the walls [m]
PERIODIC_PAD_M = 2.0  # a periodic corridor's walls reach this far beyond both ends of the period [m]
LENGTH = Bounds(4.0, 100_000.0, "m")
"""lengths of corridors, arms and rooms: the memory budget bounds them first; below 4 m an entry gate lies within
MIN_ROUTE_M of every exit gate and nobody has anywhere to go"""
WIDTH = Bounds(0.5, 1_000.0, "m")  # widths of corridors and arms


def _box(xmin: float, ymin: float, xmax: float, ymax: float) -> np.ndarray:
    """(4, 2) counter-clockwise rectangle [m]."""
    return np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], dtype=np.float64)


def _check(layout: str, **sizes: tuple[float, Bounds]) -> None:
    for name, (value, bounds) in sizes.items():
        check_value(layout, name, value, bounds)


def _build(name: str, free_polygon_m: np.ndarray, entries: list[Region], exits: list[Region],
           ego_start_m: tuple[float, float], ego_goal_m: tuple[float, float]) -> Layout:
    lo, hi = free_polygon_m.min(axis=0) - MARGIN_M, free_polygon_m.max(axis=0) + MARGIN_M
    bounds_m = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    scene, walls_m = rasterise(name, free_polygon_m, bounds_m)
    return Layout(name=name, walls_m=walls_m, entries=entries, exits=exits, bounds_m=bounds_m,
                  scene=scene, ego_start_m=np.array(ego_start_m), ego_goal_m=np.array(ego_goal_m))


def corridor(length_m: float = 20.0, width_m: float = 8.0) -> Layout:
    """Closed corridor with a gate strip at each end; pedestrians walk to the opposite end (two flows).

    Args:
        length_m: 4 to 100 000 m (within the memory budget).  width_m: 0.5 to 1000 m.
    """
    _check("corridor", length_m=(length_m, LENGTH), width_m=(width_m, WIDTH))
    gates = [Region("west", _box(0.0, 0.0, GATE_DEPTH_M, width_m)),
             Region("east", _box(length_m - GATE_DEPTH_M, 0.0, length_m, width_m))]
    return _build("corridor", _box(0.0, 0.0, length_m, width_m), gates, gates,
                  (GATE_DEPTH_M + 1.0, width_m / 2), (length_m - GATE_DEPTH_M - 1.0, width_m / 2))


def crossing(size_m: float = 20.0, arm_width_m: float = 6.0) -> Layout:
    """Two corridors crossing at right angles (a plus sign); pedestrians go from any arm to any other.

    Args:
        size_m: 4 to 100 000 m, end to end.  arm_width_m: from 0.5 m to less than size_m.
    """
    arm = Bounds(WIDTH.low, size_m, f"m (below crossing.size_m = {size_m!r})", open_high=True)
    _check("crossing", size_m=(size_m, LENGTH), arm_width_m=(arm_width_m, arm))
    a, b, s = (size_m - arm_width_m) / 2, (size_m + arm_width_m) / 2, size_m
    plus = np.array([[a, 0], [b, 0], [b, a], [s, a], [s, b], [b, b], [b, s], [a, s], [a, b], [0, b], [0, a], [a, a]],
                    dtype=np.float64)
    d = GATE_DEPTH_M
    gates = [Region("south", _box(a, 0, b, d)), Region("east", _box(s - d, a, s, b)),
             Region("north", _box(a, s - d, b, s)), Region("west", _box(0, a, d, b))]
    return _build("crossing", plus, gates, gates, (s / 2, d + 1.0), (s / 2, s - d - 1.0))


def bottleneck(room_m: float = 8.5, wall_m: float = 1.0, height_m: float = 8.0, door_m: float = 1.2) -> Layout:
    """Two rooms joined by a door in a thick wall; everybody walks from the west room to the east room.

    Args:
        room_m: depth of each room, 4 to 100 000 m.  wall_m: thickness of the wall, 0.05 to 100 m.
        height_m: 0.5 to 1000 m.  door_m: door width, more than 0 and less than height_m [m].
    """
    door = Bounds(0.0, height_m, f"m (below bottleneck.height_m = {height_m!r})", open_low=True, open_high=True)
    _check("bottleneck", room_m=(room_m, LENGTH), wall_m=(wall_m, Bounds(0.05, 100.0, "m")),
           height_m=(height_m, WIDTH), door_m=(door_m, door))
    x1, x2, x3 = room_m, room_m + wall_m, 2 * room_m + wall_m
    y1, y2 = (height_m - door_m) / 2, (height_m + door_m) / 2
    free = np.array([[0, 0], [x1, 0], [x1, y1], [x2, y1], [x2, 0], [x3, 0], [x3, height_m], [x2, height_m],
                     [x2, y2], [x1, y2], [x1, height_m], [0, height_m]], dtype=np.float64)
    west = Region("west", _box(0.0, 0.0, GATE_DEPTH_M, height_m))
    east = Region("east", _box(x3 - GATE_DEPTH_M, 0.0, x3, height_m))
    return _build("bottleneck", free, [west], [east], (GATE_DEPTH_M + 1.0, height_m / 2),
                  (x3 - GATE_DEPTH_M - 1.0, height_m / 2))


def corner(arm_m: float = 12.0, width_m: float = 2.0) -> Layout:
    """A corridor that turns left by 90 degrees (RiMEA test 6): walk in from the west end, out at the north end.

    Args:
        arm_m: length of each arm, outer side, 4 to 100 000 m.  width_m: 0.5 m to arm_m - GATE_DEPTH_M.
    """
    width = Bounds(WIDTH.low, arm_m - GATE_DEPTH_M, f"m (corner.arm_m = {arm_m!r} minus {GATE_DEPTH_M:g} m)")
    _check("corner", arm_m=(arm_m, LENGTH), width_m=(width_m, width))
    a, w = arm_m, width_m
    free = np.array([[0, 0], [a, 0], [a, a], [a - w, a], [a - w, w], [0, w]], dtype=np.float64)
    west = Region("west", _box(0.0, 0.0, GATE_DEPTH_M, w))
    north = Region("north", _box(a - w, a - GATE_DEPTH_M, a, a))
    return _build("corner", free, [west], [north], (GATE_DEPTH_M + 0.5, w / 2), (a - w / 2, a - GATE_DEPTH_M - 0.5))


def periodic_corridor(length_m: float = 20.0, width_m: float = 4.0, two_way: bool = False) -> Layout:
    """A straight corridor whose ends are joined (wrap-around along x): the fundamental-diagram set-up.

    Pedestrians walk east for ever (two_way: each one east or west at random); nobody enters or leaves.
    The walls (the bottom and top edges only) run along y = 0 and y = width_m, PERIODIC_PAD_M beyond both ends
    of the period [0, length_m).

    Args:
        length_m: period, 4 to 100 000 m.  width_m: 0.5 to 1000 m.
    """
    _check("periodic_corridor", length_m=(length_m, LENGTH), width_m=(width_m, WIDTH))
    pad, name = PERIODIC_PAD_M, "periodic_corridor"
    bounds_m = (-pad - MARGIN_M, -MARGIN_M, length_m + pad + MARGIN_M, width_m + MARGIN_M)
    scene, walls_m = rasterise(name, _box(-pad, 0.0, length_m + pad, width_m), bounds_m)
    exits = [Region("east", _box(length_m - GATE_DEPTH_M, 0.0, length_m, width_m))]
    if two_way:
        exits.append(Region("west", _box(0.0, 0.0, GATE_DEPTH_M, width_m)))
    return Layout(name=name, walls_m=walls_m[[0, 2]], entries=[], exits=exits, bounds_m=bounds_m, scene=scene,
                  ego_start_m=np.array([1.0, width_m / 2]), ego_goal_m=np.array([length_m - 1.0, width_m / 2]),
                  period=Period(0.0, float(length_m)))


def plaza(size_m: float = 30.0) -> Layout:
    """An open square room with a gate strip along its south and north walls; pedestrians cross it between them.

    Away from the side walls a pedestrian's way to a gate runs straight along y, whatever its x: the scripted
    encounters use this to send people along known lines. The ego's default route runs up the middle.

    Args:
        size_m: side, 4 to 100 000 m.
    """
    _check("plaza", size_m=(size_m, LENGTH))
    gates = [Region("south", _box(0.0, 0.0, size_m, GATE_DEPTH_M)),
             Region("north", _box(0.0, size_m - GATE_DEPTH_M, size_m, size_m))]
    return _build("plaza", _box(0.0, 0.0, size_m, size_m), gates, gates,
                  (size_m / 2, GATE_DEPTH_M + 1.0), (size_m / 2, size_m - GATE_DEPTH_M - 1.0))


def doorway(room_m: float = 10.0, wall_m: float = 0.3, height_m: float = 8.0, door_m: float = 1.2) -> Layout:
    """The bottleneck's two rooms and door (``bottleneck``, same arguments and ranges), with gates that lead both
    ways: pedestrians walk from either room to the other, through the door."""
    rooms = bottleneck(room_m, wall_m, height_m, door_m)
    gates = rooms.entries + rooms.exits  # west, east
    return replace(rooms, name="doorway", entries=gates, exits=gates, routes=(),
                   scene=Scene("doorway", rooms.scene.H, rooms.scene.walkable))


SYNTHETIC = {"corridor": corridor, "crossing": crossing, "bottleneck": bottleneck, "corner": corner,
             "periodic_corridor": periodic_corridor}
ENCOUNTER_LAYOUTS = {"plaza": plaza, "doorway": doorway}
"""layouts of the scripted encounters (``st_sim.sim.encounters``); ``make_layout`` builds them by name too"""


def make_layout(name: str) -> Layout:
    """A layout by name: "corridor", "crossing", "bottleneck", "corner", "periodic_corridor", "plaza", "doorway", or
    an ETH/UCY scene ("zara1", ...).

    Real scenes read their map from the data root (``replays.load_scene``).
    """
    if name in SYNTHETIC or name in ENCOUNTER_LAYOUTS:
        return {**SYNTHETIC, **ENCOUNTER_LAYOUTS}[name]()
    from replays.scenes import SCENE_NAMES, load_scene
    from st_sim.sim.map_walls import layout_from_scene

    if name not in SCENE_NAMES:
        raise KeyError(f"unknown layout {name!r}; expected one of "
                       f"{', '.join([*SYNTHETIC, *ENCOUNTER_LAYOUTS, *SCENE_NAMES])}")
    return layout_from_scene(load_scene(name))
