"""Who is at fault: the rule's referee cases and its properties over angles and speeds on hand-made contacts, the
robot's motion memory, the collision split it feeds, and the zone entries it splits the same way."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from envs.common.fault import (
    STOP_HOLD_STEPS,
    STOP_SPEED_MPS,
    RobotMotion,
    RobotMotionError,
    motion_before_steps,
    robot_at_fault,
    robot_to_blame,
)
from replays.constants import STEP_S
from st_sim.apps.navigation.metrics import EpisodeTrace, Outcome, episode_metrics, summarize
from st_sim.apps.navigation.social_metrics import INTIMATE_M, body_gaps_m, zone_entries
from st_sim.sim.sweep import Contact, first_contact

CONTACT_M = 0.55  # robot 0.3 m + pedestrian 0.25 m
EAST = np.array([1.0, 0.0])
STOOD = RobotMotion()  # standing since the reset
JUST_STOPPED = RobotMotion((1.0, 0.0), EAST)  # stopped one step (0.4 s) after driving east at 1 m/s
HELD = RobotMotion((0.0, 0.0), EAST)  # stopped the two steps (0.8 s) after driving east
DRIVING = RobotMotion((1.0, 1.0), EAST)  # drove east at 1 m/s
angle = st.floats(-math.pi, math.pi)
speed = st.floats(0.0, 2.5)
moving_speed = st.floats(STOP_SPEED_MPS * 1.001, 2.5)  # clear of rounding at the threshold
motions = st.sampled_from([STOOD, JUST_STOPPED, HELD, DRIVING])
non_finite = st.sampled_from([math.nan, math.inf, -math.inf])
component = st.floats(-3.0, 3.0)


def unit(radians: float) -> np.ndarray:
    return np.array([math.cos(radians), math.sin(radians)])


def contact(bearing: float, robot_mps: np.ndarray, person_mps: np.ndarray,
            where: tuple[float, float] = (0.0, 0.0)) -> Contact:
    """The robot at ``where`` touching one person at ``bearing`` [rad] from it, with both velocities [m/s]."""
    robot_xy = np.array(where, float)
    return Contact(0.1, robot_xy, np.asarray(robot_mps, float), np.array([3]),
                   (robot_xy + CONTACT_M * unit(bearing))[None], np.asarray(person_mps, float)[None])


# the referee cases ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("robot_mps", [0.3, 1.0, 1.29])
def test_head_on_with_both_moving_is_the_robots_even_when_it_is_slower(robot_mps: float) -> None:
    assert robot_at_fault(contact(0.0, robot_mps * EAST, -1.3 * EAST), DRIVING)


def test_a_right_angle_cut_in_is_the_robots_wherever_on_its_side_the_walker_touches() -> None:
    """The robot crosses a 1.3 m/s walker's path at right angles at 1.5 m/s; over every timing that makes them touch
    within the step, on the robot's front, flank or rear flank, the robot cut in: at fault."""
    verdicts, sides = [], []
    for walker_y, robot_x in itertools.product(np.linspace(-1.2, 0.0, 61), np.linspace(-1.0, 0.6, 17)):
        walker_from, robot_from = np.array([[0.04, walker_y]]), np.array([robot_x, 0.0])  # where each sets off
        hit = first_contact(robot_from, robot_from + 1.5 * STEP_S * EAST, walker_from,
                            walker_from + 1.3 * STEP_S * np.array([0.0, 1.0]), np.array([1]), CONTACT_M, STEP_S)
        if hit is not None and hit.time_s > 0:
            verdicts.append(robot_at_fault(hit, DRIVING))
            sides.append(float((hit.pedestrians_xy_m[0] - hit.robot_xy_m) @ EAST))
    assert len(verdicts) > 50 and min(sides) < -0.1 and max(sides) > 0.1, "timings on both sides of its centre"
    assert all(verdicts)


@pytest.mark.parametrize("creep_mps", [0.06, 0.08, 0.1])
@pytest.mark.parametrize("motion", [STOOD, DRIVING], ids=["from-standing", "after-driving"])
def test_creeping_into_a_standing_person_is_the_robots(creep_mps: float, motion: RobotMotion) -> None:
    assert robot_at_fault(contact(0.0, creep_mps * EAST, np.zeros(2)), motion)


@pytest.mark.parametrize("robot_mps", [0.0, 0.04])
def test_a_robot_stopped_for_a_while_is_walked_into(robot_mps: float) -> None:
    for motion in (STOOD, HELD, RobotMotion((0.04, 0.0), EAST)):
        assert not robot_at_fault(contact(0.0, robot_mps * EAST, -1.3 * EAST), motion)


def test_a_robot_that_stopped_in_the_last_step_has_not_stopped() -> None:
    assert robot_at_fault(contact(0.0, np.zeros(2), -1.3 * EAST), JUST_STOPPED), "walked into from the front"
    assert robot_at_fault(contact(math.pi / 2, np.zeros(2), np.array([0.0, -1.3])), JUST_STOPPED), "from the side"
    assert robot_at_fault(contact(math.pi, np.zeros(2), 0.8 * EAST), JUST_STOPPED), \
        "braked in front of a follower slower than the robot had been going: it would not have caught it up"
    assert not robot_at_fault(contact(math.pi, np.zeros(2), 1.3 * EAST), JUST_STOPPED), \
        "a follower faster than the robot had been going would have caught it up anyway"


@pytest.mark.parametrize("robot_mps", [0.05, 0.5, 1.2])
def test_a_robot_moving_away_caught_up_from_behind_is_not_at_fault(robot_mps: float) -> None:
    assert not robot_at_fault(contact(math.pi, robot_mps * EAST, 1.3 * EAST), DRIVING)
    assert not robot_at_fault(contact(math.pi * 0.8, robot_mps * EAST, np.array([1.3, -0.3])), DRIVING)


def test_with_several_people_touched_one_the_robot_is_to_blame_for_is_enough() -> None:
    ahead, behind = CONTACT_M * unit(0.0), CONTACT_M * unit(math.pi)
    several = Contact(0.1, np.zeros(2), EAST.copy(), np.array([1, 2]), np.stack([behind, ahead]),
                      np.array([[2.0, 0.0], [0.0, 0.0]]))  # one runs into its back, it drives into one standing
    assert robot_at_fault(several, DRIVING)
    walked_into = Contact(0.1, np.zeros(2), np.zeros(2), np.array([1, 2]), np.stack([behind, ahead]),
                          np.array([[2.0, 0.0], [-1.0, 0.0]]))  # it stands, both walk into it
    assert not robot_at_fault(walked_into, STOOD)


def test_a_person_of_unknown_velocity_walked_in() -> None:
    appeared = contact(0.0, 1.5 * EAST, np.full(2, np.nan))  # a replay's newcomer, where it appears
    assert not robot_at_fault(appeared, DRIVING)


# properties -------------------------------------------------------------------------------------------------------

@settings(max_examples=300, deadline=None)
@given(bearing=angle, robot=moving_speed, heading=angle, person=speed, person_heading=angle, motion=motions)
def test_a_moving_robot_touching_someone_ahead_or_beside_it_is_at_fault_whatever_the_person_does(
        bearing: float, robot: float, heading: float, person: float, person_heading: float,
        motion: RobotMotion) -> None:
    """In front of the robot's heading or square beside it, no speed or direction of the person's clears it: being a
    little slower than the person, or matching its speed to theirs, buys nothing."""
    assume(math.cos(bearing - heading) >= 0)
    assert robot_at_fault(contact(bearing, robot * unit(heading), person * unit(person_heading)), motion)


@settings(max_examples=300, deadline=None)
@given(bearing=angle, robot=st.floats(0.0, STOP_SPEED_MPS * 0.999), heading=angle, person=speed,
       person_heading=angle, before=st.lists(st.floats(0.0, STOP_SPEED_MPS * 0.999), min_size=STOP_HOLD_STEPS,
                                             max_size=STOP_HOLD_STEPS))
def test_a_robot_stopped_long_enough_is_never_at_fault(bearing: float, robot: float, heading: float, person: float,
                                                       person_heading: float, before: list[float]) -> None:
    motion = RobotMotion(tuple(before), unit(heading))
    assert not robot_at_fault(contact(bearing, robot * unit(heading), person * unit(person_heading)), motion)


@settings(max_examples=300, deadline=None)
@given(bearing=angle, robot=moving_speed, heading=angle, extra=st.floats(1e-6, 2.0), aside=st.floats(-2.0, 2.0),
       motion=motions)
def test_a_moving_robot_caught_up_from_behind_is_never_at_fault(bearing: float, robot: float, heading: float,
                                                                extra: float, aside: float,
                                                                motion: RobotMotion) -> None:
    """Caught up by a person faster along its heading than the robot went over the impact and the 0.8 s before."""
    assume(math.cos(bearing - heading) < -1e-6)
    fastest = max(robot, motion.recent_speed_mps)
    person = (fastest + extra) * unit(heading) + aside * unit(heading + math.pi / 2)
    assert not robot_at_fault(contact(bearing, robot * unit(heading), person), motion)


@settings(max_examples=200, deadline=None)
@given(bearing=angle, robot=speed, robot_heading=angle, person=speed, person_heading=angle, turn=angle,
       shift=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)), recent=speed, last=angle)
def test_the_judgement_is_the_same_anywhere_facing_any_way(
        bearing: float, robot: float, robot_heading: float, person: float, person_heading: float, turn: float,
        shift: tuple[float, float], recent: float, last: float) -> None:
    robot_mps, person_mps = robot * unit(robot_heading), person * unit(person_heading)
    assume(abs(robot - STOP_SPEED_MPS) > 1e-9 and abs(max(robot, recent) - STOP_SPEED_MPS) > 1e-9)
    judged = robot_at_fault(contact(bearing, robot_mps, person_mps), RobotMotion((recent, 0.0), unit(last)))
    rotation = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
    moved = contact(bearing + turn, rotation @ robot_mps, rotation @ person_mps, shift)
    direction = robot_heading if robot >= STOP_SPEED_MPS else last
    behind = math.cos(bearing - direction)
    along = float(person_mps @ unit(direction)) - max(robot, recent)
    assume(abs(behind) > 1e-6 and abs(along) > 1e-6)  # away from the rule's edges, where rounding decides
    assert robot_at_fault(moved, RobotMotion((recent, 0.0), unit(last + turn))) is judged


# the robot's motion memory ----------------------------------------------------------------------------------------

@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 2.0), angle), min_size=1, max_size=30))
def test_the_motion_memory_keeps_the_fastest_recent_speed_and_the_last_heading(
        steps: list[tuple[float, float]]) -> None:
    path = np.cumsum([np.zeros(2)] + [s * STEP_S * unit(a) for s, a in steps], axis=0)
    recent, heading = motion_before_steps(path, STEP_S)
    speeds = np.linalg.norm(np.diff(path, axis=0), axis=1) / STEP_S
    for t in range(len(steps)):
        assert recent[t] == pytest.approx(max(speeds[max(0, t - STOP_HOLD_STEPS):t], default=0.0))
        moved = [k for k in range(t) if speeds[k] >= STOP_SPEED_MPS]
        if moved:
            step = path[moved[-1] + 1] - path[moved[-1]]
            assert np.allclose(heading[t], step / np.linalg.norm(step))
        else:
            assert not heading[t].any()


# motion that is not known: an error, never a verdict ----------------------------------------------------------------

@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(["velocity_mps", "speeds_mps", "heading"]), index=st.integers(0, 1), bad=non_finite,
       velocity=st.tuples(component, component), speeds=st.tuples(speed, speed), heading=angle, bearing=angle,
       person=st.tuples(component, component))
def test_a_robot_velocity_speed_or_heading_that_is_not_finite_is_an_error_naming_it(
        name: str, index: int, bad: float, velocity: tuple[float, float], speeds: tuple[float, float],
        heading: float, bearing: float, person: tuple[float, float]) -> None:
    """Whatever else the contact holds, a NaN or an infinity in the robot's velocity, recent speeds or heading is
    refused naming the field, where it is and the value; the rule never judges it (not at fault or at fault)."""
    values = {"velocity_mps": np.array(velocity), "speeds_mps": np.array(speeds), "heading": unit(heading)}
    values[name][index] = bad
    with pytest.raises(RobotMotionError, match=rf"^the robot's {name} is not finite at \((0, )?{index},?\): {bad} "):
        robot_at_fault(contact(bearing, values["velocity_mps"], np.array(person)),
                       RobotMotion(tuple(values["speeds_mps"]), values["heading"]))


@settings(max_examples=200, deadline=None)
@given(steps=st.lists(st.tuples(st.floats(0.0, 2.0), angle), min_size=1, max_size=12), data=st.data(),
       bad=non_finite)
def test_a_robot_path_that_is_not_finite_is_an_error_in_the_motion_memory_and_the_zone_entries(
        steps: list[tuple[float, float]], data: st.DataObject, bad: float) -> None:
    path = np.cumsum([np.zeros(2)] + [s * STEP_S * unit(a) for s, a in steps], axis=0)
    row, column = data.draw(st.integers(0, len(path) - 1)), data.draw(st.integers(0, 1))
    path[row, column] = bad
    where = rf"^the robot's positions ego_xy_m is not finite at \({row}, {column}\): {bad} "
    with pytest.raises(RobotMotionError, match=where):
        motion_before_steps(path, STEP_S)
    peds = np.full((len(path), 1, 2), 3.0)
    with pytest.raises(RobotMotionError, match=where):
        zone_entries(path, peds, body_gaps_m(path, peds, CONTACT_M), INTIMATE_M, STEP_S)
    with pytest.raises(RobotMotionError, match=rf"^the robot's displacement_m is not finite at \({column},\)"):
        RobotMotion().after_step(path[row] - path[row - 1] if row else path[0], STEP_S)


@settings(max_examples=200, deadline=None)
@given(shape=st.tuples(st.integers(1, 4), st.integers(1, 3)), data=st.data(), bad=non_finite,
       name=st.sampled_from(["velocity_mps", "recent_speed_mps", "heading"]))
def test_a_batch_of_judgements_with_one_robot_value_not_finite_is_an_error_naming_where(
        shape: tuple[int, int], data: st.DataObject, bad: float, name: str) -> None:
    """``robot_to_blame`` over (T, N) zone entries: one non-finite robot value anywhere is refused, naming its index;
    a person's unknown (NaN) velocity stays allowed."""
    rng = np.random.default_rng(data.draw(st.integers(0, 2**16)))
    values = {"velocity_mps": rng.normal(size=(*shape, 2)), "recent_speed_mps": rng.uniform(0, 2, shape),
              "heading": rng.normal(size=(*shape, 2))}
    index = tuple(data.draw(st.integers(0, n - 1)) for n in values[name].shape)
    values[name][index] = bad
    person = np.where(rng.uniform(size=(*shape, 1)) < 0.5, np.nan, rng.normal(size=(*shape, 2)))
    with pytest.raises(RobotMotionError, match=rf"^the robot's {name} is not finite at \({', '.join(map(str, index))}"):
        robot_to_blame(rng.normal(size=(*shape, 2)), values["velocity_mps"], person, values["recent_speed_mps"],
                       values["heading"])


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
       gap=st.floats(INTIMATE_M + 1e-6, INTIMATE_M + 0.3), before=st.integers(0, 3), before_mps=st.floats(0.0, 1.0))
def test_a_zone_entry_is_the_robots_exactly_when_such_a_collision_would_be(
        bearing: float, robot: float, robot_heading: float, person: float, person_heading: float, gap: float,
        before: int, before_mps: float) -> None:
    """After ``before`` steps of the robot alone at ``before_mps`` (the person held still, far outside), one step from
    a body gap just outside the intimate zone, the velocities held over the step: when the gap falls inside, the entry
    is the robot's exactly when a contact on the same line with the same velocities and the same motion memory is the
    robot's fault."""
    robot_mps, person_mps = robot * unit(robot_heading), person * unit(person_heading)
    approach = [k * STEP_S * before_mps * unit(robot_heading + 0.3) for k in range(-before, 1)]
    ego = np.stack([*approach, STEP_S * robot_mps])
    start = (gap + CONTACT_M) * unit(bearing)
    peds = np.stack([start] * before + [start, start + STEP_S * person_mps])[:, None]
    gaps = body_gaps_m(ego, peds, CONTACT_M)
    assume(gaps[-1, 0] < INTIMATE_M - 1e-9 and (gaps[:-1, 0] >= INTIMATE_M).all())
    assume(abs(robot - STOP_SPEED_MPS) > 1e-9 and abs(before_mps - STOP_SPEED_MPS) > 1e-9)
    motion = RobotMotion()
    for a, b in itertools.pairwise(ego[:-1]):
        motion = motion.after_step(b - a, STEP_S)
    direction = robot_heading if robot >= STOP_SPEED_MPS else robot_heading + 0.3
    fastest = max(robot, motion.recent_speed_mps)
    assume(abs(math.cos(bearing - direction)) > 1e-6 and abs(float(person_mps @ unit(direction)) - fastest) > 1e-6)
    assume(abs(fastest - STOP_SPEED_MPS) > 1e-9)
    by_robot, by_person = zone_entries(ego, peds, gaps, INTIMATE_M, STEP_S)
    assert by_robot + by_person == 1
    assert bool(by_robot) is robot_at_fault(contact(bearing, robot_mps, person_mps), motion)


@pytest.mark.parametrize(("creep_mps", "robot_entered"), [(0.04, False), (0.06, True)])
def test_a_gap_crossing_the_limit_while_the_robot_creeps_is_the_robots_above_the_stop_speed(
        creep_mps: float, robot_entered: bool) -> None:
    """The robot, standing since the reset, creeps toward a standing person: under 0.05 m/s the entry is the
    person's (an entry must be someone's), above it the robot's."""
    start = CONTACT_M + INTIMATE_M + 0.01
    ego = np.array([[0.0, 0.0], [creep_mps * STEP_S, 0.0]])
    peds = np.array([[start, 0.0], [start - 0.8 * 0.04 * STEP_S, 0.0]])[:, None]
    entries = zone_entries(ego, peds, body_gaps_m(ego, peds, CONTACT_M), INTIMATE_M, STEP_S)
    assert entries == ((1, 0) if robot_entered else (0, 1))
