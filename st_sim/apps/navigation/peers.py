"""Planners from other projects as benchmark policies: navground's behaviours and PySocialForce's model as the robot.

    pip install -e ".[peers]"
    python -m st_sim benchmark --policy navground-orca --predictor none --out runs/bench/navground-orca-none
    planner = NavgroundHL(world, False, settings=HLSettings(eta_s=2.0))   # other settings than the tuned ones

An example of wrapping someone else's planner: each class here follows the planner protocol (``reset()``,
``act(obs) -> (2,)`` velocity [m/s], world frame) and turns an STCrowd observation into the other library's input.

- Pedestrians are the observation's people present now, with their last observed velocity (``pedestrians_of``),
  as discs of the env's pedestrian radius; those within ``sensing_m`` of the robot are passed.
- Walls are line segments from the scene's map (``map_wall_segments``: every boundary of the walkable region, the
  surface the robot must not cross); those within ``wall_sensing_m`` are passed.
- The robot gets the env's body radius and speed limit (its optimal speed: ``speed_share`` of the limit), and
  heads for a target ``waypoint_m`` along the shortest walkable path to its goal, walked in ``PATH_STEP_M`` steps
  (the goal itself once nearer, or always with ``waypoint_m`` = inf): the geodesic guidance STCrowd's own ORCA and
  MPC get; a local planner with a straight line to a goal behind a wall would stall in the bottleneck and the doorway.

Forecasts are not read (these planners react to the current state): run them with ``--predictor none``.

Settings: every adapter takes a frozen settings dataclass (``PeerSettings``; ``NavgroundSettings`` with a subclass
per behaviour, whose ``navground_property`` fields are the behaviour's own properties; ``PySocialForceSettings``,
whose ``pysocialforce_entry`` fields are entries of PySocialForce's config). A dataclass's defaults are the untuned
adapter's: the library's defaults and the guidance above (ORCA's time horizons: STCrowd's ORCA's 2 s and 0.8 s, as
navground's 10 s keep a robot in a crowd standing). The class attribute ``tuned`` holds what the shipped name runs;
``settings=`` (a keyword of the class and of ``make_planner``) builds one with others.

How the peers were tuned: on the val split (the suite's val seeds; the table's test seeds never), 30 episodes each
of sim-crossing, sim-bottleneck, doorway, eth-log and univ-reactive, predictor none, by ``python
benchmarks/tune_peers.py --out runs/peer_tune/grid --workers 1``: a documented grid of 8 to 13 settings per peer
(``GRIDS`` there: the untuned settings and overrides of them, a second round around the first one's best), each cell
one benchmark run; the pick is the cell with the highest success, the lower at-fault collision rate (benchmark
version 3's rule, ``envs.common.fault``) breaking ties. The picks, val success / at fault over the 150 episodes
(untuned: the first cell):
- navground-hl: ``eta_s`` 1.5 (navground's 0.5 s is shorter than the 0.75 s the envs' robot needs to stop from
  1.5 m/s at 2 m/s^2) and ``safety_margin_m`` 0.2: 0.740 / 0.180 (untuned 0.560 / 0.373; a docs-only HL wrapper
  with navground's defaults heading straight for the goal, ``benchmarks/hl_from_docs.py``, 0.547 / 0.407);
- navground-orca: ``safety_margin_m`` 0.2: 0.680 / 0.207 (untuned 0.587 / 0.333);
- navground-sf: ``people_range_m`` 0.6, ``wall_strength_m2ps2`` 3, ``speed_share`` 0.7: 0.587 / 0.300 (untuned
  0.267 / 0.633);
- navground-hrvo: ``wall_sensing_m`` 2, ``speed_share`` 0.8: 0.520 / 0.387 (untuned 0.327 / 0.420);
- pysocialforce: ``obstacle_factor`` 1, ``obstacle_sigma_m`` 0.1, ``social_factor`` 10, ``speed_share`` 0.8: 0.500 /
  0.467 (untuned 0.253 / 0.493).

Fixed on the way (issue 63): the target lay ``waypoint_m`` along the path's first direction, not along the path, so
round a corner or a door jamb it lay across the corner or inside the wall (HL's doorway success went from 0.30 to
0.53 with this alone); HRVO, whose velocity obstacles have no time horizon, saw every wall within 5 m and stopped
short of goals near a wall (``wall_sensing_m``); navground 0.7 registers HRVO's ``uncertainty_offset`` as an int
property, so properties are set as attributes, not with ``set()``; navground's social force returns NaN when a
neighbour walks nearly straight at the robot (``NavgroundSocialForce.act`` stops instead), which ended a benchmark
run.

navground (``navground.core``, a C++ library with Python bindings) is given the state as a ``GeometricState`` and
asked ``compute_cmd`` in the absolute (world) frame, the robot's orientation being its heading (the direction to its
target when nearly still): HL searches the directions within ``aperture_rad`` either side of it (pi: all round).
Its velocity and the twist the behaviours relax from are the observed velocity (``assume_cmd_is_actuated`` off: the
envs' robot accelerates at 2 m/s^2 at most, so the last command is not its velocity). PySocialForce is a pedestrian
simulator: the robot is its agent 0 among the pedestrians, its forces built from the settings' config, and its
velocity after one simulated step of ``world.step_s`` is the command.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import ModuleType
from typing import Any, ClassVar

import numpy as np

from st_sim.apps.navigation.pedestrians import Pedestrians, pedestrians_of
from st_sim.apps.navigation.world import NavWorld
from st_sim.sim.map_walls import map_wall_segments

PATH_STEP_M = 0.5  # the target is found by walking the shortest walkable path in steps this long [m]
STILL_MPS = 0.05  # below this speed the robot's heading is the direction to its target [m/s]
MAX_TURN_RADPS = 10.0  # angular speed limit given to navground's kinematics: the envs' robot turns at once [rad/s]
PEERS_EXTRA = 'pip install -e ".[peers]"'
NAVGROUND_PROPERTY = "navground"
"""metadata key of a settings field that is a navground behaviour's property: the property's name"""
PYSOCIALFORCE_ENTRY = "pysocialforce"
"""metadata key of a settings field that is an entry of PySocialForce's config: (section, entry)"""


@dataclass(frozen=True)
class PeerSettings:
    """What every adapter tells its planner besides the env's facts; the defaults are the adapter's untuned ones."""

    waypoint_m: float = 3.0
    """the target is the point this far along the shortest walkable path to the goal (the goal once nearer) [m];
    inf: the goal itself, in a straight line"""
    target_tolerance_m: float = 0.25
    """the planner may stop this near its target [m] (the envs' goal radius is 0.5 m)"""
    speed_share: float = 1.0
    """the planner's optimal (desired) speed as a share of the env's speed limit [-]"""
    sensing_m: float = 5.0
    """pedestrians this near the robot are passed to the planner [m]"""
    wall_sensing_m: float = 5.0
    """walls this near the robot are passed to the planner [m] (a velocity obstacle without a time horizon, as HRVO's,
    forbids every velocity toward a wall however far)"""


def navground_property(name: str, default: float) -> Any:
    """A settings field that sets the navground behaviour's property ``name``."""
    return field(default=default, metadata={NAVGROUND_PROPERTY: name})


@dataclass(frozen=True)
class NavgroundSettings(PeerSettings):
    """Settings of every navground behaviour; a subclass adds the behaviour's own properties
    (``navground_property`` fields)."""

    horizon_m: float = 5.0
    """navground's horizon: the part of the environment the behaviour considers [m] (navground's default 5 m)"""
    safety_margin_m: float = 0.05
    """navground keeps this gap to everyone [m] (navground's default 0; STCrowd's ORCA adds 0.05 m to every radius)"""

    def properties(self) -> dict[str, float]:
        """The behaviour's own properties: navground name -> value."""
        return {f.metadata[NAVGROUND_PROPERTY]: getattr(self, f.name) for f in fields(self)
                if NAVGROUND_PROPERTY in f.metadata}


@dataclass(frozen=True)
class HLSettings(NavgroundSettings):
    """HL's settings; the defaults of its own properties are navground's."""

    aperture_rad: float = navground_property("aperture", math.pi)
    """directions are searched within this angle either side of the robot's heading [rad]"""
    resolution: int = navground_property("resolution", 101)
    """directions searched over the aperture [-]"""
    tau_s: float = navground_property("tau", 0.125)
    """relaxation time of the velocity toward the chosen one [s]"""
    eta_s: float = navground_property("eta", 0.5)
    """the speed lets the robot stop this long before the nearest collision along the chosen direction [s]"""


@dataclass(frozen=True)
class OrcaSettings(NavgroundSettings):
    """ORCA's settings; its time horizons default to STCrowd's ORCA's (navground's are 10 s, which keeps a robot in
    a crowd standing)."""

    time_horizon_s: float = navground_property("time_horizon", 2.0)
    """velocities must stay collision-free among people this long [s]"""
    static_time_horizon_s: float = navground_property("static_time_horizon", 0.8)
    """... and against walls this long [s]"""


@dataclass(frozen=True)
class HrvoSettings(NavgroundSettings):
    """HRVO's settings: it has no line obstacles, so walls are discs along them."""

    wall_disc_spacing_m: float = 0.2
    """walls are discs of this diameter, this far apart along them [m]"""
    uncertainty_offset_mps: float = navground_property("uncertainty_offset", 0.0)
    """velocity obstacles are widened by this much [m/s]"""


@dataclass(frozen=True)
class SocialForceSettings(NavgroundSettings):
    """navground's social force's settings; the defaults of its own properties are navground's (Helbing and
    Molnár's values)."""

    tau_s: float = navground_property("tau", 0.5)
    """relaxation time toward the desired velocity [s]"""
    step_duration_s: float = navground_property("step_duration", 1.0)
    """the time step of the people's repulsion: how far ahead their motion is looked at [s]"""
    people_strength_m2ps2: float = navground_property("v_a", 2.1)
    """amplitude of the people's repulsive potential [m^2/s^2]"""
    people_range_m: float = navground_property("v_r", 0.3)
    """length scale of the people's repulsive potential [m]"""
    wall_strength_m2ps2: float = navground_property("u_a", 10.0)
    """amplitude of the walls' repulsive potential [m^2/s^2]"""
    wall_range_m: float = navground_property("u_r", 0.2)
    """length scale of the walls' repulsive potential [m]"""


def pysocialforce_entry(section: str, entry: str, default: float) -> Any:
    """A settings field that sets ``entry`` of ``section`` of PySocialForce's config."""
    return field(default=default, metadata={PYSOCIALFORCE_ENTRY: (section, entry)})


@dataclass(frozen=True)
class PySocialForceSettings(PeerSettings):
    """PySocialForce's settings; the defaults of its forces are its default config's (``default.toml``). A 0 reads
    as the default there (its ``Config`` takes a falsy entry as missing)."""

    relaxation_time_s: float = pysocialforce_entry("desired_force", "relaxation_time", 0.5)
    """relaxation time toward the desired velocity [s]"""
    social_factor: float = pysocialforce_entry("social_force", "factor", 5.1)
    """weight of the people's repulsion [-]"""
    social_gamma: float = pysocialforce_entry("social_force", "gamma", 0.35)
    """range of the people's repulsion per unit of interaction (relative velocity and direction) [m]"""
    obstacle_factor: float = pysocialforce_entry("obstacle_force", "factor", 10.0)
    """weight of the walls' repulsion [-]"""
    obstacle_sigma_m: float = pysocialforce_entry("obstacle_force", "sigma", 0.2)
    """length scale of the walls' repulsion [m]"""

    def config(self) -> dict[str, dict[str, float]]:
        """The entries these settings give PySocialForce's config, by section; the target tolerance is the desired
        force's goal threshold."""
        sections: dict[str, dict[str, float]] = {"desired_force": {"goal_threshold": self.target_tolerance_m}}
        for f in fields(self):
            if PYSOCIALFORCE_ENTRY in f.metadata:
                section, entry = f.metadata[PYSOCIALFORCE_ENTRY]
                sections.setdefault(section, {})[entry] = getattr(self, f.name)
        return sections


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


def wall_points(walls_m: np.ndarray, spacing_m: float) -> np.ndarray:
    """(M, 2) points every ``spacing_m`` (or closer) along each segment of ``walls_m`` (K, 2, 2) [m], both ends
    included."""
    points = [np.zeros((0, 2))]
    for a, b in walls_m:
        count = int(np.ceil(np.linalg.norm(b - a) / spacing_m)) + 1
        points.append(a + np.linspace(0.0, 1.0, count)[:, None] * (b - a))
    return np.concatenate(points)


class PeerPlanner:
    """What every adapter does first: the robot's state, its target and who is near, from an observation.

    Args:
        world: the env's robot, pedestrians and map.
        use_predictions: ignored (these planners react to the current state).
        settings: the adapter's settings (None: ``tuned``, what the shipped name runs); of the class's settings type.
    """

    tuned: ClassVar[PeerSettings] = PeerSettings()
    """the settings picked on the val split by ``benchmarks/tune_peers.py``"""

    def __init__(self, world: NavWorld, use_predictions: bool = False, settings: PeerSettings | None = None):
        if settings is not None and not isinstance(settings, type(self.tuned)):
            raise TypeError(f"{type(self).__name__} takes {type(self.tuned).__name__}, not {type(settings).__name__}")
        self.world = world
        self.settings = self.tuned if settings is None else settings
        self.walls_m = map_wall_segments(world.scene)  # (K, 2, 2) [m]

    def reset(self) -> None:
        """Nothing to forget: each command is computed from the current observation."""

    def fingerprint(self) -> str:
        """The settings, for a benchmark run's identity."""
        return repr(self.settings)

    def target_of(self, ego_xy: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """(2,) the planner's target [m]: ``waypoint_m`` along the shortest walkable path from ``ego_xy`` to ``goal``
        (2,) [m], followed in steps of at most ``PATH_STEP_M``; the goal itself once nearer."""
        budget_m = self.settings.waypoint_m
        if float(np.linalg.norm(goal - ego_xy)) <= budget_m:
            return goal
        terrain, body_m, point = self.world.terrain, self.world.wall_clearance_m, ego_xy
        while budget_m > 1e-9:
            step_m = min(PATH_STEP_M, budget_m)
            point = point + step_m * terrain.direction_to(point, goal, body_m)
            budget_m -= step_m
        return point

    def situation(self, obs: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, Pedestrians,
                                                             np.ndarray]:
        """(robot position (2,) [m], velocity (2,) [m/s], target (2,) [m], the pedestrians within ``sensing_m``,
        the walls (K', 2, 2) within ``wall_sensing_m``) of ``obs``."""
        ego_xy, ego_v, goal = (obs["ego"][i:i + 2].astype(np.float64) for i in (0, 2, 4))
        everyone = pedestrians_of(obs, 1, use_predictions=False)
        near = np.linalg.norm(everyone.xy_m - ego_xy, axis=1) <= self.settings.sensing_m
        people = Pedestrians(everyone.xy_m[near], everyone.velocity_mps[near], everyone.futures_m[near],
                             everyone.predicted[near])
        walls = near_walls(self.walls_m, ego_xy, self.settings.wall_sensing_m)
        return ego_xy, ego_v, self.target_of(ego_xy, goal), people, walls


class NavgroundPlanner(PeerPlanner):
    """A navground behaviour (``behavior``) steering a robot of the env's radius and speed limit, with the settings'
    optimal speed, horizon, safety margin and the behaviour's own properties. The robot is navground's own model of
    the env's kind: omnidirectional for a holonomic robot (``act``: a velocity); two-wheel differential drive for a
    differential drive, its wheel axis chosen so that its turn-rate limit is the robot's (``act``: the robot's (v, w),
    ``drives_robot``)."""

    behavior: ClassVar[str]
    tuned: ClassVar[NavgroundSettings] = NavgroundSettings()

    def __init__(self, world: NavWorld, use_predictions: bool = False, settings: NavgroundSettings | None = None):
        super().__init__(world, use_predictions, settings)
        self.core = _navground()
        from navground.core.kinematics import OmnidirectionalKinematics, TwoWheelsDifferentialDriveKinematics

        self.agent = self.core.Behavior.make_type(self.behavior)
        if self.agent is None:
            raise ImportError(f"navground has no behaviour {self.behavior!r} (it has "
                              f"{', '.join(t for t in self.core.Behavior.types if t)}): {PEERS_EXTRA}")
        settings = self.settings
        robot = world.robot
        self.drives_robot = robot.kind == "diff-drive"
        self.agent.kinematics = (TwoWheelsDifferentialDriveKinematics(
            robot.max_speed_mps, 2 * robot.max_speed_mps / robot.max_yaw_rate_radps) if self.drives_robot
            else OmnidirectionalKinematics(world.max_speed_mps, MAX_TURN_RADPS))
        self.agent.radius = world.ego_radius_m
        self.agent.optimal_speed = settings.speed_share * world.max_speed_mps
        self.agent.horizon = settings.horizon_m
        self.agent.safety_margin = settings.safety_margin_m
        self.agent.assume_cmd_is_actuated = False  # the robot's velocity is the observed one, not the last command
        for name, value in settings.properties().items():  # as attributes: navground 0.7 registers HRVO's
            setattr(self.agent, name, value)               # uncertainty_offset as an int, which set() truncates

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame; a differential drive's (v [m/s], w [rad/s])."""
        core, agent = self.core, self.agent
        ego_xy, ego_v, target, people, walls = self.situation(obs)
        heading = (obs["ego"][6:8].astype(np.float64) if self.drives_robot
                   else ego_v if np.linalg.norm(ego_v) >= STILL_MPS else target - ego_xy)
        agent.position = ego_xy
        agent.orientation = float(np.arctan2(heading[1], heading[0]))
        agent.set_velocity(ego_v, core.Frame.absolute)
        agent.actuated_twist = core.Twist2(ego_v, 0.0, core.Frame.absolute)  # what the behaviours relax from
        agent.target = core.Target.Point(target, self.settings.target_tolerance_m)
        state = agent.environment_state
        state.neighbors = [core.Neighbor(xy, self.world.pedestrian_radius_m, v, k)
                           for k, (xy, v) in enumerate(zip(people.xy_m, people.velocity_mps, strict=True))]
        self.show_walls(state, walls)
        if self.drives_robot:
            agent.actuated_twist = core.Twist2(ego_v, float(obs["ego"][8]), core.Frame.absolute)
            twist = agent.compute_cmd(self.world.step_s, core.Frame.relative)
            return np.array([twist.velocity[0], twist.angular_speed], np.float32)
        twist = agent.compute_cmd(self.world.step_s, core.Frame.absolute)
        return np.asarray(twist.velocity, np.float32)

    def show_walls(self, state: Any, walls_m: np.ndarray) -> None:
        """Give the behaviour's environment ``state`` the walls (K, 2, 2) [m] as line obstacles."""
        state.line_obstacles = [self.core.LineSegment(a, b) for a, b in walls_m]


class NavgroundHL(NavgroundPlanner):
    """navground's HL (Guzzi et al. 2013, human-like: the free direction nearest the target within its aperture,
    at the speed that stops in time): "navground-hl"."""

    behavior = "HL"
    tuned: ClassVar[HLSettings] = HLSettings(eta_s=1.5, safety_margin_m=0.2)


class NavgroundOrca(NavgroundPlanner):
    """navground's ORCA (van den Berg et al. 2011): "navground-orca"."""

    behavior = "ORCA"
    tuned: ClassVar[OrcaSettings] = OrcaSettings(safety_margin_m=0.2)


class NavgroundHrvo(NavgroundPlanner):
    """navground's HRVO (Snape et al. 2011, hybrid reciprocal velocity obstacles): "navground-hrvo". It has no line
    obstacles: walls are discs every ``wall_disc_spacing_m`` along them."""

    behavior = "HRVO"
    tuned: ClassVar[HrvoSettings] = HrvoSettings(wall_sensing_m=2.0, speed_share=0.8)

    def show_walls(self, state: Any, walls_m: np.ndarray) -> None:
        """Give the behaviour's environment ``state`` the walls (K, 2, 2) [m] as static discs along them."""
        spacing_m = self.settings.wall_disc_spacing_m
        state.static_obstacles = [self.core.Disc(xy, spacing_m / 2) for xy in wall_points(walls_m, spacing_m)]


class NavgroundSocialForce(NavgroundPlanner):
    """navground's social force (Helbing and Molnár 1995): "navground-sf"."""

    behavior = "SocialForce"
    tuned: ClassVar[SocialForceSettings] = SocialForceSettings(people_range_m=0.6, wall_strength_m2ps2=3.0,
                                                               speed_share=0.7)

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame; a stop where navground's social force fails with NaN (its
        distance to a neighbour walking straight at the robot, the root of (n1 + n2)^2 - n3^2, takes the root of a
        negative number after rounding)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            command = super().act(obs)
        return command if np.isfinite(command).all() else np.zeros(2, np.float32)


class PySocialForcePlanner(PeerPlanner):
    """PySocialForce's extended social force model (Moussaïd et al. 2010) with the robot as one of its agents:
    "pysocialforce". The robot's desired speed is the settings' share of the env's speed limit; the pedestrians keep
    their velocities for the step (their own goals do not change the robot's forces); no groups (the observation
    has none). Its forces read the settings' config (``PySocialForceSettings.config``) over PySocialForce's
    default one."""

    tuned: ClassVar[PySocialForceSettings] = PySocialForceSettings(obstacle_factor=1.0, obstacle_sigma_m=0.1,
                                                                   social_factor=10.0, speed_share=0.8)

    def __init__(self, world: NavWorld, use_predictions: bool = False,
                 settings: PySocialForceSettings | None = None):
        super().__init__(world, use_predictions, settings)
        self.psf = _pysocialforce()
        self.config = self.psf.utils.DefaultConfig()
        for section, entries in self.settings.config().items():
            self.config.from_dict({section: {**self.config.sub_config(section).config, **entries}})

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame."""
        ego_xy, ego_v, target, people, walls = self.situation(obs)
        robot = np.r_[ego_xy, ego_v, target]
        others = np.c_[people.xy_m, people.velocity_mps, people.xy_m + people.velocity_mps * self.world.step_s]
        sim = self.psf.Simulator(np.vstack([robot, others]), groups=None,
                                 obstacles=[(a[0], b[0], a[1], b[1]) for a, b in walls])
        sim.peds.step_width = self.world.step_s
        sim.peds.agent_radius = self.world.ego_radius_m
        sim.peds.max_speeds = np.r_[self.settings.speed_share * self.world.max_speed_mps, sim.peds.max_speeds[1:]]
        sim.forces = sim.make_forces(self.config)
        with np.errstate(divide="ignore", invalid="ignore"):  # its speed cap divides by zero for people standing
            sim.step_once()
        return np.asarray(sim.peds.vel()[0], np.float32)
