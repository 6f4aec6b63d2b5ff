"""A fixed-size view of any STCrowd observation, to train a stable-baselines3 model that runs in every scenario.

STCrowd's observation has one row per pedestrian slot, and scenes have different numbers of slots (ETH 27, UNIV 75,
a simulated crossing 40), so a model trained on one env's raw observation fits only envs of the same size
(``python -m st_sim benchmark --policy sb3:model.zip`` says so, naming both spaces). This view keeps the K people
nearest to the robot, in the robot's frame, and always has the same size:

- the goal relative to the robot (2) and the robot's velocity (2) [m, m/s];
- for each of the K nearest people present: position and velocity relative to the robot [m, m/s], and 1 (0 for an
  empty slot), nearest first.

    env = NearestObservation(gym.make("STCrowd-SimCrossing-v1"))       # train on this (train_sb3.py)
    python -m st_sim benchmark --policy examples.my_policy.nearest:Sb3Nearest ...   # MODEL_ENV names the zip
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import gymnasium as gym
import numpy as np

from st_sim.apps.navigation.sb3_zip import load_sb3_zip
from st_sim.apps.navigation.world import NavWorld

K_NEAREST = 6  # people in the view [-]
STEP_S = 0.4  # seconds between observations [s]
SIZE = 4 + 5 * K_NEAREST
MODEL_ENV = "MY_POLICY_MODEL"  # Sb3Nearest loads the model this environment variable names
DEFAULT_MODEL = "runs/my_policy/nearest.zip"


def nearest_view(obs: dict[str, np.ndarray]) -> np.ndarray:
    """(SIZE,) float32 view of an STCrowd observation (see the module docstring)."""
    ego = obs["ego"].astype(np.float64)
    present = obs["history_mask"][:, -1]
    xy = obs["history"][present, -1].astype(np.float64) - ego[:2]
    before = obs["history_mask"][present, -2]
    velocity = np.where(before[:, None], obs["history"][present, -1] - obs["history"][present, -2], 0.0) / STEP_S
    order = np.argsort(np.linalg.norm(xy, axis=1))[:K_NEAREST]
    people = np.zeros((K_NEAREST, 5))
    people[:len(order)] = np.column_stack([xy[order], velocity[order] - ego[2:4], np.ones(len(order))])
    return np.concatenate([ego[4:6] - ego[:2], ego[2:4], people.ravel()]).astype(np.float32)


class NearestObservation(gym.ObservationWrapper):
    """Any STCrowd env seen through ``nearest_view``."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (SIZE,), np.float32)

    def observation(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        return nearest_view(observation)


class Sb3Nearest:
    """A stable-baselines3 model trained on ``NearestObservation``, acting deterministically. The zip is read
    without running anything stored in it (``load_sb3_zip``), so a model file from anyone is safe to run.

    Args:
        world: the env's facts (``NavWorld``); the model acts in its ``action_space``.
        use_predictions: unused (the view reads no forecasts).
        path: the model's zip (default: $MY_POLICY_MODEL, else runs/my_policy/nearest.zip).
    """

    def __init__(self, world: NavWorld, use_predictions: bool = False, path: str | None = None):
        self.path = Path(path or os.environ.get(MODEL_ENV, DEFAULT_MODEL))
        if not self.path.is_file():
            told = f"${MODEL_ENV}" if path is None and MODEL_ENV in os.environ else "the default"
            raise FileNotFoundError(
                f"no model at {self.path} ({told}): train one with `python -m examples.my_policy.train_sb3 --out "
                f"{DEFAULT_MODEL}`, or name yours with {MODEL_ENV}=PATH.zip")
        self.policy = load_sb3_zip(self.path, world.action_space)

    def fingerprint(self) -> str:
        """The model this policy acts with and its SHA-256, so a benchmark run knows which model it scored."""
        return f"{self.path} sha256 {hashlib.sha256(self.path.read_bytes()).hexdigest()}"

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s]."""
        action, _ = self.policy.predict(nearest_view(obs), deterministic=True)
        return action
