"""Reactive baseline: ORCA (pyrvo) on the pedestrians' current positions and velocities, walls from the map.

Each decision builds an ORCA simulator with the walls (the walkability map's outlines) and one agent per
pedestrian that keeps its last observed velocity, asks ORCA for the ego's collision-free velocity nearest to
its preferred one (full speed along the shortest walkable path to the goal), and returns it. No predictions.
Needs the optional extra: ``pip install -e ".[orca]"``.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from st_sim.apps.navigation.pedestrians import pedestrians_of
from st_sim.apps.navigation.world import NavWorld
from st_sim.sim.exact import length

NEIGHBOUR_DIST_M = 5.0  # ORCA looks at agents this close [m]
MAX_NEIGHBOURS = 10  # ... and at most this many [-]
TIME_HORIZON_S = 2.0  # velocities must stay collision-free this long among agents [s]
OBSTACLE_HORIZON_S = 0.8  # ... and this long against walls [s]
BODY_MARGIN_M = 0.05  # added to every radius [m]
OUTLINE_TOLERANCE_CELLS = 1.5  # wall outlines are simplified to this many grid cells [-]


def _pyrvo() -> ModuleType:
    try:
        import pyrvo
    except ImportError as err:
        raise ImportError('planner "orca" needs pyrvo: pip install -e ".[orca]"') from err
    return pyrvo


def wall_polygons(world: NavWorld) -> list[np.ndarray]:
    """Outlines of the walkable regions (clockwise: inside is free) and of walls inside them
    (counter-clockwise), as ORCA wants them; (V, 2) metres each."""
    import cv2

    terrain = world.terrain
    contours, hierarchy = cv2.findContours(terrain.free.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)
    polygons = []
    for contour, (_, _, _, parent) in zip(contours, hierarchy[0], strict=True):
        simple = cv2.approxPolyDP(contour, OUTLINE_TOLERANCE_CELLS, closed=True)[:, 0].astype(np.float64)
        if len(simple) < 3:
            continue
        xy_m = terrain.origin_m + terrain.cell_m * simple  # grid (column, row) -> world (x, y), no flip
        x, y = xy_m[:, 0], xy_m[:, 1]
        counter_clockwise = float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) > 0
        wants_counter_clockwise = parent >= 0  # a hole in a walkable region is a wall block
        polygons.append(xy_m if counter_clockwise == wants_counter_clockwise else xy_m[::-1])
    return polygons


class OrcaPlanner:
    """ORCA through pyrvo: the ego's velocity closest to its preferred one that avoids everybody for 2 s."""

    def __init__(self, world: NavWorld, use_predictions: bool = False):
        self.pyrvo = _pyrvo()
        self.world = world
        self.walls = wall_polygons(world)

    def reset(self) -> None:
        """Nothing to forget: ORCA plans from the current state only."""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame."""
        world = self.world
        ego_xy, ego_v, goal = (obs["ego"][i:i + 2].astype(np.float64) for i in (0, 2, 4))
        sim = self.pyrvo.RVOSimulator()
        sim.set_time_step(world.step_s)
        for polygon in self.walls:
            sim.add_obstacle(polygon.tolist())
        sim.process_obstacles()
        ego = sim.add_agent(ego_xy.tolist(), NEIGHBOUR_DIST_M, MAX_NEIGHBOURS, TIME_HORIZON_S, OBSTACLE_HORIZON_S,
                            world.ego_radius_m + BODY_MARGIN_M, world.max_speed_mps, ego_v.tolist())
        distance_m = float(length(goal - ego_xy))  # the same on every CPU (OpenBLAS's is not)
        direction = world.terrain.direction_to(ego_xy, goal, world.wall_clearance_m)
        sim.set_agent_pref_velocity(ego, (direction * min(world.max_speed_mps, distance_m / world.step_s)).tolist())
        peds = pedestrians_of(obs, 1, use_predictions=False)
        for xy, velocity in zip(peds.xy_m, peds.velocity_mps, strict=True):
            agent = sim.add_agent(xy.tolist(), NEIGHBOUR_DIST_M, MAX_NEIGHBOURS, TIME_HORIZON_S, OBSTACLE_HORIZON_S,
                                  world.pedestrian_radius_m + BODY_MARGIN_M,
                                  max(float(length(velocity)), 1e-3), velocity.tolist())
            sim.set_agent_pref_velocity(agent, velocity.tolist())
        sim.do_step()
        velocity = sim.get_agent_velocity(ego)
        return np.array([velocity.x, velocity.y], np.float32)
