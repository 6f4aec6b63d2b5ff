"""Who is at fault when the robot touches a pedestrian: a moving robot is, unless the person ran into it from behind.

The rule, judged at the moment of impact (the first instant of the step at which the bodies touch,
``st_sim.sim.sweep.Contact``; a robot that drove through a pedestrian and ended past it hit it head on), on the
robot's motion over the impact and the ``STOP_HOLD_STEPS`` whole 0.4 s steps before the impact's step (0.8 s: a
walker at 1.3 m/s covers 1 m in it, the least it needs to respond to what the robot does):

1. A robot that is **stopped** is never at fault: slower than ``STOP_SPEED_MPS`` (0.05 m/s, nuPlan's threshold for a
   stopped ego) at the impact and over the 0.8 s before. A robot that brakes to zero in front of a walker in the
   last moment has not stopped: it stepped into the walker's way too late for the walker to go round. At an
   episode's start the robot has stood.
2. Otherwise the robot is moving, and it is at fault unless the person **hit it from behind**: the contact lies in
   the robot's rear half-plane (behind its heading: the direction of its velocity or, while it crawls under the
   stop speed, of its last movement) and the person was catching it up, its velocity along that heading at least
   the fastest the robot went over the impact and the 0.8 s before (so braking in front of a follower does not make
   the follower's fault). A robot that crosses a walker's path and is clipped on its flank is at fault (it cut in,
   as an ego changing lanes does), whichever side of its centre the contact falls on; so is one creeping at
   0.06 m/s into a standing person, and one hit head on while slower than the person.
3. A pedestrian whose velocity is unknown (a replay's pedestrian who appears inside the contact distance) is never
   the robot's: it was not there to be seen.

The rule judges known motion only: a robot velocity, speed or heading that is NaN or infinite is a bug upstream
(the physics or the bookkeeping failed), never "not at fault", so it raises ``RobotMotionError`` naming what was
not finite.

nuPlan's at-fault collisions (``no_ego_at_fault_collisions``) judge the same way: a stopped ego is never at fault,
nor is one hit from behind; HuNavSim blames the robot whose heading points at the person even when it is slower.
The same rule, on each step's displacements / step (mean velocities), splits the proxemic-zone entries
(``st_sim.apps.navigation.social_metrics.zone_entries``). Wall collisions are the robot's; the env decides those.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final

import numpy as np

from st_sim.sim.exact import length
from st_sim.sim.sweep import Contact

STOP_SPEED_MPS: Final[float] = 0.05
"""slower than this the robot is not moving [m/s] (nuPlan's stopped ego): under 2 cm per 0.4 s step"""
STOP_HOLD_STEPS: Final[int] = 2
"""whole 0.4 s steps before the impact's step over which the rule reads the robot's motion (0.8 s)"""


class RobotMotionError(ValueError):
    """The robot's motion given to the at-fault rule is NaN or infinite (a bug upstream); the message names the
    value, where it is and what it holds."""


def require_finite(value: np.ndarray | float, name: str) -> None:
    """Raise ``RobotMotionError`` naming ``name`` (and the first index) if ``value`` holds a NaN or an infinity."""
    array = np.asarray(value, np.float64)
    finite = np.isfinite(array)
    if finite.all():  # the common case, on every step: no search for the culprit
        return
    first = tuple(int(i) for i in np.argwhere(~finite)[0])
    where = f" at {first}" if array.ndim else ""
    raise RobotMotionError(f"the robot's {name} is not finite{where}: {float(array[first])} (the at-fault rule judges "
                           "known motion only: a bug upstream)")


@dataclass(frozen=True, eq=False)
class RobotMotion:
    """What the rule needs of the robot's past before a step.

    Attributes:
        speeds_mps: its speeds over the ``STOP_HOLD_STEPS`` whole steps before this one (the rule's 0.8 s), newest
            last [m/s]; zeros at an episode's start (it has stood).
        heading: (2,) unit direction of its last step at or above the stop speed (zeros: it has not moved yet).
    """

    speeds_mps: tuple[float, ...] = (0.0,) * STOP_HOLD_STEPS
    heading: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        require_finite(self.speeds_mps, "speeds_mps")
        require_finite(self.heading, "heading")

    @property
    def recent_speed_mps(self) -> float:
        """The fastest of ``speeds_mps`` [m/s]."""
        return max(self.speeds_mps)

    def after_step(self, displacement_m: np.ndarray, step_s: float) -> RobotMotion:
        """The motion before the next step, after one that moved the robot by ``displacement_m`` (2,) [m] in
        ``step_s`` [s]."""
        require_finite(displacement_m, "displacement_m")
        moved_m = float(length(np.asarray(displacement_m, np.float64)))  # the same on every CPU (libm's is not)
        speeds = (*self.speeds_mps[1:], moved_m / step_s)
        if moved_m < STOP_SPEED_MPS * step_s:
            return RobotMotion(speeds, self.heading)
        return RobotMotion(speeds, np.asarray(displacement_m, np.float64) / moved_m)


def motion_before_steps(ego_xy_m: np.ndarray, step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The robot's ``RobotMotion`` before each step of a path that starts at a reset.

    Args:
        ego_xy_m: (T + 1, 2) robot positions at the step ends, the reset first [m].  step_s: seconds per step.

    Returns:
        recent_speed_mps: (T,) [m/s].  heading: (T, 2) unit vectors (zeros: not moved yet).
    """
    require_finite(ego_xy_m, "positions ego_xy_m")
    steps = np.diff(np.asarray(ego_xy_m, np.float64), axis=0)
    motion, recent, heading = RobotMotion(), np.zeros(len(steps)), np.zeros((len(steps), 2))
    for t, displacement in enumerate(steps):
        recent[t], heading[t] = motion.recent_speed_mps, motion.heading
        motion = motion.after_step(displacement, step_s)
    return recent, heading


def robot_to_blame(offset_m: np.ndarray, robot_velocity_mps: np.ndarray, person_velocity_mps: np.ndarray,
                   recent_speed_mps: np.ndarray | float, heading: np.ndarray) -> np.ndarray:
    """Whether each contact (or zone entry) is the robot's by the rule of this module, element-wise.

    Args:
        offset_m: (..., 2) person's centre minus the robot's at the impact [m].
        robot_velocity_mps, person_velocity_mps: (..., 2) their velocities then [m/s] (person NaN: unknown).
        recent_speed_mps, heading: (...) [m/s] and (..., 2), the robot's ``RobotMotion`` before the impact's step.

    Returns:
        (...) bool.

    Raises:
        RobotMotionError: the robot's velocity, recent speed or heading holds a NaN or an infinity.
    """
    for value, name in ((robot_velocity_mps, "velocity_mps"), (recent_speed_mps, "recent_speed_mps"),
                        (heading, "heading")):
        require_finite(value, name)
    offset = np.asarray(offset_m, np.float64)
    robot = np.asarray(robot_velocity_mps, np.float64)
    person = np.asarray(person_velocity_mps, np.float64)
    speed = length(robot)
    judged_speed = np.maximum(speed, recent_speed_mps)  # the fastest over the impact and the 0.8 s before it
    moving = speed >= STOP_SPEED_MPS
    with np.errstate(invalid="ignore", divide="ignore"):
        direction = np.where(moving[..., None], robot / speed[..., None], np.asarray(heading, np.float64))
    behind = offset[..., 0] * direction[..., 0] + offset[..., 1] * direction[..., 1] < 0
    catching_up = person[..., 0] * direction[..., 0] + person[..., 1] * direction[..., 1] >= judged_speed
    known = np.isfinite(person).all(axis=-1)
    return np.asarray(known & (judged_speed >= STOP_SPEED_MPS) & ~(behind & catching_up), bool)


def robot_at_fault(contact: Contact, motion: RobotMotion | None = None) -> bool:
    """True if the robot is to blame (``robot_to_blame``) for at least one of the pedestrians it touched at the
    impact of ``contact``: one person it ran into is enough, whoever else ran into it at the same instant.
    ``motion``: the robot's past before the impact's step (default: it has stood since a reset)."""
    motion = RobotMotion() if motion is None else motion
    offset = np.asarray(contact.pedestrians_xy_m, np.float64).reshape(-1, 2) - contact.robot_xy_m  # (P, 2)
    person = np.asarray(contact.pedestrians_velocity_mps, np.float64).reshape(-1, 2)
    robot = np.broadcast_to(np.asarray(contact.robot_velocity_mps, np.float64), person.shape)
    return bool(robot_to_blame(offset, robot, person, motion.recent_speed_mps, motion.heading).any())
