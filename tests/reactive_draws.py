"""Drawn crowds for the reactive tests: straight logs through a square with walls, robots crossing it, and a robot
that chases the pedestrians of a replay."""

from __future__ import annotations

import numpy as np

from replays.scenes import Scene
from st_sim.reactive.footprint import Body
from st_sim.sim.map_depth import MapDepth

ROBOT = Body(radius_m=0.3)
FRAMES = 36


def scene_with_walls(half_m: float = 12.0) -> MapDepth:
    """A square with a non-walkable block left of x = -1.5 m, above y = 1 m (walls to press against)."""
    size = int(2 * half_m / 0.05)
    walkable = np.ones((size, size), bool)
    walkable[int((1.0 + half_m) / 0.05):, :int((-1.5 + half_m) / 0.05)] = False
    H = np.array([[0.05, 0.0, -half_m], [0.0, 0.05, -half_m], [0.0, 0.0, 1.0]])
    return MapDepth(Scene("block", H, walkable))


def straight_logs(seed: int, walkers: int) -> tuple[np.ndarray, np.ndarray]:
    """(F, W, 2) straight logs through the middle of the square, some starting or ending within the recording, and
    (F, W) who is present."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0, 2 * np.pi, walkers)
    start = 6.0 * np.c_[np.cos(angle), np.sin(angle)] + rng.normal(0, 0.8, (walkers, 2))
    end = -start + rng.normal(0, 0.8, (walkers, 2))
    speed = rng.uniform(0.6, 1.6, walkers)
    walked = np.arange(FRAMES)[:, None] * 0.4 * speed / np.linalg.norm(end - start, axis=1)
    log = start + (end - start) * np.minimum(walked, 1.0)[..., None]
    present = np.ones((FRAMES, walkers), bool)
    first, last = rng.integers(0, 8, walkers), rng.integers(FRAMES - 8, FRAMES + 1, walkers)
    present &= (np.arange(FRAMES)[:, None] >= first) & (np.arange(FRAMES)[:, None] < last)
    return np.where(present[..., None], log, np.nan), present


def robot_paths(seed: int, crowds: int) -> np.ndarray:
    """(N, F, 2) robots crossing the middle of the square, each its own line and pace (some standing)."""
    rng = np.random.default_rng(seed + 1)
    start = rng.uniform(-3, 3, (crowds, 2))
    velocity = rng.uniform(-1.5, 1.5, (crowds, 2)) * (rng.random((crowds, 1)) < 0.7)
    return start[:, None] + 0.4 * np.arange(FRAMES)[None, :, None] * velocity[:, None]


def chase(obs: dict[str, np.ndarray], rng: np.random.Generator) -> np.ndarray:
    """(N, 2) float32 full speed toward the nearest pedestrian plus N(0, 0.3 m/s) noise: robots that walk into the
    crowd (toward the goal where nobody is present)."""
    ego = obs["ego"][:, :2]
    now, seen = obs["history"][:, :, -1], obs["history_mask"][:, :, -1]  # (N, N_max, 2), (N, N_max)
    distance = np.where(seen, np.linalg.norm(now - ego[:, None], axis=-1), np.inf)
    target = np.where(np.isfinite(distance.min(axis=1))[:, None], now[np.arange(len(ego)), distance.argmin(axis=1)],
                      obs["ego"][:, 4:6])
    to = target - ego
    velocity = 1.5 * to / np.maximum(np.linalg.norm(to, axis=-1, keepdims=True), 1e-6)
    return (velocity + rng.normal(0.0, 0.3, velocity.shape)).astype(np.float32)
