"""The bodies in a reactive replay: the robot's footprint and its move over a step, a pedestrian's body and the gaps
reactive pedestrians keep from both.

A disc robot (STCrowd's, radius 0.3 m) is a rectangle of zero length and width grown by its radius; a vehicle (CITR's
golf cart) is a ``length x width`` rectangle along its heading. Over one 0.4 s step the body moves in a straight line
from one centre to another with its heading held (``Robot``: as the pedestrians expect it to move), and a pedestrian
too, so the pedestrian moves in a straight line in the body's frame: the least gap between them is the distance from
a segment to a rectangle, less the radius. That distance is zero where the segment meets the rectangle and is
otherwise reached at an end of the segment or at a corner of the rectangle (two convex shapes apart), which is what
``segment_box_distance`` computes, exactly. Headings turn into cosines and sines, and moves into headings, through
``st_sim.sim.exact`` (the same bits on every CPU).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from replays.constants import STEP_S
from st_sim.sim.exact import atan2, cos_sin

BODY_RADIUS_M: Final[float] = 0.2  # radius of a reactive pedestrian's body [m]
ROBOT_MARGIN_M: Final[float] = 0.05  # reactive pedestrians keep this much beyond touching the robot's body [m]
PAIR_GIVE_M: Final[float] = 0.05  # two pedestrians may come this far inside body contact (shoulders turn) [m]
PAIR_BODY_M: Final[float] = 2 * BODY_RADIUS_M - PAIR_GIVE_M  # the closest two pedestrians' centres come [m]
COMFORT_M: Final[float] = 0.3  # room kept beyond contact from others off their logs, and from a robot's body not
"""noticed (a body in the way) [m]"""
GAP_SLACK_M: Final[float] = 1e-6  # a gap is told apart from a bound only beyond this, far above rounding [m]


@dataclass(frozen=True)
class Body:
    """A robot's footprint: a ``length_m`` x ``width_m`` rectangle centred on the robot, its length along the heading,
    grown by ``radius_m`` [m] (a disc of that radius for length = width = 0)."""

    length_m: float = 0.0
    width_m: float = 0.0
    radius_m: float = 0.0

    @property
    def half_m(self) -> np.ndarray:
        """(2,) half length and half width [m]."""
        return np.array([self.length_m, self.width_m]) / 2

    @property
    def half_diagonal_m(self) -> float:
        """Half the rectangle's diagonal [m]."""
        return float(length_m(self.half_m))

    def to_body_frame(self, offset_m: np.ndarray, heading_rad: float) -> np.ndarray:
        """(..., 2) world offsets from the robot's centre [m] turned into its frame (heading along +x)."""
        cos, sin = cos_sin(heading_rad)
        return np.stack([offset_m[..., 0] * cos + offset_m[..., 1] * sin,
                         -offset_m[..., 0] * sin + offset_m[..., 1] * cos], axis=-1)

    def gap_m(self, offset_m: np.ndarray, heading_rad: float) -> np.ndarray:
        """(...) distance from the body's surface of points at world offsets ``offset_m`` (..., 2) from its centre [m]
        (minus the radius inside the rectangle)."""
        return box_distance(self.to_body_frame(offset_m, heading_rad), self.half_m) - self.radius_m

    def swept_gap_m(self, offset_from_m: np.ndarray, offset_to_m: np.ndarray, heading_rad: float) -> np.ndarray:
        """(...) least gap [m] over a step between the body's surface and a point whose offset from the body's centre
        moves linearly from ``offset_from_m`` to ``offset_to_m`` (..., 2) [m], world frame, heading held."""
        a = self.to_body_frame(np.asarray(offset_from_m, np.float64), heading_rad)
        b = self.to_body_frame(np.asarray(offset_to_m, np.float64), heading_rad)
        return segment_box_distance(a, b, self.half_m) - self.radius_m

    def swept_gap_within_m(self, offset_from_m: np.ndarray, offset_to_m: np.ndarray, heading_rad: np.ndarray,
                           within_m: float | np.ndarray) -> np.ndarray:
        """(...) ``swept_gap_m`` where it may be less than ``within_m`` [m] (all broadcast to one shape (...)), inf
        where it cannot (the move's midpoint too far from the body's centre for any of it to come that close): the
        same wherever only a gap below ``within_m`` counts, computed for fewer points."""
        a, b = np.broadcast_arrays(np.asarray(offset_from_m, np.float64), np.asarray(offset_to_m, np.float64))
        shape = a.shape[:-1]
        bound = (length_m(b - a) / 2 + self.half_diagonal_m + self.radius_m + within_m + GAP_SLACK_M)
        close = ~(length_m((a + b) / 2) > bound)  # (NaN points: close)
        gap = np.full(shape, np.inf)
        gap[close] = self.swept_gap_m(a[close], b[close], np.broadcast_to(heading_rad, shape)[close])
        return gap

    def nearest_point_m(self, offset_m: np.ndarray, heading_rad: float) -> np.ndarray:
        """(..., 2) offset from the robot's centre [m], world frame, of the point of its rectangle nearest to points at
        world offsets ``offset_m`` (..., 2) (the centre for a disc)."""
        local = np.clip(self.to_body_frame(offset_m, heading_rad), -self.half_m, self.half_m)
        return self.to_body_frame(local, -heading_rad)


@dataclass(frozen=True)
class Robot:
    """The robots' moves over the step as the pedestrians expect them, one row per crowd: from ``from_m`` to ``to_m``
    (N, 2) [m] in a straight line, each body turned to ``heading_rad`` (N,)."""

    from_m: np.ndarray
    to_m: np.ndarray
    heading_rad: np.ndarray

    @property
    def velocity_mps(self) -> np.ndarray:
        """(N, 2) [m/s]."""
        return (self.to_m - self.from_m) / STEP_S

    @property
    def heading(self) -> np.ndarray:
        """(N, 2) unit headings: the cosine and sine of ``heading_rad``."""
        return np.stack(cos_sin(self.heading_rad), axis=-1)

    def after(self) -> Robot:
        """The same robots over the next step, holding their velocities."""
        return Robot(self.to_m, 2 * self.to_m - self.from_m, self.heading_rad)


def box_distance(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(...) distance [m] of points ``p`` (..., 2) from the rectangle [-half, half] (2,); 0 inside."""
    outside = np.maximum(np.abs(p) - half, 0.0)
    return np.sqrt(outside[..., 0] * outside[..., 0] + outside[..., 1] * outside[..., 1])


def segment_box_distance(a: np.ndarray, b: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(...) least distance [m] between the segments ``a`` -> ``b`` (..., 2) and the rectangle [-half, half] (2,)."""
    a, b = np.broadcast_arrays(a, b)
    ends = np.minimum(box_distance(a, half), box_distance(b, half))
    d = b - a
    length2 = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
    to_corner = np.full(length2.shape, np.inf)
    for x, y in corners(half):  # one for a disc
        with np.errstate(invalid="ignore", divide="ignore"):
            t = np.clip(np.where(length2 > 0, ((x - a[..., 0]) * d[..., 0] + (y - a[..., 1]) * d[..., 1]) / length2,
                                 0.0), 0.0, 1.0)
        off_x, off_y = a[..., 0] + t * d[..., 0] - x, a[..., 1] + t * d[..., 1] - y
        to_corner = np.minimum(to_corner, np.sqrt(off_x * off_x + off_y * off_y))
    return np.where(_meets(a, d, half), 0.0, np.minimum(ends, to_corner))


def corners(half: np.ndarray) -> list[tuple[float, float]]:
    """The distinct corners (x, y) [m] of the rectangle [-half, half] (2,): four, two for a segment, one for a
    point."""
    xs, ys = sorted({float(half[0]), -float(half[0])}), sorted({float(half[1]), -float(half[1])})
    return [(x, y) for x in xs for y in ys]


def _meets(a: np.ndarray, d: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(...) bool: the segment a + t d, t in [0, 1], meets the rectangle [-half, half] (Liang-Barsky clipping)."""
    low, high = np.zeros(a.shape[:-1]), np.ones(a.shape[:-1])
    inside = np.ones(a.shape[:-1], bool)
    for axis in range(2):
        start, step = a[..., axis], d[..., axis]
        still = np.abs(step) < 1e-12
        inside &= ~still | (np.abs(start) <= half[axis])
        with np.errstate(invalid="ignore", divide="ignore"):
            t1, t2 = (-half[axis] - start) / step, (half[axis] - start) / step
        low = np.where(still, low, np.maximum(low, np.minimum(t1, t2)))
        high = np.where(still, high, np.minimum(high, np.maximum(t1, t2)))
    return inside & (low <= high)


def length_m(vector_m: np.ndarray) -> np.ndarray:
    """(...) lengths [m] of vectors (..., 2) [m], rounded as ``np.linalg.norm(vector_m, axis=-1)`` rounds them."""
    return np.sqrt(vector_m[..., 0] * vector_m[..., 0] + vector_m[..., 1] * vector_m[..., 1])


def heading_of(from_m: np.ndarray, to_m: np.ndarray, heading_rad: float | None = None) -> float:
    """``heading_rad`` if given, else the direction of the move ``from_m`` -> ``to_m`` (2,) [rad] (0 for no move)."""
    if heading_rad is not None:
        return float(heading_rad)
    move = np.asarray(to_m, np.float64) - np.asarray(from_m, np.float64)
    return float(atan2(move[1], move[0])) if length_m(move) > 1e-9 else 0.0
