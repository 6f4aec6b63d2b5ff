"""navground's HL as a plain navground user wraps it, from navground's documentation only: the check that our tuned
``navground-hl`` adapter (``st_sim.apps.navigation.peers``) does not run the behaviour below its best.

    cd benchmarks && python -m st_sim benchmark --policy hl_from_docs:DocsHL --predictor none --suite val \\
        --scenarios sim-crossing sim-bottleneck doorway eth-log univ-reactive --episodes 30 --workers 1 \\
        --out ../runs/peer_tune/hl-from-docs

Everything is navground's default (horizon 5 m, no safety margin, HL's aperture, resolution, tau and eta) except
what the env fixes: the robot's radius [m] and speed limit [m/s], omnidirectional. The target is the goal itself
(tolerance: the env's goal radius [m]); every pedestrian present is a neighbour with its last observed velocity
[m/s]; every boundary of the walkable map is a line obstacle. The command is asked in the world frame for one env
step (0.4 s).
"""

from __future__ import annotations

import numpy as np
from navground import core
from navground.core.behaviors import HLBehavior
from navground.core.kinematics import OmnidirectionalKinematics

from st_sim.apps.navigation.pedestrians import pedestrians_of
from st_sim.apps.navigation.world import NavWorld
from st_sim.sim.map_walls import map_wall_segments


class DocsHL:
    """HL with navground's defaults heading straight for the goal (the planner protocol: ``act(obs)`` -> (2,)
    velocity [m/s], world frame)."""

    def __init__(self, world: NavWorld, use_predictions: bool = False):
        self.world = world
        self.behavior = HLBehavior(OmnidirectionalKinematics(world.max_speed_mps), world.ego_radius_m)
        self.behavior.environment_state.line_obstacles = [core.LineSegment(a, b)
                                                          for a, b in map_wall_segments(world.scene)]

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame."""
        xy, velocity, goal = obs["ego"][0:2], obs["ego"][2:4], obs["ego"][4:6]
        behavior = self.behavior
        behavior.position = xy
        behavior.velocity = velocity
        behavior.target = core.Target.Point(goal, self.world.goal_radius_m)
        people = pedestrians_of(obs, 1, use_predictions=False)
        behavior.environment_state.neighbors = [
            core.Neighbor(p, self.world.pedestrian_radius_m, v)
            for p, v in zip(people.xy_m, people.velocity_mps, strict=True)]
        command = behavior.compute_cmd(self.world.step_s, core.Frame.absolute)
        return np.asarray(command.velocity, np.float32)
