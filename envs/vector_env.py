"""Native vector envs: N crowd envs stepped together, their forecasts made in one batched predictor call.

    import gymnasium as gym, envs
    vec = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=16, vectorization_mode="vector_entry_point")
    obs, info = vec.reset(seed=0)                      # sub-env i is reset with seed 0 + i
    obs, reward, terminated, truncated, info = vec.step(vec.action_space.sample())

Every STCrowd id has this vector entry point (``make_vec``'s default mode for them). The sub-envs are the id's own
env class, built with the same arguments and sharing one predictor. A step checks every action first (a bad one
raises before any sub-env moves), then runs ``envs.batch_step``'s two phases: every sub-env's world advanced 0.4 s
together, one forecast call for the agents of all sub-envs (each sub-env a group of its own, so agents of different
sub-envs never interact in the predictor), then every sub-env's observation, reward and info. Results equal those
of ``SyncVectorEnv`` over ``gym.make(id)`` envs with the same seeds and autoreset mode (the futures up to the
rounding of a larger batch); the time limit truncates as ``TimeLimit`` does and infos are batched as gymnasium's
vector envs batch them. Autoreset is gymnasium's default, ``AutoresetMode.NEXT_STEP`` (the step after an episode
ended resets that sub-env, ignores its action and returns its first observation with reward 0), or
``autoreset_mode=AutoresetMode.SAME_STEP`` (the ending step resets the sub-env at once and returns its first
observation, the last one in ``info["final_obs"]`` and the last info in ``info["final_info"]``; the reset sub-envs
are forecast in a second batched call), the convention of stable-baselines3 and CleanRL-style loops. A step that fails
part-way (a sub-env's autoreset, a world, the forecast) is lost for every sub-env: ``step`` raises the error (an
autoreset's names the sub-env and its seed, ``AutoresetError``) and refuses every later step, saying why, until
``reset`` (``envs.batch_step``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

from envs.batch_step import EnvBatch, StepParts
from envs.common.crowd_env import CrowdEnv
from envs.common.errors import EnvInputError


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
        for env in self.envs[1:]:  # the same recording and predictor: forecasts kept by one serve all
            env.forecasts = first.forecasts
        self.render_mode = first.render_mode
        self.single_observation_space, self.single_action_space = first.observation_space, first.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.batch = EnvBatch(self.envs, [max_episode_steps] * self.num_envs, self.autoreset_mode,
                              [autoreset_seeds] * self.num_envs)

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict | None = None):
        """Reset every sub-env: ``seed`` an int (sub-env i gets seed + i), a list of one per sub-env, or None.
        Every seed and the options are checked before any sub-env is reset."""
        observations, infos = self.reset_parts(sub_env_seeds(seed, self.num_envs), options)
        return self.batched_observations(observations), batch_infos(self, infos, {})

    def reset_parts(self, seeds: list[int | None], options: dict | None
                    ) -> tuple[list[dict[str, np.ndarray]], list[dict[str, Any]]]:
        """``reset`` with one seed per sub-env, unbatched: every sub-env's observation and info."""
        return self.batch.reset_parts(seeds, options)

    def step(self, actions: Any):
        """Step every sub-env (or reset those whose episode ended at the previous step) and forecast once."""
        return self.batched(self.step_parts(self.check_actions(actions)))

    def batched(self, parts: StepParts) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray,
                                                 dict[str, Any]]:
        """``step``'s return value from its unbatched parts."""
        return (self.batched_observations(parts.observations), parts.rewards, parts.terminated, parts.truncated,
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
        return self.batch.check_actions(list(iterate(self.action_space, actions)))

    def step_parts(self, velocities: list[np.ndarray | None]) -> StepParts:
        """``step`` after ``check_actions``, unbatched."""
        return self.batch.step_parts(velocities)

    def render(self) -> tuple[np.ndarray | None, ...]:
        """Every sub-env's ``render()`` (an RGB array each with ``render_mode="rgb_array"``)."""
        return tuple(env.render() for env in self.envs)

    def close_extras(self, **kwargs: Any) -> None:
        for env in self.envs:
            env.close()

    def batched_observations(self, observations: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """One observation per sub-env batched into the vector env's observation space."""
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
