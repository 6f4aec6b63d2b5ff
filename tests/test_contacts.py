"""Robot-pedestrian contacts between two frames (swept along the step), and the at-fault rule at the impact."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs.common.ego import on_image
from envs.common.fault import STOPPED_MPS, robot_at_fault
from replays.constants import STEP_S
from st_sim.sim import CrowdConfig, CrowdSim, EgoConfig, make_layout
from st_sim.sim.sweep import Contact, closest_approach, first_contact, first_touch

CONTACT_M = 0.55  # the replays' robot-pedestrian contact distance (0.3 m + 0.25 m)
coordinate = st.floats(-3.0, 3.0, allow_nan=False)


def _dense_distance(offset_from: np.ndarray, offset_to: np.ndarray, samples: int = 20001) -> np.ndarray:
    t = np.linspace(0.0, 1.0, samples)[:, None]
    return np.linalg.norm(offset_from + t * (offset_to - offset_from), axis=1)


@settings(max_examples=300, deadline=None)
@given(ax=coordinate, ay=coordinate, bx=coordinate, by=coordinate, reach=st.floats(0.1, 1.5))
def test_first_touch_agrees_with_dense_sampling(ax: float, ay: float, bx: float, by: float, reach: float) -> None:
    start, end = np.array([ax, ay]), np.array([bx, by])
    distance = _dense_distance(start, end)
    t = first_touch(start, end, reach)
    tolerance = 2e-3 * (np.linalg.norm(end - start) + 1.0)  # what 20001 samples resolve
    if np.isnan(t):
        assert distance.min() >= reach - tolerance, f"missed a contact: {distance.min():.4f} m < {reach:.4f} m"
    else:
        assert 0.0 <= t <= 1.0
        before = distance[: int(t * (len(distance) - 1))]
        assert before.size == 0 or before.min() >= reach - tolerance, "the contact began earlier"
        assert np.linalg.norm(start + t * (end - start)) <= reach + 1e-9, "no contact at the reported instant"
    least, when = closest_approach(start, end)
    assert abs(least - distance.min()) <= tolerance and 0.0 <= when <= 1.0


def test_a_head_on_pass_between_two_frames_is_a_contact_at_fault() -> None:
    # a robot 0.56 m in front of a walker at 1.52 m/s, driving at it at 1.5 m/s, ends 0.65 m behind it
    contact = first_contact(np.array([0.56, 0.0]), np.array([0.56 - 1.5 * STEP_S, 0.0]), np.array([[0.0, 0.0]]),
                            np.array([[1.52 * STEP_S, 0.0]]), np.array([7]), CONTACT_M, STEP_S)
    assert contact is not None and contact.pedestrian_ids.tolist() == [7]
    assert 0.0 <= contact.time_s < 0.01
    assert np.isclose(np.linalg.norm(contact.robot_xy_m - contact.pedestrians_xy_m[0]), CONTACT_M)
    assert robot_at_fault(contact)


def _contact(robot_velocity: list[float], pedestrians: list[list[float]]) -> Contact:
    return Contact(0.1, np.zeros(2), np.array(robot_velocity, float), np.arange(len(pedestrians)),
                   np.array(pedestrians, float))


def test_the_at_fault_rule_on_hand_made_contacts() -> None:
    ahead = [[0.5, 0.0]]  # just east of the robot at the origin, at the impact
    assert robot_at_fault(_contact([1.0, 0.0], ahead)), "driving into a pedestrian ahead"
    assert robot_at_fault(_contact([0.3, 0.5], ahead)), "a pedestrian beside, ahead of its line"
    assert not robot_at_fault(_contact([0.0, 0.0], ahead)), "a stopped robot is walked into"
    assert not robot_at_fault(_contact([STOPPED_MPS / 2, 0.0], ahead)), "nearly stopped"
    assert not robot_at_fault(_contact([-1.0, 0.0], ahead)), "hit from behind"
    assert robot_at_fault(_contact([-1.0, 0.0], [[0.5, 0.0], [-0.5, 0.1]])), "of two pedestrians touched, one ahead"


@settings(max_examples=200, deadline=None)
@given(angle=st.floats(0, 2 * np.pi), speed=st.floats(0.3, 2.0), robot_speed=st.floats(STOPPED_MPS, 1.5),
       crossing=st.floats(-np.pi / 2, np.pi / 2), lateral=st.floats(-0.5, 0.5), gap=st.floats(0.56, 1.6))
def test_a_robot_driving_at_a_walker_is_at_fault_however_far_it_ends(
        angle: float, speed: float, robot_speed: float, crossing: float, lateral: float, gap: float) -> None:
    """Random head-on and crossing geometries: the robot drives toward a walker ahead of it; whenever their paths
    bring them into contact during the step, the contact is found and the robot is at fault, wherever it ends."""
    heading = np.array([np.cos(angle), np.sin(angle)])
    normal = np.array([-heading[1], heading[0]])
    walker_from = gap * heading + lateral * normal
    walker_direction = -np.cos(crossing) * heading + np.sin(crossing) * normal  # coming toward the robot's side
    walker_to = walker_from + speed * STEP_S * walker_direction
    robot_to = robot_speed * STEP_S * heading
    least = _dense_distance(walker_from, walker_to - robot_to).min()
    assume(abs(least - CONTACT_M) > 1e-3)
    contact = first_contact(np.zeros(2), robot_to, walker_from[None], walker_to[None], np.array([0]), CONTACT_M, STEP_S)
    assert (contact is not None) == (least < CONTACT_M)
    if contact is not None:
        assert robot_at_fault(contact), f"robot ends at {robot_to}, walker at {walker_to}"


@pytest.fixture(scope="module")
def zara1_walkers() -> list[tuple[int, int]]:
    """(listed frame index, agent column) of ZARA1 walkers moving faster than 0.8 m/s into the next frame."""
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm")
    replay = env.unwrapped.replay
    moving = replay.present[:-1] & replay.present[1:]
    speed = np.linalg.norm(np.nan_to_num(replay.xy_m[1:] - replay.xy_m[:-1]), axis=-1) / STEP_S
    frames, agents = np.nonzero(moving & (speed > 0.8))
    env.close()
    keep = (frames >= 8) & (frames < len(replay.frames) - 2)
    return list(zip(frames[keep].tolist(), agents[keep].tolist(), strict=True))


@settings(max_examples=40, deadline=None)
@given(pick=st.integers(0, 10**9), ahead=st.floats(0.56, 1.0))
def test_in_a_replay_a_robot_driving_head_on_into_a_walker_collides_at_fault(zara1_walkers, pick: int,
                                                                              ahead: float) -> None:
    frame, agent = zara1_walkers[pick % len(zara1_walkers)]
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm")
    env.reset(seed=0, options={"start_index": frame})
    replay, unwrapped = env.unwrapped.replay, env.unwrapped
    walker = replay.xy_m[frame, agent]
    direction = replay.xy_m[frame + 1, agent] - walker
    direction /= np.linalg.norm(direction)
    start = walker + ahead * direction
    others = np.delete(replay.xy_m[frame], agent, axis=0)
    assume(np.nan_to_num(np.linalg.norm(others - start, axis=1), nan=np.inf).min() > 1.5)
    assume(on_image(unwrapped.scene, start))  # the robot can only start on the scene's image
    unwrapped.ego_xy_m = start
    _, _, terminated, _, info = env.step(-1.5 * direction)
    env.close()
    assert terminated and info["termination"] == "pedestrian_collision", \
        f"frame {frame}: the robot passed through agent {replay.agents[agent]} unnoticed"
    assert info["at_fault"] is True and 0.0 <= info["contact_time_s"] <= STEP_S


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_the_simulator_reports_every_contact_within_a_substep(seed: int) -> None:
    """One 0.4 s substep, pedestrians blind to the robot, which drives straight across the crossing: a contact that
    the bodies' straight paths within the substep imply is reported, and none other."""
    ego = EgoConfig(pedestrians_see_ego=False)
    sim = CrowdSim(make_layout("crossing"), CrowdConfig(n_substeps=1), np.random.default_rng(seed), ego=ego)
    reach = ego.radius_m + CrowdConfig().radius_m
    for step in range(40):
        ego_from, ids_from, xy_from = sim.ego_position_m, sim.ids, sim.positions_m
        sim.step(np.array([1.5, 0.0]))
        ego_to = sim.ego_position_m
        stayed = np.isin(sim.ids, ids_from)
        start = xy_from[np.searchsorted(ids_from, sim.ids[stayed])]
        least = np.inf
        for s, e in zip(start - ego_from, sim.positions_m[stayed] - ego_to, strict=True):
            least = min(least, _dense_distance(s, e, 2001).min())
        if abs(least - reach) < 2e-3:
            continue  # a graze that 2001 samples cannot decide
        assert (sim.ego_contact is not None) == (least < reach), f"[seed {seed}, step {step}] least {least:.4f} m"
        if sim.ego_contact is not None:
            break
