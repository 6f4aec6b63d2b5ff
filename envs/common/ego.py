"""The ego robot's action check, and where it starts and where it goes."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from replays.scenes import Scene

CANDIDATE_STRIDE_PX = 4  # spawn candidates: every 4th walkable pixel in each direction


def action_to_velocity(action: np.ndarray, max_speed_mps: float) -> np.ndarray:
    """Ego velocity (2,) float64 m/s from an action, scaled down (direction kept) to ``max_speed_mps``.

    Raises:
        ValueError: the action is not 2 numbers, or holds NaN/inf (a broken policy should fail loudly).
    """
    velocity = np.asarray(action, dtype=np.float64)
    if velocity.shape != (2,):
        raise ValueError(f"action must be an ego velocity (vx, vy) in m/s of shape (2,), got shape {velocity.shape}")
    if not np.isfinite(velocity).all():
        raise ValueError(f"action must be finite, got {velocity.tolist()}")
    if np.hypot(*velocity) <= max_speed_mps:
        return velocity
    direction = velocity / np.abs(velocity).max()  # no overflow for huge actions
    return direction * (max_speed_mps / np.hypot(*direction))


def walkable_points(scene: Scene, bounds_m: tuple[float, float, float, float]) -> np.ndarray:
    """(M, 2) world metres of walkable map pixels (every ``CANDIDATE_STRIDE_PX``-th) inside ``bounds_m``.

    Args:
        bounds_m: (xmin, ymin, xmax, ymax) metres.
    """
    rows, cols = np.nonzero(scene.walkable[::CANDIDATE_STRIDE_PX, ::CANDIDATE_STRIDE_PX])
    uv_px = np.stack([cols, rows], axis=1) * CANDIDATE_STRIDE_PX
    xy_m = scene.pixel_to_world(uv_px.astype(np.float64))
    xmin, ymin, xmax, ymax = bounds_m
    inside = (xy_m[:, 0] >= xmin) & (xy_m[:, 0] <= xmax) & (xy_m[:, 1] >= ymin) & (xy_m[:, 1] <= ymax)
    return xy_m[inside]


def spawn_start_goal(candidates_m: np.ndarray, peds_xy_m: np.ndarray, clearance_m: float,
                     min_goal_distance_m: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Draw a free start and a distant goal among walkable candidates.

    The start is drawn among candidates at least ``clearance_m`` from every pedestrian (the roomiest
    candidate if none is); the goal among candidates at least ``min_goal_distance_m`` from the start
    (the farthest candidate if none is).

    Args:
        candidates_m: (M, 2) walkable points, metres.  peds_xy_m: (N, 2) pedestrian positions, metres.

    Returns:
        start_m: (2,) float64 metres.  goal_m: (2,) float64 metres.
    """
    if len(candidates_m) == 0:
        raise ValueError("no walkable point to spawn the ego on (empty walkability map inside the arena)")
    room = cKDTree(peds_xy_m).query(candidates_m)[0] if len(peds_xy_m) else np.full(len(candidates_m), np.inf)
    free = np.flatnonzero(room >= clearance_m)
    start = candidates_m[rng.choice(free)] if len(free) else candidates_m[np.argmax(room)]
    distance = np.linalg.norm(candidates_m - start, axis=1)
    far = np.flatnonzero(distance >= min_goal_distance_m)
    goal = candidates_m[rng.choice(far)] if len(far) else candidates_m[np.argmax(distance)]
    return start.copy(), goal.copy()
