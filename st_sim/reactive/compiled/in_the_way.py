"""Who leaves its log, compiled: ``reactive._robot_in_the_way`` and ``reactive._others_in_the_way`` for every agent of
every crowd in one pass, with the same numbers (the constants of ``st_sim.reactive.reactive`` are passed in, as that
module calls these)."""

from __future__ import annotations

import numpy as np
from numba import njit

from replays.constants import STEP_S
from st_sim.reactive.compiled.exact import length, minimum
from st_sim.reactive.compiled.geometry import gap, swept_gap
from st_sim.reactive.compiled.tables import RouteTables
from st_sim.reactive.footprint import BODY_RADIUS_M, PAIR_GIVE_M


@njit(cache=True)
def robot_in_the_way(t: RouteTables, present: np.ndarray, index: np.ndarray, robot: np.ndarray, weight: np.ndarray,
                     room_m: np.ndarray) -> np.ndarray:
    """(N, A) bool: ``reactive._robot_in_the_way`` of the N crowds stepping into frames ``index`` (N,), the logs
    ``present`` (F, A), each crowd's robot ``robot`` (N, 8): from x, y, to x, y, cos, sin of its heading, velocity
    x, y; ``weight``, ``room_m`` (N, A)."""
    frames, agents = present.shape
    steps = t.anticipation_steps
    half_m, radius_m, corners, reach_m = t.half_m, t.radius_m, t.corners, t.robot_reach_m
    found = np.zeros((len(index), agents), np.bool_)
    course = np.empty((steps + 1, 2))
    for n in range(len(index)):
        idx = index[n]
        if idx >= frames:
            continue
        from_x, from_y, cos, sin = robot[n, 0], robot[n, 1], robot[n, 4], robot[n, 5]
        for k in range(steps + 1):  # where the robot is expected, from the frame before on
            course[k, 0] = robot[n, 2] + ((k - 1) * STEP_S) * robot[n, 6]
            course[k, 1] = robot[n, 3] + ((k - 1) * STEP_S) * robot[n, 7]
        valid = 0
        for k in range(steps + 1):
            valid += 0 <= idx - 1 + k < frames
        for a in range(agents):
            logged = False
            for k in range(steps + 1):
                logged = logged or present[min(max(idx - 1 + k, 0), frames - 1), a]
            if not logged:
                continue
            log = t.log_xy_m[:, a]
            before, now = log[max(idx - 1, 0)], log[idx]
            reacting = weight[n, a] > 0
            to_x, to_y = (robot[n, 2], robot[n, 3]) if reacting else (from_x, from_y)
            step_gap = swept_gap(before[0] - from_x, before[1] - from_y, now[0] - to_x, now[1] - to_y, cos, sin,
                                 half_m, radius_m, corners)
            if idx > 0 and step_gap < reach_m:  # its log's step into the robot's body (NaN: not there)
                found[n, a] = True
                continue
            if not reacting:
                continue
            if valid > 1:  # its log from now on against the robot's expected course
                least = np.inf
                for k in range(steps):
                    if not (0 <= idx - 1 + k < frames and 0 <= idx + k < frames):
                        continue
                    here, there = log[min(max(idx - 1 + k, 0), frames - 1)], log[min(idx + k, frames - 1)]
                    swept = swept_gap(here[0] - course[k, 0], here[1] - course[k, 1], there[0] - course[k + 1, 0],
                                      there[1] - course[k + 1, 1], cos, sin, half_m, radius_m, corners)
                    least = minimum(least, np.inf if swept != swept else swept)
            else:
                least = gap(now[0] - course[1, 0], now[1] - course[1, 1], cos, sin, half_m, radius_m)
                least = np.inf if least != least else least
            found[n, a] = least < reach_m + room_m[n, a]
    return found


@njit(cache=True)
def others_in_the_way(t: RouteTables, present: np.ndarray, index: np.ndarray, xy: np.ndarray, velocity: np.ndarray,
                      walking: np.ndarray, look_ahead_steps: int, clearance_m: float) -> np.ndarray:
    """(N, A) bool: ``reactive._others_in_the_way`` of the N crowds from frames ``index`` (N,) on, the logs
    ``present`` (F, A), the crowds' pedestrians at ``xy`` (N, A, 2) [m] going on at ``velocity`` (N, A, 2) [m/s],
    ``walking`` (N, A) bool those off their logs (and present); ``look_ahead_steps`` and ``clearance_m`` as
    ``reactive.PAIR_LOOK_AHEAD_STEPS`` and ``PAIR_CLEARANCE_M``."""
    frames, agents = present.shape
    found = np.zeros((len(index), agents), np.bool_)
    reach = 2 * BODY_RADIUS_M + clearance_m
    for n in range(len(index)):
        idx = index[n]
        if idx >= frames:
            continue
        others = np.flatnonzero(walking[n])
        if not len(others):
            continue
        for a in range(agents):
            logged = False
            for k in range(look_ahead_steps):
                logged = logged or present[min(idx + k, frames - 1), a]
            if not logged:
                continue
            for k in range(look_ahead_steps):
                if idx + k >= frames or found[n, a]:
                    break
                mine = t.log_xy_m[idx + k, a]
                for o in others:
                    if o == a:  # nobody is in their own way
                        continue
                    there_x = xy[n, o, 0] + (k * STEP_S) * velocity[n, o, 0]
                    there_y = xy[n, o, 1] + (k * STEP_S) * velocity[n, o, 1]
                    apart = length(mine[0] - there_x, mine[1] - there_y)
                    logs_apart = length(mine[0] - t.log_xy_m[idx + k, o, 0], mine[1] - t.log_xy_m[idx + k, o, 1])
                    bound = minimum(reach, (np.inf if logs_apart != logs_apart else logs_apart) - PAIR_GIVE_M)
                    if (np.inf if apart != apart else apart) < bound:
                        found[n, a] = True
                        break
    return found
