"""The robot's part of a hand-made observation: where a holonomic robot faces."""

from __future__ import annotations

import numpy as np


def facing(ego_xy: np.ndarray, ego_v: np.ndarray, goal_xy: np.ndarray) -> np.ndarray:
    """(2,) the unit vector a holonomic robot at ``ego_xy`` moving at ``ego_v`` faces: its motion, or its goal when it
    stands (as the envs place a robot: facing its goal)."""
    way = np.asarray(ego_v, np.float64) if np.linalg.norm(ego_v) > 1e-3 else np.asarray(goal_xy) - np.asarray(ego_xy)
    norm = np.linalg.norm(way)
    return way / norm if norm > 0 else np.array([1.0, 0.0])
