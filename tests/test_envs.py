"""Every registered environment: Gymnasium API, determinism, action checks, observation invariants."""

from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import envs
from envs import STCROWD_IDS
from envs.common.ego import SpawnPoints, on_image, require_on_map, spawn_start_goal, walkable_points
from replays import SCENE_NAMES, load_scene
from st_sim.sim.robot import ROBOTS, limited_command

ROLLOUT_STEPS = 30
ACTION_SPACE_ADVICE = ".*symmetric and normalized.*"  # the action is a velocity in m/s, on purpose


@pytest.mark.parametrize("env_id", STCROWD_IDS, ids=STCROWD_IDS)
def test_env_passes_check_env(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=ACTION_SPACE_ADVICE)
        check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("env_id", STCROWD_IDS, ids=STCROWD_IDS)
def test_env_same_seed_gives_same_rollout(env_id: str) -> None:
    env_a, env_b = gym.make(env_id), gym.make(env_id)
    (obs_a, _), (obs_b, _) = env_a.reset(seed=3), env_b.reset(seed=3)
    env_a.action_space.seed(3)
    for t in range(ROLLOUT_STEPS):
        for key in obs_a:
            assert np.array_equal(obs_a[key], obs_b[key]), f"[step {t}] {key} differs"
        action = env_a.action_space.sample()
        obs_a, reward_a, term_a, trunc_a, info_a = env_a.step(action)
        obs_b, reward_b, term_b, trunc_b, info_b = env_b.step(action)
        assert reward_a == reward_b, f"[step {t}] rewards {reward_a} != {reward_b}"
        assert np.array_equal(info_a["agent_ids"], info_b["agent_ids"]), f"[step {t}] agent ids differ"
        if term_a or trunc_a:
            assert (term_a, trunc_a) == (term_b, trunc_b), f"[step {t}] episode ends differ"
            (obs_a, _), (obs_b, _) = env_a.reset(), env_b.reset()


@pytest.mark.parametrize("env_id", STCROWD_IDS, ids=STCROWD_IDS)
def test_env_observation_is_consistent_with_info(env_id: str) -> None:
    env = gym.make(env_id)
    obs, info = env.reset(seed=1)
    env.action_space.seed(1)
    for t in range(ROLLOUT_STEPS):
        present = info["agent_ids"] >= 0
        assert np.array_equal(obs["history_mask"][:, -1], present), f"[step {t}] mask != rows in use"
        assert np.array_equal(info["predicted_ids"] >= 0, obs["futures_mask"]), f"[step {t}] predicted ids"
        assert obs["history_mask"][obs["futures_mask"]].all(), f"[step {t}] predicted without full history"
        assert not obs["history"][~obs["history_mask"]].any(), f"[step {t}] values in unobserved slots"
        assert not obs["futures"][~obs["futures_mask"]].any(), f"[step {t}] futures in unpredicted rows"
        obs, _, terminated, truncated, info = env.step(env.action_space.sample())
        if terminated or truncated:
            obs, info = env.reset()


FUZZ_IDS = ("STCrowd-Zara1-v0", "STCrowd-SimCorridor-v1")


@pytest.fixture(scope="module")
def fuzz_envs() -> dict[str, gym.Env]:
    """One env per fuzzed id, shared by this module's tests that only reset and step them."""
    made = {env_id: gym.make(env_id) for env_id in FUZZ_IDS}
    yield made
    for env in made.values():
        env.close()


@pytest.mark.parametrize("env_id", FUZZ_IDS, ids=FUZZ_IDS)
@settings(max_examples=30, deadline=None)
@given(vx=st.floats(allow_nan=True, allow_infinity=True), vy=st.floats(allow_nan=True, allow_infinity=True))
def test_env_action_is_clipped_or_rejected(fuzz_envs: dict[str, gym.Env], env_id: str, vx: float, vy: float) -> None:
    env = fuzz_envs[env_id]
    env.reset(seed=0)
    action = np.array([vx, vy])
    if not np.isfinite(action).all():
        with pytest.raises(ValueError, match="finite"):
            env.step(action)
        return
    obs, reward, *_ = env.step(action)
    for key, value in obs.items():
        assert np.isfinite(value).all(), f"{key} not finite after action {action}"
    assert np.hypot(*obs["ego"][2:4]) <= env.unwrapped.robot.max_speed_mps + 1e-5, f"speed not clipped: {obs['ego']}"
    assert np.isfinite(reward)


@settings(max_examples=200, deadline=None)
@given(vx=st.floats(allow_nan=False, allow_infinity=False), vy=st.floats(allow_nan=False, allow_infinity=False))
def test_limited_command_keeps_direction_within_speed_limit(vx: float, vy: float) -> None:
    velocity = limited_command(ROBOTS["holonomic"], np.array([vx, vy]))[0]
    assert np.isfinite(velocity).all() and np.hypot(*velocity) <= 1.5 + 1e-9
    if max(abs(vx), abs(vy)) <= 1.5 and np.hypot(vx, vy) <= 1.5:
        assert velocity.tolist() == [vx, vy]
    else:
        direction = np.array([vx, vy]) / max(abs(vx), abs(vy))
        assert np.allclose(velocity / 1.5, direction / np.hypot(*direction), rtol=0, atol=1e-12)


@pytest.mark.parametrize("env_id", FUZZ_IDS, ids=FUZZ_IDS)
def test_env_wrong_action_shape_is_rejected(fuzz_envs: dict[str, gym.Env], env_id: str) -> None:
    fuzz_envs[env_id].reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        fuzz_envs[env_id].step(np.zeros(3))


def test_env_registration_imports_no_env_code() -> None:
    code = "import sys, envs; print(sorted(m for m in sys.modules if m.startswith(('envs.', 'st_sim', 'predictor'))))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", f"importing envs imported {out.strip()}"
    assert len(set(STCROWD_IDS)) == 18
    assert envs.SUITE_ID in gym.registry and envs.SUITE_ID not in STCROWD_IDS, "the suite env draws among them"
    assert all(gym.spec(env_id).max_episode_steps == envs.MAX_EPISODE_STEPS for env_id in STCROWD_IDS)


@pytest.mark.parametrize("scene_name", SCENE_NAMES)
def test_every_ego_spawn_candidate_is_on_the_image_and_walkable(scene_name: str) -> None:
    """All candidates, one at a time as the env checks them, not a few seeds: an edge pixel's homography round trip
    once put a HOTEL goal off the image (mapped alone it lands at -7e-14 px; mapped in a batch, at 0)."""
    scene = load_scene(scene_name)
    candidates = walkable_points(scene, (-np.inf, -np.inf, np.inf, np.inf))
    assert len(candidates) > 100
    assert on_image(scene, candidates).all()
    for xy in candidates:
        require_on_map(scene, xy, "a spawn candidate", walkable=True)


def _reference_spawn(candidates_m: np.ndarray, peds_xy_m: np.ndarray, clearance_m: float, goal_m: float,
                     rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The spawn as first written: every candidate's room measured."""
    from scipy.spatial import cKDTree

    room = cKDTree(peds_xy_m).query(candidates_m)[0] if len(peds_xy_m) else np.full(len(candidates_m), np.inf)
    free = np.flatnonzero(room >= clearance_m)
    start = candidates_m[rng.choice(free)] if len(free) else candidates_m[np.argmax(room)]
    distance = np.linalg.norm(candidates_m - start, axis=1)
    far = np.flatnonzero(distance >= goal_m)
    return start, candidates_m[rng.choice(far)] if len(far) else candidates_m[np.argmax(distance)]


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), points=st.integers(1, 400), peds=st.integers(0, 60),
       clearance=st.sampled_from([0.0, 0.5, 1.0, 2.5, 40.0]), goal=st.floats(0.0, 30.0), grid=st.booleans())
def test_the_spawn_measures_room_only_near_pedestrians_and_draws_as_measuring_every_point(
        seed: int, points: int, peds: int, clearance: float, goal: float, grid: bool) -> None:
    """The same start and goal, and the generator left in the same state, as measuring every candidate's room: on
    random points and on a lattice with pedestrians exactly ``clearance`` from some points, crowded or empty."""
    rng = np.random.default_rng(seed)
    if grid:  # lattice points and pedestrians on it: distances that equal the clearance exactly
        side = int(np.ceil(np.sqrt(points)))
        candidates = np.stack(np.meshgrid(np.arange(side) * 0.5, np.arange(side) * 0.5), -1).reshape(-1, 2)[:points]
        people = candidates[rng.integers(0, len(candidates), peds)] if peds else np.zeros((0, 2))
    else:
        candidates, people = rng.uniform(-10, 10, (points, 2)), rng.uniform(-10, 10, (peds, 2))
    ours, theirs = np.random.default_rng(seed + 1), np.random.default_rng(seed + 1)
    start, goal_m = spawn_start_goal(SpawnPoints(candidates), people, clearance, goal, ours)
    start_ref, goal_ref = _reference_spawn(candidates, people, clearance, goal, theirs)
    assert np.array_equal(start, start_ref) and np.array_equal(goal_m, goal_ref)
    assert ours.random() == theirs.random()


def test_forecasts_run_with_one_torch_thread_and_leave_the_setting_as_it_was() -> None:
    import torch

    from envs.common.predictors import predict_futures

    seen: list[int] = []

    class Recorder:
        def predict(self, obs, group, scene, num_samples):
            seen.append(torch.get_num_threads())
            return np.zeros((len(obs), num_samples, 12, 2), np.float32)

    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        predict_futures(Recorder(), np.zeros((3, 8, 2), np.float32), None, 4)
        assert seen == [1] and torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


@pytest.mark.parametrize("env_id", ["STCrowd-Zara1-v0", "STCrowd-SimCrossing-v1"])
@pytest.mark.parametrize("task", ["stochastic", "momentary"])
def test_every_pedestrian_with_a_full_history_gets_futures_at_every_step(env_id: str, task: str) -> None:
    """README.md and docs/index.md: every pedestrian observed for the task's history (8 steps, 3.2 s; 2 for the
    momentary task) gets predicted futures at every step, and no other one does (the default sensing: everyone)."""
    env = gym.make(env_id, predictor="cvm", task=task)
    forecast = 0
    for seed in range(2):
        obs, _ = env.reset(seed=seed)
        for t in range(12):
            full = obs["history_mask"].all(axis=1)
            assert np.array_equal(obs["futures_mask"], full), f"[seed {seed} step {t}]"
            forecast += int(full.sum())
            obs, _, terminated, truncated, _ = env.step(np.zeros(2))
            if terminated or truncated:
                break
    assert forecast, "nobody was forecast: nothing was checked"
    env.close()
