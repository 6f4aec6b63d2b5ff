"""A batch's step is whole or lost (``envs.batch_step``): whichever sub-env's autoreset fails, at whichever of its
episodes' ends, in either autoreset mode, the error names the sub-env and the seed it was reset with, the vector env
refuses every step until it is reset (saying why), and a reset brings back exactly the episodes of a fresh one."""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from hypothesis import given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs.common.errors import AutoresetError, EnvInputError, NeedsResetError
from envs.sim_env import SimCrowdEnv

ENV_ID = "STCrowd-SimCrossing-v1"
LIMIT = 3  # steps per episode, so that autoresets come quickly
MODES = [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP]


class CrowdPlacementError(RuntimeError):
    """What the trapped reset raises."""


def vector_env(mode: AutoresetMode, num_envs: int, draw_seed: Callable[[], Any]) -> gym.vector.VectorEnv:
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", max_episode_steps=LIMIT,
                        autoreset_mode=mode, autoreset_seeds=draw_seed, predictor="none")


def seed_counter(first: int = 1000) -> tuple[Callable[[], int], list[int]]:
    """A seed function drawing ``first``, ``first + 1``, ..., and the list of the seeds it has drawn."""
    drawn: list[int] = []

    def draw() -> int:
        drawn.append(first + len(drawn))
        return drawn[-1]

    return draw, drawn


def still(num_envs: int) -> np.ndarray:
    return np.zeros((num_envs, 2), np.float32)  # the robots stand: no episode ends before the time limit


@settings(max_examples=12, deadline=None)
@given(mode=st.sampled_from(MODES), num_envs=st.integers(1, 3), data=st.data())
def test_a_failed_autoreset_names_the_sub_env_and_its_seed_and_the_batch_steps_no_more_until_reset(
        mode: AutoresetMode, num_envs: int, data: st.DataObject) -> None:
    failing, nth = data.draw(st.integers(0, num_envs - 1)), data.draw(st.integers(1, 3))  # its nth autoreset fails
    draw_seed, drawn = seed_counter()
    vec = vector_env(mode, num_envs, draw_seed)
    vec.reset(seed=0)
    target, calls, caught = vec.envs[failing], [0], {}
    original = SimCrowdEnv._reset_worlds.__func__

    def trap(cls: type, batch: list[SimCrowdEnv], options: list[dict]) -> Any:
        if any(env is target for env in batch):
            calls[0] += 1
            if calls[0] == nth:
                caught["resetting"] = sorted(vec.envs.index(env) for env in batch)
                raise CrowdPlacementError("the crowd could not be placed")
        return original(cls, batch, options)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(SimCrowdEnv, "_reset_worlds", classmethod(trap))
        with pytest.raises(AutoresetError) as failed:
            for _ in range(10 * LIMIT):
                before = len(drawn)
                vec.step(still(num_envs))
    seed = drawn[before + caught["resetting"].index(failing)]
    message = str(failed.value)
    assert f"sub-env {failing} (seed {seed})" in message, message
    assert "CrowdPlacementError: the crowd could not be placed" in message, message
    for attempt in range(2):  # the batch is half-stepped: refused, not stepped on
        with pytest.raises(NeedsResetError, match=rf"^the last step did not finish \(AutoresetError: .*sub-env "
                                                  rf"{failing} \(seed {seed}\).*call reset\(\) before step\(\)$"):
            vec.step(still(num_envs))
        assert len(drawn) == before + len(caught["resetting"]), f"[attempt {attempt}] no seed drawn when refused"
    fresh = vector_env(mode, num_envs, seed_counter()[0])
    ours, theirs = vec.reset(seed=7), fresh.reset(seed=7)
    for t in range(LIMIT):  # up to the episodes' end: the same episodes as a fresh vector env
        for key in theirs[0]:
            assert np.array_equal(ours[0][key], theirs[0][key]), f"[step {t}] {key} differs after the reset"
        ours, theirs = vec.step(still(num_envs)), fresh.step(still(num_envs))
    vec.close(), fresh.close()


@settings(max_examples=8, deadline=None)
@given(mode=st.sampled_from(MODES), num_envs=st.integers(1, 3),
       bad=st.sampled_from([-1, 1.5, "7", True, ValueError("no more seeds")]))
def test_a_seed_function_that_fails_or_returns_no_seed_is_refused_naming_the_sub_env(
        mode: AutoresetMode, num_envs: int, bad: Any) -> None:
    def draw_seed() -> Any:
        if isinstance(bad, Exception):
            raise bad
        return bad

    vec = vector_env(mode, num_envs, draw_seed)
    vec.reset(seed=0)
    raised, problem = ((AutoresetError, "raised ValueError: no more seeds") if isinstance(bad, Exception) else
                       (EnvInputError, f"returned {bad!r}: expected an int >= 0"))
    with pytest.raises(raised, match=f"^sub-env 0: autoreset_seeds {re.escape(problem)}$"):
        for _ in range(2 * LIMIT):
            vec.step(still(num_envs))
    with pytest.raises(NeedsResetError, match=r"^the last step did not finish .*call reset\(\) before step\(\)$"):
        vec.step(still(num_envs))
    vec.reset(seed=0)
    vec.step(still(num_envs))
    vec.close()
