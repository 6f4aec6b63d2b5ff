"""Planners from other projects as benchmark policies: navground's behaviours and PySocialForce's model as the robot.

    pip install -e ".[peers]"
    python -m st_sim benchmark --policy navground-orca --predictor none --out runs/bench/navground-orca-none

An example of wrapping someone else's planner: each class here follows the planner protocol (``reset()``,
``act(obs) -> (2,)`` velocity [m/s], world frame) and turns an STCrowd observation into the other library's input.

- Pedestrians are the observation's people present now, with their last observed velocity (``pedestrians_of``),
  as discs of the env's pedestrian radius; those within ``SENSING_M`` of the robot are passed.
- Walls are line segments from the scene's map (``map_wall_segments``: every boundary of the walkable region, the
  surface the robot must not cross); those within ``SENSING_M`` are passed.
- The robot gets the env's body radius and speed limit, and heads for a point ``WAYPOINT_M`` ahead along the
  shortest walkable path to its goal (the goal itself once nearer), the geodesic guidance STCrowd's own ORCA and MPC
  get; a local planner with a straight line to a goal behind a wall would stall in the bottleneck and the doorway.

Forecasts are not read (these planners react to the current state): run them with ``--predictor none``.

The behaviours keep their libraries' defaults except where noted on the classes, and navground's safety margin
(``SAFETY_MARGIN_M``). navground (``navground.core``, a
C++ library with Python bindings) is given the state as a ``GeometricState`` and asked ``compute_cmd`` in the
absolute (world) frame, the robot's orientation being its heading (the direction to the waypoint when nearly
still): HL sees only ahead of it. PySocialForce is a pedestrian simulator: the robot is its agent 0 among the
pedestrians, and its velocity after one simulated step of ``world.step_s`` is the command.
"""

from __future__ import annotations

import logging
from pathlib import Path
from types import ModuleType
from typing import ClassVar

import numpy as np

from st_sim.apps.navigation.pedestrians import Pedestrians, pedestrians_of
from st_sim.apps.navigation.world import NavWorld
from st_sim.sim.map_walls import map_wall_segments

SENSING_M = 5.0  # pedestrians and walls this close to the robot are passed to the planner [m]
WAYPOINT_M = 3.0  # the robot heads for the point this far along its shortest walkable path [m]
STILL_MPS = 0.05  # below this speed the robot's heading is the direction to its waypoint [m/s]
MAX_TURN_RADPS = 10.0  # angular speed limit given to navground's kinematics: the envs' robot turns at once [rad/s]
WALL_DISC_SPACING_M = 0.2  # HRVO, which has no line obstacles, sees walls as discs this far apart [m]
SAFETY_MARGIN_M = 0.05  # navground keeps this gap to everyone, as STCrowd's ORCA adds it to every radius [m]
PEERS_EXTRA = 'pip install -e ".[peers]"'


def _navground() -> ModuleType:
    try:
        import navground.core
    except ImportError as err:
        raise ImportError(f"the navground planners need navground: {PEERS_EXTRA}") from err
    return navground.core


def _pysocialforce() -> ModuleType:
    """``pysocialforce``, imported without its side effects: it sets the root logger to DEBUG (and matplotlib, which
    it imports, logs at that level), adds a console handler and a ``file.log`` handler in the working folder
    (created there). Those are undone."""
    root = logging.getLogger()
    level, handlers = root.level, list(root.handlers)
    noisy = {name: logging.getLogger(name) for name in ("matplotlib", "numba")}  # imported meanwhile
    noisy_levels = {name: logger.level for name, logger in noisy.items()}
    for logger in noisy.values():
        logger.setLevel(logging.WARNING)
    log_file = Path("file.log").resolve()
    had_log_file = log_file.exists()
    try:
        import pysocialforce
    except ImportError as err:
        raise ImportError(f"the pysocialforce planner needs PySocialForce: {PEERS_EXTRA}") from err
    finally:
        for handler in [h for h in root.handlers if h not in handlers]:
            root.removeHandler(handler)
            handler.close()
        root.setLevel(level)
        for name, logger in noisy.items():
            logger.setLevel(noisy_levels[name])
        if not had_log_file and log_file.is_file() and log_file.stat().st_size == 0:
            log_file.unlink()
    return pysocialforce


def near_walls(walls_m: np.ndarray, xy_m: np.ndarray, reach_m: float) -> np.ndarray:
    """(K', 2, 2) the segments of ``walls_m`` (K, 2, 2) that come within ``reach_m`` of ``xy_m`` (2,) [m]."""
    if not len(walls_m):
        return walls_m
    start, along = walls_m[:, 0], walls_m[:, 1] - walls_m[:, 0]
    length2 = np.maximum((along**2).sum(axis=1), 1e-12)
    t = np.clip(((xy_m - start) * along).sum(axis=1) / length2, 0.0, 1.0)
    distance_m = np.linalg.norm(start + t[:, None] * along - xy_m, axis=1)
    return walls_m[distance_m <= reach_m]


class PeerPlanner:
    """What every adapter does first: the robot's state, its waypoint and who is near, from an observation.

    Args:
        world: the env's robot, pedestrians and map.
        use_predictions: ignored (these planners react to the current state).
    """

    def __init__(self, world: NavWorld, use_predictions: bool = False):
        self.world = world
        self.walls_m = map_wall_segments(world.scene)  # (K, 2, 2) [m]

    def reset(self) -> None:
        """Nothing to forget: each command is computed from the current observation."""

    def situation(self, obs: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, Pedestrians,
                                                             np.ndarray]:
        """(robot position (2,) [m], velocity (2,) [m/s], waypoint (2,) [m], the pedestrians within ``SENSING_M``,
        the walls (K', 2, 2) within ``SENSING_M``) of ``obs``."""
        ego_xy, ego_v, goal = (obs["ego"][i:i + 2].astype(np.float64) for i in (0, 2, 4))
        distance_m = float(np.linalg.norm(goal - ego_xy))
        waypoint = goal
        if distance_m > WAYPOINT_M:
            waypoint = ego_xy + WAYPOINT_M * self.world.terrain.direction_to(ego_xy, goal,
                                                                             self.world.wall_clearance_m)
        everyone = pedestrians_of(obs, 1, use_predictions=False)
        near = np.linalg.norm(everyone.xy_m - ego_xy, axis=1) <= SENSING_M
        people = Pedestrians(everyone.xy_m[near], everyone.velocity_mps[near], everyone.futures_m[near],
                             everyone.predicted[near])
        return ego_xy, ego_v, waypoint, people, near_walls(self.walls_m, ego_xy, SENSING_M)


class NavgroundPlanner(PeerPlanner):
    """A navground behaviour (``behavior``) steering an omnidirectional robot of the env's radius and speed limit;
    ``properties`` are the behaviour's own settings that differ from navground's defaults."""

    behavior: ClassVar[str]
    properties: ClassVar[dict[str, float]] = {}
    walls_as_discs: ClassVar[bool] = False
    """the behaviour ignores line obstacles: walls are given as static discs along them"""

    def __init__(self, world: NavWorld, use_predictions: bool = False):
        super().__init__(world, use_predictions)
        self.core = _navground()
        from navground.core.kinematics import OmnidirectionalKinematics

        self.agent = self.core.Behavior.make_type(self.behavior)
        if self.agent is None:
            raise ImportError(f"navground has no behaviour {self.behavior!r} (it has "
                              f"{', '.join(t for t in self.core.Behavior.types if t)}): {PEERS_EXTRA}")
        self.agent.kinematics = OmnidirectionalKinematics(world.max_speed_mps, MAX_TURN_RADPS)
        self.agent.radius = world.ego_radius_m
        self.agent.optimal_speed = world.max_speed_mps
        self.agent.horizon = SENSING_M
        self.agent.safety_margin = SAFETY_MARGIN_M
        self.agent.assume_cmd_is_actuated = False  # the robot's velocity is the observed one, not the last command
        for name, value in self.properties.items():
            self.agent.set(name, value)

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame."""
        core, agent = self.core, self.agent
        ego_xy, ego_v, waypoint, people, walls = self.situation(obs)
        heading = ego_v if np.linalg.norm(ego_v) >= STILL_MPS else waypoint - ego_xy
        agent.position = ego_xy
        agent.orientation = float(np.arctan2(heading[1], heading[0]))
        agent.set_velocity(ego_v, core.Frame.absolute)
        agent.actuated_twist = core.Twist2(ego_v, 0.0, core.Frame.absolute)  # what the social force integrates
        agent.target = core.Target.Point(waypoint, self.world.goal_radius_m / 2)
        state = agent.environment_state
        state.neighbors = [core.Neighbor(xy, self.world.pedestrian_radius_m, v, k)
                           for k, (xy, v) in enumerate(zip(people.xy_m, people.velocity_mps, strict=True))]
        if self.walls_as_discs:
            state.static_obstacles = [core.Disc(xy, WALL_DISC_SPACING_M / 2) for xy in wall_points(walls)]
        else:
            state.line_obstacles = [core.LineSegment(a, b) for a, b in walls]
        twist = agent.compute_cmd(self.world.step_s, core.Frame.absolute)
        return np.asarray(twist.velocity, np.float32)


def wall_points(walls_m: np.ndarray) -> np.ndarray:
    """(M, 2) points every ``WALL_DISC_SPACING_M`` (or closer) along each segment of ``walls_m`` (K, 2, 2) [m],
    both ends included."""
    points = [np.zeros((0, 2))]
    for a, b in walls_m:
        count = int(np.ceil(np.linalg.norm(b - a) / WALL_DISC_SPACING_M)) + 1
        points.append(a + np.linspace(0.0, 1.0, count)[:, None] * (b - a))
    return np.concatenate(points)


class NavgroundHL(NavgroundPlanner):
    """navground's HL (Guzzi et al. 2013, human-like: the free direction nearest the target within its field of
    view, at the speed that stops in time): "navground-hl"."""

    behavior = "HL"


class NavgroundOrca(NavgroundPlanner):
    """navground's ORCA (van den Berg et al. 2011): "navground-orca". Its time horizons are STCrowd's ORCA's (2 s
    among people, 0.8 s against walls) instead of navground's 10 s, which keeps a robot in a crowd standing."""

    behavior = "ORCA"
    properties: ClassVar[dict[str, float]] = {"time_horizon": 2.0, "static_time_horizon": 0.8}


class NavgroundHrvo(NavgroundPlanner):
    """navground's HRVO (Snape et al. 2011, hybrid reciprocal velocity obstacles): "navground-hrvo". It has no line
    obstacles: walls are discs every ``WALL_DISC_SPACING_M`` along them."""

    behavior = "HRVO"
    walls_as_discs = True


class NavgroundSocialForce(NavgroundPlanner):
    """navground's social force (Helbing and Molnár 1995): "navground-sf"."""

    behavior = "SocialForce"


class PySocialForcePlanner(PeerPlanner):
    """PySocialForce's extended social force model (Moussaïd et al. 2010) with the robot as one of its agents:
    "pysocialforce". The robot's desired speed is the env's speed limit; the pedestrians keep their velocities for
    the step (their own goals do not change the robot's forces); no groups (the observation has none)."""

    def __init__(self, world: NavWorld, use_predictions: bool = False):
        super().__init__(world, use_predictions)
        self.psf = _pysocialforce()

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame."""
        ego_xy, ego_v, waypoint, people, walls = self.situation(obs)
        robot = np.r_[ego_xy, ego_v, waypoint]
        others = np.c_[people.xy_m, people.velocity_mps, people.xy_m + people.velocity_mps * self.world.step_s]
        sim = self.psf.Simulator(np.vstack([robot, others]), groups=None,
                                 obstacles=[(a[0], b[0], a[1], b[1]) for a, b in walls])
        sim.peds.step_width = self.world.step_s
        sim.peds.agent_radius = self.world.ego_radius_m
        sim.peds.max_speeds = np.r_[self.world.max_speed_mps, sim.peds.max_speeds[1:]]
        with np.errstate(divide="ignore", invalid="ignore"):  # its speed cap divides by zero for people standing
            sim.step_once()
        return np.asarray(sim.peds.vel()[0], np.float32)
