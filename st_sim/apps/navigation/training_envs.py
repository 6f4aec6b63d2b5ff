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
from gymnasium.vector.utils import iterate
from stable_baselines3.common.vec_env import VecEnv

from envs.common.config import EnvConfig
from st_sim.apps.navigation.features import FeatureConfig, encode, path_frame, to_velocity
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
        config = replace(config or EnvConfig(), sensor_range_m=features.sensor_range_m)
        self.vector = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                                   autoreset_mode=AutoresetMode.SAME_STEP, config=config, shards=shards,
                                   predictor=env_predictor("singular" if features.use_predictions else "none"))
        self.features = features
        if shards == 1:
            self.worlds = [world_of(env) for env in self.vector.envs]
        else:  # the sub-envs live elsewhere; every sub-env of an id has the same world
            self.worlds = [world_of(gym.make(env_id, predictor="cvm", config=config))] * num_envs
        self._obs: list[dict[str, np.ndarray]] = []
        self._frames: list[np.ndarray] = []  # path_frame of each sub-env's observation, for its next action
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
        self._velocities = np.stack([to_velocity(action, obs, world, frame) for action, obs, world, frame
                                     in zip(actions, self._obs, self.worlds, self._frames, strict=True)])

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        obs, rewards, terminations, truncations, batched = self.vector.step(self._velocities)
        features = self._encode_all(obs)
        infos = [sub_env_info(batched, i) for i in range(self.num_envs)]
        for i in np.flatnonzero(terminations | truncations):  # the step's own info and features, not the reset's
            final = infos[i]
            infos[i] = {**final["final_info"], "TimeLimit.truncated": bool(truncations[i] and not terminations[i]),
                        "terminal_observation": encode(final["final_obs"], self.worlds[i], self.features)}
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
        self._obs = list(iterate(self.vector.single_observation_space, obs))
        self._frames = [path_frame(o, world) for o, world in zip(self._obs, self.worlds, strict=True)]
        return np.stack([encode(o, world, self.features, frame)
                         for o, world, frame in zip(self._obs, self.worlds, self._frames, strict=True)])

    def _get_indices(self, indices: Any) -> Sequence[int]:
        return range(self.num_envs) if indices is None else [indices] if isinstance(indices, int) else indices
