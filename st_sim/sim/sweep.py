"""Swept contact tests: do two discs that each move in a straight line during a step touch, and when first?

A step's end positions miss a head-on pass: a robot and a walker closing at 3 m/s cover 1.2 m in 0.4 s and can
end on either side of each other with no overlap at either end. Here both move linearly between their positions at
the start and at the end of the step (fraction ``t`` of the step in [0, 1]), so their offset moves linearly too,
``offset(t) = (1 - t) offset_from + t offset_to``, and the first ``t`` at which its length falls below the contact
distance is the root of a quadratic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from st_sim.sim.exact import dot, length

TOUCH_SLACK_M = 0.05  # pedestrians this far beyond the contact distance at the impact count as touched too [m]


def first_touch(offset_from_m: np.ndarray, offset_to_m: np.ndarray, reach_m: float | np.ndarray) -> np.ndarray:
    """Fraction of the step at which two linearly moving discs first come closer than ``reach_m``.

    Args:
        offset_from_m: (..., 2) position of one disc minus the other's at the start of the step [m].
        offset_to_m: (..., 2) the same at the end of the step [m].
        reach_m: centre distance at which they touch [m] (scalar or broadcastable to (...)).

    Returns:
        (...) float64 in [0, 1]: 0 if they already touch at the start; NaN if they never touch during the step.
    """
    start = np.asarray(offset_from_m, np.float64)
    change = np.asarray(offset_to_m, np.float64) - start
    reach = np.asarray(reach_m, np.float64)
    # |start + t change|^2 = reach^2  <=>  a t^2 + 2 b t + c = 0
    a = dot(change, change)
    b = dot(start, change)
    c = dot(start, start) - reach ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        root = (-b - np.sqrt(np.maximum(b * b - a * c, 0.0))) / a  # the earlier of the two crossings
    touch = np.where(c < 0, 0.0, np.where((a > 0) & (b < 0) & (b * b - a * c > 0) & (root <= 1.0), root, np.nan))
    return np.asarray(touch, np.float64)


def closest_approach(offset_from_m: np.ndarray, offset_to_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least centre distance of two linearly moving discs during the step, and when.

    Args:
        offset_from_m, offset_to_m: (..., 2) offsets at the start and at the end of the step [m].

    Returns:
        distance_m: (...) least distance [m].  t: (...) fraction of the step in [0, 1] at which it occurs.
    """
    start = np.asarray(offset_from_m, np.float64)
    change = np.asarray(offset_to_m, np.float64) - start
    a = dot(change, change)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(a > 0, np.clip(-dot(start, change) / a, 0.0, 1.0), 0.0)
    closest = start + t[..., None] * change
    return length(closest), t


@dataclass(frozen=True, eq=False)
class Contact:
    """The first moment in a step at which the robot touches pedestrians, and the bodies' state then.

    Attributes:
        time_s: when, in seconds after the start of the step (0.4 s steps).
        robot_xy_m: (2,) robot position at the impact [m].  robot_velocity_mps: (2,) its velocity then [m/s].
        pedestrian_ids: (P,) ids of the pedestrians touching it then (P >= 1).
        pedestrians_xy_m: (P, 2) their positions at the impact [m].
        pedestrians_velocity_mps: (P, 2) their velocities then [m/s]; NaN rows: unknown (a replay's pedestrian who
            appears inside the contact distance).
    """

    time_s: float
    robot_xy_m: np.ndarray
    robot_velocity_mps: np.ndarray
    pedestrian_ids: np.ndarray
    pedestrians_xy_m: np.ndarray
    pedestrians_velocity_mps: np.ndarray


def first_contact(robot_from_m: np.ndarray, robot_to_m: np.ndarray, peds_from_m: np.ndarray, peds_to_m: np.ndarray,
                  ids: np.ndarray, reach_m: float, duration_s: float, start_s: float = 0.0) -> Contact | None:
    """The robot's first contact with the pedestrians while everybody moves in a straight line, or None.

    Args:
        robot_from_m, robot_to_m: (2,) robot position at the start and end of the interval [m].
        peds_from_m, peds_to_m: (P, 2) pedestrian positions at the start and end of the interval [m].
        ids: (P,) pedestrian ids.  reach_m: centre distance below which robot and pedestrian touch [m]; those
            within ``TOUCH_SLACK_M`` more of the robot at the impact count as touched too.
        duration_s: length of the interval [s].  start_s: its start, in seconds after the start of the step.
    """
    robot_from_m, robot_to_m = np.asarray(robot_from_m, np.float64), np.asarray(robot_to_m, np.float64)
    peds_from_m = np.asarray(peds_from_m, np.float64).reshape(-1, 2)
    peds_to_m = np.asarray(peds_to_m, np.float64).reshape(-1, 2)
    touch = first_touch(peds_from_m - robot_from_m, peds_to_m - robot_to_m, reach_m)
    if np.isnan(touch).all():
        return None
    t = float(np.nanmin(touch))
    robot_m = robot_from_m + t * (robot_to_m - robot_from_m)
    peds_m = peds_from_m + t * (peds_to_m - peds_from_m)
    near = length(peds_m - robot_m) < reach_m + TOUCH_SLACK_M
    near |= touch == t  # the first one touches by definition, whatever the rounding
    return Contact(start_s + t * duration_s, robot_m, (robot_to_m - robot_from_m) / duration_s,
                   np.asarray(ids)[near], peds_m[near], (peds_to_m[near] - peds_from_m[near]) / duration_s)
