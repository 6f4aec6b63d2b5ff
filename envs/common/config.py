"""Tunables of the crowd environments: ego robot, spawning, reward weights.

Both dataclasses check every field on construction: a wrong type or a value outside the field's range raises
``ConfigError`` (a ValueError) naming the field, the value and the allowed range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from numbers import Integral, Real

from envs.common.errors import ConfigError

WEIGHT_LIMIT = 1e6  # |weight| bound of every reward part


@dataclass(frozen=True)
class Interval:
    """Allowed values of a number: ``low`` to ``high``, each end open or closed."""

    low: float
    high: float
    low_open: bool = False
    high_open: bool = False

    def __contains__(self, value: float) -> bool:
        above = value > self.low if self.low_open else value >= self.low
        below = value < self.high if self.high_open else value <= self.high
        return above and below

    def __str__(self) -> str:
        return f"{'(' if self.low_open else '['}{self.low:g}, {self.high:g}{')' if self.high_open else ']'}"


def check_fields(config: object, ranges: dict[str, Interval]) -> None:
    """Check the named number fields of a frozen dataclass and store them as ``float``.

    Raises:
        ConfigError: a field is not a real number (bools, strings and NaN are refused) or is outside its range.
    """
    owner = type(config).__name__
    for name, allowed in ranges.items():
        value = getattr(config, name)
        if isinstance(value, bool) or not isinstance(value, Real) or value not in allowed:  # NaN is in no range
            shown = repr(value) if len(repr(value)) <= 40 else repr(value)[:40] + "..."
            raise ConfigError(f"{owner}.{name}={shown}: expected a number in {allowed}")
        object.__setattr__(config, name, float(value))


@dataclass(frozen=True)
class RewardWeights:
    """Weight of each named reward part; reward = sum of weight x part (parts in ``info["reward_parts"]``).

    Every weight is a finite number with |weight| <= 1e6.
    """

    progress: float = 1.0
    """per metre the ego came closer to its goal this step (negative when it moved away)"""
    goal: float = 10.0
    """once, on the step the ego reaches its goal"""
    collision: float = -10.0
    """once, on the step the ego touches a pedestrian or a wall (parts ``pedestrian_collision`` and
    ``wall_collision``, which exclude each other)"""
    at_fault: float = 0.0
    """once, on a collision the benchmark's fault rule puts on the robot (part ``at_fault_collision``: a wall
    collision, or a pedestrian collision with ``info["at_fault"]`` True; ``envs.common.fault``), on top of
    ``collision``; 0: off, every collision costs the same whoever caused it"""
    off_map: float = -1.0
    """per step the ego stands on a non-walkable or off-image pixel"""
    time: float = -0.1
    """per step (0.4 s)"""
    discomfort: float = 0.0
    """per metre that the nearest pedestrian's body is inside ``EnvConfig.discomfort_m`` of the ego's body, per step
    (CrowdNav's discomfort term; its setting, factor 10 over a 0.4 s step, is -4.0; 0: off)"""
    prediction: float = 0.0
    """per step, times 0.5^(k - 1) for the soonest future step k at which the ego's course (held at its velocity)
    meets a pedestrian's mean predicted position (part ``predicted_collision``; CrowdNav++'s prediction-aware term;
    0: off)"""

    def __post_init__(self) -> None:
        check_fields(self, {f.name: Interval(-WEIGHT_LIMIT, WEIGHT_LIMIT) for f in fields(self)})


@dataclass(frozen=True)
class EnvConfig:
    """Ego robot and episode settings shared by the replay and simulated environments (ranges in brackets). The
    robot's kind, speed and acceleration limits are the env's ``robot`` (``st_sim.sim.robot.RobotSpec``)."""

    ego_radius_m: float = 0.3
    """ego body radius [m], (0, 5]"""
    pedestrian_radius_m: float = 0.25
    """pedestrian radius used for the ego collision test in replays [m], (0, 5] (the simulator has its own bodies)"""
    goal_radius_m: float = 0.5
    """the goal is reached when the ego centre is this close [m], (0, 100]"""
    spawn_clearance_m: float = 1.0
    """least distance between the spawned ego and any pedestrian [m], [0, 100]"""
    goal_min_fraction: float = 0.5
    """least start-goal distance as a share of the arena diagonal ("across the scene"), [0, 1]"""
    arena_margin_m: float = 1.0
    """replay arena = bounding box of the recorded positions grown by this margin, within the scene's image;
    the ego stays inside [m], [0, 100]"""
    sensor_range_m: float = math.inf
    """the ego senses pedestrians whose centre is within this distance of its own; the others' observation rows are
    empty (masks False) and they are not forecast; inf: everyone (spectator envs always see everyone) [m], (0, inf]"""
    forecast_nearest: int | None = None
    """forecast only the k sensed pedestrians nearest to the ego (ties in observation-row order), the ones a policy
    that reads k pedestrians uses; the others' rows keep their histories but no futures; None: every sensed one
    (spectator envs always forecast everyone), an int >= 1"""
    discomfort_m: float = 0.25
    """gap between the ego's body and a pedestrian's (a disc of ``pedestrian_radius_m``) below which the
    ``discomfort`` reward part counts [m], [0, 5]"""
    reward: RewardWeights = field(default_factory=RewardWeights)
    """weights of the reward parts"""

    def __post_init__(self) -> None:
        positive = {"low": 0.0, "low_open": True}
        check_fields(self, {
            "ego_radius_m": Interval(high=5.0, **positive),
            "pedestrian_radius_m": Interval(high=5.0, **positive), "goal_radius_m": Interval(high=100.0, **positive),
            "spawn_clearance_m": Interval(0.0, 100.0), "goal_min_fraction": Interval(0.0, 1.0),
            "arena_margin_m": Interval(0.0, 100.0), "sensor_range_m": Interval(high=math.inf, **positive),
            "discomfort_m": Interval(0.0, 5.0),
        })
        nearest = self.forecast_nearest
        if nearest is not None and (isinstance(nearest, bool) or not isinstance(nearest, Integral) or nearest < 1):
            raise ConfigError(f"EnvConfig.forecast_nearest={nearest!r}: expected None or an int >= 1")
        if not isinstance(self.reward, RewardWeights):
            raise ConfigError(f"EnvConfig.reward={self.reward!r}: expected a RewardWeights")
