"""Navigation metrics in three groups (safety, efficiency, comfort), their means with 95 % intervals, paired tests.

Each figure of one episode is defined in ``METRICS`` with its group, unit and the benchmarks that report it
(``docs``: ``metrics_table``); the groups follow SEANavBench's safety / efficiency / socialness split, which Francis
et al. 2023 recommend. Distances between people are body gaps (``social_metrics``). Rates (success, collisions,
timeout) get Wilson score intervals; means get seeded bootstrap percentile intervals over the episodes where the
figure exists (time to goal and path ratio: successful episodes only), which stay inside the figure's range. Two
planners run on the same seeds are compared with McNemar's exact test on the episodes where only one of them
collided.

A collision is at fault (``collision_at_fault``) when the robot hit a wall, or touched a pedestrian while moving
(0.05 m/s or more at the impact, or stopped less than 0.8 s before it) unless the pedestrian ran into it from behind
(the env's ``info["at_fault"]``, ``envs.common.fault``). Pedestrian collisions are also counted apart by that rule,
robot-on-person and person-on-robot (``collision_robot_on_person``, ``collision_person_on_robot``), as SEANavBench
and HuNavSim count them; the zone entries are split by the same rule.

Choices where the sources differ: intimate-zone entries are near misses, so they count as safety, personal-zone
entries as comfort (SEANavBench counts both, split by who moved in); off-map steps are the replays' stand-in for
touching a static obstacle (their walls are only marked), so safety; ``log_ade_m`` (how far a reactive crowd was
pushed off its recorded paths) is the robot's cost to the crowd, so comfort, like HuNavSim's force on the agents.
Path ratio and path irregularity are measured against the straight line (a straight path turns by 0), not against
a search-based path as in SEANavBench and SocNavBench. Time to collision has no horizon: a pair far apart on a
collision course counts with its long time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from typing import Literal

import numpy as np
from scipy import stats

from envs.common.config import EnvConfig
from envs.common.fault import STOP_HOLD_STEPS, STOP_SPEED_MPS
from replays.constants import STEP_S
from st_sim.apps.navigation.social_metrics import (
    INTIMATE_M,
    PERSONAL_M,
    SOCIAL_M,
    STOPPED_MPS,
    ZONES,
    body_gaps_m,
    group_intrusions,
    group_spaces,
    min_time_to_collision_s,
    nearest_gap_m,
    path_irregularity_rad,
    zone_entries,
    zone_shares,
)
from st_sim.sim import CrowdConfig

DISCOMFORT_M = 0.2  # the ego is uncomfortably close when its body is this near a pedestrian's [m]
CONFIDENCE = 0.95
BOOTSTRAP_RESAMPLES = 2000  # resamples of a mean's bootstrap interval [-]
BOOTSTRAP_SEED = 0  # the bootstrap's generator seed: the same episodes always give the same interval
BOOTSTRAP_BATCH = 200  # resamples drawn at once [-]
NAN = float("nan")


class Outcome(str, Enum):
    """How an episode ended."""

    GOAL = "goal"
    PEDESTRIAN = "pedestrian collision"
    WALL = "wall collision"
    TIMEOUT = "timeout"


TERMINATION_OUTCOMES: dict[str, Outcome] = {"goal": Outcome.GOAL, "pedestrian_collision": Outcome.PEDESTRIAN,
                                            "wall_collision": Outcome.WALL}
"""the env's ``info["termination"]`` values and the outcomes they name"""


def outcome_of(termination: str | None, truncated: bool) -> Outcome | None:
    """Outcome of a step from the env's ``info["termination"]`` and ``truncated``, or None while it goes on.

    The env names its terminations (a collision outranks the goal); a truncation without one is a timeout
    (the registered time limit, or a replay's recording that ended).
    """
    if termination is not None:
        return TERMINATION_OUTCOMES[termination]
    return Outcome.TIMEOUT if truncated else None


@dataclass(frozen=True, eq=False)
class EpisodeTrace:
    """One episode, reset included (T steps, T + 1 states; N pedestrians seen in it).

    Attributes:
        ego_xy_m: (T + 1, 2) ego positions [m].  ego_velocity_mps: (T + 1, 2) ego velocities [m/s].
        clearance_m: (T + 1,) gap between the ego's body and the nearest pedestrian's [m] (inf: nobody there); the
            nearest gap when ``pedestrians_xy_m`` is None (else the gaps come from the positions).
        off_map: (T + 1,) bool, the ego stood on non-walkable ground.
        goal_m: (2,) [m].  outcome: how it ended.
        at_fault: on a pedestrian collision, whether the robot was at fault (the env's ``info["at_fault"]``; None:
            not judged, counted as the robot's).
        log_deviation_m: (T,) mean distance of the pedestrians from their recorded paths after each step [m]
            (reactive replays; empty elsewhere).
        pedestrians_xy_m: (T + 1, N, 2) float64 positions of every pedestrian seen, one column per pedestrian id,
            NaN where absent [m]; None: not recorded (time to collision and zone entries are then NaN).
        pedestrian_groups: (N,) int64 group id of each column (-1: alone); None: the env has no groups (the group
            figures are then NaN).
        ego_radius_m, pedestrian_radius_m: body radii [m].  goal_radius_m: the goal is reached this close to its
            centre [m].  step_s: seconds per step.
        clipped: (T,) bool, the robot's limits clipped the step's command (``info["robot"].clipped``); empty: not
            recorded (the figure is then NaN).
        tracking: the episode's CLEAR MOT and IDF1 figures (``st_sim.perception.MotAccumulator.summary``); None with
            the oracle's eyes (the figures are then NaN).
        forecast_ade_m, forecast_fde_m: best-of-S ADE and FDE of the forecasts the robot got in the episode against
            where the people really went (``info["metrics"]``; NaN when none matured) [m].
    """

    ego_xy_m: np.ndarray
    ego_velocity_mps: np.ndarray
    clearance_m: np.ndarray
    off_map: np.ndarray
    goal_m: np.ndarray
    outcome: Outcome
    at_fault: bool | None = None
    log_deviation_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pedestrians_xy_m: np.ndarray | None = None
    pedestrian_groups: np.ndarray | None = None
    ego_radius_m: float = EnvConfig.ego_radius_m
    pedestrian_radius_m: float = EnvConfig.pedestrian_radius_m
    goal_radius_m: float = EnvConfig.goal_radius_m
    step_s: float = STEP_S
    clipped: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    tracking: dict[str, float] | None = None
    forecast_ade_m: float = NAN
    forecast_fde_m: float = NAN

    def __post_init__(self) -> None:
        states = len(self.ego_xy_m)
        peds = self.pedestrians_xy_m
        if peds is not None and (peds.ndim != 3 or peds.shape[0] != states or peds.shape[2] != 2):
            raise ValueError(f"pedestrians_xy_m: expected ({states}, N, 2) for {states} ego states, got {peds.shape}")
        groups = self.pedestrian_groups
        if groups is not None and (peds is None or groups.shape != peds.shape[1:2]):
            raise ValueError(f"pedestrian_groups: expected one group id per pedestrians_xy_m column, got "
                             f"{groups.shape} for {None if peds is None else peds.shape}")

    @property
    def contact_m(self) -> float:
        """Centre distance at which the ego touches a pedestrian [m]."""
        return self.ego_radius_m + self.pedestrian_radius_m


def episode_metrics(trace: EpisodeTrace) -> dict[str, float | int | str | bool]:
    """Every figure of ``METRICS`` for one episode under its name (rates as bools, NaN where a figure does not
    exist), after its outcome.

    Per-step figures are taken at the steps' ends (states 1..T; the reset state alone when T = 0).
    """
    gaps = None if trace.pedestrians_xy_m is None else body_gaps_m(trace.ego_xy_m, trace.pedestrians_xy_m,
                                                                   trace.contact_m)
    nearest = _step_ends(trace.clearance_m if gaps is None else nearest_gap_m(gaps))
    return {"outcome": trace.outcome.value, **_safety(trace, gaps, nearest), **_efficiency(trace),
            **_comfort(trace, gaps, nearest), **_perception(trace)}


def _perception(trace: EpisodeTrace) -> dict[str, float]:
    """CLEAR MOT and IDF1 of the robot's tracks (NaN with the oracle's eyes), the forecasts' ADE and FDE."""
    tracking = trace.tracking or {}
    return {"mota": tracking.get("mota", NAN), "motp_m": tracking.get("motp_m", NAN), "idf1": tracking.get("idf1", NAN),
            "id_switches": float(tracking.get("id_switches", NAN)), "forecast_ade_m": trace.forecast_ade_m,
            "forecast_fde_m": trace.forecast_fde_m}


def _safety(trace: EpisodeTrace, gaps: np.ndarray | None, nearest: np.ndarray) -> dict[str, float | int | bool]:
    """Collision, at fault, who moved into whom, least gap and time to collision, intimate-zone entries, off-map
    share."""
    pedestrian = trace.outcome is Outcome.PEDESTRIAN
    robot_on_person = pedestrian and trace.at_fault is not False
    finite = nearest[np.isfinite(nearest)]
    ttc = NAN if gaps is None else min_time_to_collision_s(trace.ego_xy_m, trace.ego_velocity_mps,
                                                           trace.pedestrians_xy_m, trace.contact_m, trace.step_s)
    return {"collision": trace.outcome in (Outcome.PEDESTRIAN, Outcome.WALL),
            "collision_at_fault": trace.outcome is Outcome.WALL or robot_on_person,
            "collision_robot_on_person": robot_on_person,
            "collision_person_on_robot": pedestrian and not robot_on_person,
            "pedestrian_collision": pedestrian, "wall_collision": trace.outcome is Outcome.WALL,
            "min_step_end_gap_m": float(finite.min()) if finite.size else NAN, "min_ttc_s": ttc,
            **_entries(trace, gaps, INTIMATE_M, "intimate"), "off_map": float(np.mean(_step_ends(trace.off_map)))}


def _efficiency(trace: EpisodeTrace) -> dict[str, float | int | bool]:
    """Success, timeout, steps, time to goal, path length and ratio, SPL, time not moving."""
    steps = len(trace.ego_xy_m) - 1
    success = trace.outcome is Outcome.GOAL
    step_m = np.linalg.norm(np.diff(trace.ego_xy_m, axis=0), axis=1)
    path_m = float(step_m.sum())
    straight_m = float(np.linalg.norm(trace.goal_m - trace.ego_xy_m[0]))
    to_edge_m = straight_m - trace.goal_radius_m  # the straight way into the goal's disc [m]
    spl = straight_m / max(path_m, straight_m) if path_m + straight_m > 0 else 1.0  # 1: nothing to cover
    return {"success": success, "timeout": trace.outcome is Outcome.TIMEOUT, "steps": steps,
            "time_to_goal_s": steps * trace.step_s if success else NAN, "path_length_m": path_m,
            "path_ratio": path_m / to_edge_m if success and to_edge_m > 0 else NAN, "spl": spl * success,
            "time_not_moving_s": float(np.sum(step_m < STOPPED_MPS * trace.step_s) * trace.step_s)}


def _comfort(trace: EpisodeTrace, gaps: np.ndarray | None, nearest: np.ndarray) -> dict[str, float | int]:
    """Zone shares, personal-zone entries, acceleration, jerk, irregularity, group intrusions, discomfort, log ADE."""
    velocity, step_s = trace.ego_velocity_mps, trace.step_s
    acceleration = np.linalg.norm(np.diff(velocity, axis=0), axis=1) / step_s
    jerk = np.linalg.norm(np.diff(velocity, n=2, axis=0), axis=1) / step_s ** 2
    shares = zone_shares(nearest)
    return {**{f"zone_{zone}_share": shares[zone] for zone in ZONES}, **_entries(trace, gaps, PERSONAL_M, "personal"),
            "acceleration_mps2": _mean(acceleration), "jerk_mps3": _mean(jerk),
            "path_irregularity_rad": path_irregularity_rad(trace.ego_xy_m, STOPPED_MPS * step_s),
            **_groups(trace), "discomfort": float(np.mean(nearest < DISCOMFORT_M)),
            "log_ade_m": _mean(trace.log_deviation_m), "clipped_command_share": _mean(trace.clipped.astype(float))}


def _entries(trace: EpisodeTrace, gaps: np.ndarray | None, limit_m: float, zone: str) -> dict[str, float | int]:
    """``{zone}_entries_robot`` and ``{zone}_entries_person`` (``social_metrics.zone_entries``); NaN without
    pedestrian positions."""
    robot, person = (NAN, NAN) if gaps is None else zone_entries(trace.ego_xy_m, trace.pedestrians_xy_m, gaps,
                                                                 limit_m, trace.step_s)
    return {f"{zone}_entries_robot": robot, f"{zone}_entries_person": person}


def _groups(trace: EpisodeTrace) -> dict[str, float | int]:
    """``group_intrusions`` and ``group_intrusion_share`` (``social_metrics.group_spaces``); NaN without groups."""
    if trace.pedestrian_groups is None:
        return {"group_intrusions": NAN, "group_intrusion_share": NAN}
    inside, exists = group_spaces(trace.ego_xy_m, trace.pedestrians_xy_m, trace.pedestrian_groups)
    return {"group_intrusions": group_intrusions(inside, exists),
            "group_intrusion_share": float(np.mean(_step_ends(inside.any(axis=1))))}


def _step_ends(per_state: np.ndarray) -> np.ndarray:
    """The (T,) values at the steps' ends of (T + 1,) per-state values; the reset state's when T = 0."""
    return per_state[1:] if len(per_state) > 1 else per_state


def _mean(values: np.ndarray) -> float:
    """Mean of ``values``; NaN if there are none."""
    return float(values.mean()) if values.size else NAN


Group = Literal["safety", "efficiency", "comfort", "perception"]
GROUPS: tuple[Group, ...] = ("safety", "efficiency", "comfort", "perception")


@dataclass(frozen=True)
class Metric:
    """One figure of the benchmark, as ``summarize`` pools it over episodes and the docs describe it."""

    group: Group
    kind: Literal["rate", "mean"]
    """rate: share of episodes (Wilson score interval); mean: mean over the episodes where it is finite (seeded
    bootstrap percentile interval, which stays inside the values' range)"""
    unit: str
    definition: str
    source: str
    """the benchmarks that report it (NAV_METRICS.md); "ours" where none does"""
    counts: Callable[[dict], bool] | None = field(default=None, repr=False)
    """rates: whether an episode (an ``episode_metrics`` dict, older files included) counts"""


def _rate(group: Group, definition: str, source: str, counts: Callable[[dict], bool]) -> Metric:
    return Metric(group, "rate", "share", definition, source, counts)


def _zone_share(band: str) -> Metric:
    return Metric("comfort", "mean", "share", f"share of steps whose nearest body gap to a pedestrian is {band}",
                  "HuNavSim")


def _zone_entries(zone: str, limit_m: float, mover: str) -> Metric:
    who = {"robot": "the rule of collision_robot_on_person blames the robot, on the step's displacements / step "
                    "along the line between the bodies at its start",
           "person": "the rule does not blame the robot (it was stopped, or the person caught it up from behind), or "
                     "the person appeared inside"}[mover]
    return Metric("safety" if zone == "intimate" else "comfort", "mean", "count",
                  f"{mover}-made entries into a person's {zone} zone: the body gap falls below {limit_m} m between "
                  f"two states and {who}", "SEANavBench")


METRICS: dict[str, Metric] = {
    # safety
    "collision": _rate("safety", "the episode ended in a collision with a pedestrian or a wall", "SEANavBench, "
                       "SocNavBench, HuNavSim, CrowdNav++", lambda e: e["outcome"] in (Outcome.PEDESTRIAN.value,
                                                                                      Outcome.WALL.value)),
    "collision_at_fault": _rate("safety", "a wall collision or a robot-on-person collision (files of benchmark "
                                "versions 1 and 2 judged robot-on-person by earlier rules: see the docs' Versions)",
                                "ours after nuPlan (SEANavBench, HuNavSim count the two kinds apart)",
                                lambda e: bool(e.get("collision_at_fault", e.get("at_fault")))),
    "collision_robot_on_person": _rate("safety", "a pedestrian collision the robot made: at the impact (the first "
                                       "instant the bodies touch within the step) the robot was moving (the "
                                       "fastest it went over the impact and the "
                                       f"{STOP_HOLD_STEPS} whole steps before the impact's step at least "
                                       f"{STOP_SPEED_MPS} m/s) and the person it touched did not catch it up from "
                                       "behind (contact behind the robot's heading, the person's velocity along it "
                                       "at least that fastest speed); a person who appeared inside made it",
                                       "nuPlan, SEANavBench, HuNavSim",
                                       lambda e: bool(e.get("collision_robot_on_person"))),  # older files lack it
    "collision_person_on_robot": _rate("safety", "a pedestrian collision the person made: every other one",
                                       "SEANavBench, HuNavSim", lambda e: bool(e.get("collision_person_on_robot"))),
    "pedestrian_collision": _rate("safety", "the episode ended in a collision with a pedestrian",
                                  "SEANavBench, HuNavSim", lambda e: e["outcome"] == Outcome.PEDESTRIAN.value),
    "wall_collision": _rate("safety", "the episode ended with the robot touching a wall", "SEANavBench",
                            lambda e: e["outcome"] == Outcome.WALL.value),
    "min_step_end_gap_m": Metric("safety", "mean", "m", "least body gap between the robot and a pedestrian at the "
                             "steps' ends (negative: overlap), not during the steps: a collision within a step can "
                             "leave it positive (collisions are counted apart); NaN if nobody was ever present; former "
                             "name min_distance_m",
                             "SocNavBench, HuNavSim, CrowdNav++"),
    "min_ttc_s": Metric("safety", "mean", "s", "least time until the robot and a pedestrian touch if both keep "
                        "their velocities (the pedestrian's over its last step); NaN if never on a collision course",
                        "SocNavBench"),
    "intimate_entries_robot": _zone_entries("intimate", INTIMATE_M, "robot"),
    "intimate_entries_person": _zone_entries("intimate", INTIMATE_M, "person"),
    "off_map": Metric("safety", "mean", "share", "share of steps the robot ends on non-walkable ground", "ours"),
    # efficiency
    "success": _rate("efficiency", "the robot reached the goal radius before any collision or the time limit",
                     "SEANavBench, SocNavBench, HuNavSim, CrowdNav++", lambda e: e["outcome"] == Outcome.GOAL.value),
    "timeout": _rate("efficiency", "the time limit (or a replay's recording) ran out first", "CrowdNav++",
                     lambda e: e["outcome"] == Outcome.TIMEOUT.value),
    "steps": Metric("efficiency", "mean", "steps", "env steps of 0.4 s the episode lasted", "ours"),
    "time_to_goal_s": Metric("efficiency", "mean", "s", "episode duration, successes only", "HuNavSim, CrowdNav++"),
    "path_length_m": Metric("efficiency", "mean", "m", "distance the robot travelled",
                            "SEANavBench, SocNavBench, HuNavSim"),
    "path_ratio": Metric("efficiency", "mean", "ratio", "path length / straight distance from the start to the goal's "
                         "edge (a straight drive into the goal radius is 1), successes that started outside it only "
                         "(the straight line, not a search-based path)", "SEANavBench, SocNavBench, CrowdNav++"),
    "spl": Metric("efficiency", "mean", "share", "success weighted by path length: success x straight / "
                  "max(path, straight); 0 on failure", "SocNavGym, CrowdNav++ (path efficiency)"),
    "time_not_moving_s": Metric("efficiency", "mean", "s", f"time spent at a speed under {STOPPED_MPS} m/s (step "
                                "displacement / step)", "SEANavBench, HuNavSim"),
    # comfort
    **{f"zone_{zone}_share": _zone_share(band) for zone, band in zip(ZONES, (
        f"< {INTIMATE_M} m", f"in [{INTIMATE_M}, {PERSONAL_M}) m", f"in [{PERSONAL_M}, {SOCIAL_M}) m",
        f">= {SOCIAL_M} m, or nobody is present"), strict=True)},
    "personal_entries_robot": _zone_entries("personal", PERSONAL_M, "robot"),
    "personal_entries_person": _zone_entries("personal", PERSONAL_M, "person"),
    "acceleration_mps2": Metric("comfort", "mean", "m/s^2", "mean norm of the velocity's change per step / step",
                                "SocNavBench, HuNavSim"),
    "jerk_mps3": Metric("comfort", "mean", "m/s^3", "mean norm of the velocity's second difference / step^2",
                        "SocNavBench"),
    "path_irregularity_rad": Metric("comfort", "mean", "rad", "total absolute heading change between the robot's "
                                    "moving steps (straight: 0, a full circle: 2 pi)",
                                    "HuNavSim (cumulative heading changes), SEANavBench, SocNavBench"),
    "group_intrusions": Metric("comfort", "mean", "count", "entries of the robot's centre into a group's space (disc "
                               "at the centroid of its present members, >= 2, reaching the farthest); NaN without "
                               "group labels", "HuNavSim, TAGA, navmet"),
    "group_intrusion_share": Metric("comfort", "mean", "share", "share of steps the robot's centre is inside a "
                                    "group's space; NaN without group labels", "HuNavSim"),
    "discomfort": Metric("comfort", "mean", "share", f"share of steps with a body gap under {DISCOMFORT_M} m",
                         "CrowdNav++"),
    "log_ade_m": Metric("comfort", "mean", "m", "reactive replays: mean distance of the pedestrians from their "
                        "recorded paths (how far the robot pushed them); NaN elsewhere", "ours"),
    "clipped_command_share": Metric("comfort", "mean", "share", "share of steps whose command the robot's limits "
                                    "clipped (speed, acceleration, turn: ``st_sim.sim.robot``)", "robot_sf"),
    "mota": Metric("perception", "mean", "share", "CLEAR MOT accuracy of the robot's tracks in its field of view: 1 - "
                   "(misses + false tracks + identity switches) / true people (``st_sim.perception.mot``); NaN with "
                   "the oracle's eyes", "robot_sf (diagnostic)"),
    "motp_m": Metric("perception", "mean", "m", "CLEAR MOT precision: mean distance of a matched track from its "
                     "person", "robot_sf (diagnostic)"),
    "idf1": Metric("perception", "mean", "share", "IDF1: share of true people and tracks that one identity "
                   "pairing over the episode explains", "ours (Ristani et al. 2016)"),
    "id_switches": Metric("perception", "mean", "count", "times a tracked person's track changed", "ours"),
    "forecast_ade_m": Metric("perception", "mean", "m", "best-of-S ADE of the forecasts the robot got (made from what "
                             "it perceived) against where the people went, 12 steps on", "ours"),
    "forecast_fde_m": Metric("perception", "mean", "m", "best-of-S FDE of the same forecasts", "ours"),
}
"""every figure of ``episode_metrics``, by group"""
FORMER_NAMES: dict[str, tuple[str, ...]] = {"min_step_end_gap_m": ("min_distance_m", "min_clearance_m")}
"""current figure names -> their former names, newest first, which ``summarize`` reads in older result files"""
RATES: dict[str, Callable[[dict], bool]] = {name: m.counts for name, m in METRICS.items() if m.kind == "rate"}
"""share of episodes that ... (an episode of ``episode_metrics``)"""
MEANS: tuple[str, ...] = tuple(name for name, m in METRICS.items() if m.kind == "mean")
"""every mean of ``METRICS``"""


INTERVALS: dict[str, str] = {"rate": "Wilson score", "mean": "bootstrap percentile"}
"""how ``summarize`` bounds each kind of figure (``rate_interval``, ``mean_interval``)"""


def metrics_table() -> str:
    """``METRICS`` as markdown: a note on distances, then a table (metric, group, unit, interval, definition,
    source) group by group."""
    rows = [f"Distances between the robot and people are body gaps: centre distance minus both radii (the env's: "
            f"robot {EnvConfig.ego_radius_m} m; pedestrians {EnvConfig.pedestrian_radius_m} m in the replays, "
            f"{CrowdConfig.radius_m} m in the simulated crowds). Hall's zones (intimate < "
            f"{INTIMATE_M} m, personal < {PERSONAL_M} m, social < {SOCIAL_M} m) are centre distances in Hall's work; "
            "they are gaps here, since bodies touch at a centre distance of "
            f"{EnvConfig.ego_radius_m + CrowdConfig.radius_m:.2f} to "
            f"{EnvConfig.ego_radius_m + EnvConfig.pedestrian_radius_m:.2f} m, which would swallow the intimate zone.",
            "", "| metric | group | unit | 95 % interval | definition | source |", "|---|---|---|---|---|---|"]
    rows += [f"| `{name}` | {m.group} | {m.unit} | {INTERVALS[m.kind]} | {m.definition} | {m.source} |"
             for group in GROUPS for name, m in METRICS.items() if m.group == group]
    return "\n".join(rows)


def rate_interval(hits: int, n: int) -> tuple[float, float]:
    """Wilson score 95 % interval of a rate ``hits / n`` (NaN for n = 0)."""
    if n == 0:
        return float("nan"), float("nan")
    ci = stats.binomtest(hits, n).proportion_ci(CONFIDENCE, method="wilson")
    return float(ci.low), float(ci.high)


def mean_interval(values: np.ndarray, resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float, float]:
    """(mean, low, high): seeded bootstrap percentile 95 % interval of the mean of the finite values (NaN if none).

    The interval's ends are means of resampled values, so they never leave the values' range (a share stays in
    [0, 1], a time or a count stays >= 0, however skewed the values); they are widened to hold the mean itself if
    the percentiles miss it. The same values always give the same interval (``BOOTSTRAP_SEED``).
    """
    values = np.asarray(values, np.float64)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return NAN, NAN, NAN
    mean = float(np.clip(values.mean(), values.min(), values.max()))  # a sum's rounding can leave the range by an ulp
    if values.size == 1 or values.min() == values.max():
        return mean, mean, mean
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    means = np.empty(resamples)
    for start in range(0, resamples, BOOTSTRAP_BATCH):  # bounded memory: a batch of resamples at a time
        stop = min(start + BOOTSTRAP_BATCH, resamples)
        means[start:stop] = values[rng.integers(0, values.size, (stop - start, values.size))].mean(axis=1)
    low, high = np.quantile(means, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2])
    low, high = np.clip([low, high], values.min(), values.max())  # rounding of the resampled means aside
    return mean, float(min(low, mean)), float(max(high, mean))


def summarize(episodes: list[dict]) -> dict[str, dict[str, float]]:
    """Every figure of ``METRICS`` over ``episodes`` (dicts of ``episode_metrics``, older result files included):
    {name: {value, low, high, n}}.

    Rates count every episode (Wilson interval); means pool the finite values (bootstrap interval, ``mean_interval``;
    n of them; a figure an older file lacks has n = 0). The former names of ``FORMER_NAMES`` are read where the
    current one is missing.
    """
    n = len(episodes)
    summary = {}
    for name, metric in METRICS.items():
        if metric.kind == "rate":
            hits = sum(metric.counts(e) for e in episodes)
            low, high = rate_interval(hits, n)
            summary[name] = {"value": hits / n if n else NAN, "low": low, "high": high, "n": n}
        else:
            values = np.array([_figure(e, name) for e in episodes], np.float64)
            mean, low, high = mean_interval(values)
            summary[name] = {"value": mean, "low": low, "high": high, "n": int(np.isfinite(values).sum())}
    return summary


def _figure(episode: dict, name: str) -> float:
    """An episode's figure ``name``, under its current or a former name (``FORMER_NAMES``); NaN if it has none."""
    for key in (name, *FORMER_NAMES.get(name, ())):
        if key in episode:
            return episode[key]
    return NAN


def paired_collision_test(a: list[dict], b: list[dict], at_fault: bool = False) -> dict[str, float | int]:
    """McNemar's exact test that planner A collides less often than B on the same seeds (one-sided).

    Args:
        a, b: episodes of ``episode_metrics`` plus their ``seed``, the same seeds in both.
        at_fault: count only the collisions the robot was at fault for (else every collision).

    Returns:
        {n, a_collisions, b_collisions, only_a, only_b, p_value, difference, low, high}; A is significantly safer
        when p < 0.05; difference: A's collision rate minus B's, [low, high] its 95 % interval (``mean_interval`` of
        the per-seed differences).
    """
    test = _mcnemar(a, b, RATES["collision_at_fault" if at_fault else "collision"], "less")
    return {"n": test["n"], "a_collisions": test["a"], "b_collisions": test["b"], "only_a": test["only_a"],
            "only_b": test["only_b"], "p_value": test["p_value"], "difference": test["difference"],
            "low": test["low"], "high": test["high"]}


def paired_success_test(a: list[dict], b: list[dict]) -> dict[str, float | int]:
    """McNemar's exact test that planner A reaches the goal more often than B on the same seeds (one-sided).

    Returns:
        {n, a_successes, b_successes, only_a, only_b, p_value, difference, low, high}; only_a counts seeds that only A
        completed; difference: A's success rate minus B's, [low, high] its 95 % interval.
    """
    test = _mcnemar(a, b, RATES["success"], "greater")
    return {"n": test["n"], "a_successes": test["a"], "b_successes": test["b"], "only_a": test["only_a"],
            "only_b": test["only_b"], "p_value": test["p_value"], "difference": test["difference"],
            "low": test["low"], "high": test["high"]}


def _mcnemar(a: list[dict], b: list[dict], counts: Callable[[dict], bool], alternative: str) -> dict[str, float | int]:
    """One-sided exact McNemar test that episodes of A are ``counts`` less ("less") or more ("greater") often than
    B's, on the same seeds; a / b count them, only_a / only_b the seeds where one run alone does; difference, low,
    high: A's rate minus B's and its seeded bootstrap 95 % interval over the seeds (NaN without episodes)."""
    seeds_a, seeds_b = [e["seed"] for e in a], [e["seed"] for e in b]
    if seeds_a != seeds_b:
        raise ValueError("paired test: the two runs must hold the same seeds in the same order")
    hit_a = np.array([counts(e) for e in a], bool)
    hit_b = np.array([counts(e) for e in b], bool)
    only_a, only_b = int((hit_a & ~hit_b).sum()), int((hit_b & ~hit_a).sum())
    p_value = stats.binomtest(only_a, only_a + only_b, 0.5, alternative=alternative).pvalue if only_a + only_b else 1.0
    difference, low, high = mean_interval(hit_a.astype(np.float64) - hit_b)
    return {"n": len(a), "a": int(hit_a.sum()), "b": int(hit_b.sum()), "only_a": only_a, "only_b": only_b,
            "p_value": float(p_value), "difference": difference, "low": low, "high": high}
