"""Who is at fault when the robot touches a pedestrian: the robot, unless it was (nearly) stopped or the pedestrian
came from behind it (as driving benchmarks count only at-fault collisions: a stopped ego, or one hit from behind, is
not at fault).
"""

from __future__ import annotations

from typing import Final

import numpy as np

STOPPED_MPS: Final[float] = 0.2  # a robot moving slower than this at contact is (nearly) stopped [m/s]
CONTACT_SLACK_M: Final[float] = 0.05  # pedestrians this far beyond the contact distance count as touching [m]


def robot_at_fault(robot_xy_m: np.ndarray, robot_velocity_mps: np.ndarray, pedestrians_xy_m: np.ndarray) -> bool:
    """True if the robot is at fault for touching the pedestrians at pedestrians_xy_m (P, 2) [m]: it moved at
    ``STOPPED_MPS`` or faster (robot_velocity_mps (2,), over the step of the contact) and at least one of them
    was not behind it (the robot's velocity points into the half-plane of that pedestrian's centre)."""
    velocity = np.asarray(robot_velocity_mps, np.float64)
    if np.hypot(*velocity) < STOPPED_MPS:
        return False
    offset = np.asarray(pedestrians_xy_m, np.float64).reshape(-1, 2) - np.asarray(robot_xy_m, np.float64)
    return bool((offset @ velocity >= 0.0).any())


def touching(robot_xy_m: np.ndarray, pedestrians_xy_m: np.ndarray, contact_m: float) -> np.ndarray:
    """(P,) bool: the pedestrians within contact_m + CONTACT_SLACK_M of the robot (the nearest one at least, when
    the contact was seen by the physics and none is that close now)."""
    distance = np.linalg.norm(np.asarray(pedestrians_xy_m, np.float64).reshape(-1, 2) - robot_xy_m, axis=1)
    near = distance < contact_m + CONTACT_SLACK_M
    if not near.any() and distance.size:
        near[np.argmin(distance)] = True
    return near
