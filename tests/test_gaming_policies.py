"""Policies written to game the at-fault rule (``tests/gaming_policies.py``), scored on the five logged replays: the
rammer and the creeper are at fault on at least 85 % of their pedestrian collisions, a standing robot on none.

Since the replays' robot has inertia (benchmark version 4: it cannot stop at once) the creeper is at fault on 111 of
124 (0.895); most of the others are people who appear in the recording within reach of the robot at full speed, whom
the rule counts as walking in (``envs.common.fault``), a few are people who catch the creeping robot from behind."""

from __future__ import annotations

import pytest
from gaming_policies import LOGGED_REPLAYS, Creeper, SpeedMatchedRammer, Standing, judged_collisions

EPISODES = 25  # per replay, seeds 0..24


@pytest.fixture(scope="module")
def judged() -> dict[str, list[bool | None]]:
    """The at-fault verdict of every pedestrian collision of each policy over the logged replays."""
    return {cls.__name__: [v for env_id in LOGGED_REPLAYS for v in judged_collisions(cls, env_id, EPISODES)]
            for cls in (SpeedMatchedRammer, Creeper, Standing)}


@pytest.mark.parametrize("name", ["SpeedMatchedRammer", "Creeper"])
def test_a_policy_that_rams_people_is_at_fault_on_most_of_its_collisions(judged, name: str) -> None:
    verdicts = judged[name]
    assert len(verdicts) >= 0.8 * len(LOGGED_REPLAYS) * EPISODES, f"{name} should collide in most episodes"
    share = sum(v is True for v in verdicts) / len(verdicts)
    assert share >= 0.85, f"{name}: at fault on {share:.0%} of {len(verdicts)} pedestrian collisions"


def test_a_standing_robot_is_never_at_fault(judged) -> None:
    verdicts = judged["Standing"]
    assert len(verdicts) >= 50, "people walk into a robot standing on their paths"
    assert not any(verdicts)
