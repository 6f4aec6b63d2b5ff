"""Physics facts and tunables of the pymunk crowd simulator (metres, seconds, kilograms)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

PED_MASS_KG: Final[float] = 80.0  # body mass of a pedestrian [kg]
EGO_MASS_KG: Final[float] = 400.0  # body mass of the ego robot [kg]; heavier than a pedestrian
WALL_RADIUS_M: Final[float] = 0.05  # half thickness of a wall segment [m]; also drawn into the layout raster
MAP_PX_M: Final[float] = 0.05  # size of one pixel of a synthetic layout's walkability raster [m]


@dataclass(frozen=True)
class CrowdConfig:
    """Tunables of the pedestrian crowd: bodies, speeds, population, spawning and social-force weights."""

    radius_m: float = 0.25
    """pedestrian body radius [m]"""
    preferred_speed_mean_mps: float = 1.3
    """mean preferred walking speed [m/s]"""
    preferred_speed_std_mps: float = 0.2
    """standard deviation of the preferred walking speed [m/s]"""
    preferred_speed_range_mps: tuple[float, float] = (0.6, 2.0)
    """preferred speeds are clipped to this range [m/s]"""
    max_speed_factor: float = 1.3
    """a pedestrian's speed is capped at this multiple of its preferred speed [-]"""
    n_substeps: int = 3
    """pymunk steps per 0.4 s env step [-]"""
    max_pedestrians: int = 40
    """most pedestrians present at once; spawning stops at this count [-]"""
    density_per_m2: float | None = None
    """if set, replaces max_pedestrians by density x the layout's walkable area [1/m^2]"""
    spawn_rate_hz: float = 0.5
    """Poisson rate of new pedestrians per entry region [1/s]"""
    spawn_gap_m: float = 0.15
    """free space required between a new pedestrian and any body present; widest gap of the initial lattice [m]"""
    spawn_lane_m: float = 3.0
    """a new pedestrian does not appear with an oncoming one less than this far ahead in its path [m]"""
    patience_s: float = 20.0
    """a pedestrian that came no closer to its exit (by 0.5 m) for this long heads for another exit [s]"""
    relaxation_time_s: float = 0.5
    """time in which a pedestrian's velocity relaxes to its desired velocity [s]"""
    jam_density_per_m2: float = 5.4
    """local density at which pedestrians stop wanting to move (Weidmann) [1/m^2]"""
    density_radius_m: float = 1.0
    """radius of the disc over which the local density is counted [m]"""
    time_gap_s: float = 0.5
    """a pedestrian walks no faster than the free gap to whoever stands in its path, per this time [s]"""
    agent_strength_mps2: float = 1.0
    """agent-agent repulsion at contact (exponential potential, per unit mass) [m/s^2]"""
    agent_range_m: float = 0.3
    """decay length of the agent-agent repulsion [m]"""
    agent_cutoff_m: float = 1.5
    """centre distance beyond which two agents ignore each other [m]"""
    look_ahead_s: float = 1.0
    """agents repel each other as they will be at their closest approach within this horizon [s]"""
    keep_right_mps2: float = 1.0
    """sideways acceleration to the right of oncoming pedestrians in one's path (lane formation) [m/s^2]"""
    pass_margin_m: float = 0.3
    """an oncoming pedestrian counts as in one's path up to this far beyond body contact, sideways [m]"""
    anisotropy: float = 0.35
    """weight of the repulsion from agents behind, relative to those ahead (lambda) [-]"""
    wall_strength_mps2: float = 4.0
    """wall repulsion at contact (exponential potential, per unit mass) [m/s^2]"""
    wall_range_m: float = 0.2
    """decay length of the wall repulsion [m]"""
    wall_cutoff_m: float = 1.0
    """walls farther than this from a pedestrian's centre do not push it [m]"""
    nav_cell_m: float = 0.2
    """cell size of the navigation fields that lead pedestrians to their exits [m]"""
    solver_iterations: int = 10
    """pymunk contact solver iterations per substep [-]"""
    collision_slop_m: float = 0.005
    """overlap pymunk allows without correcting it [m]"""
    collision_bias: float = 0.0018
    """share of an overlap pymunk leaves uncorrected after one second (pymunk's default is 0.0018) [-]"""

    def __post_init__(self) -> None:
        low, high = self.preferred_speed_range_mps
        checks = {
            "radius_m must be > 0": self.radius_m > 0,
            "n_substeps must be >= 1": self.n_substeps >= 1,
            "max_pedestrians must be >= 0": self.max_pedestrians >= 0,
            "density_per_m2 must be >= 0": self.density_per_m2 is None or self.density_per_m2 >= 0,
            "spawn_rate_hz must be >= 0": self.spawn_rate_hz >= 0,
            "preferred_speed_range_mps must be (low, high) with 0 <= low <= high": 0 <= low <= high,
            "relaxation_time_s, agent_range_m and wall_range_m must be > 0":
                min(self.relaxation_time_s, self.agent_range_m, self.wall_range_m) > 0,
        }
        problems = [problem for problem, ok in checks.items() if not ok]
        if problems:
            raise ValueError(f"CrowdConfig: {'; '.join(problems)}")


@dataclass(frozen=True)
class EgoConfig:
    """The ego robot: a disc whose velocity follows the action within speed and acceleration limits."""

    radius_m: float = 0.3
    """ego body radius [m]"""
    max_speed_mps: float = 1.5
    """commanded velocities are clipped to this speed [m/s]"""
    max_accel_mps2: float = 2.0
    """the commanded velocity changes by at most this much per second [m/s^2]"""
    start_m: tuple[float, float] | None = None
    """start position [m]; None = the layout's ego_start_m"""

    def __post_init__(self) -> None:
        if min(self.radius_m, self.max_speed_mps, self.max_accel_mps2) <= 0:
            raise ValueError(f"EgoConfig: radius_m, max_speed_mps and max_accel_mps2 must be > 0, got {self}")
