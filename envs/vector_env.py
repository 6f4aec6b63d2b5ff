"""Native vector envs: N crowd envs stepped together, their forecasts made in one batched predictor call.

    import gymnasium as gym, envs
    vec = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=16, vectorization_mode="vector_entry_point")
    obs, info = vec.reset(seed=0)                      # sub-env i is reset with seed 0 + i
    obs, reward, terminated, truncated, info = vec.step(vec.action_space.sample())

Every STCrowd id has this vector entry point (``make_vec``'s default mode for them). The sub-envs are the id's own
env class, built with the same arguments and sharing one predictor. A step checks every action first (a bad one
raises before any sub-env moves), advances every sub-env's world 0.4 s, forecasts for the agents of all sub-envs in
one call (each sub-env a group of its own, so agents of different sub-envs never interact in the predictor), then
completes every sub-env's observation, reward and info. Results equal those of ``SyncVectorEnv`` over
``gym.make(id)`` envs with the same seeds and autoreset mode (the futures up to the rounding of a larger batch); the
time limit truncates as ``TimeLimit`` does and infos are batched as gymnasium's vector envs batch them. Autoreset is
gymnasium's default, ``AutoresetMode.NEXT_STEP`` (the step after an episode ended resets that sub-env, ignores its
action and returns its first observation with reward 0), or ``autoreset_mode=AutoresetMode.SAME_STEP`` (the ending
step resets the sub-env at once and returns its first observation, the last one in ``info["final_obs"]`` and the
last info in ``info["final_info"]``; the reset sub-envs are forecast in a second batched call), the convention of
stable-baselines3 and CleanRL-style loops.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

from envs.common.crowd_env import CrowdEnv
from envs.common.errors import EnvInputError
from envs.common.predictors import Forecast, predict_futures


@dataclass(eq=False)
class StepParts:
    """One vector step before batching: every sub-env's observation and info (lists), rewards, terminated and
    truncated (num_envs,), and ``finals``: sub-env -> {"final_obs", "final_info"} of episodes that ended and were
    reset at once (``AutoresetMode.SAME_STEP``)."""

    observations: list[dict[str, np.ndarray]]
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    infos: list[dict[str, Any]]
    finals: dict[int, dict[str, Any]]


def sub_env_seeds(seed: int | Sequence[int | None] | None, num_envs: int) -> list[int | None]:
    """One seed per sub-env from ``reset``'s ``seed``: an int (sub-env i gets seed + i), a list, or None."""
    if seed is None or (isinstance(seed, int | np.integer) and not isinstance(seed, bool)):
        return [None if seed is None else int(seed) + i for i in range(num_envs)]
    if isinstance(seed, Sequence) and not isinstance(seed, str) and len(seed) == num_envs:
        return list(seed)
    raise EnvInputError(f"seed={seed!r}: expected None, an int or a list of {num_envs} seeds")


def batch_infos(vec: VectorEnv, infos: list[dict[str, Any]], finals: dict[int, dict[str, Any]]) -> dict[str, Any]:
    """Sub-env infos batched as gymnasium's vector envs batch them (in ``SyncVectorEnv``'s order: a sub-env's
    final entries, then its info)."""
    batched: dict[str, Any] = {}
    for i, info in enumerate(infos):
        if i in finals:
            batched = vec._add_info(batched, finals[i], i)
        batched = vec._add_info(batched, info, i)
    return batched


class CrowdVectorEnv(VectorEnv):
    """``num_envs`` STCrowd envs made by ``make_env(**kwargs)``, forecast together.

    Args:
        make_env: an env class (``ReplayCrowdEnv``, ``SimCrowdEnv``) or factory taking the id's keyword arguments.
        num_envs: number of sub-envs, >= 1.
        max_episode_steps: steps after which a sub-env's episode is truncated (None: never), as ``TimeLimit``.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (default) or ``SAME_STEP`` (or their string values).
        autoreset_seeds: called for each autoreset, returns the seed (an int >= 0) the ended sub-env starts its next
            episode with (a training split's seeds: ``envs.suite.Suite.draw_seed``); None: the sub-env's own generator
            goes on, gymnasium's way.
        kwargs: the env's arguments (``predictor``, ``task``, ``pedestrians`` ...), the same for every sub-env.
    """

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"]}

    def __init__(self, make_env: Callable[..., CrowdEnv], num_envs: int = 1, max_episode_steps: int | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 autoreset_seeds: Callable[[], int] | None = None, **kwargs: Any):
        if autoreset_seeds is not None and not callable(autoreset_seeds):
            raise EnvInputError(f"autoreset_seeds={autoreset_seeds!r}: expected None or a function returning a seed")
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
            raise EnvInputError(f"num_envs={num_envs!r}: expected an int >= 1")
        if max_episode_steps is not None and (isinstance(max_episode_steps, bool) or
                                              not isinstance(max_episode_steps, int) or max_episode_steps < 1):
            raise EnvInputError(f"max_episode_steps={max_episode_steps!r}: expected None or an int >= 1")
        modes = (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP)
        if autoreset_mode not in modes and autoreset_mode not in [mode.value for mode in modes]:
            raise EnvInputError(f"autoreset_mode={autoreset_mode!r}: expected one of {[m.value for m in modes]}")
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        if kwargs.get("rerun") is not None:
            raise EnvInputError("rerun=: a vector env does not record; record one env made with gym.make(..., rerun=)")
        first = make_env(**kwargs)
        self.envs: list[CrowdEnv] = [first] + [make_env(**{**kwargs, "predictor": first.predictor})
                                               for _ in range(num_envs - 1)]
        self.num_envs, self.max_episode_steps = int(num_envs), max_episode_steps
        self.predictor, self.scene, self.num_samples = first.predictor, first.scene, first.num_samples
        self._env_class = type(first)  # whose begin_reset_all / advance_all step the sub-envs together
        for env in self.envs[1:]:  # the same recording and predictor: forecasts kept by one serve all
            env.forecasts = first.forecasts
        self.render_mode = first.render_mode
        self.single_observation_space, self.single_action_space = first.observation_space, first.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._elapsed = np.zeros(self.num_envs, np.int64)
        self._autoreset = np.zeros(self.num_envs, bool)
        self._autoreset_seeds = autoreset_seeds

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict | None = None):
        """Reset every sub-env: ``seed`` an int (sub-env i gets seed + i), a list of one per sub-env, or None.
        Every seed and the options are checked before any sub-env is reset."""
        observations, infos = self.reset_parts(sub_env_seeds(seed, self.num_envs), options)
        return self._batch(observations), batch_infos(self, infos, {})

    def reset_parts(self, seeds: list[int | None], options: dict | None
                    ) -> tuple[list[dict[str, np.ndarray]], list[dict[str, Any]]]:
        """``reset`` with one seed per sub-env, unbatched: every sub-env's observation and info."""
        for i, env_seed in enumerate(seeds):
            if env_seed is not None and (isinstance(env_seed, bool | np.bool_) or
                                         not isinstance(env_seed, int | np.integer) or env_seed < 0):
                raise EnvInputError(f"sub-env {i}: seed={env_seed!r}: expected None or an int >= 0; no sub-env "
                                    "was reset")
        self.envs[0].check_reset_options(options)
        self._env_class.begin_reset_all(self.envs, seeds, options)
        outputs = [env.end_reset(*prediction) for env, prediction in zip(self.envs, self._predict_all(), strict=True)]
        self._elapsed[:] = 0
        self._autoreset[:] = False
        return [obs for obs, _ in outputs], [info for _, info in outputs]

    def step(self, actions: Any):
        """Step every sub-env (or reset those whose episode ended at the previous step) and forecast once."""
        parts = self.step_parts(self.check_actions(actions))
        return (self._batch(parts.observations), parts.rewards, parts.terminated, parts.truncated,
                batch_infos(self, parts.infos, parts.finals))

    def check_actions(self, actions: Any) -> list[np.ndarray | None]:
        """Every sub-env's ego velocity (None where it resets or has no ego) after every check ``step`` makes
        before anything moves; raises ``EnvInputError`` or ``NeedsResetError``."""
        try:
            actions = np.asarray(actions)
        except (ValueError, TypeError) as err:  # ragged nesting and the like
            raise EnvInputError(f"actions must be an array of shape {self.action_space.shape} (num_envs, 2), got "
                                f"a ragged {type(actions).__name__}") from err
        if actions.shape != self.action_space.shape:
            raise EnvInputError(f"actions must have shape {self.action_space.shape} (num_envs, 2), got {actions.shape}")
        return [None if self._autoreset[i] else env.check_step(action)
                for i, (env, action) in enumerate(zip(self.envs, iterate(self.action_space, actions), strict=True))]

    def step_parts(self, velocities: list[np.ndarray | None]) -> StepParts:
        """``step`` after ``check_actions``, unbatched."""
        resetting = np.flatnonzero(self._autoreset)
        stepping = np.flatnonzero(~self._autoreset)
        self._env_class.begin_reset_all([self.envs[i] for i in resetting], self._next_seeds(len(resetting)), None)
        self._env_class.advance_all([self.envs[i] for i in stepping], [velocities[i] for i in stepping])
        forecasts = self._predict_all()
        parts = StepParts([], np.zeros(self.num_envs), np.zeros(self.num_envs, bool), np.zeros(self.num_envs, bool),
                          [], {})
        for i, (env, prediction) in enumerate(zip(self.envs, forecasts, strict=True)):
            if self._autoreset[i]:
                obs, info = env.end_reset(*prediction)
                self._elapsed[i] = 0
            else:
                obs, parts.rewards[i], parts.terminated[i], parts.truncated[i], info = env.end_step(*prediction)
                self._elapsed[i] += 1
                if self.max_episode_steps is not None and self._elapsed[i] >= self.max_episode_steps:
                    parts.truncated[i] = True
            parts.observations.append(obs)
            parts.infos.append(info)
        ended = parts.terminated | parts.truncated
        if self.autoreset_mode == AutoresetMode.SAME_STEP:  # reset the ended sub-envs now, one forecast for them
            ended_ids = np.flatnonzero(ended)
            for i in ended_ids:
                parts.finals[int(i)] = {"final_obs": parts.observations[i], "final_info": parts.infos[i]}
            self._env_class.begin_reset_all([self.envs[i] for i in ended_ids], self._next_seeds(len(ended_ids)), None)
            for i, prediction in zip(ended_ids, self._predict_all(ended_ids), strict=True):
                parts.observations[i], parts.infos[i] = self.envs[i].end_reset(*prediction)
                self._elapsed[i] = 0
        else:
            self._autoreset = ended
        return parts

    def render(self) -> tuple[np.ndarray | None, ...]:
        """Every sub-env's ``render()`` (an RGB array each with ``render_mode="rgb_array"``)."""
        return tuple(env.render() for env in self.envs)

    def close_extras(self, **kwargs: Any) -> None:
        for env in self.envs:
            env.close()

    def _next_seeds(self, count: int) -> list[int | None]:
        """Seeds of ``count`` autoresets: ``autoreset_seeds()`` each, or None (the sub-envs' generators go on)."""
        if self._autoreset_seeds is None:
            return [None] * count
        seeds = [self._autoreset_seeds() for _ in range(count)]
        for seed in seeds:
            if isinstance(seed, bool | np.bool_) or not isinstance(seed, int | np.integer) or seed < 0:
                raise EnvInputError(f"autoreset_seeds returned {seed!r}: expected an int >= 0")
        return [int(seed) for seed in seeds]

    def _predict_all(self, which: Sequence[int] | None = None) -> list[Forecast]:
        """(futures, anchors) of the sub-envs ``which`` (None: all), in that order: kept forecasts where a sub-env
        has one (``ForecastCache``), one predictor call for the agents of all the others. If the predictor fails,
        every sub-env refuses to step until the vector env is reset (``CrowdEnv.interrupt``)."""
        try:
            return self._forecasts(range(self.num_envs) if which is None else which)
        except Exception as err:
            for env in self.envs:
                env.interrupt(f"the predictor failed: {err}")
            raise

    def _forecasts(self, which: Sequence[int]) -> list[Forecast]:
        forecasts: dict[int, Forecast | None] = {i: self.envs[i].cached_forecast() for i in which}
        missing = [i for i, forecast in forecasts.items() if forecast is None]
        if missing:
            requests = [self.envs[i].forecast_request() for i in missing]
            sizes = [len(request.histories_m) for request in requests]
            targets = np.concatenate([request.targets for request in requests])
            futures, _ = predict_futures(self.predictor, np.concatenate([r.histories_m for r in requests]),
                                               self.scene, self.num_samples, np.repeat(np.arange(len(missing)), sizes),
                                               targets, anchors=False)
            cuts = np.cumsum([int(request.targets.sum()) for request in requests])[:-1]
            for i, forecast in zip(missing, np.split(futures, cuts), strict=True):
                forecasts[i] = (forecast, None)
                self.envs[i].remember_forecast(forecasts[i])
        return [forecasts[i] for i in which]

    def _batch(self, observations: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        out = create_empty_array(self.single_observation_space, self.num_envs)
        return concatenate(self.single_observation_space, observations, out)


def replay_vector_env(num_envs: int = 1, max_episode_steps: int | None = None, shards: int = 1,
                      executor: str = "process", **kwargs: Any) -> VectorEnv:
    """Vector entry point of the replay ids (``STCrowd-<Scene>-v0``); ``shards`` > 1 or ``executor="ray"``: a
    ``envs.shards.ShardedVectorEnv`` stepping its shards in parallel."""
    return _vector_env("envs.replay_env:ReplayCrowdEnv", num_envs, max_episode_steps, shards, executor, kwargs)


def sim_vector_env(num_envs: int = 1, max_episode_steps: int | None = None, shards: int = 1,
                   executor: str = "process", **kwargs: Any) -> VectorEnv:
    """Vector entry point of the simulated ids (``STCrowd-Sim<Layout>-v1``); ``shards`` > 1 or ``executor="ray"``:
    a ``envs.shards.ShardedVectorEnv`` stepping its shards in parallel."""
    return _vector_env("envs.sim_env:SimCrowdEnv", num_envs, max_episode_steps, shards, executor, kwargs)


def _vector_env(env_class_path: str, num_envs: int, max_episode_steps: int | None, shards: int, executor: str,
                kwargs: dict[str, Any]) -> VectorEnv:
    if shards == 1 and executor == "process":
        module, _, name = env_class_path.partition(":")
        return CrowdVectorEnv(getattr(__import__(module, fromlist=[name]), name), num_envs, max_episode_steps,
                              **kwargs)
    from envs.shards import ShardedVectorEnv

    if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
        raise EnvInputError(f"num_envs={num_envs!r}: expected an int >= 1")
    if kwargs.get("rerun") is not None:
        raise EnvInputError("rerun=: a vector env does not record; record one env made with gym.make(..., rerun=)")
    if kwargs.get("autoreset_seeds") is not None:
        raise EnvInputError("autoreset_seeds=: only a vector env in this process takes it (shards=1, "
                            "executor='process')")
    return ShardedVectorEnv(env_class_path, num_envs, shards, executor, max_episode_steps, **kwargs)
