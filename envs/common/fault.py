"""Who is at fault when the robot touches a pedestrian: whoever closed the gap, judged at the moment of impact.

Each body's **approach speed** is its velocity component toward the other, along the line between their centres
(negative: moving away). The robot closed the gap when its approach speed is at least the person's and above
``APPROACH_FLOOR_MPS``; otherwise the person did (a person walked into the robot). So a robot standing, creeping or
backing away is never at fault, and a robot driving into a standing person always is. SEANavBench and HuNavSim
likewise split collisions into robot-on-person and person-on-robot by who moved into whom (HuNavSim from the two
bodies' headings toward each other and their speeds; here the velocity components along the line decide).

The moment of impact is the first instant of the step at which the bodies touch (``st_sim.sim.sweep.Contact``), not
the end of the step: a robot that drove through a pedestrian and ended past it hit it head on. The same comparison,
on each step's displacements / step (mean velocities), splits the proxemic-zone entries
(``st_sim.apps.navigation.social_metrics.zone_entries``). Wall collisions are the robot's; the env decides those.
"""

from __future__ import annotations

from typing import Final

import numpy as np

from st_sim.sim.sweep import Contact

APPROACH_FLOOR_MPS: Final[float] = 0.1
"""the robot closes a gap only faster than this [m/s]: under 4 cm per 0.4 s step it is (nearly) standing"""


def approach_speeds(offset_m: np.ndarray, robot_velocity_mps: np.ndarray,
                    person_velocity_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each body's velocity component toward the other, along the line between their centres.

    Args:
        offset_m: (..., 2) person's centre minus the robot's [m].
        robot_velocity_mps, person_velocity_mps: (..., 2) velocities [m/s] (NaN: unknown).

    Returns:
        (robot toward person, person toward robot), each (...) [m/s]; NaN where the velocity is unknown or the
        centres coincide (no line between them).
    """
    offset = np.asarray(offset_m, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        line = offset / np.linalg.norm(offset, axis=-1, keepdims=True)  # robot -> person, unit
    robot = np.sum(np.asarray(robot_velocity_mps, np.float64) * line, axis=-1)
    person = -np.sum(np.asarray(person_velocity_mps, np.float64) * line, axis=-1)
    return robot, person


def robot_closed_gap(robot_approach_mps: np.ndarray | float, person_approach_mps: np.ndarray | float) -> np.ndarray:
    """Whether the robot, not the person, closed the gap: its approach speed is at least the person's and above
    ``APPROACH_FLOOR_MPS`` (element-wise over broadcastable arrays [m/s]).

    A NaN approach (a person whose velocity is unknown, such as one who appeared inside the contact distance, or no
    line between the centres) is never the robot's: who cannot be shown to have closed the gap is not blamed.
    """
    robot = np.asarray(robot_approach_mps, np.float64)
    person = np.asarray(person_approach_mps, np.float64)
    return np.asarray((robot > APPROACH_FLOOR_MPS) & (robot >= person), bool)


def robot_at_fault(contact: Contact) -> bool:
    """True if the robot closed the gap (``robot_closed_gap``) on at least one of the pedestrians it touched at the
    impact of ``contact``: one person it drove into is enough, whoever else walked into it at the same instant. A
    pedestrian whose velocity is unknown (NaN) walked in."""
    offset = np.asarray(contact.pedestrians_xy_m, np.float64).reshape(-1, 2) - contact.robot_xy_m  # (P, 2)
    robot_in, person_in = approach_speeds(offset, contact.robot_velocity_mps,
                                          np.asarray(contact.pedestrians_velocity_mps, np.float64).reshape(-1, 2))
    return bool(robot_closed_gap(robot_in, person_in).any())
