"""Physics facts and tunables of the pymunk crowd simulator (metres, seconds, kilograms).

Every numeric field states its allowed range beside its default (``checks.bounded``); a config with a value
outside it, NaN or inf raises ``ValueError`` naming the field, the value and the range. The steering
parameters' defaults are the fitted ones (``fits.steering_defaults``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final

from st_sim.sim.checks import bounded, check_fields
from st_sim.sim.fits import POPULATION_FIT, load_fit, steering_defaults
from st_sim.sim.robot import RobotSpec

PED_MASS_KG: Final[float] = 80.0  # body mass of a pedestrian [kg]
EGO_MASS_KG: Final[float] = 400.0  # body mass of the ego robot [kg]; heavier than a pedestrian
WALL_RADIUS_M: Final[float] = 0.05  # half thickness of a wall segment [m]; also drawn into the layout raster
MAP_PX_M: Final[float] = 0.05  # size of one pixel of a synthetic layout's walkability raster [m]
MAX_POPULATION: Final[int] = 5000  # most pedestrians a simulator holds [-]

_SPEED_MODEL = steering_defaults("speed_model")
_SOCIAL_FORCE = steering_defaults("social_force")


@dataclass(frozen=True)
class SpeedModelConfig:
    """Collision-free speed model with anticipation (``speed_model``): a first-order model.

    A pedestrian walks in the direction of its goal turned away from neighbours (where they will be at the
    closest approach within look_ahead_s) and from walls, at the speed that the free gap ahead allows:
    v = min(v0, gap / time_gap_s). Defaults fitted by ``benchmarks/fit_steering.py``.
    """

    time_gap_s: float = bounded(_SPEED_MODEL["time_gap_s"], 0.05, 5.0, "s")
    """a pedestrian closes the free gap to whoever is in its path in no less than this time [s]"""
    agent_strength: float = bounded(_SPEED_MODEL["agent_strength"], 0.0, 50.0)
    """weight of a neighbour's push on the walking direction at contact, relative to the goal's (1) [-]"""
    agent_range_m: float = bounded(_SPEED_MODEL["agent_range_m"], 0.01, 2.0, "m")
    """decay length of a neighbour's push [m]"""
    look_ahead_s: float = bounded(_SPEED_MODEL["look_ahead_s"], 0.0, 5.0, "s")
    """neighbours push as they will be at the closest approach within this horizon [s]"""
    keep_right: float = bounded(_SPEED_MODEL["keep_right"], 0.0, 5.0)
    """weight of the sidestep to the right of oncoming pedestrians in one's path (lane formation) [-]"""
    wall_strength: float = bounded(_SPEED_MODEL["wall_strength"], 0.0, 50.0)
    """weight of a wall's push on the walking direction at contact [-]"""
    wall_range_m: float = bounded(0.1, 0.01, 2.0, "m")
    """decay length of a wall's push [m]"""
    relaxation_time_s: float = bounded(_SPEED_MODEL["relaxation_time_s"], 0.0, 5.0, "s")
    """the velocity follows the chosen one within this time (0: at once) [s]"""
    agent_cutoff_m: float = bounded(2.0, 0.5, 5.0, "m")
    """neighbours farther than this (centre distance) are ignored; also bounds the free gap ahead [m]"""
    wall_cutoff_m: float = bounded(1.0, 0.1, 5.0, "m")
    """walls farther than this from a pedestrian's centre do not push it [m]"""

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class SocialForceConfig:
    """Social-force steering (``social_force``): accelerations toward the goal and away from neighbours and walls.

    Goal relaxation at a speed slowed by the local density (Weidmann) and by the headway, anticipatory
    anisotropic exponential repulsion, a sidestep to the right of oncoming pedestrians, and wall repulsion.
    Defaults fitted by ``benchmarks/fit_steering.py``.
    """

    relaxation_time_s: float = bounded(_SOCIAL_FORCE["relaxation_time_s"], 0.05, 5.0, "s")
    """time in which a pedestrian's velocity relaxes to its desired velocity [s]"""
    jam_density_per_m2: float = bounded(5.4, 1.0, 10.0, "1/m^2")
    """local density at which pedestrians stop wanting to move (Weidmann) [1/m^2]"""
    density_radius_m: float = bounded(1.0, 0.3, 3.0, "m")
    """radius of the disc over which the local density is counted [m]"""
    time_gap_s: float = bounded(_SOCIAL_FORCE["time_gap_s"], 0.05, 5.0, "s")
    """a pedestrian walks no faster than the free gap to whoever walks ahead of it, per this time [s]"""
    agent_strength_mps2: float = bounded(_SOCIAL_FORCE["agent_strength_mps2"], 0.0, 100.0, "m/s^2")
    """agent-agent repulsion at contact (exponential potential, per unit mass) [m/s^2]"""
    agent_range_m: float = bounded(_SOCIAL_FORCE["agent_range_m"], 0.01, 2.0, "m")
    """decay length of the agent-agent repulsion [m]"""
    agent_cutoff_m: float = bounded(1.5, 0.5, 5.0, "m")
    """centre distance beyond which two agents ignore each other [m]"""
    look_ahead_s: float = bounded(_SOCIAL_FORCE["look_ahead_s"], 0.0, 5.0, "s")
    """agents repel each other as they will be at their closest approach within this horizon [s]"""
    keep_right_mps2: float = bounded(_SOCIAL_FORCE["keep_right_mps2"], 0.0, 20.0, "m/s^2")
    """sideways acceleration to the right of oncoming pedestrians in one's path (lane formation) [m/s^2]"""
    pass_margin_m: float = bounded(0.3, 0.0, 2.0, "m")
    """an oncoming pedestrian counts as in one's path up to this far beyond body contact, sideways [m]"""
    anisotropy: float = bounded(0.35, 0.0, 1.0)
    """weight of the repulsion from agents behind, relative to those ahead (lambda) [-]"""
    wall_strength_mps2: float = bounded(4.0, 0.0, 100.0, "m/s^2")
    """wall repulsion at contact (exponential potential, per unit mass) [m/s^2]"""
    wall_range_m: float = bounded(0.2, 0.01, 2.0, "m")
    """decay length of the wall repulsion [m]"""
    wall_cutoff_m: float = bounded(1.0, 0.1, 5.0, "m")
    """walls farther than this from a pedestrian's centre do not push it [m]"""

    def __post_init__(self) -> None:
        check_fields(self)


SteeringConfig = SpeedModelConfig | SocialForceConfig


@dataclass(frozen=True)
class PopulationConfig:
    """Who walks: preferred speeds, pedestrians who stop for a while, and small groups.

    The defaults are Weidmann's free walkers (1.34 +- 0.26 m/s), nobody standing, no groups;
    ``PopulationConfig.fitted(scene)`` gives a population fitted to an ETH/UCY recording.
    """

    speed_mean_mps: float = bounded(1.34, 0.0, 5.0, "m/s")
    """mean preferred walking speed of a walker [m/s]"""
    speed_std_mps: float = bounded(0.26, 0.0, 2.0, "m/s")
    """standard deviation of the preferred walking speed [m/s]"""
    speed_range_mps: tuple[float, float] = bounded((0.3, 2.5), 0.0, 5.0, "m/s", length=2)
    """preferred walking speeds are clipped to (low, high) [m/s]"""
    standing_share: float = bounded(0.0, 0.0, 0.95)
    """share of the pedestrians present who stand still (new pedestrians stop on their way to keep it) [-]"""
    dwell_mean_s: float = bounded(60.0, 0.4, 3600.0, "s")
    """mean time a pedestrian stands before walking on (exponential) [s]"""
    group_share: float = bounded(0.0, 0.0, 1.0)
    """share of pedestrians who walk in a group of two or three [-]"""
    triple_share: float = bounded(0.2, 0.0, 1.0)
    """share of groups that have three members rather than two [-]"""

    def __post_init__(self) -> None:
        check_fields(self)
        low, high = self.speed_range_mps
        if low > high:
            raise ValueError(f"PopulationConfig.speed_range_mps = {self.speed_range_mps!r}: expected (low, high) "
                             "with low <= high")

    @classmethod
    def fitted(cls, scene: str) -> PopulationConfig:
        """The population fitted to an ETH/UCY scene's recording ("eth", ..., "zara2"; fits.population_fit.json)."""
        scenes = load_fit(POPULATION_FIT)["scenes"]
        if scene not in scenes:
            raise KeyError(f"no fitted population for {scene!r}; expected one of {', '.join(scenes)}")
        params = scenes[scene]["params"]
        return cls(**{**params, "speed_range_mps": tuple(params["speed_range_mps"])})


@dataclass(frozen=True)
class CrowdConfig:
    """Tunables of the pedestrian crowd: bodies, population and spawning, steering model, pymunk contacts."""

    radius_m: float = bounded(0.2, 0.1, 0.5, "m")
    """pedestrian body radius [m]; 0.2 m discs pack at most 7 /m^2, Weidmann's jam density is 5.4 /m^2"""
    population: PopulationConfig = PopulationConfig()
    """preferred speeds, standing pedestrians and groups"""
    steering: SteeringConfig = SpeedModelConfig()
    """steering model and its parameters: SpeedModelConfig (default) or SocialForceConfig"""
    max_speed_factor: float = bounded(1.3, 1.0, 3.0)
    """a pedestrian's speed is capped at this multiple of its preferred speed [-]"""
    n_substeps: int = bounded(2, 1, 50, integer=True)
    """pymunk steps per 0.4 s env step [-]"""
    max_pedestrians: int = bounded(40, 0, MAX_POPULATION, integer=True)
    """most pedestrians present at once; spawning stops at this count [-]"""
    density_per_m2: float | None = bounded(None, 0.0, 8.0, "1/m^2", optional=True)
    """if set, replaces max_pedestrians by density x the layout's walkable area [1/m^2]"""
    spawn_rate_hz: float = bounded(0.5, 0.0, 50.0, "1/s")
    """Poisson rate of new pedestrians (or groups) per entry region [1/s]"""
    spawn_gap_m: float = bounded(0.15, 0.0, 2.0, "m")
    """free space required between a new pedestrian and any body present; widest gap of the initial lattice [m]"""
    spawn_lane_m: float = bounded(3.0, 0.0, 50.0, "m")
    """a new pedestrian does not appear with an oncoming one less than this far ahead in its path [m]"""
    patience_s: float = bounded(20.0, 0.4, 3600.0, "s")
    """a walking pedestrian that came no closer to its exit (by 0.5 m) for this long heads for another exit [s]"""
    nav_cell_m: float = bounded(0.2, 0.05, 1.0, "m")
    """cell size of the navigation fields that lead pedestrians to their exits [m]"""
    solver_iterations: int = bounded(10, 1, 100, integer=True)
    """pymunk contact solver iterations per substep [-]"""
    collision_slop_m: float = bounded(0.005, 0.0, 0.1, "m")
    """overlap pymunk allows without correcting it [m]"""
    collision_bias: float = bounded(0.1, 0.0, 1.0, open_low=True)
    """share of an overlap pymunk leaves uncorrected after one second (pymunk's default, 0.0018, pushes so hard
    that it drives pressed bodies into their other neighbours) [-]"""

    def __post_init__(self) -> None:
        check_fields(self)
        for name, kinds in (("population", PopulationConfig), ("steering", (SpeedModelConfig, SocialForceConfig))):
            if not isinstance(getattr(self, name), kinds):
                raise ValueError(f"CrowdConfig.{name} = {getattr(self, name)!r}: expected {kinds}")

    @property
    def top_speed_mps(self) -> float:
        """Fastest a pedestrian may walk [m/s]: the cap factor times the highest preferred speed."""
        return self.max_speed_factor * self.population.speed_range_mps[1]


@dataclass(frozen=True)
class EgoConfig:
    """The ego robot: a disc that moves as its ``robot`` model turns each command into motion (``st_sim.sim.robot``)."""

    radius_m: float = bounded(0.3, 0.05, 2.0, "m")
    """ego body radius [m]"""
    robot: RobotSpec = field(default_factory=RobotSpec)
    """kind and limits: speed, acceleration, turning (the holonomic default: 1.5 m/s, 2 m/s^2)"""
    start_m: tuple[float, float] | None = bounded(None, -1e6, 1e6, "m", optional=True, length=2)
    """start position [m]; None = the layout's ego_start_m"""
    pedestrians_see_ego: bool = True
    """True: pedestrians steer around the ego as around another pedestrian; False: an invisible robot that
    pedestrians meet only by contact (as CrowdNav-style benchmarks also report)"""

    def __post_init__(self) -> None:
        check_fields(self)
        if not isinstance(self.robot, RobotSpec):
            raise ValueError(f"EgoConfig.robot = {self.robot!r}: expected an st_sim.sim.robot.RobotSpec")
        if not isinstance(self.pedestrians_see_ego, bool):
            raise ValueError(f"EgoConfig.pedestrians_see_ego = {self.pedestrians_see_ego!r}: expected True or False")
