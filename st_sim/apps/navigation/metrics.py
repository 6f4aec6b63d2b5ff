"""Navigation metrics: one episode's figures, their means with 95 % confidence intervals, a paired test.

Rates (success, collisions, timeout) get Wilson score intervals; means get Student-t intervals over the
episodes where the figure exists (time to goal and path ratio: successful episodes only). Two planners run
on the same seeds are compared with McNemar's exact test on the episodes where only one of them collided.

A collision is at fault (``collision_at_fault``) when the robot hit a wall, or hit a pedestrian while it was not
stopped and the pedestrian was not behind it (the env's ``info["at_fault"]``, ``envs.common.fault``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from scipy import stats

from replays.constants import STEP_S

DISCOMFORT_M = 0.2  # the ego is uncomfortably close when its body is this near a pedestrian's [m]
CONFIDENCE = 0.95


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
    """One episode, reset included (T steps, T + 1 states).

    Attributes:
        ego_xy_m: (T + 1, 2) ego positions [m].  ego_velocity_mps: (T + 1, 2) ego velocities [m/s].
        clearance_m: (T + 1,) gap between the ego's body and the nearest pedestrian's [m] (inf: nobody there).
        off_map: (T + 1,) bool, the ego stood on non-walkable ground.
        goal_m: (2,) [m].  outcome: how it ended.
        at_fault: on a pedestrian collision, whether the robot was at fault (the env's ``info["at_fault"]``).
        log_deviation_m: (T,) mean distance of the pedestrians from their recorded paths after each step [m]
            (reactive replays; empty elsewhere).
    """

    ego_xy_m: np.ndarray
    ego_velocity_mps: np.ndarray
    clearance_m: np.ndarray
    off_map: np.ndarray
    goal_m: np.ndarray
    outcome: Outcome
    at_fault: bool | None = None
    log_deviation_m: np.ndarray = field(default_factory=lambda: np.zeros(0))


def episode_metrics(trace: EpisodeTrace) -> dict[str, float | int | str]:
    """Figures of one episode; NaN where a figure does not exist (e.g. time to goal of a failure).

    Keys: outcome, at_fault (a wall collision, or a pedestrian collision the robot caused), steps,
    time_to_goal_s, path_ratio (path length / start-goal distance), min_clearance_m (least body gap to a
    pedestrian), discomfort (share of steps with a gap under 0.2 m), jerk_mps3 (mean norm of the velocity's second
    difference / 0.4 s^2), off_map (share of steps off the walkable map), log_ade_m (reactive replays: mean
    distance of the pedestrians from their recorded paths [m]; NaN elsewhere).
    """
    steps = len(trace.ego_xy_m) - 1
    reached = trace.outcome is Outcome.GOAL
    path_m = float(np.linalg.norm(np.diff(trace.ego_xy_m, axis=0), axis=1).sum())
    straight_m = float(np.linalg.norm(trace.goal_m - trace.ego_xy_m[0]))
    clearance = trace.clearance_m[1:] if steps else trace.clearance_m
    jerk = np.linalg.norm(np.diff(trace.ego_velocity_mps, n=2, axis=0), axis=1) / STEP_S ** 2
    finite = clearance[np.isfinite(clearance)]
    at_fault = trace.outcome is Outcome.WALL or (trace.outcome is Outcome.PEDESTRIAN and trace.at_fault is not False)
    return {
        "outcome": trace.outcome.value,
        "at_fault": bool(at_fault),
        "steps": steps,
        "time_to_goal_s": steps * STEP_S if reached else float("nan"),
        "path_ratio": path_m / straight_m if reached and straight_m > 0 else float("nan"),
        "min_clearance_m": float(finite.min()) if finite.size else float("nan"),
        "discomfort": float(np.mean(clearance < DISCOMFORT_M)) if steps else 0.0,
        "jerk_mps3": float(jerk.mean()) if jerk.size else float("nan"),
        "off_map": float(np.mean(trace.off_map[1:])) if steps else 0.0,
        "log_ade_m": float(trace.log_deviation_m.mean()) if trace.log_deviation_m.size else float("nan"),
    }


RATES: dict[str, Callable[[dict], bool]] = {
    "success": lambda e: e["outcome"] == Outcome.GOAL.value,
    "collision": lambda e: e["outcome"] in (Outcome.PEDESTRIAN.value, Outcome.WALL.value),
    "collision_at_fault": lambda e: bool(e.get("at_fault")),  # older result files lack the field
    "pedestrian_collision": lambda e: e["outcome"] == Outcome.PEDESTRIAN.value,
    "wall_collision": lambda e: e["outcome"] == Outcome.WALL.value,
    "timeout": lambda e: e["outcome"] == Outcome.TIMEOUT.value,
}
"""share of episodes that ... (an episode of ``episode_metrics``)"""
MEANS: tuple[str, ...] = ("time_to_goal_s", "path_ratio", "min_clearance_m", "discomfort", "jerk_mps3", "off_map",
                          "log_ade_m")


def rate_interval(hits: int, n: int) -> tuple[float, float]:
    """Wilson score 95 % interval of a rate ``hits / n`` (NaN for n = 0)."""
    if n == 0:
        return float("nan"), float("nan")
    ci = stats.binomtest(hits, n).proportion_ci(CONFIDENCE, method="wilson")
    return float(ci.low), float(ci.high)


def mean_interval(values: np.ndarray) -> tuple[float, float, float]:
    """(mean, low, high): Student-t 95 % interval of the mean of the finite values (NaN if none)."""
    values = np.asarray(values, np.float64)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return float("nan"), float("nan"), float("nan")
    mean = float(values.mean())
    if values.size == 1:
        return mean, mean, mean
    half = float(stats.t.ppf(0.5 + CONFIDENCE / 2, values.size - 1) * stats.sem(values))
    return mean, mean - half, mean + half


def summarize(episodes: list[dict]) -> dict[str, dict[str, float]]:
    """Every rate and mean of ``episodes`` (dicts of ``episode_metrics``): {name: {value, low, high, n}}."""
    n = len(episodes)
    summary = {}
    for name, counts in RATES.items():
        hits = sum(counts(e) for e in episodes)
        low, high = rate_interval(hits, n)
        summary[name] = {"value": hits / n if n else float("nan"), "low": low, "high": high, "n": n}
    for name in MEANS:
        values = np.array([e[name] for e in episodes], np.float64)
        mean, low, high = mean_interval(values)
        summary[name] = {"value": mean, "low": low, "high": high, "n": int(np.isfinite(values).sum())}
    return summary


def paired_collision_test(a: list[dict], b: list[dict], at_fault: bool = False) -> dict[str, float | int]:
    """McNemar's exact test that planner A collides less often than B on the same seeds (one-sided).

    Args:
        a, b: episodes of ``episode_metrics`` plus their ``seed``, the same seeds in both.
        at_fault: count only the collisions the robot was at fault for (else every collision).

    Returns:
        {n, a_collisions, b_collisions, only_a, only_b, p_value}; A is significantly safer when p < 0.05.
    """
    test = _mcnemar(a, b, RATES["collision_at_fault" if at_fault else "collision"], "less")
    return {"n": test["n"], "a_collisions": test["a"], "b_collisions": test["b"], "only_a": test["only_a"],
            "only_b": test["only_b"], "p_value": test["p_value"]}


def paired_success_test(a: list[dict], b: list[dict]) -> dict[str, float | int]:
    """McNemar's exact test that planner A reaches the goal more often than B on the same seeds (one-sided).

    Returns:
        {n, a_successes, b_successes, only_a, only_b, p_value}; only_a counts seeds that only A completed.
    """
    test = _mcnemar(a, b, RATES["success"], "greater")
    return {"n": test["n"], "a_successes": test["a"], "b_successes": test["b"], "only_a": test["only_a"],
            "only_b": test["only_b"], "p_value": test["p_value"]}


def _mcnemar(a: list[dict], b: list[dict], counts: Callable[[dict], bool], alternative: str) -> dict[str, float | int]:
    """One-sided exact McNemar test that episodes of A are ``counts`` less ("less") or more ("greater") often than
    B's, on the same seeds; a / b count them, only_a / only_b the seeds where one run alone does."""
    seeds_a, seeds_b = [e["seed"] for e in a], [e["seed"] for e in b]
    if seeds_a != seeds_b:
        raise ValueError("paired test: the two runs must hold the same seeds in the same order")
    hit_a = np.array([counts(e) for e in a], bool)
    hit_b = np.array([counts(e) for e in b], bool)
    only_a, only_b = int((hit_a & ~hit_b).sum()), int((hit_b & ~hit_a).sum())
    p_value = stats.binomtest(only_a, only_a + only_b, 0.5, alternative=alternative).pvalue if only_a + only_b else 1.0
    return {"n": len(a), "a": int(hit_a.sum()), "b": int(hit_b.sum()), "only_a": only_a, "only_b": only_b,
            "p_value": float(p_value)}
