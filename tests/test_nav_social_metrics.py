"""Safety, efficiency and comfort figures on hand-made episodes with known answers, and their properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from replays.constants import STEP_S
from st_sim.apps.navigation.metrics import (
    GROUPS,
    MEANS,
    METRICS,
    RATES,
    EpisodeTrace,
    Outcome,
    episode_metrics,
    metrics_table,
    summarize,
)
from st_sim.apps.navigation.social_metrics import ZONES

SHARES = tuple(f"zone_{zone}_share" for zone in ZONES)
ENTRIES = ("intimate_entries_robot", "intimate_entries_person", "personal_entries_robot", "personal_entries_person")


def trace_of(ego_xy_m: np.ndarray, pedestrians_xy_m: np.ndarray | None = None, groups: list[int] | None = None,
             outcome: Outcome = Outcome.TIMEOUT, goal_m: np.ndarray | None = None) -> EpisodeTrace:
    """An episode of (T + 1, 2) ego positions; its velocity is the last step's displacement / step (0 at the reset),
    the goal where it ends unless given."""
    ego = np.asarray(ego_xy_m, np.float64)
    velocity = np.vstack([np.zeros((1, 2)), np.diff(ego, axis=0) / STEP_S])
    states = len(ego)
    return EpisodeTrace(ego, velocity, np.full(states, np.inf), np.zeros(states, bool),
                        ego[-1] if goal_m is None else np.asarray(goal_m, np.float64), outcome,
                        pedestrians_xy_m=None if pedestrians_xy_m is None else np.asarray(pedestrians_xy_m, np.float64),
                        pedestrian_groups=None if groups is None else np.asarray(groups, np.int64))


def line(start: tuple[float, float], step: tuple[float, float], states: int) -> np.ndarray:
    """(states, 2) positions from ``start``, moving ``step`` metres per step."""
    return np.asarray(start) + np.arange(states)[:, None] * np.asarray(step)


def test_a_standing_robot_that_a_person_walks_up_to_suffers_a_person_on_robot_entry() -> None:
    ego = np.zeros((11, 2))
    person = np.stack([np.maximum(5.0 - 0.4 * np.arange(11), 1.35), np.zeros(11)], axis=1)  # 1 m/s, stops at 1.35
    m = episode_metrics(trace_of(ego, person[:, None]))
    assert m["path_length_m"] == 0.0 and m["path_irregularity_rad"] == 0.0
    assert m["time_not_moving_s"] == pytest.approx(10 * STEP_S), "never moved"
    assert (m["personal_entries_robot"], m["personal_entries_person"]) == (0, 1)
    assert (m["intimate_entries_robot"], m["intimate_entries_person"]) == (0, 0)
    assert m["min_step_end_gap_m"] == pytest.approx(0.8), "1.35 m between centres, 0.3 + 0.25 m of bodies"
    assert m["min_ttc_s"] == pytest.approx(0.85), "gap 0.85 m closing at 1 m/s (its last, slower step: 6.4 s)"
    # gaps at the step ends: 4.05, 3.65 | 3.25 ... 1.25 (6 steps) | 0.85, 0.8
    assert [m[name] for name in SHARES] == pytest.approx([0.0, 0.2, 0.6, 0.2])
    assert m["spl"] == 0.0 and math.isnan(m["time_to_goal_s"]) and math.isnan(m["path_ratio"])


def test_a_robot_driving_straight_past_a_standing_person_enters_its_personal_zone() -> None:
    ego = line((-5.0, 0.0), (0.4, 0.0), 26)  # 1 m/s for 10 m
    person = np.tile([0.0, 1.2], (26, 1))
    m = episode_metrics(trace_of(ego, person[:, None], outcome=Outcome.GOAL, goal_m=(5.5, 0.0)))  # its edge at 5 m
    assert (m["personal_entries_robot"], m["personal_entries_person"]) == (1, 0)
    assert m["intimate_entries_robot"] == m["intimate_entries_person"] == 0
    assert m["min_step_end_gap_m"] == pytest.approx(math.hypot(0.2, 1.2) - 0.55), "closest at x = +-0.2 m"
    # personal (gap < 1.2 m: |x| < 1.27 m): x = -1.0 ... 1.0, 6 steps; social (|x| < 3.97 m): 14; public: 5 of 25
    assert [m[name] for name in SHARES] == pytest.approx([0.0, 6 / 25, 14 / 25, 5 / 25])
    assert m["path_length_m"] == pytest.approx(10.0) and m["path_ratio"] == pytest.approx(1.0)
    assert m["spl"] == pytest.approx(1.0) and m["time_to_goal_s"] == pytest.approx(25 * STEP_S)
    assert m["path_irregularity_rad"] == pytest.approx(0.0, abs=1e-12) and m["time_not_moving_s"] == 0.0
    assert m["acceleration_mps2"] == pytest.approx(1 / 25 / STEP_S), "one jump from rest to 1 m/s over 25 steps"
    assert math.isnan(m["min_ttc_s"]), "a standing person beside the line is never on a collision course"
    assert m["success"] and not m["collision"] and not m["timeout"]


@pytest.mark.parametrize("per_loop", [24, 60], ids=["24-steps", "60-steps"])
def test_a_circling_robot_travels_2_pi_r_and_turns_2_pi_per_loop(per_loop: int) -> None:
    radius_m, loops = 2.0, 3
    angle = 2 * np.pi * np.arange(loops * per_loop + 1) / per_loop
    m = episode_metrics(trace_of(radius_m * np.stack([np.cos(angle), np.sin(angle)], axis=1)))
    chord = 2 * np.pi / per_loop
    assert m["path_length_m"] == pytest.approx(loops * 2 * np.pi * radius_m, rel=chord ** 2 / 6)
    assert m["path_irregularity_rad"] == pytest.approx(loops * 2 * np.pi - chord), "one turn fewer than steps"
    assert m["path_irregularity_rad"] == pytest.approx(loops * 2 * np.pi, abs=chord + 1e-9)
    assert m["time_not_moving_s"] == 0.0 and math.isnan(m["min_step_end_gap_m"])


def test_a_stop_in_the_middle_of_a_u_turn_counts_the_turn_once() -> None:
    ego = np.concatenate([line((0.0, 0.0), (0.4, 0.0), 5), np.tile([1.6, 0.0], (3, 1)), line((1.2, 0.0), (-0.4, 0), 4)])
    m = episode_metrics(trace_of(ego))
    assert m["path_irregularity_rad"] == pytest.approx(np.pi)
    assert m["time_not_moving_s"] == pytest.approx(3 * STEP_S), "three standing steps"


@pytest.mark.parametrize(("lateral_m", "expected_s"), [(0.0, (7.2 - 0.55) / 1.5),
                                                       (0.3, (7.2 - math.sqrt(0.55 ** 2 - 0.3 ** 2)) / 1.5),
                                                       (0.6, math.nan)], ids=["head-on", "offset-0.3", "offset-0.6"])
def test_time_to_collision_of_a_head_on_approach(lateral_m: float, expected_s: float) -> None:
    ego = line((0.0, 0.0), (0.4, 0.0), 6)  # 1 m/s
    person = line((10.2, lateral_m), (-0.2, 0.0), 6)  # 0.5 m/s toward the robot; 7.2 m apart at the last state
    ttc = episode_metrics(trace_of(ego, person[:, None]))["min_ttc_s"]
    assert ttc == pytest.approx(expected_s, nan_ok=True)


def test_time_to_collision_skips_a_pedestrians_first_state_and_is_zero_in_contact() -> None:
    ego = line((0.0, 0.0), (0.4, 0.0), 4)
    person = np.full((4, 1, 2), np.nan)
    person[3, 0] = [5.0, 0.0]  # seen at the last state only: no velocity yet
    assert math.isnan(episode_metrics(trace_of(ego, person))["min_ttc_s"])
    person[2:, 0] = [[1.0, 0.0], [1.4, 0.0]]  # touching at state 3 (0.2 m between centres), robot at x = 1.2 m
    assert episode_metrics(trace_of(ego, person))["min_ttc_s"] == 0.0


@pytest.mark.parametrize(("lateral_m", "intrusions", "share"), [(0.0, 1, 5 / 20), (2.0, 0, 0.0)],
                         ids=["between", "around"])
def test_passing_between_a_group_of_two_intrudes_and_around_does_not(lateral_m: float, intrusions: int,
                                                                      share: float) -> None:
    ego = line((-4.0, lateral_m), (0.4, 0.0), 21)
    pair = np.broadcast_to([[0.0, 0.9], [0.0, -0.9], [0.0, 1.6]], (21, 3, 2))  # two together, one alone nearby
    m = episode_metrics(trace_of(ego, pair, groups=[4, 4, -1]))
    assert (m["group_intrusions"], m["group_intrusion_share"]) == (intrusions, pytest.approx(share))
    alone = episode_metrics(trace_of(ego, pair, groups=[4, -1, -1]))
    assert (alone["group_intrusions"], alone["group_intrusion_share"]) == (0, 0.0), "one member is no group"
    unlabelled = episode_metrics(trace_of(ego, pair))
    assert math.isnan(unlabelled["group_intrusions"]) and math.isnan(unlabelled["group_intrusion_share"])


def test_a_group_whose_second_member_is_absent_has_no_space() -> None:
    ego = line((-4.0, 0.0), (0.4, 0.0), 21)
    pair = np.array(np.broadcast_to([[0.0, 0.9], [0.0, -0.9]], (21, 2, 2)))
    pair[8:13, 1] = np.nan  # gone while the robot passes between
    m = episode_metrics(trace_of(ego, pair, groups=[0, 0]))
    assert (m["group_intrusions"], m["group_intrusion_share"]) == (0, 0.0)


def test_absent_pedestrians_are_skipped_and_one_who_appears_inside_walked_in() -> None:
    ego = np.zeros((9, 2))
    peds = np.full((9, 2, 2), np.nan)  # column 1 is never present
    peds[:4, 0] = [6.0, 0.0]
    peds[6:, 0] = [0.8, 0.0]  # back at a gap of 0.25 m, standing
    m = episode_metrics(trace_of(ego, peds))
    assert (m["intimate_entries_robot"], m["intimate_entries_person"]) == (0, 1)
    assert (m["personal_entries_robot"], m["personal_entries_person"]) == (0, 1)
    assert m["min_step_end_gap_m"] == pytest.approx(0.25)
    assert math.isnan(m["min_ttc_s"]), "standing people are on no collision course"
    assert [m[name] for name in SHARES] == pytest.approx([3 / 8, 0.0, 0.0, 5 / 8]), "nobody there counts as public"


def test_an_episode_without_pedestrians_is_all_public_with_no_distance_or_ttc() -> None:
    ego = line((0.0, 0.0), (0.4, 0.0), 8)
    m = episode_metrics(trace_of(ego, np.zeros((8, 0, 2)), groups=[]))
    assert m["zone_public_share"] == 1.0 and math.isnan(m["min_step_end_gap_m"]) and math.isnan(m["min_ttc_s"])
    assert all(m[name] == 0 for name in ENTRIES) and m["group_intrusions"] == 0 and m["discomfort"] == 0.0


def test_a_trace_without_pedestrian_positions_keeps_its_clearance_and_leaves_the_rest_unknown() -> None:
    trace = trace_of(line((0.0, 0.0), (0.4, 0.0), 5))
    trace.clearance_m[:] = [2.0, 1.5, 0.3, 0.1, 0.9]
    m = episode_metrics(trace)
    assert m["min_step_end_gap_m"] == pytest.approx(0.1)
    assert [m[name] for name in SHARES] == pytest.approx([0.5, 0.25, 0.25, 0.0])
    assert all(math.isnan(m[name]) for name in (*ENTRIES, "min_ttc_s", "group_intrusions"))


def test_a_trace_refuses_pedestrian_arrays_of_the_wrong_shape() -> None:
    ego = np.zeros((5, 2))
    with pytest.raises(ValueError, match=r"pedestrians_xy_m: expected \(5, N, 2\)"):
        trace_of(ego, np.zeros((4, 3, 2)))
    with pytest.raises(ValueError, match="pedestrian_groups"):
        trace_of(ego, np.zeros((5, 3, 2)), groups=[0, 0])


def random_episode(seed: int, states: int, pedestrians: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random walks of the robot and the pedestrians near one another (each pedestrian absent now and then) and
    group ids in -1..2: (states, 2), (states, N, 2), (N,)."""
    rng = np.random.default_rng(seed)
    ego = rng.uniform(-3, 3, 2) + np.cumsum(rng.normal(0, 0.4, (states, 2)), axis=0)
    peds = rng.uniform(-3, 3, (1, pedestrians, 2)) + np.cumsum(rng.normal(0, 0.4, (states, pedestrians, 2)), axis=0)
    peds[rng.random((states, pedestrians)) < 0.15] = np.nan
    return ego, peds, rng.integers(-1, 3, pedestrians)


def numeric(metrics: dict) -> dict[str, float]:
    return {name: float(metrics[name]) for name in METRICS if name in metrics}


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.integers(1, 30), st.integers(0, 6))
def test_shares_sum_to_one_and_counts_are_whole_and_not_negative(seed: int, steps: int, pedestrians: int) -> None:
    ego, peds, groups = random_episode(seed, steps + 1, pedestrians)
    m = episode_metrics(trace_of(ego, peds, groups.tolist()))
    assert sum(m[name] for name in SHARES) == pytest.approx(1.0), [m[name] for name in SHARES]
    for name in (*ENTRIES, "group_intrusions"):
        assert isinstance(m[name], int) and m[name] >= 0, f"{name} = {m[name]}"
    assert 0.0 <= m["group_intrusion_share"] <= 1.0 and 0.0 <= m["spl"] <= 1.0
    assert not m["min_ttc_s"] < 0.0 and m["path_irregularity_rad"] >= 0.0


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.integers(1, 30), st.integers(0, 6), st.floats(-math.pi, math.pi),
       st.floats(-1e3, 1e3), st.floats(-1e3, 1e3))
def test_figures_do_not_change_when_the_whole_episode_is_moved_and_turned(seed: int, steps: int, pedestrians: int,
                                                                          angle: float, dx: float, dy: float) -> None:
    ego, peds, groups = random_episode(seed, steps + 1, pedestrians)
    turn = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    goal = ego[0] + [4.0, 1.0]
    plain = numeric(episode_metrics(trace_of(ego, peds, groups.tolist(), Outcome.GOAL, goal)))
    moved = numeric(episode_metrics(trace_of(ego @ turn.T + [dx, dy], peds @ turn.T + [dx, dy], groups.tolist(),
                                             Outcome.GOAL, goal @ turn.T + [dx, dy])))
    for name, value in plain.items():
        assert moved[name] == pytest.approx(value, rel=1e-6, abs=1e-6, nan_ok=True), f"{name}: {value} -> {moved[name]}"


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.integers(1, 30))
def test_entries_into_a_standing_robots_zones_are_the_persons_and_a_pusher_makes_them(seed: int, steps: int) -> None:
    """A robot that stands all episode never enters anyone's zone (people walked in); the same person's motion
    around a robot that drives at 1 m/s straight at where the person stands gives every entry from in front to the
    robot."""
    _, peds, _ = random_episode(seed, steps + 1, 3)
    standing = np.zeros((steps + 1, 2))
    m = episode_metrics(trace_of(standing, peds))
    assert m["intimate_entries_robot"] == 0 and m["personal_entries_robot"] == 0
    t = np.arange(steps + 1)
    pusher = np.c_[0.4 * t, np.zeros(steps + 1)]  # 1 m/s east
    walker = np.c_[3.55 - 0.24 * t, np.zeros(steps + 1)][:, None]  # 0.6 m/s west: body gap 3.0 - 0.64 t m
    m = episode_metrics(trace_of(pusher, walker))
    assert m["intimate_entries_person"] == 0 and m["personal_entries_person"] == 0
    assert (m["personal_entries_robot"], m["intimate_entries_robot"]) == (int(steps >= 3), int(steps >= 4))


def test_summary_gives_every_figure_an_interval_and_reads_former_names() -> None:
    ego = line((-5.0, 0.0), (0.4, 0.0), 26)
    person = np.tile([0.0, 1.2], (26, 1))[:, None]
    episodes = [episode_metrics(trace_of(ego, person, outcome=outcome)) for outcome in (Outcome.GOAL, Outcome.WALL)]
    oldest = {"outcome": "goal", "min_clearance_m": 0.5, "jerk_mps3": 0.0}  # result files of before the renames
    older = {"outcome": "goal", "min_distance_m": 0.7, "jerk_mps3": 0.0}
    summary = summarize([*episodes, oldest, older])
    assert set(METRICS) <= set(summary) and set(MEANS) <= set(summary)
    assert summary["success"]["value"] == pytest.approx(3 / 4) and summary["success"]["n"] == 4
    assert summary["min_step_end_gap_m"]["n"] == 4, "both former names are read from older files"
    gaps = [e["min_step_end_gap_m"] for e in episodes] + [0.5, 0.7]
    assert summary["min_step_end_gap_m"]["value"] == pytest.approx(np.mean(gaps))
    assert summary["personal_entries_robot"] == {"value": 1.0, "low": 1.0, "high": 1.0, "n": 2}
    assert summary["min_ttc_s"]["n"] == 0 and math.isnan(summary["min_ttc_s"]["value"])
    spl = summary["spl"]
    assert spl["value"] == pytest.approx(0.5) and spl["low"] < 0.5 < spl["high"], "SPL counts the failure as 0"


def test_registry_groups_every_figure_and_renders_one_table_row_each() -> None:
    assert set(RATES) == {name for name, m in METRICS.items() if m.kind == "rate"}
    former_rates = {"success", "collision", "collision_at_fault", "pedestrian_collision", "wall_collision", "timeout"}
    assert former_rates <= set(RATES)
    assert all(m.group in GROUPS and m.unit and m.definition and m.source for m in METRICS.values())
    assert all((m.counts is None) == (m.kind == "mean") for m in METRICS.values())
    episode = episode_metrics(trace_of(np.zeros((3, 2)), np.zeros((3, 0, 2)), []))
    assert set(METRICS) - set(RATES) <= set(episode), "every mean is a figure of episode_metrics"
    table = metrics_table()
    assert "body gaps" in table
    rows = [row for row in table.splitlines() if row.startswith("| `")]
    assert [row.split("`")[1] for row in rows] == sorted(METRICS, key=lambda name: GROUPS.index(METRICS[name].group))
