"""The PPO trainer's envs: STCrowd native vector envs seen through the navigation features, as a stable-baselines3
``VecEnv``.

    vec = FeatureVecEnv("STCrowd-SimCrossing-v1", num_envs=64, features=FeatureConfig(True), shards=2)
    vec = FeatureVecEnv(["STCrowd-Eth-v0:reactive", "STCrowd-Hotel-v0:reactive"], 16, FeatureConfig(True))
    features = vec.reset()                       # (64, features.size) float32
    vec.step_async(actions); features, rewards, dones, infos = vec.step_wait()

The sub-envs are made by ``gym.make_vec(..., vectorization_mode="vector_entry_point")`` and stepped, those of every
training env together, as one ``envs.batch_step.EnvBatch`` with ``AutoresetMode.SAME_STEP`` (every world, then one
batched predictor call per model for all of them), which is stable-baselines3's convention: an ended episode's
sub-env is reset in the same step, its last features go to ``info["terminal_observation"]`` and
``info["TimeLimit.truncated"]`` says whether the time limit ended it. Actions (num_envs, 2) in [-1, 1] are path-frame
velocities in speed limits (``features.to_velocities``). Only the ``NEAREST`` pedestrians the features read are
forecast (``EnvConfig.forecast_nearest``; every sensed one still conditions their forecast). Several training envs
(``ID`` or ``ID:MODE``, a replay's pedestrians "log" or "reactive") share the sub-envs evenly, in the order given,
one native vector env each (for its spaces and features). With ``shards`` > 1 the sub-envs are split into worker
processes (``FeatureShards`` in each, through ``envs.shards``), which step at once and send back features, not
observations. With a suite's ``train_seeds`` every episode is one of the suite's train split
(``envs.suite.TrainSeeds``): sub-env i's first reset seed s becomes the split's s-th seed and every later episode
starts from a seed of the split drawn by the shard (seeded by its first seeds), so training never meets a val or test
episode. ``counts`` shares the sub-envs unevenly (``train_ppo``'s failure sampling) and ``timeout_reward`` charges
the step an episode times out on (``train_ppo``'s ``benchmark`` recipe).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from itertools import pairwise
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv

from envs.batch_step import EnvBatch, StepParts
from envs.common.config import EnvConfig
from envs.common.errors import EnvInputError
from envs.common.predictors import resolve_predictor, shipped_checkpoint
from envs.replay_env import PEDESTRIAN_MODES
from envs.shards import ProcessShard, one_thread
from envs.suite import Scenario, TrainSeeds
from predictor.devices import check_device_name
from st_sim.apps.navigation.features import NEAREST, FeatureConfig, encode_batch, path_frames, to_velocities
from st_sim.apps.navigation.predictors import env_predictor
from st_sim.apps.navigation.world import world_of

StepResult = tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]
"""(features (N, size) float32, rewards (N,) float32, dones (N,) bool, infos), stable-baselines3's step result"""


def sub_env_info(batched: dict[str, Any], i: int) -> dict[str, Any]:
    """Sub-env ``i``'s own info out of a gymnasium vector env's batched info (entries it set; nested dicts too)."""
    return {key: sub_env_info(value, i) if isinstance(value, dict) else value[i]
            for key, value in batched.items() if not key.startswith("_") and batched[f"_{key}"][i]}


def check_fault_charge(charge: Any) -> None:
    """``EnvInputError`` unless ``charge`` is a finite number >= 0."""
    if isinstance(charge, bool) or not isinstance(charge, int | float | np.floating) or not 0 <= charge < np.inf:
        raise EnvInputError(f"fault_charge={charge!r}: expected a finite number >= 0")


def training_env(spec: str) -> tuple[str, dict[str, Any]]:
    """(env id, ``gym.make`` keywords) of a training env ``ID`` or ``ID:MODE`` (a replay's pedestrians, log or
    reactive); ``EnvInputError`` for an unknown id or mode."""
    env_id, _, mode = spec.partition(":")
    if env_id not in gym.registry:
        raise EnvInputError(f"training env {spec!r}: {env_id!r} is not a registered gym id")
    if not mode:
        return env_id, {}
    if mode not in PEDESTRIAN_MODES:
        raise EnvInputError(f"training env {spec!r}: {mode!r} is not a pedestrian mode ({', '.join(PEDESTRIAN_MODES)})")
    return env_id, {"pedestrians": mode}


def scenario_env(scenario: Scenario) -> str:
    """The training env (``ID`` or ``ID:MODE``) of a suite scenario; ``EnvInputError`` for keywords other than a
    replay's pedestrians."""
    kwargs = dict(scenario.env_kwargs)
    mode = kwargs.pop("pedestrians", None)
    if kwargs:
        raise EnvInputError(f"scenario {scenario.name!r}: keywords {sorted(kwargs)} cannot be trained on (only "
                            "'pedestrians')")
    return scenario.env if mode is None else f"{scenario.env}:{mode}"


def shipped_model_name(env_id: str) -> str:
    """The shipped SingularTrajectory checkpoint an id's env forecasts with on the stochastic task: a replay's
    leave-one-out model of its scene, ``universal`` for a simulated layout (``shipped_checkpoint``)."""
    return shipped_checkpoint("stochastic", gym.registry[env_id].kwargs.get("scene"))


class FeatureShard:
    """``num_envs`` sub-envs of one training env (``ID`` or ``ID:MODE``): its native vector env (the sub-envs, their
    spaces and batching; its own ``EnvBatch`` is never stepped), its world and the features of its observations;
    ``FeatureShards`` steps them in its batch. ``predictor``:
    the env's argument (a model object, shared with the shards of other training envs that use the same model, or
    a name); others as ``FeatureVecEnv``."""

    def __init__(self, env_id: str, num_envs: int, features: FeatureConfig, predictor: Any,
                 config: EnvConfig | None = None, device: str = "auto", train_seeds: TrainSeeds | None = None,
                 timeout_reward: float = 0.0, fault_charge: float = 0.0):
        config = replace(config or EnvConfig(), sensor_range_m=features.sensor_range_m, forecast_nearest=NEAREST)
        self.timeout_reward, self.fault_charge = timeout_reward, fault_charge
        env_id, kwargs = training_env(env_id)
        self.train_seeds = train_seeds
        self._draws = np.random.default_rng()  # the split's seeds of later episodes; seeded by the first reset's
        self.vector = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                                   autoreset_mode=AutoresetMode.SAME_STEP, config=config, device=device,
                                   predictor=predictor, **kwargs)
        self.features = features
        self.world = world_of(self.vector.envs[0])  # every sub-env of an id has the same world (scene, limits, map)
        self._frames = np.zeros((num_envs, 2, 2))  # path_frames of the sub-envs' observations, for their next action

    @property
    def autoreset_seeds(self) -> Callable[[], int] | None:
        """The function drawing the seed of each later episode (None without ``train_seeds``: the generators go on)."""
        return None if self.train_seeds is None else self._draw_seed

    def reset_seeds(self, seeds: list[int | None] | None) -> list[int | None]:
        """The env seeds of new episodes for ``reset``'s ``seeds`` (None: fresh ones; with ``train_seeds``, the
        split's ``seeds[i]``-th seed, or a drawn one)."""
        seeds = seeds or [None] * self.vector.num_envs
        if self.train_seeds is None:
            return list(seeds)
        given = [seed for seed in seeds if seed is not None]
        self._draws = np.random.default_rng(given or None)
        return [self._draw_seed() if seed is None else int(self.train_seeds.nth(seed % self.train_seeds.count))
                for seed in seeds]

    def _draw_seed(self) -> int:
        """A seed of the train split, drawn uniformly."""
        return int(self.train_seeds.nth(self._draws.integers(self.train_seeds.count)))

    def velocities(self, actions: np.ndarray) -> np.ndarray:
        """(num_envs, 2) float32 world-frame ego velocities [m/s] for path-frame actions (num_envs, 2) in [-1, 1]
        (unchecked: ``EnvBatch.check_actions`` checks them)."""
        return to_velocities(np.asarray(actions, np.float32).reshape(-1, 2), self._frames, self.world.max_speed_mps)

    def first_features(self, observations: list[dict[str, np.ndarray]]) -> np.ndarray:
        """(num_envs, size) features of the sub-envs' first observations."""
        return self._encode_all(self.vector.batched_observations(observations))

    def step_result(self, parts: StepParts) -> StepResult:
        """Features, rewards, dones and infos of a step (``EnvBatch.step_parts`` of these sub-envs)."""
        obs, rewards, terminations, truncations, batched = self.vector.batched(parts)
        rewards = rewards + self.timeout_reward * (truncations & ~terminations)  # a timeout is a failure too
        features = self._encode_all(obs)
        infos = [sub_env_info(batched, i) for i in range(len(features))]
        ended = np.flatnonzero(terminations | truncations)
        if ended.size:  # the step's own info and features, not the reset's
            final_obs = [infos[i]["final_obs"] for i in ended]
            final_features = encode_batch({key: np.stack([obs[key] for obs in final_obs]) for key in final_obs[0]},
                                          self.world, self.features)
            for i, features_i in zip(ended, final_features, strict=True):
                infos[i] = {**infos[i]["final_info"], "terminal_observation": features_i,
                            "TimeLimit.truncated": bool(truncations[i] and not terminations[i])}
                rewards[i] -= self.fault_charge * bool(infos[i]["at_fault"])  # the constraint's charge
        return features, rewards.astype(np.float32), terminations | truncations, infos

    def _encode_all(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        self._frames = path_frames(obs["ego"], self.world)
        return encode_batch(obs, self.world, self.features, self._frames)


class FeatureShards:
    """The sub-envs of one or more training envs in this process, a ``FeatureShard`` each, stepped as one batch
    (``envs.batch_step.EnvBatch``: every world, then one forecast call per predictor model; what ``FeatureVecEnv``
    runs, here or in each worker process). Training envs that forecast with the same shipped checkpoint share one
    model object, so that their forecasts go in one call.

    Args:
        parts: (training env, sub-envs) pairs, in sub-env order.  Others as ``FeatureVecEnv``.
    """

    def __init__(self, parts: Sequence[tuple[str, int]], features: FeatureConfig, config: EnvConfig | None = None,
                 device: str = "auto", worker: bool = False, train_seeds: TrainSeeds | None = None,
                 timeout_reward: float = 0.0, fault_charge: float = 0.0):
        if worker:
            one_thread()
        name = env_predictor("singular" if features.use_predictions else "none")
        models: dict[str, Any] = {}
        self.shards = []
        for env_id, size in parts:
            checkpoint = shipped_model_name(training_env(env_id)[0]) if features.use_predictions else name
            if checkpoint not in models:
                models[checkpoint] = resolve_predictor(name, pretrained=checkpoint, device=check_device_name(device))
            self.shards.append(FeatureShard(env_id, size, features, models[checkpoint], config, device, train_seeds,
                                            timeout_reward, fault_charge))
        vectors = [shard.vector for shard in self.shards]
        self.batch = EnvBatch([env for vector in vectors for env in vector.envs],
                              [vector.max_episode_steps for vector in vectors for _ in vector.envs],
                              AutoresetMode.SAME_STEP,
                              [shard.autoreset_seeds for shard in self.shards for _ in shard.vector.envs])
        self._cuts = np.cumsum([size for _, size in parts])[:-1]

    def reset(self, seeds: list[int | None] | None) -> np.ndarray:
        """(num_envs, size) features of new episodes, sub-env i seeded with ``seeds[i]`` (None: fresh ones)."""
        parts = [None] * len(self.shards) if seeds is None else np.split(np.array(seeds, object), self._cuts)
        env_seeds = [seed for shard, part in zip(self.shards, parts, strict=True)
                     for seed in shard.reset_seeds(None if part is None else list(part))]
        observations, _ = self.batch.reset_parts(env_seeds, None)
        return np.concatenate([shard.first_features(part)
                               for shard, part in zip(self.shards, self._split(observations), strict=True)])

    def step(self, actions: np.ndarray) -> StepResult:
        """One step of every sub-env with path-frame actions (num_envs, 2) in [-1, 1]."""
        velocities = np.concatenate([shard.velocities(part) for shard, part in
                                     zip(self.shards, np.split(actions, self._cuts), strict=True)])
        step = self.batch.step_parts(self.batch.check_actions(velocities))
        finals = [{i - start: final for i, final in step.finals.items() if start <= i < start + shard.vector.num_envs}
                  for shard, start in zip(self.shards, np.r_[0, self._cuts].tolist(), strict=True)]
        results = [shard.step_result(StepParts(obs, rewards, terminated, truncated, infos, final))
                   for shard, obs, rewards, terminated, truncated, infos, final in zip(
                       self.shards, self._split(step.observations), np.split(step.rewards, self._cuts),
                       np.split(step.terminated, self._cuts), np.split(step.truncated, self._cuts),
                       self._split(step.infos), finals, strict=True)]
        return (np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results]),
                np.concatenate([r[2] for r in results]), [info for r in results for info in r[3]])

    def set_fault_charge(self, charge: float) -> None:
        """Charge ``charge`` for each later at-fault collision (``FeatureVecEnv.set_fault_charge``)."""
        for shard in self.shards:
            shard.fault_charge = charge

    def get_attr(self, attr_name: str, indices: Sequence[int]) -> list[Any]:
        return [getattr(self.batch.envs[i], attr_name) for i in indices]

    def set_attr(self, attr_name: str, value: Any, indices: Sequence[int]) -> None:
        for i in indices:
            setattr(self.batch.envs[i], attr_name, value)

    def env_method(self, method_name: str, method_args: tuple, method_kwargs: dict, indices: Sequence[int]) -> list:
        return [getattr(self.batch.envs[i], method_name)(*method_args, **method_kwargs) for i in indices]

    def close(self) -> None:
        for shard in self.shards:
            shard.vector.close()

    def _split(self, items: list[Any]) -> list[list[Any]]:
        """A per-sub-env list cut into the shards' parts."""
        return [items[a:b] for a, b in pairwise(np.r_[0, self._cuts, len(items)].tolist())]


class FeatureVecEnv(VecEnv):
    """``num_envs`` sub-envs of one or more training envs stepped as native vector envs, observed through
    ``encode_batch``.

    Args:
        env_id: an STCrowd id with an ego, ``ID:MODE`` for a replay's pedestrians (log, reactive), or several of them:
            they share the sub-envs evenly, in the order given (the first ones get one more where they do not divide).
        num_envs: sub-envs, >= 1 (and >= the number of training envs).
        features: what the policy sees; with ``use_predictions`` the env runs SingularTrajectory, without it no
            predictor. Its ``sensor_range_m`` is also the env's, so only sensed pedestrians are forecast.
        config: the env's settings (its ``sensor_range_m`` is replaced by the features'); None: defaults.
        shards: worker processes the sub-envs are split into (``FeatureShard`` each; 1: this process), at most
            ``num_envs``. Sub-env i is the same env, with the same seed, whichever shard holds it.
        device: where the forecasts run (``predictor.devices``; "auto": a GPU when torch sees one).
        train_seeds: a suite's train split (``Suite.train``): every episode is one of its seeds; None: the sub-envs'
            seeds and generators as ever.
        counts: sub-envs of each training env, in ``env_id``'s order (each >= 1, summing to ``num_envs``); None:
            evenly. ``env_of[i]`` names sub-env i's.
        timeout_reward: added to the reward of a step that ends an episode without a termination (the time limit or
            a replay's recording ran out: the benchmark's timeout), as the training env's charge for a failure
            that is no collision [reward units]; 0: none (the env's own reward).
        fault_charge: subtracted from the reward of a step whose collision the fault rule puts on the robot
            (``info["at_fault"]``), >= 0 [reward units]: ``fault_constraint``'s multiplier, moved between rollouts
            with ``set_fault_charge``; 0: none.
    """

    def __init__(self, env_id: str | Sequence[str], num_envs: int, features: FeatureConfig,
                 config: EnvConfig | None = None, shards: int = 1, device: str = "auto",
                 train_seeds: TrainSeeds | None = None, counts: Sequence[int] | None = None,
                 timeout_reward: float = 0.0, fault_charge: float = 0.0):
        if isinstance(shards, bool) or not isinstance(shards, int | np.integer) or not 1 <= shards <= num_envs:
            raise EnvInputError(f"shards={shards!r}: expected an int between 1 and num_envs={num_envs}")
        env_ids = [env_id] if isinstance(env_id, str) else list(env_id)
        if not 1 <= len(env_ids) <= num_envs:
            raise EnvInputError(f"{len(env_ids)} training envs for num_envs={num_envs}: give each at least one")
        for spec in env_ids:
            training_env(spec)
        if counts is None:
            counts = [len(p) for p in np.array_split(np.arange(num_envs), len(env_ids))]
        if (len(counts) != len(env_ids) or any(isinstance(c, bool) or not isinstance(c, int | np.integer) or c < 1
                                                for c in counts) or sum(counts) != num_envs):
            raise EnvInputError(f"counts={list(counts)!r}: expected {len(env_ids)} ints >= 1 summing to "
                                f"num_envs={num_envs}")
        if not np.isfinite(timeout_reward):
            raise EnvInputError(f"timeout_reward={timeout_reward!r}: expected a finite number")
        check_fault_charge(fault_charge)
        which = np.repeat(np.arange(len(env_ids)), counts)
        self.env_of = tuple(env_ids[k] for k in which.tolist())
        blocks = np.array_split(which, shards)  # the training env of each sub-env, shard by shard
        parts = [[(env_ids[k], int(np.sum(block == k))) for k in dict.fromkeys(block.tolist())] for block in blocks]
        self.sizes = [len(block) for block in blocks]
        self._cuts = np.cumsum(self.sizes)[:-1]
        self._local = None if shards > 1 else FeatureShards(parts[0], features, config, device, False, train_seeds,
                                                             float(timeout_reward), float(fault_charge))
        self._workers = [] if shards == 1 else [
            ProcessShard(f"{__name__}:FeatureShards", part, features, config, device, True, train_seeds,
                         float(timeout_reward), float(fault_charge))
            for part in parts]
        super().__init__(num_envs, spaces.Box(-np.inf, np.inf, (features.size,), np.float32),
                         spaces.Box(-1.0, 1.0, (2,), np.float32))
        self._actions = np.zeros((num_envs, 2), np.float32)

    def reset(self) -> np.ndarray:
        """(num_envs, size) features of new episodes (seeds from ``seed()`` if given, then fresh ones)."""
        seeds = None if all(seed is None for seed in self._seeds) else list(self._seeds)
        self._reset_seeds()
        if self._local is not None:
            return self._local.reset(seeds)
        parts = [None] * len(self._workers) if seeds is None else np.split(np.array(seeds, object), self._cuts)
        return np.concatenate(self._all("reset", [(None if p is None else list(p),) for p in parts]))

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, np.float32).reshape(self.num_envs, 2)
        if self._workers:
            for worker, part in zip(self._workers, np.split(self._actions, self._cuts), strict=True):
                worker.send("step", part)

    def step_wait(self) -> StepResult:
        if self._local is not None:
            return self._local.step(self._actions)
        parts = self._receive_all()
        return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
                np.concatenate([p[2] for p in parts]), [info for p in parts for info in p[3]])

    def set_fault_charge(self, charge: float) -> None:
        """Charge ``charge`` (>= 0, reward units) for each at-fault collision from the next step on, in every shard
        (``fault_constraint``'s multiplier after an update)."""
        check_fault_charge(charge)
        if self._local is not None:
            self._local.set_fault_charge(float(charge))
        for worker in self._workers:
            worker.call("set_fault_charge", float(charge))

    def close(self) -> None:
        if self._local is not None:
            self._local.close()
        for worker in self._workers:
            worker.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return self._per_sub_env("get_attr", (attr_name,), indices)

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        self._per_sub_env("set_attr", (attr_name, value), indices)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list:
        return self._per_sub_env("env_method", (method_name, method_args, method_kwargs), indices)

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def _per_sub_env(self, method: str, args: tuple, indices: Any) -> list[Any]:
        """``method(*args, local_indices)`` of the shards holding the sub-envs ``indices``, results in their order."""
        wanted = list(self._get_indices(indices))
        if self._local is not None:
            return getattr(self._local, method)(*args, wanted) or []
        starts = np.r_[0, np.cumsum(self.sizes)]
        holder = np.searchsorted(starts, wanted, side="right") - 1
        results: list[Any] = []
        for i, shard in zip(wanted, holder.tolist(), strict=True):
            results += self._workers[shard].call(method, *args, [i - int(starts[shard])]) or []
        return results

    def _all(self, method: str, args: list[tuple]) -> list[Any]:
        for worker, worker_args in zip(self._workers, args, strict=True):
            worker.send(method, *worker_args)
        return self._receive_all()

    def _receive_all(self) -> list[Any]:
        """Every worker's answer, in order; re-raise the first error a worker raised."""
        results = [worker.receive() for worker in self._workers]
        for outcome, value in results:
            if outcome == "error":
                raise value
        return [value for _, value in results]

    def _get_indices(self, indices: Any) -> Sequence[int]:
        return range(self.num_envs) if indices is None else [indices] if isinstance(indices, int) else indices
