"""The scripted encounters (``STCrowd-Sim{FrontalApproach,...}-v1``): every seed a slightly different instance of the
same encounter, deterministic, the same in the native vector env, and an encounter that really happens; and
``info["group_ids"]`` in every simulated env."""

from __future__ import annotations

import json
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from test_vector_env import assert_same_step, make_pair

import envs
from envs import ENCOUNTER_IDS, SIM_ENCOUNTERS
from envs.common.errors import EnvInputError
from envs.sim_env import SimCrowdEnv
from st_sim.apps.navigation.straight import StraightPlanner
from st_sim.apps.navigation.world import world_of
from st_sim.sim import CrowdConfig, PopulationConfig
from st_sim.sim.encounters import ENCOUNTERS

SEEDS = st.integers(0, 2**31 - 1)
MEET_M = 1.0  # the straight robot "meets" the scripted pedestrians when their centres come this close [m]
MEET_SEEDS = 20  # episodes per encounter in which the straight robot must meet them ...
MEET_MOST = 15  # ... in at least this many
TOGETHER_M = 0.5  # over the warm-up, no member of the group walks farther than this from the group's mean walk [m]
ANGLE_SLACK_DEG = 2.0  # how far a pedestrian's measured walking direction may stray from its line [deg]
ACTION_SPACE_ADVICE = ".*symmetric and normalized.*"  # the action is a velocity in m/s, on purpose


@pytest.fixture(scope="module")
def light_envs() -> dict[str, gym.Env]:
    """One env per encounter with constant-velocity forecasts (the straight robot reads none), shared by the tests
    that only reset and step them."""
    made = {env_id: gym.make(env_id, predictor="cvm") for env_id in ENCOUNTER_IDS}
    yield made
    for env in made.values():
        env.close()


def straight_episode(env: gym.Env, seed: int) -> tuple[list[dict[str, np.ndarray]], list[dict]]:
    """Reset with ``seed`` and drive straight to the goal at full speed until the episode ends: observations and
    infos, reset included."""
    planner = StraightPlanner(world_of(env))
    obs, info = env.reset(seed=seed)
    observations, infos = [obs], [info]
    for _ in range(env.spec.max_episode_steps):
        obs, _, terminated, truncated, info = env.step(planner.act(obs))
        observations.append(obs)
        infos.append(info)
        if terminated or truncated:
            break
    return observations, infos


def walking_angle_deg(obs: dict[str, np.ndarray], rows: np.ndarray) -> np.ndarray:
    """(R,) angle between the ego's route (start to goal) and each row's walking direction over its history [deg]."""
    route = obs["ego"][4:6].astype(np.float64) - obs["ego"][:2]
    walked = obs["history"][rows, -1].astype(np.float64) - obs["history"][rows, 0]
    cosine = walked @ route / (np.linalg.norm(walked, axis=1) * np.linalg.norm(route))
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


@pytest.mark.parametrize("env_id", ENCOUNTER_IDS, ids=ENCOUNTER_IDS)
@pytest.mark.parametrize("kwargs", [{}, {"ego": False}, {"pedestrians_see_ego": False}],
                         ids=["ego", "spectator", "unseen-ego"])
def test_encounter_passes_check_env(env_id: str, kwargs: dict) -> None:
    env = gym.make(env_id, predictor="cvm", render_mode="rgb_array", **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=ACTION_SPACE_ADVICE)
        check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("env_id", ENCOUNTER_IDS, ids=ENCOUNTER_IDS)
@settings(max_examples=5, deadline=None)
@given(seed=SEEDS)
def test_encounter_same_seed_gives_same_episode_and_another_seed_another_instance(env_id: str, seed: int) -> None:
    env_a, env_b = gym.make(env_id, predictor="cvm"), gym.make(env_id, predictor="cvm")
    run_a, run_b = straight_episode(env_a, seed), straight_episode(env_b, seed)
    assert len(run_a[0]) == len(run_b[0]), f"seed {seed}: episodes of {len(run_a[0])} and {len(run_b[0])} steps"
    for t, (obs_a, info_a, obs_b, info_b) in enumerate(zip(*run_a, *run_b, strict=True)):
        for key in obs_a:
            assert np.array_equal(obs_a[key], obs_b[key]), f"[seed {seed}, step {t}] {key} differs"
        for key in ("agent_ids", "group_ids", "termination"):
            assert np.array_equal(info_a[key], info_b[key]), f"[seed {seed}, step {t}] info[{key!r}] differs"
    other, _ = env_b.reset(seed=seed + 1)
    assert not np.array_equal(run_a[0][0]["ego"], other["ego"]), f"seeds {seed} and {seed + 1}: the same route"
    assert not np.array_equal(run_a[0][0]["history"], other["history"]), f"seeds {seed}, {seed + 1}: same people"


@pytest.mark.parametrize("env_id", ENCOUNTER_IDS, ids=ENCOUNTER_IDS)
def test_encounter_vector_env_equals_single_envs(env_id: str) -> None:
    """Four sub-envs stepped by the native vector env as by single envs, through the end of their episodes (every
    sub-env's robot drives straight to its goal) and the resets after."""
    vec, sync = make_pair(env_id, 4, predictor="cvm-s")
    ours, theirs = vec.reset(seed=11), sync.reset(seed=11)
    assert_same_step(ours, theirs, "reset")
    planner = StraightPlanner(world_of(sync.envs[0]))
    ends = 0
    for t in range(40):
        assert np.array_equal(ours[-1]["group_ids"], theirs[-1]["group_ids"]), f"[step {t}] group ids"
        actions = np.stack([planner.act({"ego": ego}) for ego in ours[0]["ego"]])
        ours, theirs = vec.step(actions), sync.step(actions)
        assert_same_step(ours, theirs, f"step {t}")
        ends += int((ours[2] | ours[3]).sum())
    assert ends >= 4, f"only {ends} sub-env episodes ended"
    vec.close(), sync.close()


@pytest.mark.parametrize("env_id", ENCOUNTER_IDS, ids=ENCOUNTER_IDS)
def test_the_straight_robot_meets_the_scripted_pedestrians_in_most_seeds(light_envs: dict[str, gym.Env],
                                                                          env_id: str) -> None:
    env = light_envs[env_id]
    least_m = []
    for seed in range(MEET_SEEDS):
        _, infos = straight_episode(env, seed)
        assert infos[-1]["termination"] != "wall_collision", f"seed {seed}: the straight route touches a wall"
        least_m.append(infos[-1]["metrics"]["min_ego_ped_distance_m"])
    met = sum(gap < MEET_M for gap in least_m)
    assert met >= MEET_MOST, f"the robot met them in {met} of {MEET_SEEDS} seeds; least distances {least_m}"


@settings(max_examples=20, deadline=None)
@given(seed=SEEDS)
def test_the_crossing_angle_lies_in_its_range(light_envs: dict[str, gym.Env], seed: int) -> None:
    low, high = ENCOUNTERS["crossing_angle"].angle_deg
    obs, info = light_envs["STCrowd-SimCrossingAngle-v1"].reset(seed=seed)
    rows = np.flatnonzero(info["agent_ids"] >= 0)
    assert len(rows) == 1, f"seed {seed}: {len(rows)} pedestrians, expected one"
    angle = walking_angle_deg(obs, rows)[0]
    assert low - ANGLE_SLACK_DEG <= angle <= high + ANGLE_SLACK_DEG, f"seed {seed}: crossing at {angle:.1f} deg"


@settings(max_examples=20, deadline=None)
@given(seed=SEEDS)
def test_the_group_walks_together_under_one_group_id(light_envs: dict[str, gym.Env], seed: int) -> None:
    low, high = ENCOUNTERS["group"].group_size
    obs, info = light_envs["STCrowd-SimGroup-v1"].reset(seed=seed)
    present = info["agent_ids"] >= 0
    group = info["group_ids"][present]
    assert low <= present.sum() <= high, f"seed {seed}: a group of {present.sum()}"
    assert group[0] >= 0 and (group == group[0]).all(), f"seed {seed}: group ids {group}"
    assert (info["group_ids"][~present] == -1).all(), f"seed {seed}: a group id on an empty row"
    walked = obs["history"][present, -1] - obs["history"][present, 0]
    apart_m = np.linalg.norm(walked - walked.mean(axis=0), axis=1)
    assert apart_m.max() < TOGETHER_M, f"seed {seed}: members walked apart {walked.tolist()}"


def test_group_sizes_and_angles_vary_over_seeds(light_envs: dict[str, gym.Env]) -> None:
    sizes, angles = set(), []
    for seed in range(20):
        _, info = light_envs["STCrowd-SimGroup-v1"].reset(seed=seed)
        sizes.add(int((info["agent_ids"] >= 0).sum()))
        obs, info = light_envs["STCrowd-SimCrossingAngle-v1"].reset(seed=seed)
        angles.append(walking_angle_deg(obs, np.flatnonzero(info["agent_ids"] >= 0))[0])
    assert sizes == {2, 3, 4}, f"group sizes over 20 seeds: {sorted(sizes)}"
    assert min(angles) < 70 and max(angles) > 110, f"crossing angles over 20 seeds: {np.round(angles)}"


def test_an_encounter_goes_on_after_its_people_have_left() -> None:
    """The scripted pedestrians leave at their gates and nobody arrives: the env steps on with an empty crowd (the
    forecasts made before they left never mature)."""
    env = gym.make("STCrowd-SimDoorway-v1", predictor="cvm", ego=False)
    _, info = env.reset(seed=0)
    empty_steps = 0
    for t in range(env.spec.max_episode_steps):
        obs, _, terminated, truncated, info = env.step(np.zeros(2))
        assert not terminated and not truncated, f"[step {t}] the spectator's episode ended"
        if (info["agent_ids"] < 0).all():
            assert not obs["history_mask"][:, -1].any() and (info["group_ids"] == -1).all(), f"[step {t}]"
            empty_steps += 1
        if empty_steps == 3:
            break
    assert empty_steps == 3, "the pedestrian never left"


@pytest.mark.parametrize("env_id", ENCOUNTER_IDS, ids=ENCOUNTER_IDS)
def test_one_walks_alone_outside_the_group_encounter(light_envs: dict[str, gym.Env], env_id: str) -> None:
    _, info = light_envs[env_id].reset(seed=0)
    present = info["agent_ids"] >= 0
    assert present.any(), "nobody scripted"
    if env_id != "STCrowd-SimGroup-v1":
        assert present.sum() == 1 and (info["group_ids"] == -1).all(), f"{info['group_ids'][present]}"


@pytest.mark.parametrize("env_id", ["STCrowd-SimCorridor-v1", "STCrowd-SimZara1-v1"])
def test_group_ids_are_the_simulators_groups_row_by_row(env_id: str) -> None:
    crowd = CrowdConfig(population=PopulationConfig(group_share=0.6))
    env = gym.make(env_id, predictor="cvm", crowd=crowd)
    _, info = env.reset(seed=2)
    for t in range(15):
        sim, rows = env.unwrapped.sim, info["agent_ids"]
        assert info["group_ids"].shape == rows.shape and info["group_ids"].dtype == np.int64, f"[step {t}]"
        expected = np.full(len(rows), -1)
        present = rows >= 0
        expected[present] = sim.groups[np.searchsorted(sim.ids, rows[present])]
        assert np.array_equal(info["group_ids"], expected), f"[step {t}] {info['group_ids']} vs {expected}"
        _, _, terminated, truncated, info = env.step(np.zeros(2))
        if terminated or truncated:
            break
    assert (info["group_ids"] >= 0).sum() >= 2, "no group among the pedestrians"


@pytest.mark.parametrize("bad", ["Group", "frontal", "", 3, ["group"], True])
def test_an_unknown_encounter_is_refused_naming_the_choices(bad: object) -> None:
    with pytest.raises(EnvInputError, match=r"encounter=.*expected None or one of 'frontal_approach'.*'group'"):
        SimCrowdEnv(encounter=bad, predictor="cvm")


def test_an_encounter_with_a_layout_is_refused() -> None:
    with pytest.raises(EnvInputError, match=r"layout='crossing' with encounter='group'.*own layout"):
        gym.make("STCrowd-SimCrossing-v1", encounter="group", predictor="cvm")


def test_an_encounter_needs_room_for_its_people() -> None:
    with pytest.raises(EnvInputError, match=r"at most 3 pedestrians.*4"):
        gym.make("STCrowd-SimGroup-v1", crowd=CrowdConfig(max_pedestrians=3, spawn_rate_hz=0.0), predictor="cvm")


@pytest.mark.parametrize("env_id", ENCOUNTER_IDS, ids=ENCOUNTER_IDS)
def test_encounter_ids_take_their_arguments_from_json(env_id: str) -> None:
    kwargs = json.loads(json.dumps(gym.spec(env_id).kwargs))
    assert kwargs == {"encounter": SIM_ENCOUNTERS[env_id.split("-")[1].removeprefix("Sim")]}
    env = gym.make(env_id, **{**kwargs, **json.loads('{"predictor": "cvm", "pedestrians_see_ego": false}')})
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert set(ENCOUNTER_IDS) <= set(envs.STCROWD_IDS)
