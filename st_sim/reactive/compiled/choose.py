"""Every chooser of every crowd chooses its place, compiled: ``choosing.choose_all`` with the candidates of
``st_sim.reactive.candidates``, the same numbers and the same choices.

The plain path scores all choosers at once in rounds until no choice changes; its fixed point is each choosing one
after another, the nearest to the robot first, seeing the choices made before it. Here they do exactly that, in
turn: each lays out its candidates (the same grid, the same order), scores them lazily in the same order as
``choosing._best`` (those that may keep every bound, least costly first, ``FIRST_LOOK`` at first), and takes the
same one. The terms between pedestrians are laid out in the dense rows the plain path sums (``ragged.exact_row_sums``)
and summed as numpy sums them (``exact.total``); only the pairs whose boxes come within reach are looked at, as in
``choosing._near_pairs`` (the others add 0).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from replays.constants import STEP_S
from st_sim.reactive.candidates import (
    ANTICIPATION_STEPS,
    CATCH_UP_FACTOR,
    CATCH_UP_MPS,
    DETOUR_BACK_FRAMES,
    DETOUR_COST,
    FREE_STEP_M,
    HEADWAY_M,
    LAG_PACE_MPS,
    NEAR_SLACK_M,
    OFFSETS_M,
    PATH_SAMPLES,
    PROGRESS_SHARES,
    ROBOT_WEIGHT,
    STUCK_COST,
    SWAY_COST,
    Step,
)
from st_sim.reactive.choosing import FIRST_LOOK, PAIR_REACH_M, RISK_COST, WALL_WEIGHT
from st_sim.reactive.compiled.exact import clip, length, maximum, minimum, total
from st_sim.reactive.compiled.geometry import robot_rows, swept_gap_within
from st_sim.reactive.compiled.tables import (
    RouteTables,
    depth_window,
    nearest_on_route,
    place,
    progress,
    tau_ahead,
    too_deep,
)
from st_sim.reactive.compiled.way_round import way_round
from st_sim.reactive.footprint import COMFORT_M, PAIR_BODY_M
from st_sim.reactive.reaction import MOVING_MPS
from st_sim.reactive.routes import Routes

SAMPLES = np.array(PATH_SAMPLES)
DRIFT_S = np.arange(1, ANTICIPATION_STEPS + 1) * STEP_S  # how far ahead the others are seen walking on [s]
GRID = len(PROGRESS_SHARES) + 1  # route points of a chooser's grid (and where its log is now) [-]
SIDES = len(OFFSETS_M) + 1  # side offsets of its grid (and its own) [-]
# the columns of a chooser's candidates: route point, side, x, y, the bounds it breaks (too fast, into the robot, too
# deep), the costs (fixed, no headway, way round), the risk round the robot; NaN until scored
TAU, SIDE, X, Y, TOO_FAST, INTO_ROBOT, TOO_DEEP, FIXED, STUCK, WAY, RISK = range(11)
COLUMNS = 11


class StepArrays(NamedTuple):
    """``Step``'s arrays as the kernels read them (N crowds, A agents), with the choosers' route points and sides.

    Attributes:
        index: (N,) int64.  start, xy: (N, A, 2) [m] (``xy`` updated as they choose).  present, off_log, detour:
            (N, A) bool.  velocity: (N, A, 2) [m/s].  stuck: (N, A) int64.  farthest: (N, A).  recent: (N, A, R) [m].
            weight: (N, A).  room: (N, A) [m].  aside_cost: (N, A) [1/m].  robot: (N, 8) from x, y, to x, y, cos,
            sin of its heading, velocity x, y.  tau, offset: (N, A) route points and sides [m] (updated as they choose).
    """

    index: np.ndarray
    start: np.ndarray
    xy: np.ndarray
    present: np.ndarray
    off_log: np.ndarray
    detour: np.ndarray
    velocity: np.ndarray
    stuck: np.ndarray
    farthest: np.ndarray
    recent: np.ndarray
    weight: np.ndarray
    room: np.ndarray
    aside_cost: np.ndarray
    robot: np.ndarray
    tau: np.ndarray
    offset: np.ndarray


def choose_compiled(routes: Routes, step: Step, tau: np.ndarray, offset: np.ndarray) -> None:
    """``choosing.choose_all``, compiled: ``step.xy``, ``step.chosen``, ``tau`` and ``offset`` (N, A) updated in
    place with the same places."""
    rows, agents = np.nonzero(step.off_log & ~step.chosen)
    if not len(agents):
        return
    gap = routes.body.gap_m(step.start[rows, agents] - step.robot.from_m[rows], step.robot.heading_rad[rows])
    order = np.lexsort((gap, rows))  # by crowd, then the nearest to the robot first (stable: by agent on ties)
    _choose(routes.tables(), StepArrays(step.index, step.start, step.xy, step.present, step.off_log, step.detour,
                                        step.velocity_mps, step.stuck, step.farthest, step.recent_m, step.weight,
                                        step.room_m, step.aside_cost, robot_rows(step.robot), tau, offset),
            rows[order], agents[order])
    step.chosen[rows, agents] = True


@njit(cache=True)
def _choose(t: RouteTables, s: StepArrays, rows: np.ndarray, agents: np.ndarray) -> None:
    """The choosers ``rows``, ``agents`` (J,) in turn choose: ``s.xy``, ``s.tau`` and ``s.offset`` updated in
    place."""
    horizon = max(t.anticipation_steps, ANTICIPATION_STEPS)
    counts = np.empty(len(agents), np.int64)
    for j in range(len(agents)):
        n, a = rows[j], agents[j]
        reach = maximum(CATCH_UP_MPS, CATCH_UP_FACTOR * t.log_speed_mps[int(s.tau[n, a]), a]) * STEP_S
        span = int(np.ceil(reach / FREE_STEP_M)) + 1
        counts[j] = GRID * SIDES + 1 + (2 * span + 1) ** 2 * s.detour[n, a]
    first = np.zeros(len(agents) + 1, np.int64)
    first[1:] = np.cumsum(counts)
    table = np.full((first[-1], COLUMNS), np.nan)
    later = np.full((first[-1], horizon, 2), np.nan)
    box = np.empty((len(agents), 4))
    size = np.empty(len(agents), np.int64)
    for j in range(len(agents)):
        size[j] = _candidates(t, s, rows[j], agents[j], horizon, table[first[j]:first[j + 1]], box[j])
    low, high = _boxes(s, rows, agents, table, first, size)
    for j in range(len(agents)):
        n, a = rows[j], agents[j]
        near = np.zeros(s.present.shape[1], np.bool_)
        for o in range(s.present.shape[1]):
            apart_x = maximum(maximum(low[n, o, 0] - box[j, 2], box[j, 0] - high[n, o, 0]), 0.0)
            apart_y = maximum(maximum(low[n, o, 1] - box[j, 3], box[j, 1] - high[n, o, 1]), 0.0)
            near[o] = length(apart_x, apart_y) < PAIR_REACH_M + NEAR_SLACK_M and s.present[n, o] and o != a
        mine = table[first[j]:first[j] + size[j]]
        best = _best(t, s, n, a, mine, later[first[j]:first[j] + size[j]], np.flatnonzero(near))
        s.xy[n, a, 0], s.xy[n, a, 1] = mine[best, X], mine[best, Y]
        s.tau[n, a], s.offset[n, a] = mine[best, TAU], mine[best, SIDE]


@njit(cache=True)
def _candidates(t: RouteTables, s: StepArrays, n: int, a: int, horizon: int, table: np.ndarray,
                box: np.ndarray) -> int:
    """Lay out chooser ``a`` of crowd ``n``'s candidates in ``table``'s rows (the columns ``TAU`` ... ``WAY``) and the
    box holding its start, candidates and its route over the next ``horizon`` frames (x low, y low, x high, y high)
    in ``box``, as ``candidates.place_candidates``; returns how many."""
    log, tangent, arc_m = t.log_xy_m[:, a], t.tangent[:, a], t.arc_m[:, a]
    idx, tau_now, side_now, farthest = s.index[n], s.tau[n, a], s.offset[n, a], s.farthest[n, a]
    run_frame = int(tau_now)
    first, last = t.run_first[run_frame, a], t.run_last[run_frame, a]
    p_first, p_last = t.run_first[int(farthest), a], t.run_last[int(farthest), a]  # the run progress is counted in
    here_x, here_y = s.start[n, a, 0], s.start[n, a, 1]
    cap = maximum(tau_now, float(min(idx, last)))  # never ahead of the log
    reach = maximum(CATCH_UP_MPS, CATCH_UP_FACTOR * t.log_speed_mps[run_frame, a]) * STEP_S
    taus = np.empty(GRID)
    for k in range(GRID - 1):
        taus[k] = tau_ahead(arc_m, first, last, tau_now, reach * PROGRESS_SHARES[k])
    taus[GRID - 1] = cap
    for k in range(GRID):
        taus[k] = clip(taus[k], float(first), cap)
    taus.sort()
    sides = np.empty(SIDES)
    sides[:SIDES - 1] = OFFSETS_M
    sides[SIDES - 1] = side_now
    sides.sort()
    count = 0
    for i in range(GRID):  # its route's grid, progress first, without repeats
        if i and taus[i] == taus[i - 1]:
            continue
        for k in range(SIDES):
            if k and sides[k] == sides[k - 1]:
                continue
            table[count, TAU], table[count, SIDE] = taus[i], sides[k]
            table[count, X], table[count, Y] = place(log, tangent, first, last, taus[i], sides[k])
            count += 1
    x, y = place(log, tangent, first, last, tau_now, side_now)  # where it stands, if off its grid (a free step)
    if length(x - here_x, y - here_y) > 0.0:
        table[count, TAU], table[count, SIDE], table[count, X], table[count, Y] = tau_now, side_now, here_x, here_y
        count += 1
    if s.detour[n, a]:  # its free steps, every FREE_STEP_M within its reach
        span = int(np.ceil(reach / FREE_STEP_M)) + 1
        low = max(first, int(np.floor(tau_now)) - DETOUR_BACK_FRAMES)
        for i in range(-span, span + 1):
            for k in range(-span, span + 1):
                step_x, step_y = FREE_STEP_M * float(i), FREE_STEP_M * float(k)
                if not length(step_x, step_y) <= reach:
                    continue
                x, y = here_x + step_x, here_y + step_y
                table[count, TAU], table[count, SIDE] = nearest_on_route(log, tangent, first, last, x, y, low,
                                                                         int(np.floor(cap)))
                table[count, X], table[count, Y] = x, y
                count += 1
    mine = table[:count]
    robot = s.robot[n]
    from_x, from_y, to_x, to_y, cos, sin = robot[0], robot[1], robot[2], robot[3], robot[4], robot[5]
    if not s.weight[n, a] > 0:  # not reacting: the robot's body where it stands
        to_x, to_y = from_x, from_y
    half_m, radius_m, corners, half_diagonal_m, reach_m = t.half_m, t.radius_m, t.corners, t.half_diagonal_m, \
        t.robot_reach_m
    delay_cost, aside_cost, stuck = t.delay_cost, s.aside_cost[n, a], s.stuck[n, a]
    recent_m = s.recent[n, a, 0]
    for k in range(1, s.recent.shape[2]):
        recent_m = minimum(recent_m, s.recent[n, a, k])
    for r in range(count):
        c_tau, c_side, c_x, c_y = mine[r, TAU], mine[r, SIDE], mine[r, X], mine[r, Y]
        mine[r, TOO_FAST] = maximum(length(c_x - here_x, c_y - here_y) - reach, 0.0)
        robot_gap = swept_gap_within(here_x - from_x, here_y - from_y, c_x - to_x, c_y - to_y, cos, sin, half_m,
                                     radius_m, corners, half_diagonal_m, reach_m)
        mine[r, INTO_ROBOT] = maximum(reach_m - robot_gap, 0.0)
        gain, behind = progress(arc_m, p_first, p_last, c_tau, farthest, idx)
        staying = gain < HEADWAY_M and behind + abs(c_side) > recent_m - HEADWAY_M  # candidates.no_headway
        delay = minimum(idx - c_tau, behind / (STEP_S * LAG_PACE_MPS))  # [frame]
        mine[r, FIXED] = delay_cost * delay + aside_cost * abs(c_side) + SWAY_COST * abs(c_side - side_now)
        mine[r, STUCK] = STUCK_COST * stuck * (1.0 if staying else 0.0)
        mine[r, WAY] = 0.0
    if s.detour[n, a]:
        standing = np.empty((s.present.shape[1], 2))
        others = 0
        for o in range(s.present.shape[1]):  # those standing round it block its way too
            if s.present[n, o] and o != a and length(s.velocity[n, o, 0], s.velocity[n, o, 1]) < MOVING_MPS:
                standing[others, 0], standing[others, 1] = s.start[n, o, 0], s.start[n, o, 1]
                others += 1
        way = way_round(t, a, idx, tau_now, farthest, mine[:, X:Y + 1], s.start[n, a], robot, standing[:others])
        for r in range(count):
            mine[r, WAY] = DETOUR_COST * way[r]
    # the box of its start, its candidates and its route over the next frames, widened by its farthest side
    least_tau, most_tau, aside = np.inf, -np.inf, -np.inf
    box[0], box[1], box[2], box[3] = np.inf, np.inf, -np.inf, -np.inf
    for r in range(count):
        least_tau, most_tau = minimum(least_tau, mine[r, TAU]), maximum(most_tau, mine[r, TAU])
        aside = maximum(aside, abs(mine[r, SIDE]))
        box[0], box[1] = minimum(box[0], mine[r, X]), minimum(box[1], mine[r, Y])
        box[2], box[3] = maximum(box[2], mine[r, X]), maximum(box[3], mine[r, Y])
    aside = aside + NEAR_SLACK_M
    box[0], box[1] = minimum(box[0], here_x), minimum(box[1], here_y)
    box[2], box[3] = maximum(box[2], here_x), maximum(box[3], here_y)
    window_low = int(np.floor(clip(least_tau + 1, float(first), float(last))))
    window_high = min(int(np.floor(clip(most_tau + horizon, float(first), float(last)))) + 1, last)
    route = np.array([np.inf, np.inf, -np.inf, -np.inf])
    for frame in range(window_low, window_high + 1):
        route[0], route[1] = minimum(route[0], log[frame, 0]), minimum(route[1], log[frame, 1])
        route[2], route[3] = maximum(route[2], log[frame, 0]), maximum(route[3], log[frame, 1])
    box[0], box[1] = minimum(box[0], route[0] - aside), minimum(box[1], route[1] - aside)
    box[2], box[3] = maximum(box[2], route[2] + aside), maximum(box[3], route[3] + aside)
    return count


@njit(cache=True)
def _boxes(s: StepArrays, rows: np.ndarray, agents: np.ndarray, table: np.ndarray, first: np.ndarray,
           size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) (N, A, 2): the box where each pedestrian may be during the step (where it stands and goes, any
    of its candidates for a chooser, walking on for one off its log), as ``choosing._near_pairs``."""
    low, high = np.fmin(s.start, s.xy), np.fmax(s.start, s.xy)
    for j in range(len(agents)):
        n, a = rows[j], agents[j]
        for r in range(first[j], first[j] + size[j]):
            for axis in range(2):
                low[n, a, axis] = minimum(low[n, a, axis], table[r, X + axis])
                high[n, a, axis] = maximum(high[n, a, axis], table[r, X + axis])
    for n in range(low.shape[0]):
        for o in range(low.shape[1]):
            if not s.off_log[n, o]:
                continue
            for axis in range(2):
                least, most = np.inf, -np.inf
                for k in range(len(DRIFT_S)):
                    drift = s.velocity[n, o, axis] * DRIFT_S[k]
                    least, most = minimum(least, drift), maximum(most, drift)
                low[n, o, axis] = minimum(low[n, o, axis], low[n, o, axis] + least)
                high[n, o, axis] = maximum(high[n, o, axis], high[n, o, axis] + most)
    return low, high


@njit(cache=True)
def _best(t: RouteTables, s: StepArrays, n: int, a: int, mine: np.ndarray, later: np.ndarray,
          near: np.ndarray) -> int:
    """The candidate (row of ``mine``) chooser ``a`` of crowd ``n`` takes, seeing the others ``near`` it (P,) at
    ``s.xy`` (those before it where they chose), scored lazily in ``choosing._best``'s order; ``later`` (C, H, 2)
    its candidates' walks on, filled as they are scored."""
    count = mine.shape[0]
    least_cost = np.empty(count)
    hopeful = np.empty(count, np.bool_)
    for r in range(count):
        least_cost[r] = mine[r, FIXED] + mine[r, STUCK] + mine[r, WAY]
        hopeful[r] = not (mine[r, TOO_FAST] + ROBOT_WEIGHT * mine[r, INTO_ROBOT] > 0)
    hopes = int(hopeful.sum())
    # those that may keep every bound first, least costly first (NaN last), then the others, each in their order
    order = np.concatenate((np.flatnonzero(hopeful)[np.argsort(least_cost[hopeful], kind="mergesort")],
                            np.flatnonzero(~hopeful)))
    # what its candidates' scores share: its log, its depth window, its robot, the others near it
    log, tangent, trace, trace_depth = t.log_xy_m[:, a], t.tangent[:, a], t.trace_m[:, a], t.trace_depth_m[:, a]
    run_frame = int(s.tau[n, a])
    first, last = t.run_first[run_frame, a], t.run_last[run_frame, a]
    window = depth_window(trace_depth, first, last, s.tau[n, a], 0.0, False)
    here_x, here_y, detour = s.start[n, a, 0], s.start[n, a, 1], s.detour[n, a]
    from_m, to_m, future_m, allowed_m, together_m, walks, column, walk_column, width, walk_width = \
        _others(t, s, n, a, near)
    rows, walk_rows = np.empty((2, width)), np.empty(ANTICIPATION_STEPS * walk_width)
    walk = np.empty((later.shape[1] + 1, 2))
    violation, cost = np.empty(count), np.empty(count)
    take = min(hopes, FIRST_LOOK) if hopes > 0 else count
    done, fine = 0, False
    while True:
        for p in range(done, take):
            r = order[p]
            c_x, c_y = mine[r, X], mine[r, Y]
            if mine[r, TOO_DEEP] != mine[r, TOO_DEEP]:  # alone: its depth along the way, its walk on, its risk
                deepest = 0.0
                for k in range(len(SAMPLES)):
                    deep = too_deep(trace, trace_depth, window, t.depth_m, t.to_pixel, t.affine, t.open_ground,
                                    here_x + SAMPLES[k] * (c_x - here_x), here_y + SAMPLES[k] * (c_y - here_y), False)
                    deepest = deep if k == 0 else maximum(deepest, deep)
                mine[r, TOO_DEEP] = deepest
                walk[0, 0], walk[0, 1] = c_x, c_y
                for k in range(later.shape[1]):  # along its route at its log's pace; on its way round where it steps
                    later[r, k, 0], later[r, k, 1] = place(log, tangent, first, last, mine[r, TAU] + (k + 1),
                                                           mine[r, SIDE])
                    walk[k + 1, 0], walk[k + 1, 1] = (c_x, c_y) if detour else (later[r, k, 0], later[r, k, 1])
                mine[r, RISK] = _robot_risk(walk, s.weight[n, a], s.room[n, a], s.robot[n], t.half_m, t.radius_m,
                                            t.corners, t.half_diagonal_m, t.robot_reach_m, t.anticipation_steps)
            too_close, pair_risk = _pair_terms(c_x, c_y, here_x, here_y, later[r], from_m, to_m, future_m, allowed_m,
                                               together_m, walks, column, walk_column, rows, walk_rows)
            violation[r] = (mine[r, TOO_FAST] + too_close + WALL_WEIGHT * mine[r, TOO_DEEP]
                            + ROBOT_WEIGHT * mine[r, INTO_ROBOT])
            cost[r] = mine[r, FIXED] + RISK_COST * (mine[r, RISK] + pair_risk) + mine[r, STUCK] + mine[r, WAY]
        done = take
        fine, cheapest = False, np.inf
        for p in range(take):
            r = order[p]
            fine = fine or violation[r] == 0
            affordable = np.inf if violation[r] > 0 else cost[r]
            cheapest = minimum(cheapest, affordable) if p else affordable
        needed = 0
        for p in range(hopes):
            needed += least_cost[order[p]] <= cheapest
        wider = max(take, needed) if fine else (min(2 * take, hopes) if take < hopes else count)
        if wider == take:
            break
        take = wider
    best, least = count, np.inf
    for p in range(take):  # as np.argmin over every row: the first of the least (NaN as -inf)
        r = order[p]
        value = (np.inf if violation[r] > 0 else cost[r]) if fine else violation[r]
        value = -np.inf if value != value else value
        if value < least or (value == least and r < best):
            best, least = r, value
    return best


@njit(cache=True, inline="always")
def _robot_risk(walk: np.ndarray, weight: float, room_m: float, robot: np.ndarray, half_m: np.ndarray,
                radius_m: float, corners: np.ndarray, half_diagonal_m: float, reach_m: float,
                anticipation_steps: int) -> float:
    """Squared intrusions [m^2] round the robot (``robot``: from x, y, to x, y, cos, sin of its heading, velocity x,
    y) of a walk (H + 1, 2) [m] of a pedestrian reacting by ``weight`` and keeping ``room_m``
    (``candidates._robot_risk``)."""
    from_x, from_y, to_x, to_y, cos, sin = robot[0], robot[1], robot[2], robot[3], robot[4], robot[5]
    risk = 0.0
    if weight < 1.0:  # a body in the way, standing where it is
        within = reach_m + COMFORT_M
        terms = np.empty(ANTICIPATION_STEPS)
        for k in range(ANTICIPATION_STEPS):
            gap = swept_gap_within(walk[k, 0] - from_x, walk[k, 1] - from_y, walk[k + 1, 0] - from_x,
                                   walk[k + 1, 1] - from_y, cos, sin, half_m, radius_m, corners, half_diagonal_m,
                                   within)
            into = maximum(within - gap, 0.0)
            terms[k] = into * into
        risk = (1.0 - weight) * total(terms, ANTICIPATION_STEPS)
    if weight > 0:  # the robot going on at its velocity, as far as it reacts
        within = reach_m + room_m
        moving = np.empty((anticipation_steps + 1, 2))
        for k in range(anticipation_steps + 1):
            moving[k, 0] = walk[k, 0] - (to_x + (k * STEP_S) * robot[6])
            moving[k, 1] = walk[k, 1] - (to_y + (k * STEP_S) * robot[7])
        terms = np.empty(anticipation_steps)
        for k in range(anticipation_steps):
            gap = swept_gap_within(moving[k, 0], moving[k, 1], moving[k + 1, 0], moving[k + 1, 1], cos, sin, half_m,
                                   radius_m, corners, half_diagonal_m, within)
            into = maximum(within - gap, 0.0)
            terms[k] = into * into
        risk = risk + weight * total(terms, anticipation_steps)
    return risk


class Others(NamedTuple):
    """The others near a chooser (P of them), what its candidates' terms with them need (``_pair_terms``).

    Attributes:
        from_m, to_m: (P, 2) where each is before and after the step as the chooser sees it [m].  future_m: (P, H, 2)
            where it walks on [m] (H = ``ANTICIPATION_STEPS``).  allowed_m: (P,) the least gap a step keeps from it
            [m].  together_m: (P,) the gap by the end of the step [m].  walks: (P,) bool, off its log.
        column: (P,) its column among the others present, ``walk_column`` (P,) among those off their logs; width,
            walk_width: how many of each.
    """

    from_m: np.ndarray
    to_m: np.ndarray
    future_m: np.ndarray
    allowed_m: np.ndarray
    together_m: np.ndarray
    walks: np.ndarray
    column: np.ndarray
    walk_column: np.ndarray
    width: int
    walk_width: int


@njit(cache=True)
def _others(t: RouteTables, s: StepArrays, n: int, a: int, near: np.ndarray) -> Others:
    """``Others`` near chooser ``a`` of crowd ``n``: the others ``near`` it (P,) ascending, where they are and walk
    on (those before it where they chose), and their columns in the dense rows the plain path sums
    (``choosing._pair_terms``)."""
    count = len(near)
    from_m, to_m = np.empty((count, 2)), np.empty((count, 2))
    future = np.empty((count, ANTICIPATION_STEPS, 2))
    allowed, together, walks = np.empty(count), np.empty(count), np.empty(count, np.bool_)
    column, walk_column = np.empty(count, np.int64), np.empty(count, np.int64)
    here_x, here_y, idx = s.start[n, a, 0], s.start[n, a, 1], s.index[n]
    width, walk_width, p = 0, 0, 0
    for o in range(s.present.shape[1]):
        if p < count and near[p] == o:
            column[p], walk_column[p] = width, walk_width
            from_m[p, 0], from_m[p, 1], to_m[p, 0], to_m[p, 1] = s.start[n, o, 0], s.start[n, o, 1], s.xy[n, o, 0], \
                s.xy[n, o, 1]
            for k in range(ANTICIPATION_STEPS):
                future[p, k, 0] = to_m[p, 0] + DRIFT_S[k] * s.velocity[n, o, 0]
                future[p, k, 1] = to_m[p, 1] + DRIFT_S[k] * s.velocity[n, o, 1]
            allowed[p] = minimum(PAIR_BODY_M, length(from_m[p, 0] - here_x, from_m[p, 1] - here_y) - 1e-6)
            logged = length(t.log_xy_m[idx, a, 0] - t.log_xy_m[idx, o, 0],
                            t.log_xy_m[idx, a, 1] - t.log_xy_m[idx, o, 1])
            together[p] = minimum(PAIR_BODY_M, np.inf if logged != logged else logged)  # closer now: part as logs do
            walks[p] = s.off_log[n, o]
            p += 1
        if o != a:
            width += s.present[n, o]
            walk_width += s.present[n, o] and s.off_log[n, o]
    return Others(from_m, to_m, future, allowed, together, walks, column, walk_column, width, walk_width)


@njit(cache=True, inline="always")
def _pair_terms(c_x: float, c_y: float, here_x: float, here_y: float, later: np.ndarray, from_m: np.ndarray,
                to_m: np.ndarray, future_m: np.ndarray, allowed_m: np.ndarray, together_m: np.ndarray,
                walks: np.ndarray, column: np.ndarray, walk_column: np.ndarray, rows: np.ndarray,
                walk_rows: np.ndarray) -> tuple[float, float]:
    """(too_close [m], pair_risk [m^2]) of a chooser at (here_x, here_y) stepping to (c_x, c_y) and walking on
    through ``later`` (H, 2), against the others near it (``Others``' fields; ``choosing._pair_terms``): each sum
    laid out in the dense row the plain path sums (``rows`` (2, width) and ``walk_rows`` (H walk_width,), zeroed
    here), those out of reach adding 0."""
    rows[:] = 0.0
    walk_rows[:] = 0.0
    walk_width = len(walk_rows) // ANTICIPATION_STEPS
    for p in range(len(allowed_m)):
        to_x, to_y = to_m[p, 0], to_m[p, 1]
        s_x, s_y = here_x - from_m[p, 0], here_y - from_m[p, 1]  # the least distance along the step
        d_x, d_y = (c_x - to_x) - s_x, (c_y - to_y) - s_y
        length2 = 0.0 + d_x * d_x + d_y * d_y
        share = clip(-(0.0 + s_x * d_x + s_y * d_y) / length2, 0.0, 1.0) if length2 > 0 else 0.0
        rows[0, column[p]] = maximum(allowed_m[p] - length(s_x + share * d_x, s_y + share * d_y), 0.0)
        rows[1, column[p]] = maximum(together_m[p] - length(c_x - to_x, c_y - to_y), 0.0)
        if walks[p]:  # walking on, against those off their logs
            for k in range(ANTICIPATION_STEPS):
                into = maximum(PAIR_REACH_M - length(later[k, 0] - future_m[p, k, 0], later[k, 1] - future_m[p, k, 1]),
                               0.0)
                walk_rows[k * walk_width + walk_column[p]] = into * into
    return total(rows[0], rows.shape[1]) + total(rows[1], rows.shape[1]), total(walk_rows, len(walk_rows))
