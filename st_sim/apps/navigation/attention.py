"""A policy input that reads each pedestrian alone, then attends over them: any order, any number present.

The flat feature vector of ``features.encode`` is the robot's part (goal, velocity, wall rays) followed by
``NEAREST`` equal pedestrian slots (present flag first). ``PedestrianAttention`` encodes every present slot with one
shared MLP (so a pedestrian's forecast means the same in every slot), lets the robot's encoding attend over them
(multi-head attention with a learned "nobody" entry, so an empty street is a valid input) and returns the robot's
encoding beside what it attended to. Permuting the slots leaves the output unchanged; an absent slot has no effect.
As a stable-baselines3 features extractor:

    PPO("MlpPolicy", env, policy_kwargs={"features_extractor_class": PedestrianAttention,
                                         "features_extractor_kwargs": {"config": FeatureConfig(True)}})
"""

from __future__ import annotations

from typing import Any

import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn
from torch.nn import functional

from st_sim.apps.navigation.features import NEAREST, RAY_COUNT, FeatureConfig

EMBED = 64  # width of the robot's and each pedestrian's encoding [-]
HEADS = 4  # attention heads [-]


class PedestrianAttention(BaseFeaturesExtractor):
    """Features (batch, 2 EMBED) from flat observations (batch, ``config.size``); see the module docstring."""

    def __init__(self, observation_space: spaces.Box, config: FeatureConfig | dict[str, Any]):
        super().__init__(observation_space, features_dim=2 * EMBED)
        self.config = config if isinstance(config, FeatureConfig) else FeatureConfig(**config)
        if observation_space.shape != (self.config.size,):
            raise ValueError(f"PedestrianAttention: observations of shape {observation_space.shape}, expected "
                             f"({self.config.size},) for {self.config}")
        self.robot_size = 3 + RAY_COUNT
        self.slot_size = (self.config.size - self.robot_size) // NEAREST
        self.robot = nn.Sequential(nn.Linear(self.robot_size, EMBED), nn.Tanh(), nn.Linear(EMBED, EMBED), nn.Tanh())
        self.pedestrian = nn.Sequential(nn.Linear(self.slot_size, EMBED), nn.Tanh(), nn.Linear(EMBED, EMBED),
                                        nn.Tanh())
        self.nobody = nn.Parameter(torch.zeros(1, 1, EMBED))
        self.attend = nn.MultiheadAttention(EMBED, HEADS, batch_first=True)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        robot = self.robot(observations[:, :self.robot_size])  # (B, E)
        slots = observations[:, self.robot_size:].reshape(-1, NEAREST, self.slot_size)  # (B, N, F)
        keys = torch.cat([self.nobody.expand(len(slots), -1, -1), self.pedestrian(slots)], dim=1)  # (B, 1 + N, E)
        present = torch.cat([torch.ones_like(slots[:, :1, 0], dtype=torch.bool), slots[:, :, 0] >= 0.5], dim=1)
        return torch.cat([robot, self._attended(robot, keys, present)], dim=1)

    def _attended(self, robot: torch.Tensor, keys: torch.Tensor, present: torch.Tensor) -> torch.Tensor:
        """(B, E) what the robot's encoding (B, E) attends to among ``keys`` (B, 1 + N, E) where ``present`` (B, 1 + N):
        ``self.attend``'s multi-head attention with its own weights, one fused call instead of its general path (the
        same values; several times faster for one query over seven keys)."""
        weight, bias = self.attend.in_proj_weight, self.attend.in_proj_bias
        heads, width = self.attend.num_heads, EMBED // self.attend.num_heads
        query = functional.linear(robot, weight[:EMBED], bias[:EMBED]).view(-1, heads, 1, width)
        key, value = functional.linear(keys, weight[EMBED:], bias[EMBED:]).view(*keys.shape[:2], 2, heads, width) \
            .permute(2, 0, 3, 1, 4)  # each (B, heads, 1 + N, width)
        mixed = functional.scaled_dot_product_attention(query, key, value, attn_mask=present[:, None, None, :])
        return self.attend.out_proj(mixed.reshape(-1, EMBED))
