"""Navigation metrics on hand-made episodes: outcomes, per-episode figures, intervals, the paired test."""

from __future__ import annotations

import numpy as np
import pytest

from replays.constants import STEP_S
from st_sim.apps.navigation.metrics import (
    EpisodeTrace,
    Outcome,
    episode_metrics,
    outcome_of,
    paired_collision_test,
    paired_success_test,
    rate_interval,
    summarize,
)


def straight_episode(steps: int, outcome: Outcome, clearance_m: float = 1.0) -> EpisodeTrace:
    """The ego walks from (0, 0) along +x at 1 m/s; it ends on the edge of the goal's disc."""
    xy = np.stack([np.arange(steps + 1) * STEP_S, np.zeros(steps + 1)], axis=1)
    velocity = np.tile([1.0, 0.0], (steps + 1, 1))
    goal = xy[-1] + [EpisodeTrace.goal_radius_m, 0.0]
    return EpisodeTrace(xy, velocity, np.full(steps + 1, clearance_m), np.zeros(steps + 1, bool), goal, outcome)


def test_outcome_comes_from_the_envs_termination_and_truncation() -> None:
    assert outcome_of(None, truncated=False) is None
    assert outcome_of("goal", False) is Outcome.GOAL
    assert outcome_of("pedestrian_collision", False) is Outcome.PEDESTRIAN
    assert outcome_of("wall_collision", False) is Outcome.WALL
    assert outcome_of(None, truncated=True) is Outcome.TIMEOUT
    assert outcome_of("goal", truncated=True) is Outcome.GOAL, "a termination on the last step is not a timeout"
    with pytest.raises(KeyError):
        outcome_of("teleported", False)


def test_straight_successful_episode_has_ratio_one_and_no_jerk() -> None:
    metrics = episode_metrics(straight_episode(25, Outcome.GOAL))
    assert metrics["outcome"] == "goal" and metrics["steps"] == 25
    assert metrics["time_to_goal_s"] == pytest.approx(25 * STEP_S)
    assert metrics["path_ratio"] == pytest.approx(1.0)
    assert metrics["jerk_mps3"] == pytest.approx(0.0)
    assert metrics["discomfort"] == 0.0 and metrics["min_step_end_gap_m"] == pytest.approx(1.0)


def test_failed_episode_has_no_time_to_goal_and_counts_discomfort() -> None:
    trace = straight_episode(10, Outcome.PEDESTRIAN)
    trace.clearance_m[-4:] = [0.3, 0.15, 0.1, -0.02]  # closing in: the last 3 steps are under 0.2 m
    metrics = episode_metrics(trace)
    assert np.isnan(metrics["time_to_goal_s"]) and np.isnan(metrics["path_ratio"])
    assert metrics["discomfort"] == pytest.approx(3 / 10)
    assert metrics["min_step_end_gap_m"] == pytest.approx(-0.02)


def test_jerk_of_a_stop_and_go_episode() -> None:
    trace = straight_episode(4, Outcome.TIMEOUT)
    trace.ego_velocity_mps[:, 0] = [0.0, 0.0, 1.0, 1.0, 1.0]  # one jump of 1 m/s: second differences 1, -1, 0
    assert episode_metrics(trace)["jerk_mps3"] == pytest.approx((1 + 1 + 0) / 3 / STEP_S ** 2)


def test_summary_rates_carry_wilson_intervals_around_them() -> None:
    episodes = [episode_metrics(straight_episode(5, Outcome.GOAL))] * 8
    episodes += [episode_metrics(straight_episode(5, kind)) for kind in (Outcome.WALL, Outcome.TIMEOUT)]
    summary = summarize(episodes)
    assert summary["success"]["value"] == pytest.approx(0.8)
    assert summary["success"]["low"] < 0.8 < summary["success"]["high"] <= 1.0
    assert summary["wall_collision"]["value"] == summary["collision"]["value"] == pytest.approx(0.1)
    assert summary["pedestrian_collision"]["value"] == 0.0 and summary["pedestrian_collision"]["high"] > 0.0
    assert summary["time_to_goal_s"]["n"] == 8, "time to goal averages the successful episodes only"
    low, high = rate_interval(0, 500)
    assert low == 0.0 and 0.0 < high < 0.01


def test_paired_test_finds_the_safer_planner_and_refuses_unpaired_runs() -> None:
    safe = [{"seed": s, "outcome": "goal"} for s in range(30)]
    risky = [{"seed": s, "outcome": "pedestrian collision" if s % 3 == 0 else "goal"} for s in range(30)]
    result = paired_collision_test(safe, risky)
    assert (result["only_a"], result["only_b"]) == (0, 10) and result["p_value"] < 0.05
    assert paired_collision_test(risky, safe)["p_value"] > 0.5
    assert paired_collision_test(safe, safe)["p_value"] == 1.0
    with pytest.raises(ValueError, match="same seeds"):
        paired_collision_test(safe, risky[::-1])


def test_paired_success_test_finds_the_planner_that_arrives_more_often() -> None:
    arrives = [{"seed": s, "outcome": "goal" if s % 5 else "timeout"} for s in range(40)]
    stalls = [{"seed": s, "outcome": "goal" if s % 2 else "wall collision"} for s in range(40)]
    result = paired_success_test(arrives, stalls)
    assert (result["a_successes"], result["b_successes"]) == (32, 20)
    assert (result["only_a"], result["only_b"]) == (16, 4) and result["p_value"] < 0.05
    assert paired_success_test(stalls, arrives)["p_value"] > 0.5
    with pytest.raises(ValueError, match="same seeds"):
        paired_success_test(arrives, stalls[::-1])
