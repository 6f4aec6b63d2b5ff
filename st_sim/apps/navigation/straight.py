"""The floor of the benchmark: head straight for the goal at full speed, avoiding nothing."""

from __future__ import annotations

import numpy as np

from st_sim.apps.navigation.world import NavWorld
from st_sim.sim.exact import length


class StraightPlanner:
    """Full speed along the straight line to the goal, slowing down to stop on it; ignores everybody."""

    def __init__(self, world: NavWorld, use_predictions: bool = False):
        self.world = world

    def reset(self) -> None:
        """Nothing to forget."""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame."""
        to_goal = obs["ego"][4:6].astype(np.float64) - obs["ego"][:2]
        distance_m = float(length(to_goal))  # the same on every CPU (OpenBLAS's is not)
        if distance_m == 0.0:
            return np.zeros(2, np.float32)
        speed_mps = min(self.world.max_speed_mps, distance_m / self.world.step_s)
        return (to_goal / distance_m * speed_mps).astype(np.float32)
