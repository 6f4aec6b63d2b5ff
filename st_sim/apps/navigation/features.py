"""What the learned policy sees and does: a flat, robot-centred feature vector and a velocity in the path frame.

The frame's x axis points along the shortest walkable path to the goal (``Terrain.direction_to``), y to its
left. Features, all scaled to about [-1, 1]:
- ego (3): distance to the goal / 10 m (at most 2), velocity along x and y / speed limit;
- walls (16): free distance along 16 rays from the ego's centre until its body would touch a wall, / 3 m;
- pedestrians (6 nearest within the sensor range, by distance; absent slots all zero): present flag, position / 5 m
  and velocity / speed limit relative to the ego (5 each); with predictions also the mean predicted position over the
  samples 0.8, 1.6 and 3.2 s ahead / 5 m (6) and the samples' spread (root mean square distance from that
  mean) 1.6 and 3.2 s ahead / 2 m (2); with ``closest_approach`` also the forecast's summary for the robot: the least
  distance between the mean predicted path and the robot's course held at its velocity over the 4.8 s forecast / 5 m,
  and when / 4.8 s (2).
The action (2,) in [-1, 1] is the velocity along x and y in speed limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from replays.constants import STEP_S, T_PRED
from st_sim.apps.navigation.pedestrians import pedestrians_of
from st_sim.apps.navigation.world import NavWorld, world_of

GOAL_SCALE_M = 10.0  # goal distance unit [m]
RAY_COUNT = 16  # wall rays, evenly spaced from the path direction [-]
RAY_RANGE_M = 3.0  # rays see this far [m]
RAY_STEP_M = 0.1  # ray sampling interval [m]
NEAREST = 6  # pedestrians in the features [-]
POSITION_SCALE_M = 5.0  # pedestrian position unit [m]
SPREAD_SCALE_M = 2.0  # prediction spread unit [m]
PREDICTED_STEPS = (2, 4, 8)  # future steps (0.4 s) whose mean predicted position is a feature
SPREAD_STEPS = (4, 8)  # future steps whose sample spread is a feature


@dataclass(frozen=True)
class FeatureConfig:
    """Which features the policy gets (saved with the policy)."""

    use_predictions: bool = True
    """include the predicted futures (False: positions and velocities only)"""
    sensor_range_m: float = math.inf
    """pedestrians whose centre is farther from the ego's are left out [m] (train in an env with the same
    ``EnvConfig.sensor_range_m``, which then forecasts only the ones the policy sees)"""
    closest_approach: bool = False
    """with predictions, also each pedestrian's predicted closest approach to the robot's course and its time"""

    @property
    def size(self) -> int:
        """Length of the feature vector."""
        return 3 + RAY_COUNT + NEAREST * self.slot_size

    @property
    def slot_size(self) -> int:
        """Features per pedestrian slot."""
        if not self.use_predictions:
            return 5
        return 5 + 2 * len(PREDICTED_STEPS) + len(SPREAD_STEPS) + (2 if self.closest_approach else 0)


def path_frame(obs: dict[str, np.ndarray], world: NavWorld) -> np.ndarray:
    """(2, 2) rows = unit x (along the path to the goal) and y (to its left), world frame."""
    x_axis = world.terrain.direction_to(obs["ego"][:2].astype(np.float64), obs["ego"][4:6], world.wall_clearance_m)
    if not x_axis.any():
        x_axis = np.array([1.0, 0.0])
    return np.stack([x_axis, [-x_axis[1], x_axis[0]]])


def encode(obs: dict[str, np.ndarray], world: NavWorld, cfg: FeatureConfig, frame: np.ndarray | None = None
           ) -> np.ndarray:
    """(cfg.size,) float32 features of an STCrowd observation (see the module docstring); ``frame``: its
    ``path_frame`` if already computed."""
    frame = path_frame(obs, world) if frame is None else frame
    ego_xy, ego_v, goal = (obs["ego"][i:i + 2].astype(np.float64) for i in (0, 2, 4))
    ego = [min(np.linalg.norm(goal - ego_xy) / GOAL_SCALE_M, 2.0), *(frame @ ego_v / world.max_speed_mps)]

    angles = np.arange(RAY_COUNT) * 2 * np.pi / RAY_COUNT
    rays = np.cos(angles)[:, None] * frame[0] + np.sin(angles)[:, None] * frame[1]  # (R, 2)
    reach = np.arange(1, int(RAY_RANGE_M / RAY_STEP_M) + 1) * RAY_STEP_M  # (D,)
    blocked = world.terrain.clearance_at(ego_xy + rays[:, None] * reach[:, None]) <= world.wall_clearance_m  # (R, D)
    free_m = np.where(blocked.any(axis=1), reach[np.argmax(blocked, axis=1)] - RAY_STEP_M, RAY_RANGE_M)

    horizon = T_PRED if cfg.use_predictions and cfg.closest_approach else max(PREDICTED_STEPS)
    peds = pedestrians_of(obs, horizon, cfg.use_predictions)
    slots = np.zeros((NEAREST, cfg.slot_size))
    distance_m = np.linalg.norm(peds.xy_m - ego_xy, axis=1)
    nearest = np.argsort(distance_m)[:NEAREST]
    nearest = nearest[distance_m[nearest] <= cfg.sensor_range_m]
    for slot, p in enumerate(nearest):
        row = [1.0, *(frame @ (peds.xy_m[p] - ego_xy) / POSITION_SCALE_M),
               *(frame @ (peds.velocity_mps[p] - ego_v) / world.max_speed_mps)]
        if cfg.use_predictions:
            samples = peds.futures_m[p]  # (S, H, 2)
            mean = samples.mean(axis=0)  # (H, 2)
            spread = np.sqrt(((samples - mean) ** 2).sum(axis=-1).mean(axis=0))  # (H,)
            row += [*(((mean[[s - 1 for s in PREDICTED_STEPS]] - ego_xy) @ frame.T) / POSITION_SCALE_M).ravel(),
                    *(spread[[s - 1 for s in SPREAD_STEPS]] / SPREAD_SCALE_M)]
            if cfg.closest_approach:
                course = ego_xy + STEP_S * np.arange(1, len(mean) + 1)[:, None] * ego_v  # (H, 2)
                gap = np.linalg.norm(mean - course, axis=-1)
                row += [gap.min() / POSITION_SCALE_M, (np.argmin(gap) + 1) / len(mean)]
        slots[slot] = row
    return np.concatenate([ego, free_m / RAY_RANGE_M, slots.ravel()]).astype(np.float32)


def drop_predictions(features: np.ndarray, cfg: FeatureConfig = FeatureConfig(True)) -> np.ndarray:
    """(..., cfg.size) features with predictions -> (..., FeatureConfig(False).size): the same observation's
    features without the prediction columns (each pedestrian slot keeps its first 5 values)."""
    slots = features[..., 3 + RAY_COUNT:].reshape(*features.shape[:-1], NEAREST, cfg.slot_size)[..., :5]
    return np.concatenate([features[..., :3 + RAY_COUNT], slots.reshape(*features.shape[:-1], -1)], axis=-1)


def to_velocity(action: np.ndarray, obs: dict[str, np.ndarray], world: NavWorld, frame: np.ndarray | None = None
                ) -> np.ndarray:
    """(2,) float32 world-frame velocity [m/s] of a policy action (2,) in [-1, 1] (path frame, speed limits);
    ``frame``: the observation's ``path_frame`` if already computed."""
    frame = path_frame(obs, world) if frame is None else frame
    return (np.clip(action, -1.0, 1.0) @ frame * world.max_speed_mps).astype(np.float32)


class NavFeatures(gym.Wrapper):
    """An STCrowd env seen through ``encode``: Box observations and path-frame actions in [-1, 1]."""

    def __init__(self, env: gym.Env, cfg: FeatureConfig):
        super().__init__(env)
        self.cfg, self.world = cfg, world_of(env)
        self.observation_space = spaces.Box(-np.inf, np.inf, (cfg.size,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self._obs: dict[str, np.ndarray] | None = None
        self._frame: np.ndarray | None = None  # path_frame of _obs, for the next action

    def reset(self, **kwargs):
        self._obs, info = self.env.reset(**kwargs)
        return self._encode(), info

    def step(self, action: np.ndarray):
        velocity = to_velocity(action, self._obs, self.world, self._frame)
        self._obs, reward, terminated, truncated, info = self.env.step(velocity)
        return self._encode(), reward, terminated, truncated, info

    def _encode(self) -> np.ndarray:
        self._frame = path_frame(self._obs, self.world)
        return encode(self._obs, self.world, self.cfg, self._frame)
