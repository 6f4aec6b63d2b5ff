"""Layouts from real ETH/UCY scene geometry: walkability-map contours become walls, border openings gates.

The map's walkable region is traced with OpenCV (outer boundaries and holes), simplified, and mapped to
metres through the scene homography; every edge is a wall. Where the walkable region touches the image
border (or comes within a thin band of it), people walk in and out of view: those stretches become
entry/exit strips reaching gate_depth_m into the scene, split into pieces of at most max_gate_m.
"""

from __future__ import annotations

import numpy as np

from replays.scenes import Scene
from st_sim.sim.checks import Bounds, check_value
from st_sim.sim.layout import Layout, Region, polygon_edges

MIN_HOLE_M2 = 0.25  # contours enclosing less area than this are map noise [m^2]
MIN_GATE_M = 1.0  # border openings narrower than this are ignored [m]
MARGIN_M = 0.5  # bounds margin around the walls [m]
EGO_ROOM_M = 0.6  # the ego's start and goal, and the area joining them, keep this far from obstacles [m]
BORDER_BAND = 0.08  # walkable pixels this close to the image edge (share of the smaller side) count as at the border


def _metres_per_pixel(scene: Scene, uv_px: np.ndarray) -> np.ndarray:
    """(M, 2) pixels -> (M,) local scale [m/px] (mean of the two axis steps)."""
    uv_px = np.asarray(uv_px, dtype=np.float64)
    origin = scene.pixel_to_world(uv_px)
    du = np.linalg.norm(scene.pixel_to_world(uv_px + np.array([1.0, 0.0])) - origin, axis=-1)
    dv = np.linalg.norm(scene.pixel_to_world(uv_px + np.array([0.0, 1.0])) - origin, axis=-1)
    return (du + dv) / 2


def map_polygons(scene: Scene, simplify_m: float = 0.1) -> list[np.ndarray]:
    """Boundaries of the walkable region (outer contours and holes) as (P, 2) polygons in metres."""
    import cv2

    mask = scene.walkable.astype(np.uint8)
    contours, _ = cv2.findContours(mask, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    height, width = mask.shape
    scale = float(np.median(_metres_per_pixel(scene, np.array([[width / 2, height / 2]]))))
    polygons = []
    for contour in contours:
        simple = cv2.approxPolyDP(contour, simplify_m / scale, True).reshape(-1, 2).astype(np.float64)
        if len(simple) < 3:
            continue
        polygon_m = scene.pixel_to_world(simple)
        x, y = polygon_m[:, 0], polygon_m[:, 1]
        if 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) >= MIN_HOLE_M2:
            polygons.append(polygon_m)
    return polygons


def map_wall_segments(scene: Scene, simplify_m: float = 0.1) -> np.ndarray:
    """(K, 2, 2) the edges of ``map_polygons``: every boundary of the walkable region as a line segment [m]."""
    polygons = map_polygons(scene, simplify_m)
    return np.concatenate([polygon_edges(p) for p in polygons]) if polygons else np.zeros((0, 2, 2))


def _runs(profile: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index intervals [a, b) where the bool profile (L,) is True."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], profile.astype(np.int8), [0]])))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True))


def border_gates(scene: Scene, gate_depth_m: float = 1.5, max_gate_m: float = 4.0) -> list[Region]:
    """Strips along the image border where the walkable region leaves the image, as world polygons.

    Maps often stop a few pixels short of the image edge, so "at the border" means within a band of
    BORDER_BAND of the image's smaller side; a gate spans that band plus gate_depth_m inward.
    """
    walkable = scene.walkable
    height, width = walkable.shape
    band = max(1, round(BORDER_BAND * min(height, width)))
    sides = {  # name: (walkable somewhere in the band, along the side; pixel of index t at depth s)
        "top": (walkable[:band].any(axis=0), lambda t, s: np.stack([t, s], -1)),
        "bottom": (walkable[-band:].any(axis=0), lambda t, s: np.stack([t, height - 1 - s], -1)),
        "left": (walkable[:, :band].any(axis=1), lambda t, s: np.stack([s, t], -1)),
        "right": (walkable[:, -band:].any(axis=1), lambda t, s: np.stack([width - 1 - s, t], -1)),
    }
    gates = []
    for side, (profile, to_px) in sides.items():
        for a, b in _runs(profile):
            ends = scene.pixel_to_world(to_px(np.array([a, b - 1.0]), np.full(2, band / 2)))
            length_m = float(np.linalg.norm(ends[1] - ends[0]))
            if length_m < MIN_GATE_M:
                continue
            n_pieces = int(np.ceil(length_m / max_gate_m))
            cuts = np.linspace(a, b - 1.0, n_pieces + 1)
            depth_px = band + gate_depth_m / _metres_per_pixel(scene, to_px(cuts, np.full_like(cuts, band)))
            for k in range(n_pieces):
                t = np.array([cuts[k], cuts[k + 1], cuts[k + 1], cuts[k]])
                s = np.array([0.0, 0.0, depth_px[k + 1], depth_px[k]])
                gates.append(Region(f"{side}{len(gates)}", scene.pixel_to_world(to_px(t, s))))
    return gates


def ego_route(scene: Scene, gates: list[Region]) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal (2,) [m] of the ego: the two farthest-apart gates of the main open area.

    Each gate is represented by its roomiest point (farthest from obstacles and the image border). Only
    points with at least EGO_ROOM_M of room count, and both must lie in the largest area that such points
    form, so that the ego's route never squeezes through a gap narrower than about 2 x EGO_ROOM_M.
    """
    import cv2

    padded = np.pad(scene.walkable.astype(np.uint8), 1)  # the image border is a wall too
    room_px = cv2.distanceTransform(padded, cv2.DIST_L2, 5)[1:-1, 1:-1]
    v, u = np.nonzero(scene.walkable)
    xy_m = scene.pixel_to_world(np.stack([u, v], -1).astype(np.float64))
    roomy = room_px[v, u] * _metres_per_pixel(scene, np.stack([u, v], -1)) >= EGO_ROOM_M
    mask = np.zeros(scene.walkable.shape, np.uint8)
    mask[v[roomy], u[roomy]] = 1
    _, labels = cv2.connectedComponents(mask, connectivity=8)
    main = np.argmax(np.bincount(labels[v[roomy], u[roomy]]))
    in_main = roomy & (labels[v, u] == main)
    points = []
    for gate in gates:
        inside = in_main & gate.contains(xy_m)
        if inside.any():
            points.append(xy_m[np.argmax(np.where(inside, room_px[v, u], -1.0))])
    if len(points) < 2:
        return gates[0].centre_m, gates[-1].centre_m
    points = np.array(points)
    apart = np.linalg.norm(points[:, None] - points[None], axis=-1)
    a, b = np.unravel_index(np.argmax(apart), apart.shape)
    return points[a], points[b]


def layout_from_scene(scene: Scene, gate_depth_m: float = 1.5, max_gate_m: float = 4.0,
                      simplify_m: float = 0.1) -> Layout:
    """A simulator layout with the walls and openings of a real scene.

    Args:
        scene: an ETH/UCY scene (``replays.load_scene``) or any Scene with a walkability map.
        gate_depth_m: how far entry/exit strips reach into the scene from the image border [m].
        max_gate_m: longer border openings are split into strips of at most this length [m].
        simplify_m: contour simplification tolerance (Douglas-Peucker) [m].

    Returns:
        Layout whose scene is the given one; every gate is both an entry and an exit, and pedestrians head
        to any gate farther than MIN_ROUTE_M from where they entered.

    Raises:
        ValueError: a parameter outside its range (gate_depth_m in (0, 50], max_gate_m in [0.5, 1000],
            simplify_m in (0, 5] metres), or the map has no walkable region or no opening on the image border.
    """
    for name, value, bounds in (("gate_depth_m", gate_depth_m, Bounds(0.0, 50.0, "m", open_low=True)),
                                ("max_gate_m", max_gate_m, Bounds(0.5, 1000.0, "m")),
                                ("simplify_m", simplify_m, Bounds(0.0, 5.0, "m", open_low=True))):
        check_value("layout_from_scene", name, value, bounds)
    walls_m = map_wall_segments(scene, simplify_m)
    gates = border_gates(scene, gate_depth_m, max_gate_m)
    if not len(walls_m) or len(gates) < 2:
        raise ValueError(f"scene {scene.name}: need a walkable region touching the image border in two places "
                         f"(found {len(walls_m)} wall segments, {len(gates)} border openings)")
    lo = walls_m.reshape(-1, 2).min(axis=0) - MARGIN_M
    hi = walls_m.reshape(-1, 2).max(axis=0) + MARGIN_M
    start, goal = ego_route(scene, gates)
    return Layout(name=scene.name, walls_m=walls_m, entries=gates, exits=gates,
                  bounds_m=(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])), scene=scene,
                  ego_start_m=start, ego_goal_m=goal)
