"""The ego robot's command check, where it starts and where it goes, and how far it may move."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from envs.common.errors import ActionError, EgoPlacementError
from replays.scenes import Scene
from st_sim.sim.exact import length

CANDIDATE_STRIDE_PX = 4  # spawn candidates: every 4th walkable pixel in each direction
# A pixel on the image's border, mapped to metres and back, lands up to ~1e-13 px outside it, and by a different
# amount when one point is mapped than when many are: "on the image" allows this much.
ROUND_TRIP_TOLERANCE_PX = 1e-6
NUMBER_KINDS = "iuf"  # numpy dtype kinds an action may have: signed, unsigned, float (not bool, complex, text)


def checked_command(action: Any, names: tuple[str, str] = ("vx_mps", "vy_mps"), finite: bool = True) -> np.ndarray:
    """The action as a (2,) float64 command, after refusing anything that is not 2 finite real numbers.

    Args:
        names: what the two components are (the robot's ``command_names``), for the messages.
        finite: refuse NaN and inf too (False: a spectator env's action, which nothing reads).

    Raises:
        ActionError: complex, text, bool or object values, a shape other than (2,), NaN or inf (a broken policy
            should fail loudly). Nothing in the env changes before this check.
    """
    what = f"a robot command ({', '.join(names)})"
    try:
        array = np.asarray(action)
    except (ValueError, TypeError) as err:  # ragged nesting and the like
        raise ActionError(f"action must be {what}, got {type(action).__name__}") from err
    if array.dtype.kind not in NUMBER_KINDS:
        raise ActionError(f"action must be {what} of 2 real numbers, got dtype {array.dtype} "
                          "(bool, complex, text and objects are refused)")
    if array.shape != (2,):
        raise ActionError(f"action must be {what} of shape (2,), got shape {array.shape}")
    command = array.astype(np.float64)
    if finite and not np.isfinite(command).all():
        raise ActionError(f"action must be finite, got {command.tolist()}")
    return command


def on_image(scene: Scene, xy_m: np.ndarray) -> np.ndarray:
    """(..., 2) world metres -> (...) bool: the point is finite and maps inside the scene's image."""
    xy_m = np.asarray(xy_m, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        uv = scene.world_to_pixel(xy_m)
    low, (height, width) = -ROUND_TRIP_TOLERANCE_PX, scene.walkable.shape
    return (np.isfinite(xy_m).all(-1) & (uv[..., 0] >= low) & (uv[..., 0] <= width - 1 - low)
            & (uv[..., 1] >= low) & (uv[..., 1] <= height - 1 - low))


def require_on_map(scene: Scene, xy_m: np.ndarray, what: str, walkable: bool) -> None:
    """Raise ``EgoPlacementError`` unless ``xy_m`` (2,) metres is on the image (and on a walkable pixel)."""
    inside = bool(on_image(scene, xy_m))
    if not inside or (walkable and not scene.is_walkable(xy_m)):
        where = "off the scene's image" if not inside else "on a non-walkable pixel (inside a wall or obstacle)"
        raise EgoPlacementError(f"{what} {np.asarray(xy_m).tolist()} m is {where} of scene {scene.name}")


def move_within(scene: Scene, xy_m: np.ndarray, velocity_mps: np.ndarray, dt_s: float,
                low_m: np.ndarray, high_m: np.ndarray) -> np.ndarray:
    """(2,) metres after moving at ``velocity_mps`` for ``dt_s``, kept in the box [low_m, high_m] and on the image.

    A move that would leave the image keeps whichever single axis stays on it (sliding along the edge), or
    none: the image border is a wall.
    """
    target = np.clip(xy_m + velocity_mps * dt_s, low_m, high_m)
    for candidate in (target, np.array([target[0], xy_m[1]]), np.array([xy_m[0], target[1]])):
        if on_image(scene, candidate):
            return candidate
    return xy_m.copy()


def point_on_image(scene: Scene, x_m: float, y_m: float) -> bool:
    """``on_image`` of one finite point (x_m, y_m) [m], on floats: the same sums of products, in the same order, as
    ``replays.scenes.apply_homography`` (the same answer, without an array's overhead)."""
    H = scene.H_inv
    u = x_m * float(H[0, 0]) + y_m * float(H[0, 1]) + float(H[0, 2])
    v = x_m * float(H[1, 0]) + y_m * float(H[1, 1]) + float(H[1, 2])
    if not (H[2, 0] == 0.0 and H[2, 1] == 0.0 and H[2, 2] == 1.0):
        w = x_m * float(H[2, 0]) + y_m * float(H[2, 1]) + float(H[2, 2])
        if w == 0.0:
            return False
        u, v = u / w, v / w
    low, (height, width) = -ROUND_TRIP_TOLERANCE_PX, scene.walkable.shape
    return low <= u <= width - 1 - low and low <= v <= height - 1 - low


def move_along(scene: Scene, xy_m: np.ndarray, velocities_mps: np.ndarray, dt_s: float, low_m: np.ndarray,
               high_m: np.ndarray) -> np.ndarray:
    """(2,) metres after the moves ``velocities_mps`` (K, 2) of ``dt_s`` each, one after another, each as
    ``move_within``: when every point of the way is inside the box and on the image, the way as it is, else move by
    move."""
    x, y = float(xy_m[0]), float(xy_m[1])
    (low_x, low_y), (high_x, high_y) = low_m.tolist(), high_m.tolist()
    for vx, vy in velocities_mps.tolist():
        x, y = x + vx * dt_s, y + vy * dt_s
        if not (low_x <= x <= high_x and low_y <= y <= high_y and point_on_image(scene, x, y)):
            break
    else:
        return np.array([x, y])
    for velocity_mps in velocities_mps:
        xy_m = move_within(scene, xy_m, velocity_mps, dt_s, low_m, high_m)
    return xy_m


def walkable_points(scene: Scene, bounds_m: tuple[float, float, float, float]) -> np.ndarray:
    """(M, 2) world metres of walkable map pixels (every ``CANDIDATE_STRIDE_PX``-th) inside ``bounds_m``.

    Every point returned passes ``on_image``, mapped alone or with the others.

    Args:
        bounds_m: (xmin, ymin, xmax, ymax) metres.
    """
    rows, cols = np.nonzero(scene.walkable[::CANDIDATE_STRIDE_PX, ::CANDIDATE_STRIDE_PX])
    uv_px = np.stack([cols, rows], axis=1) * CANDIDATE_STRIDE_PX
    xy_m = scene.pixel_to_world(uv_px.astype(np.float64))
    xmin, ymin, xmax, ymax = bounds_m
    inside = (xy_m[:, 0] >= xmin) & (xy_m[:, 0] <= xmax) & (xy_m[:, 1] >= ymin) & (xy_m[:, 1] <= ymax)
    return xy_m[inside & on_image(scene, xy_m)]


class SpawnPoints:
    """The walkable points a robot may start on and aim at, (M, 2) metres, with a k-d tree over them built once: a
    start's room from the pedestrians is measured only for the points near one (``spawn_start_goal``)."""

    def __init__(self, xy_m: np.ndarray):
        self.xy_m = np.array(xy_m, np.float64)
        self.xy_m.setflags(write=False)  # the tree holds these points: change them through a new SpawnPoints
        self._tree = cKDTree(self.xy_m) if len(self.xy_m) else None

    def room_m(self, peds_xy_m: np.ndarray) -> np.ndarray:
        """(M,) distance [m] from each point to the nearest pedestrian (inf with none)."""
        return cKDTree(peds_xy_m).query(self.xy_m)[0] if len(peds_xy_m) else np.full(len(self.xy_m), np.inf)

    def free(self, peds_xy_m: np.ndarray, clearance_m: float) -> np.ndarray:
        """(M,) bool: ``room_m(peds_xy_m) >= clearance_m``, the same to the last bit: the points within a hair less
        than ``clearance_m`` of a pedestrian are not free, those farther than a hair more are, and only those in
        between are measured as ``room_m`` measures them."""
        free = np.ones(len(self.xy_m), bool)
        if self._tree is None or not len(peds_xy_m):
            return free
        hair = clearance_m * 1e-9 + 1e-9  # far more than the rounding of two ways of measuring a distance [m]
        outer, inner = (self._points_within(peds_xy_m, clearance_m + side) for side in (hair, -hair))
        free[outer] = False
        band = outer & ~inner
        if band.any():
            free[band] = cKDTree(peds_xy_m).query(self.xy_m[band])[0] >= clearance_m
        return free

    def _points_within(self, peds_xy_m: np.ndarray, radius_m: float) -> np.ndarray:
        """(M,) bool: the points within ``radius_m`` of a pedestrian (none for a negative radius)."""
        within = np.zeros(len(self.xy_m), bool)
        if radius_m >= 0:
            lists = self._tree.query_ball_point(peds_xy_m, radius_m, return_sorted=False)
            within[np.fromiter(itertools.chain.from_iterable(lists), np.int64)] = True
        return within


def spawn_start_goal(points: SpawnPoints, peds_xy_m: np.ndarray, clearance_m: float,
                     min_goal_distance_m: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Draw a free start and a distant goal among walkable candidates.

    The start is drawn among candidates at least ``clearance_m`` from every pedestrian (the roomiest
    candidate if none is); the goal among candidates at least ``min_goal_distance_m`` from the start
    (the farthest candidate if none is).

    Args:
        points: the (M, 2) walkable candidates, metres.  peds_xy_m: (N, 2) pedestrian positions, metres.

    Returns:
        start_m: (2,) float64 metres.  goal_m: (2,) float64 metres.

    Raises:
        EgoPlacementError: no candidate (no walkable pixel inside the arena).
    """
    candidates_m = points.xy_m
    if len(candidates_m) == 0:
        raise EgoPlacementError("no walkable point to spawn the ego on (empty walkability map inside the arena)")
    free = np.flatnonzero(points.free(peds_xy_m, clearance_m))
    start = candidates_m[rng.choice(free)] if len(free) else candidates_m[np.argmax(points.room_m(peds_xy_m))]
    distance = length(candidates_m - start)
    far = np.flatnonzero(distance >= min_goal_distance_m)
    goal = candidates_m[rng.choice(far)] if len(far) else candidates_m[np.argmax(distance)]
    return start.copy(), goal.copy()
