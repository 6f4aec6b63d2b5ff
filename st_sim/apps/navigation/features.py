"""What the learned policy sees and does: a flat, robot-centred feature vector and a velocity in the path frame.

The frame's x axis points along the shortest walkable path to the goal (``Terrain.direction_to``), y to its
left. Features, all scaled to about [-1, 1]:
- ego (3): distance to the goal / 10 m (at most 2), velocity along x and y / speed limit;
- walls (16): free distance along 16 rays from the ego's centre until its body would touch a wall, / 3 m (the
  readings of the fixed-size view, ``envs.view.wall_readings_m``);
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

from envs.view import RAY_COUNT, RAY_RANGE_M, frames_along_path, nearest_pedestrians, to_world, wall_readings_m
from replays.constants import STEP_S, T_PRED
from st_sim.apps.navigation.world import NavWorld, world_of

GOAL_SCALE_M = 10.0  # goal distance unit [m]
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
    return path_frames(obs["ego"][None], world)[0]


def path_frames(ego: np.ndarray, world: NavWorld) -> np.ndarray:
    """(B, 2, 2) ``path_frame`` of B observations from their ego rows ``obs["ego"]`` (B, 6)."""
    return frames_along_path(ego, world.terrain, world.wall_clearance_m)


def encode(obs: dict[str, np.ndarray], world: NavWorld, cfg: FeatureConfig, frame: np.ndarray | None = None
           ) -> np.ndarray:
    """(cfg.size,) float32 features of an STCrowd observation (see the module docstring); ``frame``: its
    ``path_frame`` if already computed."""
    return encode_batch({key: value[None] for key, value in obs.items()}, world, cfg,
                        None if frame is None else frame[None])[0]


def encode_batch(obs: dict[str, np.ndarray], world: NavWorld, cfg: FeatureConfig, frames: np.ndarray | None = None
                 ) -> np.ndarray:
    """(B, cfg.size) float32 features of B observations batched as a vector env batches them (every array with a
    leading axis B); ``frames``: their ``path_frames`` (B, 2, 2) if already computed. Row b equals ``encode`` of
    observation b."""
    frames = path_frames(obs["ego"], world) if frames is None else frames
    ego_xy, ego_v, goal = (obs["ego"][:, i:i + 2].astype(np.float64) for i in (0, 2, 4))
    batch = len(ego_xy)
    ego = np.concatenate([np.minimum(np.linalg.norm(goal - ego_xy, axis=1) / GOAL_SCALE_M, 2.0)[:, None],
                          np.einsum("bij,bj->bi", frames, ego_v) / world.max_speed_mps], axis=1)

    free_m = wall_readings_m(world.terrain, ego_xy, frames, world.wall_clearance_m, RAY_COUNT)  # (B, RAY_COUNT)

    slots = np.zeros((batch, NEAREST, cfg.slot_size))
    nearest, sensed = nearest_pedestrians(obs, ego_xy, cfg.sensor_range_m, NEAREST)  # (B, NEAREST) rows, bool
    rows = np.arange(batch)[:, None]
    xy = obs["history"][rows, nearest, -1].astype(np.float64)  # (B, NEAREST, 2)
    seen_before = obs["history_mask"][rows, nearest, -2] if obs["history"].shape[2] > 1 else np.zeros(xy.shape[:2],
                                                                                                      bool)
    step = np.where(seen_before[..., None], xy - obs["history"][rows, nearest, -2], 0.0)
    slots[..., 0] = 1.0
    slots[..., 1:3] = np.einsum("bij,bnj->bni", frames, xy - ego_xy[:, None]) / POSITION_SCALE_M
    slots[..., 3:5] = np.einsum("bij,bnj->bni", frames, step / STEP_S - ego_v[:, None]) / world.max_speed_mps
    if cfg.use_predictions:
        horizon = T_PRED if cfg.closest_approach else max(PREDICTED_STEPS)
        ahead = np.arange(1, horizon + 1)[:, None]  # (H, 1)
        walking = xy[:, :, None] + ahead * step[:, :, None]  # (B, NEAREST, H, 2): constant velocity
        samples = np.where(obs["futures_mask"][rows, nearest][..., None, None, None],
                           obs["futures"][rows, nearest, :, :horizon].astype(np.float64), walking[:, :, None])
        mean = samples.mean(axis=2)  # (B, NEAREST, H, 2)
        spread = np.sqrt(((samples - mean[:, :, None]) ** 2).sum(axis=-1).mean(axis=2))  # (B, NEAREST, H)
        future = np.einsum("bij,bnhj->bnhi", frames, mean[:, :, [s - 1 for s in PREDICTED_STEPS]] - ego_xy[:, None,
                                                                                                          None])
        columns = 5 + 2 * len(PREDICTED_STEPS)
        slots[..., 5:columns] = future.reshape(batch, NEAREST, -1) / POSITION_SCALE_M
        slots[..., columns:columns + len(SPREAD_STEPS)] = spread[..., [s - 1 for s in SPREAD_STEPS]] / SPREAD_SCALE_M
        if cfg.closest_approach:
            course = ego_xy[:, None] + STEP_S * ahead * ego_v[:, None]  # (B, H, 2)
            gap = np.linalg.norm(mean - course[:, None], axis=-1)  # (B, NEAREST, H)
            slots[..., -2] = gap.min(axis=-1) / POSITION_SCALE_M
            slots[..., -1] = (np.argmin(gap, axis=-1) + 1) / horizon
    slots[~sensed] = 0.0
    return np.concatenate([ego, free_m / RAY_RANGE_M, slots.reshape(batch, -1)], axis=1).astype(np.float32)


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
    return to_velocities(np.asarray(action)[None], frame[None], world.max_speed_mps)[0]


def to_velocities(actions: np.ndarray, frames: np.ndarray, max_speed_mps: float) -> np.ndarray:
    """(B, 2) float32 world-frame velocities [m/s] of B policy actions (B, 2) in [-1, 1] in their path frames
    (B, 2, 2)."""
    return (to_world(np.clip(actions, -1.0, 1.0), frames) * max_speed_mps).astype(np.float32)


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
