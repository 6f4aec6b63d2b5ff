"""How an episode ends: info["termination"], the two collision parts, timeouts, the ego's acceleration limit."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from envs.common.config import EnvConfig, RewardWeights
from envs.common.crowd_env import REWARD_PARTS, TERMINATIONS, WEIGHT_OF

SIM_ID = "STCrowd-SimCrossing-v1"  # ego starts at (10, 2.5) m, the crossing's bottom wall is at y = 0 m


def run_until_end(env: gym.Env, action: np.ndarray, seed: int) -> tuple[int, float, bool, dict]:
    """Step ``action`` from ``reset(seed=seed)`` until the episode ends: (steps, last reward, truncated, info)."""
    _, info = env.reset(seed=seed)
    assert info["termination"] is None, "reset names no termination"
    for t in range(1, 500):
        _, reward, terminated, truncated, info = env.step(action)
        assert (info["termination"] is not None) == terminated, f"[step {t}] termination {info['termination']}"
        if terminated or truncated:
            return t, reward, truncated, info
    raise AssertionError("the episode did not end")


def test_sim_wall_contact_is_a_wall_collision_with_the_collision_weight() -> None:
    env = gym.make(SIM_ID, predictor="cvm")
    _, reward, _, info = run_until_end(env, np.array([0.0, -1.5]), seed=1)  # reverse into the wall behind
    parts = info["reward_parts"]
    assert info["termination"] == "wall_collision"
    assert info["at_fault"] is True and info["contact_time_s"] is None, "a wall collision is the robot's"
    assert parts["wall_collision"] == 1.0 and parts["pedestrian_collision"] == 0.0
    assert parts["at_fault_collision"] == 1.0, "the at-fault part follows info['at_fault']"
    weights = env.unwrapped.cfg.reward
    assert reward == pytest.approx(weights.collision + weights.time + parts["progress"] + weights.off_map
                                   * parts["off_map"])


def test_sim_walking_into_the_crowd_is_a_pedestrian_collision() -> None:
    env = gym.make(SIM_ID, predictor="cvm")
    _, _, _, info = run_until_end(env, np.array([0.0, 1.5]), seed=0)  # straight up through the crossing flow
    assert info["termination"] == "pedestrian_collision"
    assert info["reward_parts"]["pedestrian_collision"] == 1.0 and info["reward_parts"]["wall_collision"] == 0.0
    assert info["metrics"]["ego_collisions"] == 1


@pytest.mark.parametrize("env_id", [SIM_ID, "STCrowd-Zara2-v0"], ids=["sim", "replay"])
def test_goal_and_timeout_are_named(env_id: str) -> None:
    env = gym.make(env_id, predictor="cvm", max_episode_steps=3)
    steps, _, truncated, info = run_until_end(env, np.zeros(2), seed=4)
    assert (steps, truncated, info["termination"]) == (3, True, None), "the time limit is a truncation"
    env.reset(seed=4)
    env.unwrapped.goal_m = env.unwrapped.ego_xy_m + np.array([0.0, 0.3])
    _, _, terminated, _, info = env.step(np.zeros(2))
    assert terminated and info["termination"] == "goal"
    assert set(info["reward_parts"]) == set(REWARD_PARTS) and info["termination"] in TERMINATIONS


def test_replay_collision_is_a_pedestrian_collision() -> None:
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm")
    env.reset(seed=0, options={"start_index": 100})
    env.unwrapped.ego_xy_m = env.unwrapped.replay.frame(101).xy_m[0].copy()  # where a pedestrian will be
    _, _, terminated, _, info = env.step(np.zeros(2))
    assert terminated and info["termination"] == "pedestrian_collision"
    assert info["reward_parts"]["wall_collision"] == 0.0
    assert info["at_fault"] is False, "the pedestrian walked into a standing robot"


def test_sim_ego_velocity_follows_the_command_within_the_exposed_acceleration_limit() -> None:
    env = gym.make(SIM_ID, predictor="cvm")
    accel_mps2 = env.unwrapped.robot.max_accel_mps2
    assert accel_mps2 == pytest.approx(2.0)
    assert gym.make("STCrowd-Zara1-v0", predictor="cvm").unwrapped.robot == env.unwrapped.robot, \
        "one robot in every world"
    obs, _ = env.reset(seed=2)
    speeds = []
    for t in range(4):  # full speed toward the goal from standing: 0.8 m/s more per 0.4 s step, no faster
        obs, *_ = env.step(np.array([0.0, 1.5]))
        speeds.append(float(np.linalg.norm(obs["ego"][2:4])))
        assert speeds[-1] <= accel_mps2 * 0.4 * (t + 1) + 1e-3, f"[step {t}] speed {speeds[-1]:.3f} m/s"
    assert speeds[1] > speeds[0] > 0.5, "the ego does accelerate"


@pytest.mark.parametrize("robot_moves", [False, True], ids=["walked-into", "drove-into"])
@pytest.mark.parametrize("at_fault_weight", [0.0, -7.5])
def test_a_collision_outranks_the_goal_and_costs_extra_only_when_at_fault(robot_moves: bool,
                                                                          at_fault_weight: float) -> None:
    """docs/environments.md: a collision outranks the goal (``info["termination"]``), and the reward is the weighted
    sum of its parts; the part ``at_fault_collision`` is 1 exactly when ``info["at_fault"]`` is, so a collision
    costs ``at_fault`` more when the fault rule puts it on the robot (by default 0: the same whoever caused it)."""
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm",
                   config=EnvConfig(reward=RewardWeights(at_fault=at_fault_weight)))
    env.reset(seed=0, options={"start_index": 100})
    walker_next = env.unwrapped.replay.frame(101).xy_m[0].copy()  # where a pedestrian will be after the step
    env.unwrapped.ego_xy_m = walker_next + (np.array([0.5, 0.0]) if robot_moves else 0.0)
    env.unwrapped.goal_m = env.unwrapped.ego_xy_m.copy()  # the goal is reached on the same step
    _, reward, terminated, _, info = env.step(np.array([-1.5, 0.0]) if robot_moves else np.zeros(2))
    parts, weights = info["reward_parts"], env.unwrapped.cfg.reward
    assert terminated and parts["goal"] == 1.0 and parts["pedestrian_collision"] == 1.0, parts
    assert info["termination"] == "pedestrian_collision", "the collision outranks the goal"
    assert info["at_fault"] is robot_moves, "a standing robot was walked into; a moving one drove in"
    assert parts["at_fault_collision"] == float(robot_moves), parts
    weighted = sum(getattr(weights, WEIGHT_OF.get(name, name)) * value for name, value in parts.items())
    assert reward == pytest.approx(weighted), "the reward is the weighted sum of its parts"
    fault_aside = sum(getattr(weights, WEIGHT_OF.get(name, name)) * value for name, value in parts.items()
                      if name != "at_fault_collision")
    assert reward - fault_aside == pytest.approx(at_fault_weight if robot_moves else 0.0)


@pytest.mark.parametrize("env_id", ["STCrowd-Zara1-v0", "STCrowd-Eth-v0"])
def test_a_replay_robot_pressed_against_the_image_border_pays_no_wall_collision(env_id: str) -> None:
    """docs/environments.md: ``wall_collision`` is always 0 in replays, whose image border only stops the robot."""
    env = gym.make(env_id, predictor="none", max_episode_steps=1000)
    for direction in ([1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]):
        obs, _ = env.reset(seed=3)
        stopped = 0
        for t in range(60):
            before = obs["ego"][:2].copy()
            obs, _, terminated, truncated, info = env.step(1.5 * np.array(direction))
            stopped += bool(np.linalg.norm(obs["ego"][:2] - before) < 1e-3)
            assert info["reward_parts"]["wall_collision"] == 0.0, f"{direction} [step {t}]"
            assert info["termination"] != "wall_collision", f"{direction} [step {t}]"
            if terminated or truncated:
                break
        assert stopped, f"{direction}: the robot never reached the image border"


def test_a_step_touching_a_wall_and_a_pedestrian_pays_the_collision_weight_once() -> None:
    """docs/environments.md: the two collision parts exclude each other, so a step pays the weight at most once.
    The simulator's step that meets the crowd is made to touch a wall too."""
    env = gym.make(SIM_ID, predictor="cvm")
    unwrapped = env.unwrapped
    contacts = unwrapped._ego_contact

    def touching_a_wall_too() -> tuple:
        hit, wall, nearest_m = contacts()
        return hit, wall or hit is not None, nearest_m

    unwrapped._ego_contact = touching_a_wall_too
    _, reward, _, info = run_until_end(env, np.array([0.0, 1.5]), seed=0)  # as in the test of the crowd above
    parts, weights = info["reward_parts"], unwrapped.cfg.reward
    assert info["termination"] == "pedestrian_collision"
    assert (parts["pedestrian_collision"], parts["wall_collision"]) == (1.0, 0.0), parts
    others = sum(getattr(weights, WEIGHT_OF.get(name, name)) * value for name, value in parts.items()
                 if not name.endswith("_collision"))
    assert reward == pytest.approx(others + weights.collision), "one collision weight, not two"
