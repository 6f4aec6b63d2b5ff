"""The robot's body gaps and the scene's depth at one point, compiled: ``footprint.Body``'s gaps and
``MapDepth.at`` with the same rounding (``exact``).

The body is given by its half length and width ``half_m`` (2,), its radius and its distinct corners (``corners``,
(C, 2)); its heading by its cosine and sine, computed once per robot (``st_sim.sim.exact.cos_sin``), so that no
transcendental function is evaluated here. The functions are inlined where they are called (``inline="always"``): a
call that passes arrays costs their reference counts, more than the arithmetic.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from st_sim.reactive.compiled.exact import clip, length, maximum, minimum
from st_sim.reactive.footprint import GAP_SLACK_M, Robot


def robot_rows(robot: Robot) -> np.ndarray:
    """(N, 8) the robots as the kernels read them, one row per crowd: from x, y, to x, y, the cosine and sine of
    the heading, velocity x, y (``Robot.heading`` and ``Robot.velocity_mps``)."""
    return np.c_[robot.from_m, robot.to_m, robot.heading, robot.velocity_mps]


@njit(cache=True, inline="always")
def to_body_frame(x: float, y: float, cos: float, sin: float) -> tuple[float, float]:
    """The world offset (x, y) from the robot's centre [m] in its frame (heading along +x)."""
    return x * cos + y * sin, -x * sin + y * cos


@njit(cache=True, inline="always")
def box_distance(x: float, y: float, half_m: np.ndarray) -> float:
    """Distance [m] of the point (x, y) from the rectangle [-half, half]; 0 inside."""
    out_x, out_y = maximum(abs(x) - half_m[0], 0.0), maximum(abs(y) - half_m[1], 0.0)
    return np.sqrt(out_x * out_x + out_y * out_y)


@njit(cache=True, inline="always")
def _meets(a_x: float, a_y: float, d_x: float, d_y: float, half_m: np.ndarray) -> bool:
    """The segment a + t d, t in [0, 1], meets the rectangle [-half, half] (``footprint._meets``)."""
    low, high, inside = 0.0, 1.0, True
    for axis in range(2):
        start, step, half = (a_x, d_x, half_m[0]) if axis == 0 else (a_y, d_y, half_m[1])
        still = abs(step) < 1e-12
        inside = inside and (not still or abs(start) <= half)
        if not still:
            t1, t2 = (-half - start) / step, (half - start) / step
            low, high = maximum(low, minimum(t1, t2)), minimum(high, maximum(t1, t2))
    return inside and low <= high


@njit(cache=True, inline="always")
def segment_box_distance(a_x: float, a_y: float, b_x: float, b_y: float, half_m: np.ndarray,
                         corners: np.ndarray) -> float:
    """Least distance [m] between the segment a -> b and the rectangle [-half, half] with the given corners."""
    ends = minimum(box_distance(a_x, a_y, half_m), box_distance(b_x, b_y, half_m))
    d_x, d_y = b_x - a_x, b_y - a_y
    length2 = d_x * d_x + d_y * d_y
    to_corner = np.inf
    for k in range(corners.shape[0]):
        x, y = corners[k, 0], corners[k, 1]
        t = clip(((x - a_x) * d_x + (y - a_y) * d_y) / length2 if length2 > 0 else 0.0, 0.0, 1.0)
        off_x, off_y = a_x + t * d_x - x, a_y + t * d_y - y
        to_corner = minimum(to_corner, np.sqrt(off_x * off_x + off_y * off_y))
    return 0.0 if _meets(a_x, a_y, d_x, d_y, half_m) else minimum(ends, to_corner)


@njit(cache=True, inline="always")
def gap(x: float, y: float, cos: float, sin: float, half_m: np.ndarray, radius_m: float) -> float:
    """``Body.gap_m``: distance [m] from the body's surface of a point at world offset (x, y) from its centre."""
    local_x, local_y = to_body_frame(x, y, cos, sin)
    return box_distance(local_x, local_y, half_m) - radius_m


@njit(cache=True, inline="always")
def swept_gap(from_x: float, from_y: float, to_x: float, to_y: float, cos: float, sin: float, half_m: np.ndarray,
              radius_m: float, corners: np.ndarray) -> float:
    """``Body.swept_gap_m``: least gap [m] over a step between the body and a point whose world offset from its
    centre moves from (from_x, from_y) to (to_x, to_y)."""
    a_x, a_y = to_body_frame(from_x, from_y, cos, sin)
    b_x, b_y = to_body_frame(to_x, to_y, cos, sin)
    return segment_box_distance(a_x, a_y, b_x, b_y, half_m, corners) - radius_m


@njit(cache=True, inline="always")
def swept_gap_within(from_x: float, from_y: float, to_x: float, to_y: float, cos: float, sin: float,
                     half_m: np.ndarray, radius_m: float, corners: np.ndarray, half_diagonal_m: float,
                     within_m: float) -> float:
    """``Body.swept_gap_within_m``: ``swept_gap`` where it may be less than ``within_m`` [m], inf where it cannot
    (``half_diagonal_m``: ``hypot`` of the half length and width)."""
    bound = length(to_x - from_x, to_y - from_y) / 2 + half_diagonal_m + radius_m + within_m + GAP_SLACK_M
    if length((from_x + to_x) / 2, (from_y + to_y) / 2) > bound:
        return np.inf
    return swept_gap(from_x, from_y, to_x, to_y, cos, sin, half_m, radius_m, corners)


@njit(cache=True, inline="always")
def depth_at(x: float, y: float, depth_m: np.ndarray, to_pixel: np.ndarray, affine: bool,
             open_ground: bool) -> float:
    """``MapDepth.at`` of the world point (x, y) [m] (0 everywhere on ``open_ground``): the depth raster ``depth_m``
    (H, W) [m] at the pixel that ``to_pixel`` (3, 3) maps it to, inf off the image."""
    if open_ground:
        return 0.0
    u = x * to_pixel[0, 0] + y * to_pixel[0, 1] + to_pixel[0, 2]
    v = x * to_pixel[1, 0] + y * to_pixel[1, 1] + to_pixel[1, 2]
    if not affine:
        w = x * to_pixel[2, 0] + y * to_pixel[2, 1] + to_pixel[2, 2]
        u, v = u / w, v / w
    u, v = np.rint(u), np.rint(v)
    if not (np.isfinite(u) and np.isfinite(v) and 0 <= u < depth_m.shape[1] and 0 <= v < depth_m.shape[0]):
        return np.inf
    return depth_m[int(v), int(u)]
