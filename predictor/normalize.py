"""Agent frames: translate to the last observed point, rotate the recent heading onto +x, scale by speed.

Agents slower than ``SLOW_SPEED_M`` per step form their own population: heading and speed are noise for
them, so they are rotated but never scaled (their Singular space and anchors are fitted separately).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SLOW_SPEED_M = 0.3  # metres per 0.4 s step; below this an agent belongs to the slow population
MIN_HEADING_M = 1e-3  # displacement below which the heading is undefined (no rotation)


@dataclass(frozen=True)
class AgentFrame:
    """Per-agent transform world -> agent frame: ``p_agent = R(-angle) (p_world - origin) / scale``.

    Attributes:
        origin_m: (N, 2) last observed position, metres.
        angle_rad: (N,) heading of the recent displacement.
        scale_m: (N,) metres per agent-frame unit (recent speed per step, or 1 for slow agents).
        slow: (N,) bool, the slow population.
    """

    origin_m: np.ndarray
    angle_rad: np.ndarray
    scale_m: np.ndarray
    slow: np.ndarray

    def to_agent(self, xy_m: np.ndarray) -> np.ndarray:
        """(N, ..., 2) world metres -> agent frame (same shape)."""
        extra = (slice(None),) + (None,) * (xy_m.ndim - 2)
        rel = xy_m - self.origin_m[extra]
        return rotate(rel, -self.angle_rad[extra]) / self.scale_m[extra][..., None]

    def to_world(self, xy: np.ndarray) -> np.ndarray:
        """(N, ..., 2) agent frame -> world metres (same shape)."""
        extra = (slice(None),) + (None,) * (xy.ndim - 2)
        return rotate(xy * self.scale_m[extra][..., None], self.angle_rad[extra]) + self.origin_m[extra]

    def subset(self, mask: np.ndarray) -> AgentFrame:
        """Frames of the agents where ``mask`` (N,) is true."""
        return AgentFrame(self.origin_m[mask], self.angle_rad[mask], self.scale_m[mask], self.slow[mask])


def rotate(xy: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    """Rotate (..., 2) vectors counter-clockwise by (...) angles [rad]."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], axis=-1)


def agent_frames(obs_m: np.ndarray, scale: bool = True, slow_speed_m: float = SLOW_SPEED_M,
                 slow_scale_floor_m: float = 0.0) -> AgentFrame:
    """Frames for observed paths (N, T_obs, 2) metres.

    Heading: last minus third-last point (last minus second-last when T_obs = 2). Scale: mean step
    length over that span, for agents at or above ``slow_speed_m`` per step when ``scale`` is set. Agents
    under MIN_HEADING_M per step are slow at any threshold.
    With ``slow_scale_floor_m`` > 0, slow agents are scaled too, by max(speed, floor) [m per step].
    """
    obs_m = np.asarray(obs_m, dtype=np.float64)
    back = 2 if obs_m.shape[1] >= 3 else 1
    step = (obs_m[:, -1] - obs_m[:, -1 - back]) / back  # (N, 2) metres per step
    speed = np.linalg.norm(step, axis=-1)
    angle = np.where(speed > MIN_HEADING_M, np.arctan2(step[:, 1], step[:, 0]), 0.0)
    slow = speed < max(slow_speed_m, MIN_HEADING_M)  # without a heading there is no speed to scale by either
    scale_m = np.where(slow | (not scale), 1.0, speed)
    if scale and slow_scale_floor_m > 0:
        scale_m = np.where(slow, np.maximum(speed, slow_scale_floor_m), scale_m)
    return AgentFrame(obs_m[:, -1].copy(), angle, scale_m, slow)
