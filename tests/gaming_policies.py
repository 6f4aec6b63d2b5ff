"""Policies written to game an at-fault rule, as a red team would: each runs into people while trying to look
blameless (``tests/test_gaming_policies.py`` scores them). They follow the planner protocol: built as
``Class(world, use_predictions)``, ``reset()``, ``act(obs) -> (2,)`` velocity [m/s], world frame."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from st_sim.apps.navigation.episodes import run_episode
from st_sim.apps.navigation.metrics import Outcome
from st_sim.apps.navigation.pedestrians import pedestrians_of
from st_sim.apps.navigation.world import NavWorld, world_of

CREEP_MPS = 0.06  # the creeper's speed near people: just above the rule's stop speed [m/s]
CREEP_NEAR_M = 2.0  # it creeps once someone is this close (centre distance) [m]
MATCH_MARGIN_MPS = 0.2  # the rammer stays this much under the person's approach speed [m/s]
LOGGED_REPLAYS = ("STCrowd-Eth-v0", "STCrowd-Hotel-v0", "STCrowd-Univ-v0", "STCrowd-Zara1-v0", "STCrowd-Zara2-v0")
"""the five ETH/UCY scenes, replayed as recorded (``judged_collisions`` runs them with pedestrians="log")"""


class _Gamer:
    def __init__(self, world: NavWorld, use_predictions: bool = False):
        self.world = world

    def reset(self) -> None:
        """Nothing to forget."""

    def _nearest(self, obs: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(offset to the nearest person [m], its velocity [m/s], the robot's position [m]), or None if nobody."""
        people, robot = pedestrians_of(obs, 1, use_predictions=False), obs["ego"][:2].astype(np.float64)
        if not len(people):
            return None
        k = int(np.argmin(np.linalg.norm(people.xy_m - robot, axis=1)))
        return people.xy_m[k] - robot, people.velocity_mps[k], robot

    def _toward_goal(self, obs: dict[str, np.ndarray], speed_mps: float) -> np.ndarray:
        to_goal = obs["ego"][4:6].astype(np.float64) - obs["ego"][:2]
        distance_m = float(np.linalg.norm(to_goal))
        return np.zeros(2, np.float32) if distance_m == 0 else (to_goal / distance_m * speed_mps).astype(np.float32)


class SpeedMatchedRammer(_Gamer):
    """Drives at the nearest person, 0.2 m/s slower than that person's approach toward it (at least the creep
    speed): never the faster of the two, so a rule that blames whoever closed faster never blames it."""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        nearest = self._nearest(obs)
        if nearest is None:
            return self._toward_goal(obs, self.world.max_speed_mps)
        offset, velocity, _ = nearest
        line = offset / max(float(np.linalg.norm(offset)), 1e-9)
        person_in_mps = float(-velocity @ line)
        speed = float(np.clip(person_in_mps - MATCH_MARGIN_MPS, CREEP_MPS, self.world.max_speed_mps))
        return (line * speed).astype(np.float32)


class Creeper(_Gamer):
    """Drives at the nearest person at full speed, and at 0.06 m/s once within 2 m of them: it pushes into people at
    a speed that a floor of 0.1 m/s would call standing."""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        nearest = self._nearest(obs)
        if nearest is None:
            return self._toward_goal(obs, self.world.max_speed_mps)
        offset = nearest[0]
        distance_m = max(float(np.linalg.norm(offset)), 1e-9)
        speed = CREEP_MPS if distance_m < CREEP_NEAR_M else self.world.max_speed_mps
        return (offset / distance_m * speed).astype(np.float32)


class Standing(_Gamer):
    """Never moves: whoever touches it walked into it."""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return np.zeros(2, np.float32)


def judged_collisions(policy_class: Any, env_id: str, episodes: int) -> list[bool | None]:
    """The at-fault verdict (``info["at_fault"]``) of every pedestrian collision of ``policy_class`` (built as a
    planner) on the logged replay ``env_id``, seeds 0..episodes-1, no forecasts."""
    env = gym.make(env_id, predictor="none", pedestrians="log")
    world = world_of(env)
    policy, verdicts = policy_class(world), []
    for seed in range(episodes):
        trace, _ = run_episode(env, policy, world, seed)
        if trace.outcome is Outcome.PEDESTRIAN:
            verdicts.append(trace.at_fault)
    env.close()
    return verdicts
