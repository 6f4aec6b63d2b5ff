"""A replay's route tables as the kernels read them (``RouteTables``), and the places along one pedestrian's route:
``Routes``' ``route``, ``place``, ``arc``, ``tau_ahead``, ``progress``, ``nearest_on_route`` and ``too_deep_m`` for
one point, with the same rounding.

The functions here take one agent's columns of the tables (``log`` (F, 2), ``tangent`` (F, 2), ``arc_m`` (F,),
``trace`` (F, K, 2), ``trace_depth`` (F, K)) and the bounds ``first``, ``last`` of the run of presence its route point
is held in, and are inlined where they are called: a caller takes the columns once per pedestrian (a tuple of arrays
passed to every call would cost its reference counts, more than the arithmetic).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from st_sim.reactive.compiled.exact import clip, first_of_least, length, maximum, minimum
from st_sim.reactive.compiled.geometry import depth_at, gap
from st_sim.reactive.footprint import corners
from st_sim.reactive.routes import CROSSING_WINDOW, DEPTH_TOLERANCE_M, DEPTH_WINDOW, OpenGround, Routes
from st_sim.sim.map_depth import MapDepth


class RouteTables(NamedTuple):
    """``Routes``' tables and the constants the kernels need (F frames, A agents, K trace points per frame).

    Attributes:
        log_xy_m: (F, A, 2) [m].  run_first, run_last: (F, A) int64.  log_speed_mps: (F, A) [m/s].  arc_m: (F, A) [m].
        tangent: (F, A, 2).  trace_m: (F, A, K, 2) [m].  trace_depth_m: (F, A, K) [m].
        depth_m: (H, W) the scene's depth raster [m].  to_pixel: (3, 3) world to pixel homography.  affine: bool,
            its last row is (0, 0, 1).  open_ground: bool, every point at depth 0 (no raster).
        half_m: (2,) the robot's half length and width [m].  radius_m: its radius [m].  corners: (C, 2) its
            rectangle's distinct corners [m].  half_diagonal_m: ``Body.half_diagonal_m`` [m].
        robot_reach_m: gap kept from the robot's body [m].  delay_cost: the reaction's cost of delay.
            anticipation_steps: the reaction's look-ahead in steps.
    """

    log_xy_m: np.ndarray
    run_first: np.ndarray
    run_last: np.ndarray
    log_speed_mps: np.ndarray
    arc_m: np.ndarray
    tangent: np.ndarray
    trace_m: np.ndarray
    trace_depth_m: np.ndarray
    depth_m: np.ndarray
    to_pixel: np.ndarray
    affine: bool
    open_ground: bool
    half_m: np.ndarray
    radius_m: float
    corners: np.ndarray
    half_diagonal_m: float
    robot_reach_m: float
    delay_cost: float
    anticipation_steps: int


def route_tables(routes: Routes) -> RouteTables | None:
    """``routes``' tables for the kernels; None where its depth is neither a ``MapDepth`` nor ``OpenGround`` (the
    kernels read only those)."""
    if isinstance(routes.depth, OpenGround):
        depth_m, to_pixel, open_ground = np.zeros((1, 1)), np.eye(3), True
    elif isinstance(routes.depth, MapDepth):
        depth_m, to_pixel, open_ground = routes.depth.depth_m, routes.depth.scene.H_inv, False
    else:
        return None
    affine = bool(to_pixel[2, 0] == 0.0 and to_pixel[2, 1] == 0.0 and to_pixel[2, 2] == 1.0)
    half_m = np.asarray(routes.body.half_m, np.float64)
    reaction = routes.reaction
    return RouteTables(routes.log_xy_m, routes.run_first, routes.run_last, routes.log_speed_mps, routes.arc_m,
                       routes.tangent, routes.trace_m, routes.trace_depth_m, np.ascontiguousarray(depth_m, np.float64),
                       np.ascontiguousarray(to_pixel, np.float64), affine, open_ground, half_m,
                       float(routes.body.radius_m), np.array(corners(half_m), np.float64).reshape(-1, 2),
                       routes.body.half_diagonal_m, float(routes.robot_reach_m), float(reaction.delay_cost),
                       int(reaction.anticipation_steps))


@njit(cache=True, inline="always")
def route(log: np.ndarray, tangent: np.ndarray, first: int, last: int, tau: float) -> tuple[float, float, float, float]:
    """(x, y, normal x, normal y): the point of the route ``log`` (F, 2) at fractional frame ``tau``, held within the
    run ``first`` .. ``last``, and the left normal there (``tangent`` (F, 2))."""
    tau = clip(tau, float(first), float(last))
    frame = int(np.floor(tau))
    after = min(frame + 1, last)
    share = tau - frame
    x = (1 - share) * log[frame, 0] + share * log[after, 0]
    y = (1 - share) * log[frame, 1] + share * log[after, 1]
    t_x = (1 - share) * tangent[frame, 0] + share * tangent[after, 0]
    t_y = (1 - share) * tangent[frame, 1] + share * tangent[after, 1]
    norm = maximum(length(t_x, t_y), 1e-9)
    t_x, t_y = t_x / norm, t_y / norm
    return x, y, -t_y, t_x


@njit(cache=True, inline="always")
def place(log: np.ndarray, tangent: np.ndarray, first: int, last: int, tau: float,
          offset_m: float) -> tuple[float, float]:
    """(x, y) [m]: the route point at ``tau`` moved ``offset_m`` to its left."""
    x, y, n_x, n_y = route(log, tangent, first, last, tau)
    return x + offset_m * n_x, y + offset_m * n_y


@njit(cache=True, inline="always")
def arc(arc_m: np.ndarray, first: int, last: int, tau: float) -> float:
    """Metres along the route (``arc_m`` (F,)) at fractional frame ``tau``, within the run ``first`` .. ``last``."""
    tau = clip(tau, float(first), float(last))
    frame = int(np.floor(tau))
    return arc_m[frame] + (tau - frame) * (arc_m[min(frame + 1, last)] - arc_m[frame])


@njit(cache=True, inline="always")
def tau_ahead(arc_m: np.ndarray, first: int, last: int, tau: float, ahead_m: float) -> float:
    """The latest fractional frame of the run ``first`` .. ``last`` whose route point lies ``ahead_m`` further along
    than ``tau``."""
    target = arc(arc_m, first, last, tau) + ahead_m
    low, high = first - 1, last
    while low < high:
        middle = (low + high + 1) // 2
        if arc_m[max(middle, first)] <= target:
            low = middle
        else:
            high = middle - 1
    k = max(low, first)
    step = arc_m[min(k + 1, last)] - arc_m[k]
    share = clip((target - arc_m[k]) / step, 0.0, 1.0) if step > 0 else 0.0
    return k + share


@njit(cache=True, inline="always")
def progress(arc_m: np.ndarray, first: int, last: int, tau: float, farthest: float,
             index: int) -> tuple[float, float]:
    """(gain, behind) [m]: how much farther along the route than ``farthest`` the route point ``tau`` is, and how far
    behind the log at frame ``index`` (or where it ended); ``first`` .. ``last`` the run holding ``farthest``."""
    at = arc(arc_m, first, last, tau)
    now = arc(arc_m, first, last, float(min(index, last)))
    return at - arc(arc_m, first, last, farthest), maximum(now - at, 0.0)


@njit(cache=True, inline="always")
def nearest_on_route(log: np.ndarray, tangent: np.ndarray, first: int, last: int, x: float, y: float, low: int,
                     high: int) -> tuple[float, float]:
    """(tau, offset_m): the point of the log between frames ``low`` and ``high`` nearest to (x, y) [m] (the first of
    equals) as a fractional frame, and how far left of the route there the point lies [m]."""
    best, best_frame, best_share = np.inf, -1, 0.0
    for frame in range(low, high + 1):
        p_x, p_y = log[frame, 0], log[frame, 1]
        after = min(frame + 1, high)
        s_x, s_y = log[after, 0] - p_x, log[after, 1] - p_y
        length2 = 0.0 + s_x * s_x + s_y * s_y
        share = clip((0.0 + (x - p_x) * s_x + (y - p_y) * s_y) / (length2 if length2 > 0 else 1.0), 0.0, 1.0)
        distance = length(x - p_x - share * s_x, y - p_y - share * s_y)
        if first_of_least(distance, best, best_frame >= 0):
            best, best_frame, best_share = distance, frame, share
    tau = best_frame + best_share
    r_x, r_y, n_x, n_y = route(log, tangent, first, last, tau)
    return tau, 0.0 + (x - r_x) * n_x + (y - r_y) * n_y


@njit(cache=True, inline="always")
def _window_depths(trace_depth: np.ndarray, low: int, high: int) -> tuple[float, float]:
    """(least, most) [m]: the shallowest and the deepest point of the log's trace (``trace_depth`` (F, K)) between
    frames ``low`` and ``high`` (inf, -inf for none)."""
    least, most = np.inf, -np.inf
    for frame in range(low, high + 1):
        for k in range(trace_depth.shape[1]):
            least, most = minimum(least, trace_depth[frame, k]), maximum(most, trace_depth[frame, k])
    return least, most


@njit(cache=True)
def depth_window(trace_depth: np.ndarray, first: int, last: int, tau: float, through: float,
                 whether: bool) -> tuple[int, int, float, float, float]:
    """What ``too_deep`` compares a pedestrian's places with, the same for every place at route point ``tau`` of the
    run ``first`` .. ``last``: (low, high, least, most, crossing), the frames of its log looked at, their
    shallowest and deepest trace points [m] and the deepest point of a crossing beside ``tau`` [m] (-inf with
    ``whether``: its log from ``tau`` through ``through``)."""
    frame = int(np.floor(tau))
    if whether:
        end = max(frame, int(np.floor(through)))
        low, high = max(first, frame), min(last, end + DEPTH_WINDOW)
        crossing = -np.inf
    else:
        low, high = max(first, frame - DEPTH_WINDOW), min(last, frame + DEPTH_WINDOW)
        crossing = _window_depths(trace_depth, max(first, frame - CROSSING_WINDOW),
                                  min(last, frame + CROSSING_WINDOW))[1]
    least, most = _window_depths(trace_depth, low, high)
    return low, high, least, most, crossing


@njit(cache=True, inline="always")
def _nearest_trace_depth(trace: np.ndarray, trace_depth: np.ndarray, low: int, high: int, x: float,
                         y: float) -> float:
    """Depth [m] of the point of the log's trace (``trace`` (F, K, 2)) between frames ``low`` and ``high`` nearest to
    (x, y) (the first of equals)."""
    best, depth, found = np.inf, np.nan, False
    for frame in range(low, high + 1):
        for k in range(trace.shape[1]):
            distance = length(x - trace[frame, k, 0], y - trace[frame, k, 1])
            if first_of_least(distance, best, found):
                best, depth, found = distance, trace_depth[frame, k], True
    return depth


@njit(cache=True, inline="always")
def too_deep(trace: np.ndarray, trace_depth: np.ndarray, window: tuple[int, int, float, float, float],
             depth_m: np.ndarray, to_pixel: np.ndarray, affine: bool, open_ground: bool, x: float, y: float,
             whether: bool) -> float:
    """``Routes.too_deep_m`` of one place (x, y) [m] against its log's ``window`` (``depth_window``): how much deeper
    in the non-walkable area (the scene's ``depth_at``) it is than its log near that route point; with ``whether``,
    than its log through the window, and only whether it is (inf) or not (0)."""
    here = depth_at(x, y, depth_m, to_pixel, affine, open_ground)
    if not here > 0:
        return 0.0
    low, high, least, most, crossing = window
    log_depth = maximum(least, crossing)
    search = here > log_depth and least < most
    if whether:
        search = search and here <= maximum(most, crossing)
        if here > maximum(most, crossing) and least < most:
            log_depth = most
    if search:
        log_depth = maximum(_nearest_trace_depth(trace, trace_depth, low, high, x, y), crossing)
    over = 0.0
    if not np.isinf(log_depth):
        over = minimum(maximum(here - log_depth - DEPTH_TOLERANCE_M, 0.0), 1e3)
    if whether:
        return np.inf if over > 0 else 0.0
    return over


@njit(cache=True, inline="always")
def clear_of_robot(half_m: np.ndarray, radius_m: float, reach_m: float, x: float, y: float, robot: np.ndarray) -> bool:
    """``Routes.clear_of_robot`` of one point (x, y) [m]: at least ``reach_m`` from the robot's body where it stands
    and where it is expected (``robot``: from x, y, to x, y, cos, sin of its heading, ...); a NaN point is clear."""
    nearest = minimum(gap(x - robot[0], y - robot[1], robot[4], robot[5], half_m, radius_m),
                      gap(x - robot[2], y - robot[3], robot[4], robot[5], half_m, radius_m))
    return nearest != nearest or nearest >= reach_m
