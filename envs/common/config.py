"""Tunables of the crowd environments: ego robot, spawning, reward weights."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class RewardWeights:
    """Weight of each named reward part; reward = sum of weight x part (parts in ``info["reward_parts"]``)."""

    progress: float = 1.0
    """per metre the ego came closer to its goal this step (negative when it moved away)"""
    goal: float = 10.0
    """once, on the step the ego reaches its goal"""
    collision: float = -10.0
    """once, on the step the ego touches a pedestrian"""
    off_map: float = -1.0
    """per step the ego stands on a non-walkable or off-image pixel"""
    time: float = -0.1
    """per step (0.4 s)"""


@dataclass(frozen=True)
class EnvConfig:
    """Ego robot and episode settings shared by the replay and simulated environments."""

    max_speed_mps: float = 1.5
    """ego speed limit; actions are velocity vectors scaled down to this norm [m/s]"""
    ego_radius_m: float = 0.3
    """ego body radius [m]"""
    pedestrian_radius_m: float = 0.25
    """pedestrian radius used for the ego collision test in replays [m] (the simulator has its own bodies)"""
    goal_radius_m: float = 0.5
    """the goal is reached when the ego centre is this close [m]"""
    spawn_clearance_m: float = 1.0
    """least distance between the spawned ego and any pedestrian [m]"""
    goal_min_fraction: float = 0.5
    """least start-goal distance as a share of the arena diagonal ("across the scene")"""
    arena_margin_m: float = 1.0
    """replay arena = bounding box of the recorded positions grown by this margin; the ego stays inside [m]"""
    reward: RewardWeights = field(default_factory=RewardWeights)
    """weights of the reward parts"""
