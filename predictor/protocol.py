"""The interface every predictor offers, and the input checks they share."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from replays.constants import T_PRED
from replays.scenes import Scene


@runtime_checkable
class Predictor(Protocol):
    """Anything with this ``predict`` can run inside the environments and evaluators (from outside the project:
    a plug-in factory, ``predictor.plugins``)."""

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None, num_samples: int) -> np.ndarray:
        """Futures for every agent.

        Args:
            obs: (N, T_obs, 2) observed positions, metres, world frame (T_obs >= 2).
            group: (N,) int, equal for agents that share a scene moment (interaction partners).
            scene: the scene (homography, walkability map) or None for a scene without a map.
            num_samples: S, futures per agent.

        Returns:
            (N, S, 12, 2) float32 positions, metres, world frame, steps of 0.4 s.
        """
        ...


def check_inputs(obs: np.ndarray, group: np.ndarray, num_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Validate and convert predictor inputs; raises ValueError with the problem named."""
    obs = np.asarray(obs, dtype=np.float32)
    if obs.ndim != 3 or obs.shape[-1] != 2 or obs.shape[1] < 2:
        raise ValueError(f"obs must be (N, T_obs >= 2, 2) metres, got shape {obs.shape}")
    if not np.isfinite(obs).all():
        raise ValueError("obs holds NaN or inf")
    group = np.asarray(group)
    if group.shape != (obs.shape[0],):
        raise ValueError(f"group must be (N,) = ({obs.shape[0]},), got shape {group.shape}")
    if int(num_samples) < 1:
        raise ValueError(f"num_samples must be >= 1, got {num_samples}")
    return obs, group.astype(np.int64)


def scenes_of_agents(scene: Scene | Sequence[Scene | None] | None, group: np.ndarray
                     ) -> tuple[list[Scene | None], np.ndarray]:
    """The distinct scenes of N agents and (N,) int64 which of them each agent lies on, from one ``scene`` for all
    of them or a sequence holding one scene per group value (group g's agents lie on ``scene[g]``; scenes are told
    apart by identity, in order of first appearance)."""
    group = np.asarray(group, np.int64)
    if scene is None or isinstance(scene, Scene):
        return [scene], np.zeros(len(group), np.int64)
    per_group = list(scene)
    if len(group) and (group.min() < 0 or group.max() >= len(per_group)):
        raise ValueError(f"scene: one scene per group value expected, got {len(per_group)} scenes for group values "
                         f"{int(group.min())}..{int(group.max())}")
    first_of: dict[int, int] = {}
    index_of_group = np.array([first_of.setdefault(id(s), len(first_of)) for s in per_group], np.int64)
    distinct = list({id(s): s for s in per_group}.values())
    return distinct, index_of_group[group] if len(group) else np.zeros(0, np.int64)


def empty_prediction(num_samples: int) -> np.ndarray:
    """(0, S, 12, 2) float32: the answer for zero agents."""
    return np.zeros((0, num_samples, T_PRED, 2), np.float32)
