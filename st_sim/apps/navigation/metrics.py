"""Navigation metrics: one episode's figures, their means with 95 % confidence intervals, a paired test.

Rates (success, collisions, timeout) get Wilson score intervals; means get Student-t intervals over the
episodes where the figure exists (time to goal and path ratio: successful episodes only). Two planners run
on the same seeds are compared with McNemar's exact test on the episodes where only one of them collided.
"""

from __future__ import annotations

from dataclasses import dataclass
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
    """

    ego_xy_m: np.ndarray
    ego_velocity_mps: np.ndarray
    clearance_m: np.ndarray
    off_map: np.ndarray
    goal_m: np.ndarray
    outcome: Outcome


def episode_metrics(trace: EpisodeTrace) -> dict[str, float | int | str]:
    """Figures of one episode; NaN where a figure does not exist (e.g. time to goal of a failure).

    Keys: outcome, steps, time_to_goal_s, path_ratio (path length / start-goal distance), min_clearance_m
    (least body gap to a pedestrian), discomfort (share of steps with a gap under 0.2 m), jerk_mps3 (mean
    norm of the velocity's second difference / 0.4 s^2), off_map (share of steps off the walkable map).
    """
    steps = len(trace.ego_xy_m) - 1
    reached = trace.outcome is Outcome.GOAL
    path_m = float(np.linalg.norm(np.diff(trace.ego_xy_m, axis=0), axis=1).sum())
    straight_m = float(np.linalg.norm(trace.goal_m - trace.ego_xy_m[0]))
    clearance = trace.clearance_m[1:] if steps else trace.clearance_m
    jerk = np.linalg.norm(np.diff(trace.ego_velocity_mps, n=2, axis=0), axis=1) / STEP_S ** 2
    finite = clearance[np.isfinite(clearance)]
    return {
        "outcome": trace.outcome.value,
        "steps": steps,
        "time_to_goal_s": steps * STEP_S if reached else float("nan"),
        "path_ratio": path_m / straight_m if reached and straight_m > 0 else float("nan"),
        "min_clearance_m": float(finite.min()) if finite.size else float("nan"),
        "discomfort": float(np.mean(clearance < DISCOMFORT_M)) if steps else 0.0,
        "jerk_mps3": float(jerk.mean()) if jerk.size else float("nan"),
        "off_map": float(np.mean(trace.off_map[1:])) if steps else 0.0,
    }


RATES: dict[str, tuple[Outcome, ...]] = {
    "success": (Outcome.GOAL,),
    "collision": (Outcome.PEDESTRIAN, Outcome.WALL),
    "pedestrian_collision": (Outcome.PEDESTRIAN,),
    "wall_collision": (Outcome.WALL,),
    "timeout": (Outcome.TIMEOUT,),
}
MEANS: tuple[str, ...] = ("time_to_goal_s", "path_ratio", "min_clearance_m", "discomfort", "jerk_mps3", "off_map")


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
    outcomes = [e["outcome"] for e in episodes]
    summary = {}
    for name, kinds in RATES.items():
        hits = sum(outcome in {k.value for k in kinds} for outcome in outcomes)
        low, high = rate_interval(hits, n)
        summary[name] = {"value": hits / n if n else float("nan"), "low": low, "high": high, "n": n}
    for name in MEANS:
        values = np.array([e[name] for e in episodes], np.float64)
        mean, low, high = mean_interval(values)
        summary[name] = {"value": mean, "low": low, "high": high, "n": int(np.isfinite(values).sum())}
    return summary


def paired_collision_test(a: list[dict], b: list[dict]) -> dict[str, float | int]:
    """McNemar's exact test that planner A collides less often than B on the same seeds (one-sided).

    Args:
        a, b: episodes of ``episode_metrics`` plus their ``seed``, the same seeds in both.

    Returns:
        {n, a_collisions, b_collisions, only_a, only_b, p_value}; A is significantly safer when p < 0.05.
    """
    test = _mcnemar(a, b, (Outcome.PEDESTRIAN.value, Outcome.WALL.value), "less")
    return {"n": test["n"], "a_collisions": test["a"], "b_collisions": test["b"], "only_a": test["only_a"],
            "only_b": test["only_b"], "p_value": test["p_value"]}


def paired_success_test(a: list[dict], b: list[dict]) -> dict[str, float | int]:
    """McNemar's exact test that planner A reaches the goal more often than B on the same seeds (one-sided).

    Returns:
        {n, a_successes, b_successes, only_a, only_b, p_value}; only_a counts seeds that only A completed.
    """
    test = _mcnemar(a, b, (Outcome.GOAL.value,), "greater")
    return {"n": test["n"], "a_successes": test["a"], "b_successes": test["b"], "only_a": test["only_a"],
            "only_b": test["only_b"], "p_value": test["p_value"]}


def _mcnemar(a: list[dict], b: list[dict], outcomes: tuple[str, ...], alternative: str) -> dict[str, float | int]:
    """One-sided exact McNemar test that episodes of A end in ``outcomes`` less ("less") or more ("greater")
    often than B's, on the same seeds; a / b count them, only_a / only_b the seeds where one run alone does."""
    seeds_a, seeds_b = [e["seed"] for e in a], [e["seed"] for e in b]
    if seeds_a != seeds_b:
        raise ValueError("paired test: the two runs must hold the same seeds in the same order")
    hit_a = np.array([e["outcome"] in outcomes for e in a])
    hit_b = np.array([e["outcome"] in outcomes for e in b])
    only_a, only_b = int((hit_a & ~hit_b).sum()), int((hit_b & ~hit_a).sum())
    p_value = stats.binomtest(only_a, only_a + only_b, 0.5, alternative=alternative).pvalue if only_a + only_b else 1.0
    return {"n": len(a), "a": int(hit_a.sum()), "b": int(hit_b.sum()), "only_a": only_a, "only_b": only_b,
            "p_value": float(p_value)}
