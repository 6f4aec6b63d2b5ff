"""Simulated environments: vector envs, population-sized observations, the ego inside the simulator."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from envs.common.config import EnvConfig
from envs.sim_env import build_layout, population_cap
from st_sim.sim import CrowdConfig, CrowdSim

VECTOR_STEPS = 15


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_sim_env_runs_in_vector_envs(mode: str) -> None:
    vec = gym.make_vec("STCrowd-SimCorridor-v1", num_envs=2, vectorization_mode=mode)
    obs, info = vec.reset(seed=0)
    vec.action_space.seed(0)
    for t in range(VECTOR_STEPS):
        obs, reward, _, _, info = vec.step(vec.action_space.sample())
        assert obs["history"].shape == (2, 40, 8, 2), f"[step {t}] {obs['history'].shape}"
        assert all(np.isfinite(value).all() for value in obs.values()), f"[step {t}] non-finite observation"
        assert info["predicted_ids"].shape == (2, 40) and reward.shape == (2,)
    assert not np.array_equal(obs["history"][0], obs["history"][1]), "both envs hold the same crowd"
    vec.close()


def test_sim_n_max_follows_the_crowd_config() -> None:
    env = gym.make("STCrowd-SimBottleneck-v1", crowd=CrowdConfig(max_pedestrians=12))
    obs, _ = env.reset(seed=0)
    assert obs["history"].shape[0] == 12
    for t in range(20):
        obs, *_ = env.step(np.zeros(2))
        assert obs["history_mask"][:, -1].sum() <= 12, f"[step {t}]"


@pytest.mark.parametrize("crowd", [CrowdConfig(max_pedestrians=7), CrowdConfig(density_per_m2=0.2)],
                         ids=["cap", "density"])
def test_sim_population_cap_matches_the_simulator(crowd: CrowdConfig) -> None:
    layout = build_layout("corridor")
    assert population_cap(crowd, layout) == CrowdSim(layout, crowd, np.random.default_rng(0)).max_pedestrians


def test_sim_histories_are_full_at_reset() -> None:
    env = gym.make("STCrowd-SimCrossing-v1")
    obs, info = env.reset(seed=4)
    present = obs["history_mask"][:, -1]
    assert present.any() and obs["futures_mask"][present].all(), "the warm-up should fill every history"
    assert info["frame"] == 7


def test_sim_ego_moves_with_the_action_toward_its_goal() -> None:
    env = gym.make("STCrowd-SimCorridor-v1", crowd=CrowdConfig(max_pedestrians=1), config=EnvConfig())
    obs, _ = env.reset(seed=0)
    layout = build_layout("corridor")
    assert np.allclose(obs["ego"][:2], layout.ego_start_m, atol=1e-3)
    assert np.allclose(obs["ego"][4:6], layout.ego_goal_m)
    progress = 0.0
    for _ in range(10):
        obs, _, terminated, _, info = env.step(np.array([5.0, 0.0]))  # clipped to 1.5 m/s
        progress += info["reward_parts"]["progress"]
        if terminated:
            break
    assert obs["ego"][0] > layout.ego_start_m[0] + 2.0
    assert progress == pytest.approx(np.linalg.norm(layout.ego_goal_m - layout.ego_start_m)
                                     - np.linalg.norm(layout.ego_goal_m - obs["ego"][:2]), abs=1e-4)
    assert np.hypot(*obs["ego"][2:4]) <= 1.5 + 1e-5


def test_sim_spectator_has_no_ego() -> None:
    env = gym.make("STCrowd-SimCrossing-v1", ego=False)
    obs, _ = env.reset(seed=0)
    obs, reward, terminated, _, info = env.step(np.array([np.nan, 0.0]))
    assert not obs["ego"].any() and reward == 0.0 and not terminated
    assert info["metrics"]["min_ego_ped_distance_m"] == np.inf


def test_sim_unknown_layout_is_rejected() -> None:
    with pytest.raises(ValueError, match="crossing"):
        gym.make("STCrowd-SimCrossing-v1", layout="maze")


@pytest.mark.parametrize("task, t_obs", [("stochastic", 8), ("momentary", 2)])
def test_sim_default_predictor_is_the_universal_singular_model_for_its_history_length(task: str, t_obs: int) -> None:
    env = gym.make("STCrowd-SimCrossing-v1", task=task)
    model = env.unwrapped.predictor
    assert type(model).__name__ == "SingularTrajectory" and model.cfg.obs_len == t_obs
    obs, _ = env.reset(seed=0)
    present = obs["futures_mask"]
    assert present.any() and np.isfinite(obs["futures"][present]).all()
