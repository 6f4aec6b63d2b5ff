"""The rest of the reactive step compiled: ``reactive.advance``'s bookkeeping round the choice, for every agent of
every crowd, with the same numbers. Three passes, with what numpy computes between them (the room each keeps, the
same code in both paths; the newcomers, a rare case) and the choice (``choose``):

- ``attention``: walking directions, who notices the robot, how long each has had it in mind, how far it reacts;
- ``leave``: who is present, who leaves its log (``in_the_way``), where each starts and what it carries over;
- ``settle``: who rejoins its log or leaves the scene, and the headway, stuck and way-round counts.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from replays.constants import STEP_S
from st_sim.reactive.candidates import HEADWAY_M
from st_sim.reactive.compiled.exact import atan2, clip, length, maximum
from st_sim.reactive.compiled.geometry import gap, to_body_frame
from st_sim.reactive.compiled.in_the_way import others_in_the_way, robot_in_the_way
from st_sim.reactive.compiled.tables import RouteTables, clear_of_robot, progress
from st_sim.reactive.reaction import MEMORY_S, MOVING_MPS


@njit(cache=True)
def attention(t: RouteTables, present: np.ndarray, xy: np.ndarray, velocity: np.ndarray, tau: np.ndarray,
              noticed_s: np.ndarray, unseen_s: np.ndarray, robot: np.ndarray, turned_back: np.ndarray, fov_rad: float,
              hearing_m: np.ndarray, reaction_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(walking (N, A, 2), noticed_s, unseen_s, weight (N, A)): each pedestrian's unit walking direction
    (``reactive._walking``), its attention after noticing the robot or not (``reactive._notices``,
    ``reaction.attend``) and how far it reacts (``Reaction.weight``), for the state (N, A, ...) before the step;
    ``turned_back`` (N, 2): the cosine and sine of minus each robot's heading; the reaction's field of view [rad],
    each pedestrian's hearing [m] and reaction time [s] (N, A)."""
    crowds, agents = present.shape
    frames = t.tangent.shape[0]
    walking = np.empty((crowds, agents, 2))
    noticed, unseen, weight = np.empty((crowds, agents)), np.empty((crowds, agents)), np.empty((crowds, agents))
    for n in range(crowds):
        from_x, from_y, cos, sin = robot[n, 0], robot[n, 1], robot[n, 4], robot[n, 5]
        for a in range(agents):
            speed = length(velocity[n, a, 0], velocity[n, a, 1])
            if speed > MOVING_MPS:
                walking[n, a, 0] = velocity[n, a, 0] / maximum(speed, 1e-12)
                walking[n, a, 1] = velocity[n, a, 1] / maximum(speed, 1e-12)
            else:  # the route's direction where it is on it
                frame = int(clip(np.floor(tau[n, a]), 0.0, float(frames - 1)))
                walking[n, a, 0], walking[n, a, 1] = t.tangent[frame, a, 0], t.tangent[frame, a, 1]
            off_x, off_y = xy[n, a, 0] - from_x, xy[n, a, 1] - from_y
            local_x, local_y = to_body_frame(off_x, off_y, cos, sin)
            local_x, local_y = clip(local_x, -t.half_m[0], t.half_m[0]), clip(local_y, -t.half_m[1], t.half_m[1])
            near_x, near_y = to_body_frame(local_x, local_y, turned_back[n, 0], turned_back[n, 1])
            toward_x, toward_y = from_x + near_x - xy[n, a, 0], from_y + near_y - xy[n, a, 1]
            bearing = atan2(walking[n, a, 0] * toward_y - walking[n, a, 1] * toward_x,
                            0.0 + walking[n, a, 0] * toward_x + walking[n, a, 1] * toward_y)
            bearing = np.pi if bearing != bearing else bearing
            body_gap = gap(off_x, off_y, cos, sin, t.half_m, t.radius_m)
            body_gap = np.inf if body_gap != body_gap else body_gap
            noticing = present[n, a] and (body_gap <= hearing_m[n, a] or abs(bearing) <= fov_rad)
            unseen[n, a] = 0.0 if noticing else unseen_s[n, a] + STEP_S
            kept = noticing or (noticed_s[n, a] > 0 and unseen[n, a] <= MEMORY_S)
            noticed[n, a] = noticed_s[n, a] + STEP_S if kept else 0.0
            unseen[n, a] = unseen[n, a] if kept else 0.0
            weight[n, a] = clip((noticed[n, a] - reaction_s[n, a]) / STEP_S, 0.0, 1.0) if present[n, a] else 0.0
    return walking, noticed, unseen, weight


@njit(cache=True)
def leave(t: RouteTables, logs_present: np.ndarray, index: np.ndarray, robot: np.ndarray, weight: np.ndarray,
          room_m: np.ndarray, old_xy: np.ndarray, old_velocity: np.ndarray, old_present: np.ndarray,
          old_off_log: np.ndarray, old_linger: np.ndarray, old_tau: np.ndarray, old_farthest: np.ndarray,
          old_recent: np.ndarray, old_detour: np.ndarray, old_offset: np.ndarray, max_linger: int,
          look_ahead_steps: int, clearance_m: float):
    """Who is present, who leaves its log and where each starts (``reactive.advance`` up to the choice), for the
    N crowds stepping into frames ``index`` (N,): (lingering, present, off_log, start, tau, farthest, recent, detour,
    offset, xy, clear), with the previous state's arrays (N, A, ...) and ``reactive``'s constants."""
    crowds, agents = old_present.shape
    log = t.log_xy_m
    going = robot_in_the_way(t, logs_present, index, robot, weight, room_m) | others_in_the_way(
        t, logs_present, index, old_xy, old_velocity, old_off_log & old_present, look_ahead_steps, clearance_m)
    lingering, present = np.empty((crowds, agents), np.bool_), np.empty((crowds, agents), np.bool_)
    off_log, detour, clear = np.empty((crowds, agents), np.bool_), np.empty((crowds, agents), np.bool_), \
        np.empty((crowds, agents), np.bool_)
    start, xy = np.empty((crowds, agents, 2)), np.empty((crowds, agents, 2))
    tau, farthest, offset = np.empty((crowds, agents)), np.empty((crowds, agents)), np.empty((crowds, agents))
    recent = np.empty(old_recent.shape)
    for n in range(crowds):
        idx = index[n]
        frame = float(idx)
        for a in range(agents):
            logged = logs_present[idx, a]
            was = old_present[n, a]
            lingering[n, a] = was and old_off_log[n, a] and not logged and old_linger[n, a] < max_linger
            present[n, a] = logged or lingering[n, a]
            off = (old_off_log[n, a] and was and logged and old_linger[n, a] == 0) or lingering[n, a]
            goes = was and logged and not off and going[n, a]
            off = off or goes
            off_log[n, a] = off
            for axis in range(2):
                start[n, a, axis] = old_xy[n, a, axis] if was else log[idx, a, axis]
                xy[n, a, axis] = (start[n, a, axis] if off else log[idx, a, axis]) if present[n, a] else np.nan
            tau[n, a] = frame - 1.0 if goes else (old_tau[n, a] if off else frame)
            farthest[n, a] = (tau[n, a] if goes else old_farthest[n, a]) if off else frame
            for k in range(recent.shape[2]):
                recent[n, a, k] = old_recent[n, a, k] if off and not goes else np.inf
            detour[n, a] = off and not goes and old_detour[n, a]
            offset[n, a] = old_offset[n, a] if off else 0.0
            clear[n, a] = clear_of_robot(t.half_m, t.radius_m, t.robot_reach_m, log[idx, a, 0], log[idx, a, 1],
                                         robot[n])
    return lingering, present, off_log, start, tau, farthest, recent, detour, offset, xy, clear


@njit(cache=True)
def settle(t: RouteTables, logs_present: np.ndarray, index: np.ndarray, robot_after: np.ndarray, weight: np.ndarray,
           room_m: np.ndarray, xy: np.ndarray, present: np.ndarray, off_log: np.ndarray, lingering: np.ndarray,
           start: np.ndarray, clear: np.ndarray, tau: np.ndarray, offset: np.ndarray, farthest: np.ndarray,
           recent: np.ndarray, detour: np.ndarray, old_xy: np.ndarray, old_present: np.ndarray,
           old_linger: np.ndarray, old_stuck: np.ndarray, rejoin_m: float, still_m: float, leave_blocked_m: float,
           detour_after_steps: int, look_ahead_steps: int, clearance_m: float):
    """After the choice (``reactive.advance`` from the rejoining on): who rejoins its log, who leaves the scene
    where its log ended, and what each carries into the next step: (xy, velocity, present, off_log, tau, offset,
    linger, stuck, farthest, recent, detour) of the new state; ``xy``, ``present`` and ``off_log`` are changed in
    place, ``robot_after`` is the robots over the next step (``Robot.after``), the rest as ``leave`` returned them,
    the previous state's arrays and ``reactive``'s constants."""
    crowds, agents = present.shape
    log = t.log_xy_m
    frames = log.shape[0]
    ahead_velocity = _velocity(xy, old_xy, old_present & present)
    blocked_by_robot = robot_in_the_way(t, logs_present, index + 1, robot_after, weight, room_m)
    blocked_by_others = others_in_the_way(t, logs_present, index + 1, xy, ahead_velocity, off_log & present,
                                          look_ahead_steps, clearance_m)
    new_tau, new_offset, new_farthest = np.empty((crowds, agents)), np.empty((crowds, agents)), \
        np.empty((crowds, agents))
    linger, stuck = np.empty((crowds, agents), np.int64), np.empty((crowds, agents), np.int64)
    new_recent = np.empty(recent.shape)
    for n in range(crowds):
        idx = index[n]
        frame = float(idx)
        for a in range(agents):
            logged = logs_present[idx, a]
            if off_log[n, a] and logged:  # back on the log: caught up, beside it, and nothing in the way
                apart = length(xy[n, a, 0] - log[idx, a, 0], xy[n, a, 1] - log[idx, a, 1])
                apart = np.inf if apart != apart else apart
                if (apart <= rejoin_m and not blocked_by_robot[n, a] and not blocked_by_others[n, a]
                        and clear[n, a]):
                    xy[n, a, 0], xy[n, a, 1] = log[idx, a, 0], log[idx, a, 1]
                    off_log[n, a] = False
            if lingering[n, a]:  # out of the scene where its log ended (or near it, where it cannot get closer)
                ended = t.run_last[int(maximum(np.floor(tau[n, a]), 0.0)), a]
                ended = ended if ended >= 0 else frames + ended
                to_end = length(xy[n, a, 0] - log[ended, a, 0], xy[n, a, 1] - log[ended, a, 1])
                to_end = np.inf if to_end != to_end else to_end
                moved_x, moved_y = xy[n, a, 0] - start[n, a, 0], xy[n, a, 1] - start[n, a, 1]
                moved = length(0.0 if moved_x != moved_x else moved_x, 0.0 if moved_y != moved_y else moved_y)
                if to_end <= rejoin_m or (moved < still_m and to_end <= leave_blocked_m):
                    present[n, a] = False
            off_log[n, a] = off_log[n, a] and present[n, a]
            if not present[n, a]:
                xy[n, a, 0], xy[n, a, 1] = np.nan, np.nan
            headway, farther, behind = True, True, np.inf
            if off_log[n, a]:
                run_frame = int(farthest[n, a])
                gain, lag = progress(t.arc_m[:, a], t.run_first[run_frame, a], t.run_last[run_frame, a], tau[n, a],
                                     farthest[n, a], idx)
                behind = lag + abs(offset[n, a])
                nearest = recent[n, a, 0]
                for k in range(1, recent.shape[2]):
                    nearest = nearest if nearest < recent[n, a, k] or nearest != nearest else recent[n, a, k]
                farther = gain >= HEADWAY_M
                headway = not (gain < HEADWAY_M and behind > nearest - HEADWAY_M)  # candidates.no_headway
            stuck[n, a] = old_stuck[n, a] + 1 if off_log[n, a] and not headway else 0
            detour[n, a] = (detour[n, a] and off_log[n, a] and not farther) or stuck[n, a] >= detour_after_steps
            new_tau[n, a] = tau[n, a] if off_log[n, a] else frame
            new_offset[n, a] = offset[n, a] if off_log[n, a] else 0.0
            linger[n, a] = old_linger[n, a] + 1 if present[n, a] and lingering[n, a] else 0
            new_farthest[n, a] = maximum(farthest[n, a], tau[n, a]) if off_log[n, a] else frame
            for k in range(recent.shape[2] - 1):
                new_recent[n, a, k] = recent[n, a, k + 1]
            new_recent[n, a, recent.shape[2] - 1] = behind
    return (xy, _velocity(xy, old_xy, old_present & present), present, off_log, new_tau, new_offset, linger, stuck,
            new_farthest, new_recent, detour)


@njit(cache=True)
def _velocity(xy: np.ndarray, old_xy: np.ndarray, stays: np.ndarray) -> np.ndarray:
    """``reactive.velocity``: (N, A, 2) velocity over the step [m/s] of those present before and after it."""
    out = np.zeros(xy.shape)
    for n in range(xy.shape[0]):
        for a in range(xy.shape[1]):
            if stays[n, a]:
                for axis in range(2):
                    moved = xy[n, a, axis] - old_xy[n, a, axis]
                    if moved != moved:
                        moved = 0.0
                    elif moved == np.inf:
                        moved = np.finfo(np.float64).max
                    elif moved == -np.inf:
                        moved = -np.finfo(np.float64).max
                    out[n, a, axis] = moved / STEP_S
    return out
