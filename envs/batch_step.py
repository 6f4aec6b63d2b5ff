"""Crowd envs of any ids stepped together in two phases: every world, then one forecast per predictor model.

A step first moves every sub-env's world 0.4 s, each env class over all its sub-envs at once (``advance_all``:
simulated crowds of one layout in one ``step_crowds`` call, reactive replays of one scene in one batched pass),
then forecasts for the agents of every sub-env in one ``predict_futures`` call per predictor model (each sub-env's
moment a group of its own, on its own scene), then completes each sub-env's observation, reward and info. Resets go
the same way (``begin_reset_all``, one forecast per model, ``end_reset``). ``CrowdVectorEnv`` is a batch of one id's
sub-envs; ``st_sim.apps.navigation.training_envs.FeatureShards`` one batch of every training scenario's.

Each sub-env moves exactly as it would stepped alone: worlds never mix, and every sub-env draws from its own
generator. Only the forecasts depend on the batch, in their last bits (a larger torch batch rounds otherwise).

A step is whole or lost: if anything fails in it (an autoreset, a world, the forecast, an observation), some sub-envs
have moved and others not, so every sub-env is interrupted and the batch refuses to step (``NeedsResetError``
saying why) until it is reset. A failed autoreset raises ``AutoresetError`` naming the sub-envs and their seeds.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

from envs.common.crowd_env import CrowdEnv, is_seed
from envs.common.errors import AutoresetError, EnvInputError, NeedsResetError
from envs.common.predictors import forecast_all


@dataclass(eq=False)
class StepParts:
    """One step of a batch, unbatched: every sub-env's observation and info (lists), rewards, terminated and
    truncated (num_envs,), and ``finals``: sub-env -> {"final_obs", "final_info"} of episodes that ended and were
    reset at once (``AutoresetMode.SAME_STEP``)."""

    observations: list[dict[str, np.ndarray]]
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    infos: list[dict[str, Any]]
    finals: dict[int, dict[str, Any]]


def by_class(envs: Sequence[CrowdEnv]) -> dict[type, list[int]]:
    """The positions in ``envs`` of each env class's sub-envs, classes in order of first appearance."""
    groups: dict[type, list[int]] = {}
    for i, env in enumerate(envs):
        groups.setdefault(type(env), []).append(i)
    return groups


def begin_resets(envs: Sequence[CrowdEnv], seeds: Sequence[int | None], options: dict | None) -> None:
    """The first half of ``reset`` of every env, each class's together (``CrowdEnv.begin_reset_all``)."""
    for env_class, members in by_class(envs).items():
        env_class.begin_reset_all([envs[i] for i in members], [seeds[i] for i in members], options)


def advance_worlds(envs: Sequence[CrowdEnv], velocities_mps: Sequence[np.ndarray | None]) -> None:
    """The first half of ``step`` of every env (its ego at ``velocities_mps[i]`` (2,) m/s, None: none), each class's
    together (``CrowdEnv.advance_all``)."""
    for env_class, members in by_class(envs).items():
        env_class.advance_all([envs[i] for i in members], [velocities_mps[i] for i in members])


class EnvBatch:
    """Sub-envs of any STCrowd ids stepped together, with gymnasium's time limit and autoreset bookkeeping.

    Args:
        envs: the sub-envs (``CrowdEnv``s); sub-envs that share a predictor object are forecast in one call (their
            ``num_samples`` equal).
        max_episode_steps: per sub-env, steps after which its episode is truncated (None: never), as ``TimeLimit``.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` or ``SAME_STEP`` (see ``envs.vector_env``).
        autoreset_seeds: per sub-env, None (its generator goes on) or a function returning the seed (an int >= 0)
            it starts its next episode with after an autoreset.
    """

    def __init__(self, envs: Sequence[CrowdEnv], max_episode_steps: Sequence[int | None],
                 autoreset_mode: AutoresetMode, autoreset_seeds: Sequence[Callable[[], int] | None]):
        if not len(envs) == len(max_episode_steps) == len(autoreset_seeds):
            raise ValueError(f"EnvBatch: {len(envs)} envs, {len(max_episode_steps)} time limits and "
                             f"{len(autoreset_seeds)} autoreset seed functions")
        self.envs, self.autoreset_mode = list(envs), AutoresetMode(autoreset_mode)
        self.num_envs = len(self.envs)
        self._limits = np.array([np.iinfo(np.int64).max if limit is None else limit for limit in max_episode_steps],
                                np.int64)
        self._seed_functions = list(autoreset_seeds)
        self.elapsed = np.zeros(self.num_envs, np.int64)
        self.autoreset = np.zeros(self.num_envs, bool)
        """sub-envs whose episode ended at the last step (``NEXT_STEP``: this step resets them)"""
        self._unfinished: str | None = None
        """why the batch cannot step until it is reset: a step or reset that did not finish (None: it can)"""

    def reset_parts(self, seeds: Sequence[int | None], options: dict | None
                    ) -> tuple[list[dict[str, np.ndarray]], list[dict[str, Any]]]:
        """Every sub-env's first observation and info; sub-env i reset with ``seeds[i]``. Every seed and the options
        are checked before any sub-env is reset."""
        for i, env_seed in enumerate(seeds):
            if not is_seed(env_seed):
                raise EnvInputError(f"sub-env {i}: seed={env_seed!r}: expected None or an int >= 0; no sub-env "
                                    "was reset")
        for members in by_class(self.envs).values():
            self.envs[members[0]].check_reset_options(options)
        try:
            begin_resets(self.envs, seeds, options)
            outputs = [env.end_reset(*prediction) for env, prediction in zip(self.envs, forecast_all(self.envs),
                                                                              strict=True)]
        except BaseException as err:
            self._unfinished = f"the last reset did not finish ({type(err).__name__}: {err})"
            raise
        self.elapsed[:] = 0
        self.autoreset[:] = False
        self._unfinished = None
        return [obs for obs, _ in outputs], [info for _, info in outputs]

    def check_actions(self, actions: Sequence[Any] | np.ndarray) -> list[np.ndarray | None]:
        """Every sub-env's ego velocity (2,) m/s for ``actions[i]`` (None where it resets at this step or has no
        ego), after every check ``step`` makes before anything moves (``CrowdEnv.check_step``); ``NeedsResetError``
        after a step or reset that did not finish, until a reset succeeds."""
        if self._unfinished is not None:
            raise NeedsResetError(f"{self._unfinished}: some sub-envs had moved and others not; call reset() "
                                  "before step()")
        if len(actions) != self.num_envs:
            raise EnvInputError(f"{len(actions)} actions for {self.num_envs} sub-envs")
        return [None if self.autoreset[i] else env.check_step(action)
                for i, (env, action) in enumerate(zip(self.envs, actions, strict=True))]

    def step_parts(self, velocities_mps: Sequence[np.ndarray | None]) -> StepParts:
        """One step of every sub-env (ego velocities (2,) m/s, None where it resets or has no ego, from
        ``check_actions``), or the reset of those whose episode ended at the previous step (``NEXT_STEP``). Whatever
        fails in it leaves every sub-env interrupted and the batch refusing to step until it is reset."""
        try:
            return self._step(velocities_mps)
        except BaseException as err:  # some sub-envs moved, others not: the step is lost for every sub-env
            self._unfinished = f"the last step did not finish ({type(err).__name__}: {err})"
            for env in self.envs:
                env.interrupt(f"the batch's step failed ({type(err).__name__}: {err})")
            raise

    def _step(self, velocities_mps: Sequence[np.ndarray | None]) -> StepParts:
        """``step_parts`` without the clean-up of a failure."""
        resetting, stepping = np.flatnonzero(self.autoreset), np.flatnonzero(~self.autoreset)
        self._autoreset(resetting)
        advance_worlds([self.envs[i] for i in stepping], [velocities_mps[i] for i in stepping])
        parts = StepParts([], np.zeros(self.num_envs), np.zeros(self.num_envs, bool), np.zeros(self.num_envs, bool),
                          [], {})
        for i, (env, prediction) in enumerate(zip(self.envs, forecast_all(self.envs), strict=True)):
            if self.autoreset[i]:
                obs, info = env.end_reset(*prediction)
                self.elapsed[i] = 0
            else:
                obs, parts.rewards[i], parts.terminated[i], parts.truncated[i], info = env.end_step(*prediction)
                self.elapsed[i] += 1
                parts.truncated[i] |= self.elapsed[i] >= self._limits[i]
            parts.observations.append(obs)
            parts.infos.append(info)
        ended = np.flatnonzero(parts.terminated | parts.truncated)
        if self.autoreset_mode == AutoresetMode.SAME_STEP:  # reset the ended sub-envs now, one forecast for them
            for i in ended:
                parts.finals[int(i)] = {"final_obs": parts.observations[i], "final_info": parts.infos[i]}
            self._autoreset(ended)
            for i, prediction in zip(ended, forecast_all([self.envs[i] for i in ended]), strict=True):
                parts.observations[i], parts.infos[i] = self.envs[i].end_reset(*prediction)
                self.elapsed[i] = 0
        else:
            self.autoreset = parts.terminated | parts.truncated
        return parts

    def _autoreset(self, which: np.ndarray) -> None:
        """Start the next episode of the sub-envs ``which`` (each class's together) with the seeds their functions
        draw; ``AutoresetError`` naming the sub-envs and seeds of a class whose reset failed."""
        seeds = self._next_seeds(which)
        for members in by_class([self.envs[i] for i in which]).values():
            try:
                begin_resets([self.envs[which[k]] for k in members], [seeds[k] for k in members], None)
            except Exception as err:
                named = ", ".join(f"sub-env {which[k]} (seed {seeds[k]})" if seeds[k] is not None else
                                  f"sub-env {which[k]} (its generator's next episode)" for k in members)
                raise AutoresetError(f"the autoreset of {named} failed ({type(err).__name__}: {err})") from err

    def _next_seeds(self, which: np.ndarray) -> list[int | None]:
        """The seeds the sub-envs ``which`` start their next episode with, drawn in that order (None: their
        generators go on)."""
        seeds = []
        for i in which:
            function = self._seed_functions[i]
            try:
                seed = None if function is None else function()
            except Exception as err:
                raise AutoresetError(f"sub-env {i}: autoreset_seeds raised {type(err).__name__}: {err}") from err
            if not is_seed(seed):
                raise EnvInputError(f"sub-env {i}: autoreset_seeds returned {seed!r}: expected an int >= 0")
            seeds.append(None if seed is None else int(seed))
        return seeds
