"""Stable-baselines3 model files in the tests: the env the tests train on, and zips rewritten member by member."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from st_sim.apps.navigation.sb3_zip import Sb3ZipError, load_sb3_zip

ENV = "STCrowd-SimFrontalApproach-v1"  # 40 pedestrian slots, as the corridor; quicker to step
KEYS = ["ego", "history", "history_mask"]
ACTIONS = gym.spaces.Box(-1.5, 1.5, (2,), np.float32)  # the env's


def make_env(policy: str) -> gym.Env:
    """The env with the keys a model reads; flattened into a Box for an MlpPolicy."""
    env = gym.wrappers.FilterObservation(gym.make(ENV, predictor="none"), KEYS)
    return gym.wrappers.FlattenObservation(env) if policy == "MlpPolicy" else env


def rewrite(source: Path, target: Path, members: dict[str, bytes]) -> Path:
    """A copy of the zip ``source`` with ``members`` replaced."""
    with zipfile.ZipFile(source) as original, zipfile.ZipFile(target, "w") as copy:
        for info in original.infolist():
            copy.writestr(info.filename, members.get(info.filename, original.read(info.filename)))
    return target


def data_of(path: Path) -> dict[str, Any]:
    with zipfile.ZipFile(path) as archive:
        return json.loads(archive.read("data"))


def with_data(source: Path, target: Path, data: dict[str, Any]) -> Path:
    return rewrite(source, target, {"data": json.dumps(data).encode()})


def outcome(path: Path) -> str:
    """"loaded", or the refusal's message (checked to be one line naming the file)."""
    try:
        load_sb3_zip(path, ACTIONS)
    except Sb3ZipError as err:
        message = str(err)
        assert "\n" not in message and message.startswith(f"{path}: "), message
        return message
    return "loaded"
