"""Policies written to game the at-fault rule (``tests/gaming_policies.py``), scored on the five logged replays: the
rammer and the creeper are at fault on at least 90 % of their pedestrian collisions, a standing robot on none."""

from __future__ import annotations

import gymnasium as gym
import pytest
from gaming_policies import Creeper, SpeedMatchedRammer, Standing

import envs  # noqa: F401  (registers the ids)
from st_sim.apps.navigation.episodes import run_episode
from st_sim.apps.navigation.metrics import Outcome
from st_sim.apps.navigation.world import world_of

REPLAYS = ("STCrowd-Eth-v0", "STCrowd-Hotel-v0", "STCrowd-Univ-v0", "STCrowd-Zara1-v0", "STCrowd-Zara2-v0")
EPISODES = 25  # per replay, seeds 0..24


@pytest.fixture(scope="module")
def judged() -> dict[str, list[bool | None]]:
    """The at-fault verdict of every pedestrian collision of each policy over the logged replays."""
    verdicts: dict[str, list[bool | None]] = {cls.__name__: [] for cls in (SpeedMatchedRammer, Creeper, Standing)}
    for env_id in REPLAYS:
        env = gym.make(env_id, predictor="none", pedestrians="log")
        world = world_of(env)
        for cls in (SpeedMatchedRammer, Creeper, Standing):
            policy = cls(world)
            for seed in range(EPISODES):
                trace, _ = run_episode(env, policy, world, seed)
                if trace.outcome is Outcome.PEDESTRIAN:
                    verdicts[cls.__name__].append(trace.at_fault)
        env.close()
    return verdicts


@pytest.mark.parametrize("name", ["SpeedMatchedRammer", "Creeper"])
def test_a_policy_that_rams_people_is_at_fault_on_at_least_nine_collisions_in_ten(judged, name: str) -> None:
    verdicts = judged[name]
    assert len(verdicts) >= 0.8 * len(REPLAYS) * EPISODES, f"{name} should collide in most episodes"
    share = sum(v is True for v in verdicts) / len(verdicts)
    assert share >= 0.9, f"{name}: at fault on {share:.0%} of {len(verdicts)} pedestrian collisions"


def test_a_standing_robot_is_never_at_fault(judged) -> None:
    verdicts = judged["Standing"]
    assert len(verdicts) >= 50, "people walk into a robot standing on their paths"
    assert not any(verdicts)
