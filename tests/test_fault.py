"""Who closed the gap: the at-fault rule on hand-made contacts over angles and speeds, the collision split it feeds,
and the zone entries it splits the same way."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from envs.common.fault import APPROACH_FLOOR_MPS, approach_speeds, robot_at_fault, robot_closed_gap
from replays.constants import STEP_S
from st_sim.apps.navigation.metrics import EpisodeTrace, Outcome, episode_metrics, summarize
from st_sim.apps.navigation.social_metrics import INTIMATE_M, body_gaps_m, zone_entries
from st_sim.sim.sweep import Contact

CONTACT_M = 0.55  # robot 0.3 m + pedestrian 0.25 m
angle = st.floats(-math.pi, math.pi)
speed = st.floats(0.0, 2.5)


def unit(radians: float) -> np.ndarray:
    return np.array([math.cos(radians), math.sin(radians)])


def contact(bearing: float, robot_mps: np.ndarray, person_mps: np.ndarray,
            where: tuple[float, float] = (0.0, 0.0)) -> Contact:
    """The robot at ``where`` touching one person at ``bearing`` [rad] from it, with both velocities [m/s]."""
    robot_xy = np.array(where, float)
    return Contact(0.1, robot_xy, np.asarray(robot_mps, float), np.array([3]),
                   (robot_xy + CONTACT_M * unit(bearing))[None], np.asarray(person_mps, float)[None])


def velocity(bearing: float, toward_mps: float, aside_mps: float) -> np.ndarray:
    """A velocity with ``toward_mps`` along ``bearing`` and ``aside_mps`` across it."""
    return toward_mps * unit(bearing) + aside_mps * unit(bearing + math.pi / 2)


@settings(max_examples=300, deadline=None)
@given(bearing=angle, heading=angle, person=speed, person_heading=angle)
def test_a_standing_robot_is_never_at_fault(bearing: float, heading: float, person: float,
                                            person_heading: float) -> None:
    assert not robot_at_fault(contact(bearing, np.zeros(2), person * unit(person_heading)))


@settings(max_examples=300, deadline=None)
@given(bearing=angle, away=st.floats(0.0, 2.0), aside=st.floats(-2.0, 2.0), person=speed, person_heading=angle)
def test_a_robot_backing_away_or_passing_square_on_is_never_at_fault(bearing: float, away: float, aside: float,
                                                                       person: float, person_heading: float) -> None:
    """Its velocity has no component toward the person (or one away from it): whatever the person did."""
    robot = velocity(bearing, -away, aside)
    assert not robot_at_fault(contact(bearing, robot, person * unit(person_heading)))


@settings(max_examples=300, deadline=None)
@given(bearing=angle, toward=st.floats(0.0, APPROACH_FLOOR_MPS - 1e-9), aside=st.floats(-2.0, 2.0), person=speed,
       person_heading=angle)
def test_a_robot_creeping_toward_a_person_is_never_at_fault(bearing: float, toward: float, aside: float,
                                                            person: float, person_heading: float) -> None:
    robot = velocity(bearing, toward, aside)
    assert not robot_at_fault(contact(bearing, robot, person * unit(person_heading)))


@settings(max_examples=300, deadline=None)
@given(bearing=angle, robot_toward=st.floats(0.0, 2.0), margin=st.floats(1e-6, 2.0), robot_aside=st.floats(-2.0, 2.0),
       person_aside=st.floats(-2.0, 2.0))
def test_a_robot_approaching_slower_than_the_person_is_never_at_fault(bearing: float, robot_toward: float,
                                                                      margin: float, robot_aside: float,
                                                                      person_aside: float) -> None:
    robot = velocity(bearing, robot_toward, robot_aside)
    person = velocity(bearing + math.pi, robot_toward + margin, person_aside)  # toward the robot, faster
    assert not robot_at_fault(contact(bearing, robot, person))


@settings(max_examples=300, deadline=None)
@given(bearing=angle, toward=st.floats(APPROACH_FLOOR_MPS * 1.001, 2.0), aside=st.floats(-2.0, 2.0),
       person_toward=st.floats(-2.0, 0.0), person_aside=st.floats(-2.0, 2.0))
def test_a_robot_driving_into_a_person_who_stands_or_walks_off_is_always_at_fault(
        bearing: float, toward: float, aside: float, person_toward: float, person_aside: float) -> None:
    robot = velocity(bearing, toward, aside)
    assert robot_at_fault(contact(bearing, robot, np.zeros(2))), "a standing person"
    person = velocity(bearing + math.pi, person_toward, person_aside)  # not toward the robot: sideways or away
    assert robot_at_fault(contact(bearing, robot, person)), "a person moving aside or away"


@settings(max_examples=200, deadline=None)
@given(bearing=angle, robot=speed, robot_heading=angle, person=speed, person_heading=angle, turn=angle,
       shift=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)))
def test_the_judgement_is_the_same_anywhere_facing_any_way_and_never_both_ways(
        bearing: float, robot: float, robot_heading: float, person: float, person_heading: float, turn: float,
        shift: tuple[float, float]) -> None:
    """Moving and turning the whole contact changes nothing; swapping the two bodies' motions never makes the robot
    at fault both times (at most one of them closed the gap faster)."""
    robot_mps, person_mps = robot * unit(robot_heading), person * unit(person_heading)
    judged = robot_at_fault(contact(bearing, robot_mps, person_mps))
    robot_in, person_in = approach_speeds(CONTACT_M * unit(bearing), robot_mps, person_mps)
    assume(abs(robot_in - person_in) > 1e-9 and abs(robot_in - APPROACH_FLOOR_MPS) > 1e-9)
    rotation = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
    moved = contact(bearing + turn, rotation @ robot_mps, rotation @ person_mps, shift)
    assert robot_at_fault(moved) is judged
    # the person's motion given to the robot, seen from the other side: the robot's approach becomes the person's
    swapped = robot_at_fault(contact(bearing, -person_mps, -robot_mps))
    assert not (judged and swapped)


def test_with_several_people_touched_one_the_robot_drove_into_is_enough() -> None:
    ahead, behind = CONTACT_M * unit(0.0), CONTACT_M * unit(math.pi)
    several = Contact(0.1, np.zeros(2), np.array([1.0, 0.0]), np.array([1, 2]), np.stack([behind, ahead]),
                      np.array([[2.0, 0.0], [0.0, 0.0]]))  # one runs into its back, it drives into one standing
    assert robot_at_fault(several)
    walked_into = Contact(0.1, np.zeros(2), np.zeros(2), np.array([1, 2]), np.stack([behind, ahead]),
                          np.array([[2.0, 0.0], [-1.0, 0.0]]))  # it stands, both walk into it
    assert not robot_at_fault(walked_into)


def test_a_person_of_unknown_velocity_walked_in() -> None:
    appeared = contact(0.0, np.array([1.5, 0.0]), np.full(2, np.nan))  # a replay's newcomer, where it appears
    assert not robot_at_fault(appeared)
    assert not robot_closed_gap(1.5, np.nan) and not robot_closed_gap(np.nan, 0.0)
    robot_in, person_in = approach_speeds(np.zeros(2), np.array([1.0, 0.0]), np.zeros(2))
    assert np.isnan(robot_in) and np.isnan(person_in) and not robot_closed_gap(robot_in, person_in), \
        "coincident centres have no line between them"


def test_the_rule_on_the_issues_measured_impacts() -> None:
    """Approach speeds of the robot and the person at impacts measured on UNIV reactive (issue 55)."""
    for robot_in, person_in in ((0.14, 1.81), (0.21, 0.95), (0.47, 1.00), (-0.36, 0.76)):
        assert not robot_closed_gap(robot_in, person_in)
    assert robot_closed_gap(0.5, 0.5) and robot_closed_gap(0.3, -1.0), "a tie, and a person backing off"
    assert not robot_closed_gap(APPROACH_FLOOR_MPS, -1.0), "at the floor it is (nearly) standing"


def trace(outcome: Outcome, at_fault: bool | None, states: int = 3) -> EpisodeTrace:
    ego = np.zeros((states, 2))
    return EpisodeTrace(ego, ego.copy(), np.full(states, np.inf), np.zeros(states, bool), np.ones(2), outcome,
                        at_fault=at_fault)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(list(Outcome)), st.sampled_from([True, False, None])), max_size=40))
def test_pedestrian_collisions_split_into_robot_on_person_and_person_on_robot(
        episodes: list[tuple[Outcome, bool | None]]) -> None:
    metrics = [episode_metrics(trace(outcome, at_fault)) for outcome, at_fault in episodes]
    for m, (outcome, at_fault) in zip(metrics, episodes, strict=True):
        pedestrian = outcome is Outcome.PEDESTRIAN
        assert m["collision_robot_on_person"] + m["collision_person_on_robot"] == pedestrian
        assert m["collision_at_fault"] == (outcome is Outcome.WALL or m["collision_robot_on_person"])
        assert m["collision_person_on_robot"] == (pedestrian and at_fault is False), \
            "an unjudged collision is the robot's"
    if metrics:
        summary = summarize(metrics)
        split = summary["collision_robot_on_person"]["value"] + summary["collision_person_on_robot"]["value"]
        assert split == pytest.approx(summary["pedestrian_collision"]["value"])
        assert summary["collision_at_fault"]["value"] == pytest.approx(
            summary["collision_robot_on_person"]["value"] + summary["wall_collision"]["value"])


def test_older_result_files_without_the_split_count_none_of_it() -> None:
    older = [{"outcome": "pedestrian collision", "at_fault": True}, {"outcome": "goal", "at_fault": False}]
    summary = summarize(older)
    for name in ("collision_robot_on_person", "collision_person_on_robot"):
        assert (summary[name]["value"], summary[name]["n"]) == (0.0, 2)
    assert summary["collision_at_fault"]["value"] == 0.5, "their at_fault is read as written"


@settings(max_examples=300, deadline=None)
@given(bearing=angle, robot=speed, robot_heading=angle, person=speed, person_heading=angle,
       gap=st.floats(INTIMATE_M + 1e-6, INTIMATE_M + 0.3))
def test_a_zone_entry_is_the_robots_exactly_when_such_a_collision_would_be(
        bearing: float, robot: float, robot_heading: float, person: float, person_heading: float, gap: float) -> None:
    """One step from a body gap just outside the intimate zone, with the velocities held over the step: when the gap
    falls inside, the entry is the robot's exactly when a contact on the same line with the same velocities is the
    robot's fault."""
    robot_mps, person_mps = robot * unit(robot_heading), person * unit(person_heading)
    start = (gap + CONTACT_M) * unit(bearing)
    ego = np.stack([np.zeros(2), STEP_S * robot_mps])
    peds = np.stack([start, start + STEP_S * person_mps])[:, None]
    gaps = body_gaps_m(ego, peds, CONTACT_M)
    assume(gaps[1, 0] < INTIMATE_M - 1e-9)
    robot_in, person_in = approach_speeds(start, robot_mps, person_mps)
    assume(abs(robot_in - person_in) > 1e-9 and abs(robot_in - APPROACH_FLOOR_MPS) > 1e-9)
    by_robot, by_person = zone_entries(ego, peds, gaps, INTIMATE_M, STEP_S)
    assert by_robot + by_person == 1
    assert bool(by_robot) is robot_at_fault(contact(bearing, robot_mps, person_mps))


def test_a_gap_that_drifts_across_the_limit_is_entered_by_the_person() -> None:
    """Both creep toward each other under the floor: nobody closed the gap, so it counts as the person's, as such a
    collision would (an entry must be someone's)."""
    creep_m = 0.8 * APPROACH_FLOOR_MPS * STEP_S
    ego = np.array([[0.0, 0.0], [creep_m, 0.0]])
    peds = np.array([[CONTACT_M + INTIMATE_M + 0.01, 0.0], [CONTACT_M + INTIMATE_M + 0.01 - creep_m, 0.0]])[:, None]
    assert zone_entries(ego, peds, body_gaps_m(ego, peds, CONTACT_M), INTIMATE_M, STEP_S) == (0, 1)
    faster = ego * 2  # the robot at 1.6 times the floor
    assert zone_entries(faster, peds, body_gaps_m(faster, peds, CONTACT_M), INTIMATE_M, STEP_S) == (1, 0)
