"""Where a pedestrian off its log may step in one 0.4 s step, and what each place costs on its own.

Each step it picks, among a grid of progress along its route (``PROGRESS_SHARES`` of the farthest it can walk in one,
from half a step back, or to where its log is now) and side offsets (``OFFSETS_M``, up to ``MAX_OFFSET_M``), the place
that loses the least time and strays the least (as its reaction weighs the two: ``Reaction.delay_cost`` a frame behind
its log, ``Reaction.aside_cost`` a metre aside) while

- it walks no faster than it can catch up (``CATCH_UP_MPS``, or ``CATCH_UP_FACTOR`` times its log's speed);
- along its step (at ``PATH_SAMPLES``) it is never deeper in the scene's non-walkable area, nor farther off the image,
  than its log near that point of its route (``Routes.too_deep_m``);
- along the whole step, moving in a straight line, it keeps ``ROBOT_MARGIN_M`` beyond touching the robot's body (as
  it expects the robot to move once it reacts; as the robot stands before);
- once it reacts, it keeps its room from where the robot will be over the reaction's anticipation; before, it keeps
  ``COMFORT_M`` from the robot's body where it stands (a body in its way, not a robot it expects to move) (costs, so
  that it steps aside early rather than at the last moment); one that has made no headway for a while
  (``HEADWAY_M``) pays ``STUCK_COST`` per such step for making none again, so that it tries another way round.

**The way round.** One that plans a way round (``ReactiveState.detour``) also pays ``DETOUR_COST`` per metre it would
have to walk from the place to its route a few metres ahead (``DETOUR_AHEAD_M``, but no farther than where its log
will be ``DETOUR_LEAD_STEPS`` on: it does not walk ahead to wait for its log), round the robot's body, the walls and
the others standing there (``detour.walking_distances_m``; where that point of its route is within the robot's reach,
to the nearest place clear of it). It follows that way off its route's grid too: it may step anywhere within its
reach (every ``FREE_STEP_M``; each such place counted at the point of its route nearest to it), and round the robot
it risks only where it stands, not along its route at its side. From a pocket between the robot and a wall, or
between the robot and where its log began, turned back or stood, it walks back out and round. One that stands off
its grid so may also stay where it is.

``place_candidates`` lays out every candidate of every pedestrian off its log, in every crowd, in one pass, with the
bounds and costs that need neither its depth, its risk nor the others (``Candidates``); ``score_alone`` adds its
depth and its risk round the robot when a candidate is looked at; the terms between pedestrians and the choice are
``st_sim.reactive.choosing``'s. A place that breaks a bound weighs ``ROBOT_WEIGHT`` per metre into the robot's margin.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from replays.constants import STEP_S
from st_sim.reactive.detour import cells_near, grid_cells, nearest_free_m, walking_distances_m
from st_sim.reactive.footprint import COMFORT_M, PAIR_BODY_M, Robot, length_m
from st_sim.reactive.ragged import distinct
from st_sim.reactive.reaction import MOVING_MPS
from st_sim.reactive.routes import Routes

CATCH_UP_MPS: Final[float] = 1.8  # fastest a pedestrian walks to catch up with its log [m/s] ...
CATCH_UP_FACTOR: Final[float] = 1.25  # ... or this multiple of its log's own speed, if that is faster [-]
MAX_OFFSET_M: Final[float] = 3.0  # farthest a pedestrian steps to the side of its route [m]
PROGRESS_SHARES: Final[np.ndarray] = np.linspace(-0.5, 1.0, 25)  # progress along the route it may choose per step,
"""as shares of the farthest it can walk in one (and catching up with its log at once); back up to half a step [-]"""
OFFSETS_M: Final[np.ndarray] = np.linspace(-MAX_OFFSET_M, MAX_OFFSET_M, 31)  # side offsets it may choose [m]
ANTICIPATION_STEPS: Final[int] = 3  # it keeps clear of where the others off their logs will be over this many steps
LAG_PACE_MPS: Final[float] = 1.0  # a delay counts at most the time to walk what it is behind at this pace [m/s]
SWAY_COST: Final[float] = 0.2  # cost of changing its side offset by a metre in one step [1/m]
STUCK_COST: Final[float] = 0.5  # cost of making no headway again, per step it already made none off its log [-]
HEADWAY_M: Final[float] = 0.05  # ... a step makes none that gets it less than this farther along its route than it has
"""been, or nearer to its log (metres behind it along the route plus metres aside) than in its last ``RECENT_STEPS``
[m]"""
RECENT_STEPS: Final[int] = 5  # ... steps (2 s)
PATH_SAMPLES: Final[tuple[float, ...]] = (0.25, 0.5, 0.75, 1.0)  # where along a step the map bound is checked [-]
ROBOT_WEIGHT: Final[float] = 1e4  # with no place within every bound: a metre into the robot's margin weighs 10^4 of
"""the others and its pace (it stands still rather than step in) [-]"""
DETOUR_AHEAD_M: Final[tuple[float, ...]] = (3.0, 3.5, 4.0, 4.5, 5.0)  # one that plans a way round plans it to the
"""first of these points of its route beyond the farthest it has reached that is clear of the robot (or to where its
log ends, if nearer; with none clear, to the last, or the free place nearest to it) [m] ..."""
DETOUR_LEAD_STEPS: Final[int] = 5  # ... nor beyond where its log will be this many 0.4 s steps on [-] ...
DETOUR_MARGIN_M: Final[float] = 1.5  # ... on a grid reaching this far round it, the goal and its candidates [m]
DETOUR_BACK_FRAMES: Final[int] = 16  # ... and round its route from this many frames behind its route point [-]
DETOUR_COST: Final[float] = 10.0  # ... and pays this per metre it would then have to walk to that point [1/m]
FREE_STEP_M: Final[float] = 0.2  # ... and may also step off its route's grid, anywhere within reach on a grid this fine
NEAR_SLACK_M: Final[float] = 1e-6  # boxes are apart only beyond a reach plus this [m]


@dataclass(frozen=True, eq=False)
class Step:
    """What the pedestrians off their log see while they choose within one step of N crowds to frames ``index`` (N,):
    rows are crowds, columns the replay's agents.

    Attributes:
        start: (N, A, 2) positions before the step [m].  xy: (N, A, 2) positions after it, as far as chosen (the log
            for those on it, the choice for those who chose, the start for those yet to choose) [m].
        present, off_log, chosen: (N, A) bool.  velocity_mps: (N, A, 2) velocities over the previous step [m/s].
        stuck, farthest, recent_m, detour: as ``ReactiveState`` (N, A, ...), for this step.
        weight: (N, A) how far each reacts to its crowd's robot in this step, in [0, 1].  room_m: (N, A) the room it
            keeps [m].  aside_cost: (N, A) what a metre aside costs it [1/m].
    """

    index: np.ndarray
    start: np.ndarray
    xy: np.ndarray
    present: np.ndarray
    off_log: np.ndarray
    chosen: np.ndarray
    velocity_mps: np.ndarray
    stuck: np.ndarray
    farthest: np.ndarray
    recent_m: np.ndarray
    detour: np.ndarray
    robot: Robot
    weight: np.ndarray
    room_m: np.ndarray
    aside_cost: np.ndarray


@dataclass(frozen=True, eq=False)
class Candidates:
    """The places every chooser (a pedestrian off its log, J of them in all crowds) may choose in one step, its C
    candidates in a row (M = sum of C in all, in the order of its own grid: progress, then side; then where it
    stands, if off its grid, and its free steps, if it takes its way round).

    Attributes:
        owner: (M,) chooser.  first: (J + 1,) where each chooser's rows start.  tau_now: (J,) the route point
            each chooser's place is taken from now.
        tau: (M,) route point.  offset_m: (M,) side [m].  xy_m: (M, 2) position [m].
        too_fast, into_robot: (M,) two of the bounds it breaks (``violation``).  too_deep: (M,) a third, NaN until
            scored (``score_alone``).
        fixed_cost: (M,) delay, offset and sway.  stuck_cost: (M,) no headway again.  way_cost: (M,) the way round
            (0 where none is planned).  risk: (M,) round the robot [m^2], NaN until scored.
        later_m: (M, H, 2) where it would walk on over the longer of ``ANTICIPATION_STEPS`` and the reaction's
            anticipation [m], NaN until scored.
        box_m: (J, 4) box (x low, y low, x high, y high) [m] holding each chooser's start, candidates and ``later_m``
            (its log over those frames, widened by its farthest side offset).
        least_cost: (M,) the least its cost can be (with no risk): the cost of a place that breaks no bound.
        order: (M,) each chooser's rows, those that may break no bound first (``too_fast`` and ``into_robot`` 0) by
            ``least_cost``, then the others.  hopeful: (J,) how many of each chooser's rows may break no bound.
    """

    owner: np.ndarray
    first: np.ndarray
    tau_now: np.ndarray
    tau: np.ndarray
    offset_m: np.ndarray
    xy_m: np.ndarray
    too_fast: np.ndarray
    into_robot: np.ndarray
    too_deep: np.ndarray
    fixed_cost: np.ndarray
    stuck_cost: np.ndarray
    way_cost: np.ndarray
    risk: np.ndarray
    later_m: np.ndarray
    box_m: np.ndarray
    least_cost: np.ndarray
    order: np.ndarray
    hopeful: np.ndarray


def place_candidates(routes: Routes, step: Step, rows: np.ndarray, agents: np.ndarray, tau: np.ndarray,
                     offset: np.ndarray) -> Candidates:
    """Every place the choosers ``rows``, ``agents`` (J,), now at route points ``tau`` and sides ``offset`` (J,),
    may choose, with the bounds and costs that do not need its depth, its risk or the others, in one pass."""
    index, run_frame = step.index[rows], tau.astype(int)
    here = step.start[rows, agents]  # (J, 2)
    first, last = routes.run_first[run_frame, agents], routes.run_last[run_frame, agents]
    cap = np.maximum(tau, np.minimum(index, last).astype(np.float64))  # never ahead of the log
    reach_m = np.maximum(CATCH_UP_MPS, CATCH_UP_FACTOR * routes.log_speed_mps[run_frame, agents]) * STEP_S
    owner, c_tau, c_off = _route_grid(routes, agents, tau, offset, run_frame, first, cap, reach_m)
    places = routes.place(agents[owner], c_tau, c_off, run_frame[owner])  # (M, 2)
    # after the grid's: where it stands, if off its grid (a free step took it there), and the free steps of those
    # taking their way round
    stays = np.flatnonzero(length_m(routes.place(agents, tau, offset, run_frame) - here) > 0.0)
    detour = np.flatnonzero(step.detour[rows, agents])
    extra = [(stays, tau[stays], offset[stays], here[stays])]
    if detour.size:
        extra.append(_free_steps(routes, detour, agents, here, tau, run_frame, first, cap, reach_m))
    parts = [(owner, c_tau, c_off, places), *extra]
    keep = np.argsort(np.concatenate([part[0] for part in parts]), kind="stable")
    owner, c_tau, c_off, places = (np.concatenate(column)[keep] for column in zip(*parts, strict=True))
    a, start = agents[owner], here[owner]
    too_fast = np.maximum(length_m(places - start) - reach_m[owner], 0.0)
    robot, heading = step.robot, step.robot.heading_rad[rows][owner]
    reacts = step.weight[rows, agents] > 0
    robot_to = np.where(reacts[:, None], robot.to_m[rows], robot.from_m[rows])[owner]  # noticed, or its body
    robot_gap = routes.body.swept_gap_within_m(start - robot.from_m[rows][owner], places - robot_to, heading,
                                               routes.robot_reach_m)
    into_robot = np.maximum(routes.robot_reach_m - robot_gap, 0.0)
    gain, behind = routes.progress(a, c_tau, step.farthest[rows, agents][owner], index[owner])
    staying = no_headway(gain, behind + np.abs(c_off), step.recent_m[rows, agents].min(axis=1)[owner])
    delay = np.minimum(index[owner] - c_tau, behind / (STEP_S * LAG_PACE_MPS))  # [frame]
    fixed_cost = (routes.reaction.delay_cost * delay + step.aside_cost[rows, agents][owner] * np.abs(c_off)
                  + SWAY_COST * np.abs(c_off - offset[owner]))
    stuck_cost = STUCK_COST * step.stuck[rows, agents][owner] * staying
    firsts = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=len(agents)))])
    way_cost = np.zeros(len(owner))
    if detour.size:
        way = _way_round_m(routes, step, rows[detour], agents[detour], tau[detour], run_frame[detour],
                           [places[firsts[j]:firsts[j + 1]] for j in detour])
        for j, way_m in zip(detour, way, strict=True):
            way_cost[firsts[j]:firsts[j + 1]] = DETOUR_COST * way_m
    horizon = max(routes.reaction.anticipation_steps, ANTICIPATION_STEPS)
    # where each may walk on to: its route's points over those frames (the log between them), moved aside
    ahead = np.clip(np.c_[np.minimum.reduceat(c_tau, firsts[:-1]) + 1, np.maximum.reduceat(c_tau, firsts[:-1])
                          + horizon], first[:, None], last[:, None])
    window, inside = routes.frames_of(agents, np.floor(ahead[:, 0]).astype(int),
                                      np.minimum(np.floor(ahead[:, 1]).astype(int) + 1, last))
    route = routes.log_xy_m[window]  # (J, W, 2)
    aside = np.maximum.reduceat(np.abs(c_off), firsts[:-1])[:, None] + NEAR_SLACK_M
    box = np.c_[np.minimum(np.minimum(np.minimum.reduceat(places, firsts[:-1]), here),
                           np.where(inside[..., None], route, np.inf).min(axis=1) - aside),
                np.maximum(np.maximum(np.maximum.reduceat(places, firsts[:-1]), here),
                           np.where(inside[..., None], route, -np.inf).max(axis=1) + aside)]
    least_cost = fixed_cost + stuck_cost + way_cost  # the cost with no risk: no more than any cost
    hopeful = ~(too_fast + ROBOT_WEIGHT * into_robot > 0)  # no more than any violation
    order = np.lexsort((np.where(hopeful, least_cost, 0.0), ~hopeful, owner))
    return Candidates(owner, firsts, tau, c_tau, c_off, places, too_fast, into_robot, np.full(len(owner), np.nan),
                      fixed_cost, stuck_cost, way_cost, np.full(len(owner), np.nan),
                      np.full((len(owner), horizon, 2), np.nan), box, least_cost,
                      order, np.bincount(owner, hopeful, minlength=len(agents)).astype(int))


def _route_grid(routes: Routes, agents: np.ndarray, tau: np.ndarray, offset: np.ndarray, run_frame: np.ndarray,
                first: np.ndarray, cap: np.ndarray, reach_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(owner (M,), tau (M,), offset_m (M,)): each chooser's grid of route points (``PROGRESS_SHARES`` of its reach
    ``reach_m`` from ``tau``, and ``cap``, within ``first``..``cap``) and side offsets (``OFFSETS_M`` and its own
    ``offset``), progress first, without repeats; the arguments (J,)."""
    taus = routes.tau_ahead(agents, tau, reach_m[:, None] * PROGRESS_SHARES, run_frame)
    taus = np.sort(np.clip(np.concatenate([taus, cap[:, None]], axis=1), first[:, None], cap[:, None]), axis=1)
    sides = np.sort(np.concatenate([np.broadcast_to(OFFSETS_M, (len(agents), len(OFFSETS_M))), offset[:, None]],
                                   axis=1), axis=1)
    grid = distinct(taus)[:, :, None] & distinct(sides)[:, None, :]  # (J, T, O): the tau-major grid of each
    owner, t_col, o_col = np.nonzero(grid)
    return owner, taus[owner, t_col], sides[owner, o_col]


def _free_steps(routes: Routes, detour: np.ndarray, agents: np.ndarray, here: np.ndarray, tau: np.ndarray,
                run_frame: np.ndarray, first: np.ndarray, cap: np.ndarray, reach_m: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(owner (F,), tau (F,), offset_m (F,), xy_m (F, 2)): the places off their route's grid that the choosers
    ``detour`` (D,) taking their way round may step to, every ``FREE_STEP_M`` within their reach of where they are
    (``here`` (J, 2) [m]), each with the point of its route nearest to it (from ``DETOUR_BACK_FRAMES`` behind ``tau``
    to ``cap``) and its side of it; the other arguments (J,)."""
    span = np.arange(-np.ceil(reach_m[detour].max() / FREE_STEP_M), np.ceil(reach_m[detour].max() / FREE_STEP_M) + 1)
    pattern = FREE_STEP_M * np.stack(np.meshgrid(span, span, indexing="ij"), axis=-1).reshape(-1, 2)  # (S, 2)
    j, k = np.nonzero(length_m(pattern)[None] <= reach_m[detour][:, None])
    owner = detour[j]
    xy = here[owner] + pattern[k]
    low = np.maximum(first[owner], np.floor(tau[owner]).astype(int) - DETOUR_BACK_FRAMES)
    c_tau, c_off = routes.nearest_on_route(agents[owner], xy, low, np.floor(cap[owner]).astype(int), run_frame[owner])
    return owner, c_tau, c_off, xy


def no_headway(gain_m: np.ndarray, away_m: np.ndarray, recent_m: np.ndarray) -> np.ndarray:
    """(K,) bool: places that make no headway: less than ``HEADWAY_M`` farther along the route than the pedestrian has
    been (``gain_m``) and no nearer to its log (``away_m``: metres behind it along the route plus metres aside) than
    in its last ``RECENT_STEPS`` steps (``recent_m``, the nearest of them), all (K,) [m]."""
    return (gain_m < HEADWAY_M) & (away_m > recent_m - HEADWAY_M)


def score_alone(routes: Routes, step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates,
                scored: np.ndarray) -> None:
    """Score ``too_deep``, ``later_m`` and ``risk`` (round the robot) of the rows ``scored`` of ``c`` not scored
    yet, in place."""
    new = scored[np.isnan(c.too_deep[scored])]
    if not new.size:
        return
    j = c.owner[new]
    crowd, agent, tau = rows[j], agents[j], c.tau_now[j]
    run_frame = tau.astype(int)
    start = step.start[crowd, agent]
    path = start[:, None] + np.array(PATH_SAMPLES)[:, None] * (c.xy_m[new] - start)[:, None]  # along the way
    c.too_deep[new] = routes.too_deep_m(agent[:, None], tau[:, None], path, run_frame[:, None]).max(axis=1)
    c.later_m[new] = routes.place(agent[:, None], c.tau[new][:, None] + np.arange(1, c.later_m.shape[1] + 1),
                                  c.offset_m[new][:, None], run_frame[:, None])  # along its route at its log's pace
    # one that plans a way round takes it, not its route at its side: round the robot it risks only where it stands
    walk_on = np.where(step.detour[crowd, agent][:, None, None], c.xy_m[new][:, None], c.later_m[new])
    c.risk[new] = _robot_risk(routes, step, crowd, agent, np.concatenate([c.xy_m[new][:, None], walk_on], axis=1))


def _robot_risk(routes: Routes, step: Step, rows: np.ndarray, agents: np.ndarray, walk: np.ndarray) -> np.ndarray:
    """(K,) squared intrusions [m^2], if ``agents`` in crowds ``rows`` (K,) walk on along their routes at their
    logs' pace through ``walk`` (K, H + 1, 2) [m] (from the candidate on, ``Candidates.later_m``): into their
    room round the robot going on at its velocity over ``anticipation_s`` (as far as they react), or into
    ``COMFORT_M`` round the robot's body standing where it is over ``ANTICIPATION_STEPS`` (as far as they do not:
    a body in the way)."""
    weight, robot, heading = step.weight[rows, agents], step.robot, step.robot.heading_rad[rows]
    robot_steps = routes.reaction.anticipation_steps
    risk = np.zeros(len(rows))  # as far as it does not react (0 for those that react fully: 0 times a finite sum)
    body = np.flatnonzero(weight < 1.0)
    standing = walk[body, :ANTICIPATION_STEPS + 1] - robot.from_m[rows[body]][:, None]  # from the body standing
    gap = routes.body.swept_gap_within_m(standing[:, :-1], standing[:, 1:], heading[body][:, None],
                                         routes.robot_reach_m + COMFORT_M)  # (B, H_s)
    risk[body] = (1.0 - weight[body]) * (np.maximum(routes.robot_reach_m + COMFORT_M - gap, 0.0) ** 2).sum(axis=1)
    react = np.flatnonzero(weight > 0)
    if react.size:
        ahead = np.arange(robot_steps + 1, dtype=np.float64)
        course = robot.to_m[rows[react]][:, None] + (ahead[:, None] * STEP_S)[None] \
            * robot.velocity_mps[rows[react]][:, None]  # (R, H_r + 1, 2)
        moving = walk[react, :robot_steps + 1] - course  # from the body on its course
        room = routes.robot_reach_m + step.room_m[rows[react], agents[react]]
        gap = routes.body.swept_gap_within_m(moving[:, :-1], moving[:, 1:], heading[react][:, None],
                                             room[:, None])  # (R, H_r)
        risk[react] = risk[react] + weight[react] * (np.maximum(room[:, None] - gap, 0.0) ** 2).sum(axis=1)
    return risk


def _way_round_m(routes: Routes, step: Step, rows: np.ndarray, agents: np.ndarray, tau: np.ndarray,
                 run_frame: np.ndarray, places: list[np.ndarray]) -> list[np.ndarray]:
    """For each of the choosers ``rows``, ``agents`` (D,) at route points ``tau`` (D,): (C,) how far [m] it would
    have to walk from each of its ``places`` (C, 2) to a point of its route ahead (``DETOUR_AHEAD_M``; where that
    point is within the robot's reach, the nearest place clear of it) round the robot's body (where it stands and
    where it is expected) and the others standing there (slower than ``MOVING_MPS``; no closer to their centres than
    a step may come, ``PAIR_BODY_M``: a gap a step may not pass is closed to the way round too), over ground no deeper
    in the non-walkable area than its log there (its route from ``DETOUR_BACK_FRAMES`` behind route point ``tau`` to
    that point); counted from the nearest, and those cut off from that point 1 m beyond the farthest (0 for all when
    none can reach it). The shortest walks of all of them are found in one search."""
    robot = step.robot
    ends = (robot.from_m[rows], robot.to_m[rows], robot.heading_rad[rows])  # (D, 2), (D, 2), (D,)
    ahead = routes.tau_ahead(agents, step.farthest[rows, agents], np.broadcast_to(DETOUR_AHEAD_M, (len(rows), 5)),
                             run_frame)  # (D, 5) to its run's end
    ahead = np.minimum(ahead, (step.index[rows] + DETOUR_LEAD_STEPS)[:, None])  # not where its log is much later
    goals = routes.place(agents[:, None], ahead, np.zeros(ahead.shape), run_frame[:, None])  # (D, 5, 2)
    clear = routes.clear_of_robot(goals, *(end[:, None] for end in ends))
    pick = np.where(clear.any(axis=1), np.argmax(clear, axis=1), len(DETOUR_AHEAD_M) - 1)  # else the farthest
    goal_tau, goal = ahead[np.arange(len(rows)), pick], goals[np.arange(len(rows)), pick]
    back = np.maximum(routes.run_first[run_frame, agents].astype(np.float64), tau - DETOUR_BACK_FRAMES)
    way = [np.zeros(len(p)) for p in places]
    grids, clear_cells = [], []
    for j in range(len(rows)):
        route = routes.log_xy_m[int(back[j]):int(np.ceil(goal_tau[j])) + 1, agents[j]]
        around = np.vstack([places[j], route, goal[j][None], step.start[rows[j], agents[j]][None]])
        grids.append(grid_cells(around.min(axis=0) - DETOUR_MARGIN_M, around.max(axis=0) + DETOUR_MARGIN_M))
        standing = step.present[rows[j]] & (length_m(step.velocity_mps[rows[j]]) < MOVING_MPS)
        standing[agents[j]] = False  # those standing round it block its way too, as close as a step may come
        clear_cells.append(routes.clear_of_robot(grids[-1].reshape(-1, 2), *(end[j] for end in ends))
                           & ~cells_near(grids[-1], step.start[rows[j]][standing], PAIR_BODY_M).ravel())
    cells = np.concatenate([grid.reshape(-1, 2) for grid in grids])
    whose = np.repeat(np.arange(len(grids)), [grid.shape[0] * grid.shape[1] for grid in grids])
    free = np.concatenate(clear_cells)
    free[free] = routes.too_deep_m(agents[whose][free], back[whose][free], cells[free], run_frame[whose][free],
                                   through=goal_tau[whose][free]) == 0
    cuts = np.cumsum([grid.shape[0] * grid.shape[1] for grid in grids])[:-1]
    free_cells = [f.reshape(g.shape[:2]) for f, g in zip(np.split(free, cuts), grids, strict=True)]
    reachable = np.array([nearest_free_m(*grid) for grid in zip(grids, free_cells, goal, strict=True)])
    walks = walking_distances_m(grids, free_cells, reachable, places)
    for j, walk_m in enumerate(walks):
        known = np.isfinite(walk_m)
        if known.any():
            nearest, farthest = walk_m[known].min(), walk_m[known].max()
            way[j] = np.where(known, walk_m - nearest, farthest - nearest + 1.0)
    return way
