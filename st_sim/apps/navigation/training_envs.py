"""The PPO trainer's envs: an STCrowd native vector env seen through the navigation features, as a
stable-baselines3 ``VecEnv``.

    vec = FeatureVecEnv("STCrowd-SimCrossing-v1", num_envs=16, features=FeatureConfig(True, sensor_range_m=5.0))
    features = vec.reset()                       # (16, features.size) float32
    vec.step_async(actions); features, rewards, dones, infos = vec.step_wait()

The sub-envs are stepped by ``gym.make_vec(..., vectorization_mode="vector_entry_point")`` with
``AutoresetMode.SAME_STEP`` (one batched predictor call per step for all of them), which is stable-baselines3's
convention: an ended episode's sub-env is reset in the same step, its last features go to
``info["terminal_observation"]`` and ``info["TimeLimit.truncated"]`` says whether the time limit ended it.
Actions (num_envs, 2) in [-1, 1] are path-frame velocities in speed limits (``features.to_velocity``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv

from envs.common.config import EnvConfig
from st_sim.apps.navigation.features import NEAREST, FeatureConfig, encode_batch, path_frames, to_velocities
from st_sim.apps.navigation.predictors import env_predictor
from st_sim.apps.navigation.world import world_of


def sub_env_info(batched: dict[str, Any], i: int) -> dict[str, Any]:
    """Sub-env ``i``'s own info out of a gymnasium vector env's batched info (entries it set; nested dicts too)."""
    return {key: sub_env_info(value, i) if isinstance(value, dict) else value[i]
            for key, value in batched.items() if not key.startswith("_") and batched[f"_{key}"][i]}


class FeatureVecEnv(VecEnv):
    """``num_envs`` sub-envs of ``env_id`` stepped as one native vector env, observed through ``encode``.

    Args:
        env_id: an STCrowd id with an ego.
        num_envs: sub-envs, >= 1.
        features: what the policy sees; with ``use_predictions`` the env runs SingularTrajectory, without it no
            predictor. Its ``sensor_range_m`` is also the env's, so only sensed pedestrians are forecast.
        config: the env's settings (its ``sensor_range_m`` is replaced by the features'); None: defaults.
        shards: worker processes the sub-envs are split into (``envs.shards``; 1: this process).
    """

    def __init__(self, env_id: str, num_envs: int, features: FeatureConfig, config: EnvConfig | None = None,
                 shards: int = 1):
        config = replace(config or EnvConfig(), sensor_range_m=features.sensor_range_m, forecast_nearest=NEAREST)
        self.vector = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                                   autoreset_mode=AutoresetMode.SAME_STEP, config=config, shards=shards,
                                   predictor=env_predictor("singular" if features.use_predictions else "none"))
        self.features = features
        # every sub-env of an id has the same world (scene, limits, map); the sub-envs may live in other processes
        self.world = world_of(self.vector.envs[0] if shards == 1 else gym.make(env_id, predictor="cvm", config=config))
        self._frames = np.zeros((num_envs, 2, 2))  # path_frames of the sub-envs' observations, for their next action
        self._velocities = np.zeros((num_envs, 2), np.float32)
        super().__init__(num_envs, spaces.Box(-np.inf, np.inf, (features.size,), np.float32),
                         spaces.Box(-1.0, 1.0, (2,), np.float32))

    def reset(self) -> np.ndarray:
        """(num_envs, size) features of new episodes (seeds from ``seed()`` if given, then fresh ones)."""
        seeds = None if all(seed is None for seed in self._seeds) else list(self._seeds)
        obs, _ = self.vector.reset(seed=seeds)
        self._reset_seeds()
        return self._encode_all(obs)

    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions, np.float32).reshape(self.num_envs, 2)
        self._velocities = to_velocities(actions, self._frames, self.world.max_speed_mps)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        obs, rewards, terminations, truncations, batched = self.vector.step(self._velocities)
        features = self._encode_all(obs)
        infos = [sub_env_info(batched, i) for i in range(self.num_envs)]
        ended = np.flatnonzero(terminations | truncations)
        if ended.size:  # the step's own info and features, not the reset's
            final_obs = [infos[i]["final_obs"] for i in ended]
            final_features = encode_batch({key: np.stack([obs[key] for obs in final_obs]) for key in final_obs[0]},
                                          self.world, self.features)
            for i, features_i in zip(ended, final_features, strict=True):
                infos[i] = {**infos[i]["final_info"], "terminal_observation": features_i,
                            "TimeLimit.truncated": bool(truncations[i] and not terminations[i])}
        return features, rewards.astype(np.float32), terminations | truncations, infos

    def close(self) -> None:
        self.vector.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.vector.envs[i], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        for i in self._get_indices(indices):
            setattr(self.vector.envs[i], attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list:
        return [getattr(self.vector.envs[i], method_name)(*method_args, **method_kwargs)
                for i in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def _encode_all(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        self._frames = path_frames(obs["ego"], self.world)
        return encode_batch(obs, self.world, self.features, self._frames)

    def _get_indices(self, indices: Any) -> Sequence[int]:
        return range(self.num_envs) if indices is None else [indices] if isinstance(indices, int) else indices
