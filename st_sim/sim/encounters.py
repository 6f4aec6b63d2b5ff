"""Scripted encounters: the canonical social-navigation scenarios of Francis et al. (2023), "Principles and
Guidelines for Evaluating Social Robot Navigation Algorithms": a frontal approach, overtaking, a person crossing at
an angle, a doorway with someone coming through the other way, and a group.

An encounter is a small spec of ranges (``EncounterSpec``). ``draw_encounter`` draws one instance of it from a
generator (``EncounterPlan``): the ego's straight route and a few pedestrians, set to meet on it. The pedestrians
(a group: its centre) walk a straight line toward a gate of the layout (in the plaza along y, in the doorway along x,
through the door) and are placed back along that line so that they would reach the *meeting point* on the ego's route
when the ego does, give or take ``delay_s``: an ego that stands ``EgoMotion.lead_s`` (an env's warm-up) and then
drives the route straight at full speed. ``EncounterPlan.pedestrians`` places them once the crowd's navigation field
is built (the ego's start must be known first).

    plan = draw_encounter("crossing_angle", layout, rng)
    sim = CrowdSim(layout, CrowdConfig(spawn_rate_hz=0.0), rng, ego=EgoConfig(start_m=tuple(plan.ego_start_m)),
                   n_initial=0)
    sim.add(plan.pedestrians(sim.nav, EgoMotion(lead_s=2.8), keep_clear_m=0.65))
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from st_sim.sim.exact import cos_sin, length
from st_sim.sim.groups import ABREAST_M
from st_sim.sim.layout import Layout
from st_sim.sim.navigation import NavigationField
from st_sim.sim.pairs import right_of
from st_sim.sim.population import PopulationError
from st_sim.sim.spawning import Arrivals

SEARCH_STEP_M: Final[float] = 0.1  # pedestrians too far back for the layout move toward the meeting point by this [m]
GROUP_ID: Final[int] = 0  # the group id of an encounter's group (the crowd has no other pedestrians) [-]


@dataclass(frozen=True)
class EgoMotion:
    """How the ego is expected to move: it stands ``lead_s``, then drives its route straight, accelerating at
    ``accel_mps2`` up to ``speed_mps`` (a straight planner's robot)."""

    lead_s: float = 0.0
    """time the ego stands before it sets off (an env's warm-up, T_obs - 1 steps of 0.4 s) [s]"""
    speed_mps: float = 1.5
    """its top speed [m/s]"""
    accel_mps2: float = 2.0
    """its acceleration from standing [m/s^2]"""

    def arrival_s(self, distance_m: float) -> float:
        """Time from now until the ego has driven ``distance_m`` along its route [s]."""
        ramp_m = self.speed_mps * self.speed_mps / (2 * self.accel_mps2)  # not ** 2: libm's pow
        if distance_m <= ramp_m:
            return self.lead_s + float(np.sqrt(2 * distance_m / self.accel_mps2))
        return self.lead_s + self.speed_mps / self.accel_mps2 + (distance_m - ramp_m) / self.speed_mps


@dataclass(frozen=True)
class EncounterSpec:
    """What an encounter varies per instance, each drawn uniformly from its (low, high) range (metres, seconds)."""

    layout: str
    """the layout's name (``make_layout``): "plaza" or "doorway" """
    exits: tuple[str, ...]
    """the pedestrians head for one of these gates (drawn) and walk from the layout's centre's side toward it"""
    angle_deg: tuple[float, float]
    """angle between the pedestrians' walking direction and the ego's route: 0 the same way, 180 head-on [deg]; they
    come from the ego's left or right (drawn)"""
    speed_mps: tuple[float, float]
    """walking speed, one for the group [m/s]"""
    meet_m: tuple[float, float]
    """where the encounter is set: the meeting point's distance along the ego's route from its start [m]"""
    delay_s: tuple[float, float]
    """the pedestrians reach the meeting point this long after the ego would (negative: before it) [s]"""
    offset_m: tuple[float, float] = (0.0, 0.0)
    """the pedestrians' line passes this far to the right of the meeting point, seen along their way [m]"""
    group_size: tuple[int, int] = (1, 1)
    """how many walk together, abreast (1: one person alone, group id -1)"""
    route_m: float = 16.0
    """length of the ego's straight route [m]"""
    shift_m: tuple[float, float] = (1.0, 1.0)
    """the route's midpoint lies within +-shift_m of the layout's centre, in x and in y [m]"""


ENCOUNTERS: dict[str, EncounterSpec] = {
    "frontal_approach": EncounterSpec(layout="plaza", exits=("north", "south"), angle_deg=(180.0, 180.0),
                                      speed_mps=(1.0, 1.4), meet_m=(5.0, 8.0), delay_s=(-0.5, 0.5),
                                      offset_m=(-0.8, 0.8)),
    "overtaking": EncounterSpec(layout="plaza", exits=("north", "south"), angle_deg=(0.0, 0.0),
                                speed_mps=(0.5, 0.8), meet_m=(9.0, 12.0), delay_s=(-0.5, 0.5), offset_m=(-0.8, 0.8)),
    "crossing_angle": EncounterSpec(layout="plaza", exits=("north", "south"), angle_deg=(45.0, 135.0),
                                    speed_mps=(0.9, 1.4), meet_m=(5.0, 7.0), delay_s=(-0.8, 0.8)),
    "doorway": EncounterSpec(layout="doorway", exits=("west", "east"), angle_deg=(180.0, 180.0),
                             speed_mps=(1.0, 1.3), meet_m=(5.5, 6.5), delay_s=(-1.0, 0.5), offset_m=(-0.2, 0.2),
                             route_m=14.0, shift_m=(0.5, 0.0)),
    "group": EncounterSpec(layout="plaza", exits=("north", "south"), angle_deg=(90.0, 180.0), speed_mps=(1.0, 1.3),
                           meet_m=(5.0, 7.0), delay_s=(-0.5, 0.5), offset_m=(-0.5, 0.5), group_size=(2, 4)),
}
"""the encounters by name; see ``docs/environments.md`` for their geometry"""


@dataclass(frozen=True, eq=False)
class EncounterPlan:
    """One drawn instance of an encounter (metres, seconds, world frame).

    Attributes:
        name: the encounter's name.  ego_start_m, ego_goal_m: (2,) the ego's route.
        meeting_m: (2,) where the pedestrians (a group: its centre) would be when the ego is ``meet_m`` along its
            route, ``delay_s`` aside.
        meet_m: how far along its route from its start the ego meets them [m].
        heading: (2,) unit walking direction of the pedestrians.  exit_idx: the gate they head for.
        angle_deg: angle between their walking direction and the ego's route [deg].
        speed_mps: their walking speed [m/s].  delay_s: how long after the ego they would reach the meeting point [s].
        group_size: how many walk together (1: alone).
    """

    name: str
    ego_start_m: np.ndarray
    ego_goal_m: np.ndarray
    meeting_m: np.ndarray
    meet_m: float
    heading: np.ndarray
    exit_idx: int
    angle_deg: float
    speed_mps: float
    delay_s: float
    group_size: int

    def __repr__(self) -> str:
        return f"{self.name}/{self.group_size}x{self.speed_mps:.2f}m/s/{self.angle_deg:.0f}deg"

    def pedestrians(self, nav: NavigationField, ego: EgoMotion, keep_clear_m: float) -> Arrivals:
        """The pedestrians, placed on their line back from the meeting point by the distance they walk until the ego
        (moving as ``ego``) reaches it, plus ``delay_s``; moved toward the meeting point, by SEARCH_STEP_M at a time,
        while a member would stand where no pedestrian may start (``nav.startable_at``) or closer than
        ``keep_clear_m`` to the ego's start.

        Raises:
            PopulationError: no place on the line fits them all.
        """
        n = self.group_size
        abreast_m = (np.arange(n) - (n - 1) / 2) * ABREAST_M
        right = right_of(self.heading[None])[0]
        walk_m = self.speed_mps * max(ego.arrival_s(self.meet_m) + self.delay_s, 0.0)
        back_m = np.arange(walk_m, -SEARCH_STEP_M / 2, -SEARCH_STEP_M)  # (K,) farthest first
        centre = self.meeting_m - back_m[:, None] * self.heading  # (K, 2)
        members = centre[:, None] + abreast_m[None, :, None] * right  # (K, n, 2)
        flat = members.reshape(-1, 2)
        fits = nav.startable_at(flat) & (length(flat - self.ego_start_m) >= keep_clear_m)
        fitting = np.flatnonzero(fits.reshape(len(back_m), n).all(axis=1))
        if not fitting.size:
            raise PopulationError(f"encounter {self.name}: no room for {n} pedestrian(s) on their line to the "
                                  f"meeting point {self.meeting_m.round(2).tolist()} m")
        return Arrivals(xy_m=members[fitting[0]], exit_idx=np.full(n, self.exit_idx, np.int64),
                        speed_mps=np.full(n, self.speed_mps), group=np.full(n, GROUP_ID if n > 1 else -1, np.int64),
                        stop_step=np.full(n, -1, np.int64), go_step=np.zeros(n, np.int64))


def draw_encounter(name: str, layout: Layout, rng: np.random.Generator) -> EncounterPlan:
    """An instance of encounter ``name`` (a key of ``ENCOUNTERS``) in its layout, every range drawn from ``rng``.

    The pedestrians walk in the direction from the layout's centre to their gate's centre (along y in the plaza,
    along x through the doorway); the ego's route, ``route_m`` long, runs in that direction turned by the angle,
    counterclockwise or clockwise (drawn), its midpoint shifted from the layout's centre; the meeting point lies
    ``meet_m`` along it, moved sideways by the offset.
    """
    spec = ENCOUNTERS[name]
    assert layout.name == spec.layout, f"encounter {name} runs in layout {spec.layout}, not {layout.name}"
    exit_name = spec.exits[int(rng.integers(len(spec.exits)))]
    exit_idx = [region.name for region in layout.exits].index(exit_name)
    side = 1.0 if rng.random() < 0.5 else -1.0  # the route turns counterclockwise (+1) or clockwise (-1) from them
    angle_deg = float(rng.uniform(*spec.angle_deg))
    speed_mps = float(rng.uniform(*spec.speed_mps))
    meet_m = float(rng.uniform(*spec.meet_m))
    delay_s = float(rng.uniform(*spec.delay_s))
    offset_m = float(rng.uniform(*spec.offset_m))
    group_size = int(rng.integers(spec.group_size[0], spec.group_size[1] + 1))
    shift_m = rng.uniform(-1.0, 1.0, 2) * np.array(spec.shift_m)

    xmin, ymin, xmax, ymax = layout.bounds_m
    centre = np.array([(xmin + xmax) / 2, (ymin + ymax) / 2])
    to_exit = layout.exits[exit_idx].centre_m - centre
    heading = to_exit / length(to_exit)
    cos, sin = cos_sin(side * angle_deg * (np.pi / 180.0))
    route = np.array([cos * heading[0] - sin * heading[1], sin * heading[0] + cos * heading[1]])
    start = centre + shift_m - spec.route_m / 2 * route
    meeting = start + meet_m * route + offset_m * right_of(heading[None])[0]
    return EncounterPlan(name, start, start + spec.route_m * route, meeting, meet_m, heading, exit_idx, angle_deg,
                         speed_mps, delay_s, group_size)
