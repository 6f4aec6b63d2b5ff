"""The people sensor: who the robot detects in one step, where, and who each detection came from.

Every operation is IEEE-exact (``st_sim.sim.exact``; draws from the sensor's own generator), so that a detection is the
same to the last bit on every CPU (``tests/test_cpu_dispatch.py`` runs the ``realistic`` sensor under emulated CPUs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np

from replays.scenes import Scene
from st_sim.perception.spec import SensingSpec
from st_sim.sim.exact import atan2, cos_sin, dot, exp, length

WALL_SAMPLE_M = 0.1  # a line of sight is tested for walls every this many metres [m]
FALSE_ID = -1  # ``Detections.source`` of a false detection


@dataclass(frozen=True, eq=False)
class Detections:
    """One step's detections.

    Attributes:
        xy_m: (D, 2) detected positions, world frame [m].
        source: (D,) int64 the true id each came from, ``FALSE_ID`` for a false one.
        distance_m: (D,) distance from the robot's centre to each detection [m].
        visible_ids: (V,) int64 the true ids the sensor could see this step (in range and field of view, not
            occluded), detected or missed.
    """

    xy_m: np.ndarray
    source: np.ndarray
    distance_m: np.ndarray
    visible_ids: np.ndarray


@cache
def half_view_cos(fov_deg: float) -> float:
    """Cosine of half the field of view ``fov_deg`` [deg] (exact arithmetic, computed once per angle)."""
    return float(cos_sin(math.radians(fov_deg / 2))[0])


def in_field(spec: SensingSpec, robot_xy: np.ndarray, heading: np.ndarray, xy_m: np.ndarray) -> np.ndarray:
    """(N,) bool: the points ``xy_m`` (N, 2) lie within the sensor's range and field of view of a robot at
    ``robot_xy`` (2,) facing ``heading`` (2,), a unit vector."""
    offset = xy_m - robot_xy
    distance = length(offset)
    inside = distance <= spec.range_m
    if spec.fov_deg >= 360.0:
        return inside
    half_cos = half_view_cos(spec.fov_deg)
    along = dot(offset, np.broadcast_to(heading, offset.shape))
    return inside & ((along >= half_cos * distance) | (distance == 0))


def occluded(robot_xy: np.ndarray, xy_m: np.ndarray, radius_m: float, scene: Scene | None,
             robot_radius_m: float) -> np.ndarray:
    """(N,) bool: the line of sight from ``robot_xy`` to each of the people at ``xy_m`` (N, 2) passes through another
    person's body (a disc of ``radius_m`` nearer to the robot) or over non-walkable ground of ``scene`` (sampled every
    ``WALL_SAMPLE_M``, from the robot's body edge to the person's)."""
    n = len(xy_m)
    if n == 0:
        return np.zeros(0, bool)
    offset = xy_m - robot_xy  # (N, 2)
    distance = length(offset)
    hidden = np.zeros(n, bool)
    if n > 1:
        # person j hides person i if j is nearer and j's centre is within radius_m of the segment robot -> i
        along = (offset[None, :, 0] * offset[:, None, 0] + offset[None, :, 1] * offset[:, None, 1])  # (i, j)
        reach = np.where(distance > 0, distance * distance, 1.0)[:, None]
        t = np.clip(along / reach, 0.0, 1.0)
        gap_x = offset[None, :, 0] - t * offset[:, None, 0]
        gap_y = offset[None, :, 1] - t * offset[:, None, 1]
        near_line = gap_x * gap_x + gap_y * gap_y < radius_m * radius_m
        nearer = distance[None, :] < distance[:, None]
        blocks = near_line & nearer
        np.fill_diagonal(blocks, False)
        hidden |= blocks.any(axis=1)
    if scene is not None:
        hidden |= _behind_walls(robot_xy, offset, distance, scene, robot_radius_m, radius_m)
    return hidden


def _behind_walls(robot_xy: np.ndarray, offset: np.ndarray, distance: np.ndarray, scene: Scene,
                  robot_radius_m: float, radius_m: float) -> np.ndarray:
    """(N,) bool: some sample of the line of sight between the two bodies' edges is not walkable."""
    longest = float(distance.max(initial=0.0))
    steps = math.ceil(longest / WALL_SAMPLE_M) + 1
    fractions = np.arange(steps + 1) / steps  # (K,)
    points = robot_xy + fractions[None, :, None] * offset[:, None, :]  # (N, K, 2)
    from_robot = fractions[None, :] * distance[:, None]
    between = (from_robot > robot_radius_m) & (from_robot < distance[:, None] - radius_m)
    blocked = ~scene.is_walkable(points) & between
    return blocked.any(axis=1)


def poisson(rng: np.random.Generator, mean: float) -> int:
    """A Poisson draw of ``mean`` (< 100) by inversion of one uniform draw, with the exact exponential (numpy's
    Poisson sampler calls the CPU's libm)."""
    if mean <= 0:
        return 0
    u, k = float(rng.random()), 0
    p = float(exp(-mean))
    cumulative = p
    while u > cumulative and k < 10 * int(mean) + 50:
        k += 1
        p = p * mean / k
        cumulative += p
    return k


def detect(spec: SensingSpec, robot_xy: np.ndarray, heading: np.ndarray, ids: np.ndarray, xy_m: np.ndarray,
           scene: Scene | None, radius_m: float, robot_radius_m: float, rng: np.random.Generator) -> Detections:
    """What the sensor reports of the people ``ids`` (N,) at ``xy_m`` (N, 2) [m] for a robot at ``robot_xy`` facing
    ``heading`` (unit vector): the visible ones (in range and field of view, not occluded when ``spec.occlusion``),
    each missed with ``spec.miss_rate``, the others with position noise; then the false detections."""
    ids = np.asarray(ids, np.int64)
    xy_m = np.asarray(xy_m, np.float64).reshape(-1, 2)
    visible = in_field(spec, robot_xy, heading, xy_m)
    if spec.occlusion and visible.any():
        # anyone in range hides those behind them, seen or not; walls only matter for those still visible
        near = np.flatnonzero(length(xy_m - robot_xy) <= spec.range_m)
        hidden = occluded(robot_xy, xy_m[near], radius_m, scene, robot_radius_m)
        visible[near[hidden]] = False
    seen = np.flatnonzero(visible)
    kept = seen[rng.random(len(seen)) >= spec.miss_rate] if spec.miss_rate > 0 else seen
    xy = xy_m[kept].copy()
    distance = length(xy - robot_xy)
    sigma = spec.noise_m + spec.noise_per_m * distance
    if spec.noise_m > 0 or spec.noise_per_m > 0:
        xy = xy + sigma[:, None] * rng.standard_normal((len(kept), 2))
    ghosts = _false_detections(spec, robot_xy, heading, scene, rng)
    all_xy = np.concatenate([xy, ghosts])
    return Detections(all_xy, np.concatenate([ids[kept], np.full(len(ghosts), FALSE_ID, np.int64)]),
                      length(all_xy - robot_xy), np.sort(ids[seen]))


def _false_detections(spec: SensingSpec, robot_xy: np.ndarray, heading: np.ndarray, scene: Scene | None,
                      rng: np.random.Generator) -> np.ndarray:
    """(G, 2) ghosts: a Poisson count, each uniform over the field of view within range, those off walkable ground
    dropped [m]."""
    count = poisson(rng, spec.false_per_step)
    if count == 0:
        return np.zeros((0, 2))
    radius = spec.range_m * np.sqrt(rng.random(count))
    angle = atan2(heading[1], heading[0]) + (rng.random(count) - 0.5) * math.radians(spec.fov_deg)
    cos, sin = cos_sin(angle)
    ghosts = robot_xy + radius[:, None] * np.stack([cos, sin], axis=1)
    return ghosts if scene is None else ghosts[scene.is_walkable(ghosts)]
