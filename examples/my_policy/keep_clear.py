"""A hand-written policy: full speed toward the goal, pushed away from where people will be in the next 1.2 s.

It follows STCrowd's planner protocol (``reset()``, ``act(obs) -> (2,)`` velocity [m/s]) and reads nothing but the
observation: the robot's state (``obs["ego"]``: x, y, vx, vy, goal x, goal y), the pedestrians' last positions
(``history``, ``history_mask``) and, when the env forecasts, the mean of their predicted futures (``futures``,
``futures_mask``).

    python -m st_sim benchmark --policy examples.my_policy.keep_clear:KeepClear --suite val --episodes 20 \\
        --out runs/bench/keep-clear-val
"""

from __future__ import annotations

import numpy as np

MAX_SPEED_MPS = 1.5  # the envs' speed limit [m/s]
LOOKAHEAD_STEPS = 3  # predicted steps the policy keeps clear of (3 x 0.4 s) [-]
PUSH_RANGE_M = 2.0  # people closer than this (centre distance) push the robot away [m]
PUSH_GAIN = 1.5  # how hard [-]
SLOW_RANGE_M = 1.0  # someone this close ahead makes the robot slow down [m]


class KeepClear:
    """Goal-seeking with a push away from the predicted positions of the people nearby.

    Args:
        world: what STCrowd knows of the env (unused here: this policy needs only the observation).
        use_predictions: read the forecasts (True) or the people's last positions only (False).
    """

    def __init__(self, world: object = None, use_predictions: bool = True):
        self.use_predictions = use_predictions

    def reset(self) -> None:
        """Nothing to forget between episodes."""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame."""
        ego = obs["ego"].astype(np.float64)
        to_goal = ego[4:6] - ego[:2]
        distance_m = float(np.linalg.norm(to_goal))
        if distance_m < 1e-6:
            return np.zeros(2, np.float32)
        heading = to_goal / distance_m
        away = ego[:2] - self._people_ahead(obs)  # (P, 2) from each person to the robot [m]
        gap_m = np.linalg.norm(away, axis=1)
        near = (gap_m > 1e-6) & (gap_m < PUSH_RANGE_M)
        strength = PUSH_GAIN * (PUSH_RANGE_M - gap_m[near]) / PUSH_RANGE_M
        direction = heading + (strength[:, None] * away[near] / gap_m[near, None]).sum(axis=0)
        direction /= max(float(np.linalg.norm(direction)), 1e-6)
        speed = min(MAX_SPEED_MPS, distance_m / 0.4)  # arrive on the goal, not past it
        if ((gap_m < SLOW_RANGE_M) & (away @ heading < 0)).any():  # someone close in front
            speed *= 0.3
        return (direction * speed).astype(np.float32)

    def _people_ahead(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(P, 2) where each person present will be ``LOOKAHEAD_STEPS`` steps on (their last position without a
        forecast) [m]."""
        present = obs["history_mask"][:, -1]
        xy = obs["history"][present, -1].astype(np.float64)
        if self.use_predictions:
            predicted = obs["futures_mask"][present]
            mean = obs["futures"][present][:, :, LOOKAHEAD_STEPS - 1].mean(axis=1)
            xy = np.where(predicted[:, None], mean, xy)
        return xy
