"""Social-navigation figures of one episode from the robot's and the pedestrians' positions.

Body gaps and Hall's zones, the least time to collision, zone entries split by who moved into whom, group spaces
and the robot's heading changes; each is NumPy over all steps and pedestrians at once. The arrays follow one
episode: T steps, T + 1 states (the reset included), N pedestrian columns (one per pedestrian id, NaN where the
pedestrian is absent).

Distances between people are **body gaps**: centre distance minus both radii. Hall's zones (0.45, 1.2, 3.6 m) are
centre distances in Hall's work; here they are gaps, because the robot (0.3 m) touches a pedestrian (0.25 m) at a
centre distance of 0.55 m, which would swallow the whole intimate zone.
"""

from __future__ import annotations

from typing import Final

import numpy as np

from envs.common.fault import motion_before_steps, robot_to_blame

INTIMATE_M: Final[float] = 0.45  # Hall's intimate zone ends at this body gap [m]
PERSONAL_M: Final[float] = 1.2  # ... the personal zone [m]
SOCIAL_M: Final[float] = 3.6  # ... the social zone; beyond it lies the public zone [m]
ZONES: Final[tuple[str, ...]] = ("intimate", "personal", "social", "public")  # nearest to farthest
STOPPED_MPS: Final[float] = 0.1
"""the robot is not moving below this speed [m/s]: under 4 cm per 0.4 s step is no real progress (HuNavSim tests
0.001 m/s on the robot's own velocity); steps this short have no heading either"""


def body_gaps_m(ego_xy_m: np.ndarray, pedestrians_xy_m: np.ndarray, contact_m: float) -> np.ndarray:
    """Gap between the robot's body and each pedestrian's.

    Args:
        ego_xy_m: (T + 1, 2) robot positions [m].  pedestrians_xy_m: (T + 1, N, 2) [m], NaN where absent.
        contact_m: sum of the two radii [m].

    Returns:
        (T + 1, N) gaps [m] (negative: the bodies overlap), NaN where the pedestrian is absent.
    """
    return np.linalg.norm(pedestrians_xy_m - ego_xy_m[:, None], axis=-1) - contact_m


def nearest_gap_m(gaps_m: np.ndarray) -> np.ndarray:
    """(T + 1,) the least of each state's (T + 1, N) gaps [m]; inf where nobody is present."""
    return np.fmin.reduce(gaps_m, axis=1, initial=np.inf)


def zone_shares(nearest_m: np.ndarray) -> dict[str, float]:
    """Share of the (S,) states whose nearest gap lies in each of ``ZONES`` (< 0.45, [0.45, 1.2), [1.2, 3.6),
    >= 3.6 m or nobody); the shares sum to 1 (all 0 for S = 0)."""
    zone = np.searchsorted([INTIMATE_M, PERSONAL_M, SOCIAL_M], nearest_m, side="right")
    counts = np.bincount(zone, minlength=len(ZONES))
    return {name: float(count / max(len(nearest_m), 1)) for name, count in zip(ZONES, counts, strict=True)}


def min_time_to_collision_s(ego_xy_m: np.ndarray, ego_velocity_mps: np.ndarray, pedestrians_xy_m: np.ndarray,
                            contact_m: float, step_s: float) -> float:
    """Least time until the robot's body would touch a pedestrian's, both keeping their velocities.

    At each state after a step, each pedestrian present then and one step before moves at its velocity over that
    step (a pedestrian's first state has none and is skipped), the robot at its reported velocity. Touching
    bodies give 0.

    Args:
        ego_xy_m: (T + 1, 2) [m].  ego_velocity_mps: (T + 1, 2) [m/s].
        pedestrians_xy_m: (T + 1, N, 2) [m], NaN where absent.  contact_m: sum of the radii [m].  step_s: [s].

    Returns:
        The least time to collision over the episode [s]; NaN if no pair was ever on a collision course.
    """
    offset = pedestrians_xy_m[1:] - ego_xy_m[1:, None]  # (T, N, 2) robot -> pedestrian [m]
    closing = np.diff(pedestrians_xy_m, axis=0) / step_s - ego_velocity_mps[1:, None]  # relative velocity [m/s]
    # |offset + closing * t| = contact_m:  a t^2 + 2 b t + c = 0
    a = np.sum(closing ** 2, axis=-1)
    b = np.sum(offset * closing, axis=-1)
    c = np.sum(offset ** 2, axis=-1) - contact_m ** 2
    disc = b ** 2 - a * c
    ttc = np.full(c.shape, np.inf)
    course = (b < 0) & (disc >= 0)  # approaching, and the paths come within contact (False where NaN)
    ttc[course] = c[course] / (np.sqrt(disc[course]) - b[course])  # the smaller root, without cancellation
    ttc[(c <= 0) & np.isfinite(a)] = 0.0
    least = float(ttc.min(initial=np.inf))
    return least if np.isfinite(least) else float("nan")


def zone_entries(ego_xy_m: np.ndarray, pedestrians_xy_m: np.ndarray, gaps_m: np.ndarray, limit_m: float,
                 step_s: float) -> tuple[int, int]:
    """Entries into the zone of gaps under ``limit_m``, split by who moved in.

    An entry is a pedestrian's gap going from >= limit_m at one state to < limit_m at the next. It is the robot's
    when the at-fault rule of collisions (``envs.common.fault``) blames the robot for it, judged on the step's mean
    velocities (displacements / step) along the line between the bodies at the step's start: the robot was moving
    (or stopped under 0.8 s before) and the pedestrian did not catch it up from behind; else it is the pedestrian's.
    A pedestrian who appears already inside has walked in: the pedestrian's entry. At the reset nobody has entered.

    Args:
        ego_xy_m: (T + 1, 2) [m].  pedestrians_xy_m: (T + 1, N, 2) [m], NaN where absent.
        gaps_m: (T + 1, N) their ``body_gaps_m``.  limit_m: the zone's outer gap [m].  step_s: seconds per step.

    Returns:
        (robot-on-person entries, person-on-robot entries).
    """
    inside = gaps_m < limit_m  # False where absent
    entered = inside[1:] & ~inside[:-1]  # (T, N), appearances inside included
    offset = pedestrians_xy_m[:-1] - ego_xy_m[:-1, None]  # robot -> pedestrian at each step's start, (T, N, 2)
    recent_mps, heading = motion_before_steps(ego_xy_m, step_s)
    by_robot = entered & robot_to_blame(offset, np.diff(ego_xy_m, axis=0)[:, None] / step_s,
                                        np.diff(pedestrians_xy_m, axis=0) / step_s,  # NaN for who just appeared
                                        recent_mps[:, None], heading[:, None])
    return int(by_robot.sum()), int((entered & ~by_robot).sum())


def path_irregularity_rad(ego_xy_m: np.ndarray, min_step_m: float) -> float:
    """Total absolute heading change of the robot's motion [rad]: 0 on a straight line, 2 pi per full circle.

    Headings are those of the steps at least ``min_step_m`` long; a turn across standstill steps counts between
    the moving steps either side (turning on the spot is a heading change too). Each change is wrapped to
    [-pi, pi] before its absolute value is summed.

    Args:
        ego_xy_m: (T + 1, 2) [m].  min_step_m: shortest step that has a heading [m].
    """
    steps = np.diff(ego_xy_m, axis=0)
    moving = steps[np.linalg.norm(steps, axis=1) >= min_step_m]
    heading = np.arctan2(moving[:, 1], moving[:, 0])
    return float(np.abs(np.angle(np.exp(1j * np.diff(heading)))).sum())


def group_spaces(ego_xy_m: np.ndarray, pedestrians_xy_m: np.ndarray,
                 groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Whether the robot's centre lies inside each group's space.

    A group's space, at a state where at least two of its members are present, is the disc at their centroid whose
    radius is the farthest member's distance from it (for two people: the disc with them at either end of a
    diameter, the space between them).

    Args:
        ego_xy_m: (T + 1, 2) [m].  pedestrians_xy_m: (T + 1, N, 2) [m], NaN where absent.
        groups: (N,) int group id of each column; -1 walks alone.

    Returns:
        inside: (T + 1, K) bool, the robot inside group k's space (K groups with an id >= 0).
        exists: (T + 1, K) bool, group k has a space (two or more members present).
    """
    grouped = groups >= 0
    ids = np.unique(groups[grouped])
    member = groups[grouped][None, :] == ids[:, None]  # (K, G) over the grouped columns
    xy = pedestrians_xy_m[:, grouped]  # (T + 1, G, 2)
    present = np.isfinite(xy).all(axis=-1)
    count = present.astype(np.float64) @ member.T  # (T + 1, K) members present
    centroid = np.einsum("tgd,kg->tkd", np.where(present[..., None], xy, 0.0), member.astype(np.float64))
    centroid /= np.maximum(count, 1.0)[..., None]
    own = np.searchsorted(ids, groups[grouped])  # (G,) each grouped column's group index
    spread = np.linalg.norm(xy - centroid[:, own], axis=-1)  # (T + 1, G) member distance from its centroid
    radius = np.where(member[None] & present[:, None], spread[:, None], 0.0).max(axis=2, initial=0.0)
    exists = count >= 2
    inside = exists & (np.linalg.norm(ego_xy_m[:, None] - centroid, axis=-1) < radius)
    return inside, exists


def group_intrusions(inside: np.ndarray, exists: np.ndarray) -> int:
    """Times the robot's centre entered a group's space between two states at which that space exists.

    Args:
        inside, exists: (T + 1, K) of ``group_spaces``.
    """
    return int((inside[1:] & ~inside[:-1] & exists[:-1]).sum())
