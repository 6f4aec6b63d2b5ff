"""How the pedestrians off their logs choose their places in one step: one after another, the nearest to the robot
first, each seeing the choices made before it, batched in rounds.

A candidate place (``st_sim.reactive.candidates``) is also scored against the others: along the whole step, moving in a
straight line, it keeps ``PAIR_BODY_M`` from everybody else (or at least the gap it already had, and that much again
by the end of the step where their logs are that far apart), a bound; and it keeps its body's
width from where the others off their logs will be over ``ANTICIPATION_STEPS`` (a cost, ``RISK_COST`` per square
metre of intrusion, as round the robot: it steps aside early rather than at the last moment). Each pedestrian takes
the cheapest place within every bound or, when none is, the one that breaks them least: a metre into the robot's
margin weighs ``ROBOT_WEIGHT``, into a wall ``WALL_WEIGHT``, into the others or beyond its pace 1.

**Batched, with the same walks.** Every candidate of every chooser, in every crowd, is placed in one pass; its depth,
its risk and the terms between pedestrians are scored only for the candidates that could still be chosen (a
candidate costs at least its cost with no risk: ``_best`` scores them least costly first until the cheapest within
every bound is cheaper than every one left). The pedestrians of each crowd choose in rounds (``choose_all``): all at
once against the others where they stand, then again only those that see, before them in their crowd's order, a
pedestrian within reach whose choice changed, until none changes; each has then chosen seeing the choices made before
it, as one after another. Terms are summed over the others as numpy sums them all (``ragged.exact_row_sums``): the
walks are those of scoring every pedestrian alone, to the last bit (``tests/test_reactive_batched.py``;
``benchmarks/bench_reactive.py --digest``).
"""

from __future__ import annotations

from typing import Final

import numpy as np

from replays.constants import STEP_S
from st_sim.reactive.candidates import (
    ANTICIPATION_STEPS,
    NEAR_SLACK_M,
    ROBOT_WEIGHT,
    Candidates,
    Step,
    place_candidates,
    score_alone,
)
from st_sim.reactive.footprint import BODY_RADIUS_M, COMFORT_M, PAIR_BODY_M, length_m
from st_sim.reactive.ragged import exact_row_sums, spans
from st_sim.reactive.routes import Routes
from st_sim.sim.sweep import closest_approach

RISK_COST: Final[float] = 10.0  # cost of the anticipated intrusions into the room round the robot and others [1/m^2]
WALL_WEIGHT: Final[float] = 100.0  # with no candidate within every bound: a metre into a wall weighs 100 of the rest
PAIR_REACH_M: Final[float] = 2 * BODY_RADIUS_M + COMFORT_M / 2  # the farthest two pedestrians' terms reach [m]
FIRST_LOOK: Final[int] = 32  # candidates each chooser scores in full at first, those least costly first [-]


def choose_all(routes: Routes, step: Step, tau: np.ndarray, offset: np.ndarray) -> None:
    """Every pedestrian off its log and not placed yet takes the cheapest of its candidates that keeps every
    bound (see the module docstring), or the one that breaks them the least; ``step.xy``, ``tau`` and ``offset``
    (N, A) are updated in place.

    In each crowd they choose one after another, the nearest to the robot first, each seeing the choices made
    before it. Here every candidate is scored in one pass, then the terms between pedestrians in rounds: the
    first round scores every chooser against the others where they stand, and each further round only those
    that see a pedestrian of their crowd before them whose choice changed in the last round (one that chose to
    stand where it stood changed nothing). When no choice changes, each is the one it makes seeing the choices
    before it: the walks are those of one after another.
    """
    rows, agents = np.nonzero(step.off_log & ~step.chosen)
    if not len(agents):
        return
    gap = routes.body.gap_m(step.start[rows, agents] - step.robot.from_m[rows], step.robot.heading_rad[rows])
    order = np.lexsort((gap, rows))  # by crowd, then the nearest to the robot first (stable: by agent on ties)
    rows, agents = rows[order], agents[order]
    c = place_candidates(routes, step, rows, agents, tau[rows, agents], offset[rows, agents])
    turn = np.full(step.present.shape, len(agents))  # (N, A) each chooser's turn; the others' come last
    turn[rows, agents] = np.arange(len(agents))
    near = _near_pairs(step, rows, agents, c)
    seen = step.xy.copy()  # (N, A, 2) the choices as they stand, for those whose turn comes later
    best = np.full(len(agents), -1)
    pending = np.arange(len(agents))
    while pending.size:
        choice = _best(routes, step, rows, agents, c, pending, near, seen, turn)
        moved = pending[(c.xy_m[choice] != seen[rows[pending], agents[pending]]).any(axis=-1)]  # as the others see
        best[pending] = choice
        seen[rows[moved], agents[moved]] = c.xy_m[best[moved]]
        changed = np.zeros(step.present.shape, bool)
        changed[rows[moved], agents[moved]] = True
        chooser, other = near
        again = changed[rows[chooser], other] & (turn[rows[chooser], other] < chooser)
        pending = np.unique(chooser[again])
    tau[rows, agents], offset[rows, agents] = c.tau[best], c.offset_m[best]
    step.xy[rows, agents] = c.xy_m[best]
    step.chosen[rows, agents] = True


def _near_pairs(step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates) -> tuple[np.ndarray, np.ndarray]:
    """(chooser (P,), agent (P,)): the pairs of a chooser (of ``rows``, ``agents`` (J,)) and a pedestrian present
    in its crowd whose terms can be other than 0: the box where the other may be during the step (where it
    stands and goes, any of its candidates for a chooser, walking on for one off its log) comes within
    ``PAIR_REACH_M`` of the chooser's (``Candidates.box_m``)."""
    low, high = np.fmin(step.start, step.xy), np.fmax(step.start, step.xy)  # (N, A, 2)
    low[rows, agents] = np.minimum(low[rows, agents], np.minimum.reduceat(c.xy_m, c.first[:-1]))
    high[rows, agents] = np.maximum(high[rows, agents], np.maximum.reduceat(c.xy_m, c.first[:-1]))
    drift = step.velocity_mps[..., None, :] * (np.arange(1, ANTICIPATION_STEPS + 1) * STEP_S)[:, None]
    walks = step.off_log[..., None]
    low = np.where(walks, np.minimum(low, low + drift.min(axis=-2)), low)
    high = np.where(walks, np.maximum(high, high + drift.max(axis=-2)), high)
    apart = np.maximum(np.maximum(low[rows] - c.box_m[:, None, 2:], c.box_m[:, None, :2] - high[rows]), 0.0)
    near = ((length_m(apart) < PAIR_REACH_M + NEAR_SLACK_M) & step.present[rows]
            & (np.arange(step.present.shape[1]) != agents[:, None]))
    return np.nonzero(near)


def _best(routes: Routes, step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates, pending: np.ndarray,
          near: tuple[np.ndarray, np.ndarray], seen: np.ndarray, turn: np.ndarray) -> np.ndarray:
    """(T,) the candidate each of the choosers ``pending`` (T,) takes, seeing the choices ``seen`` (N, A, 2) of
    those whose ``turn`` (N, A) comes before theirs, the others where they stand (``step.xy``).

    A candidate's cost is at least its ``least_cost``, and one that breaks ``too_fast`` or ``into_robot`` breaks
    a bound: each chooser scores its candidates in full in the order of ``Candidates.order``, first
    ``FIRST_LOOK`` of them, until every hopeful one it has not scored costs at least more than the cheapest
    within every bound it has (all of them if none is). What it leaves unscored could not have been chosen. A
    row's terms do not depend on the others scored with it: each widening scores only the rows it adds."""
    count, hopeful = c.first[pending + 1] - c.first[pending], c.hopeful[pending]
    take = np.where(hopeful > 0, np.minimum(hopeful, FIRST_LOOK), count)
    done = np.zeros(len(pending), int)  # how many of each chooser's rows (in ``c.order``) are scored
    violation, cost = np.empty(len(c.owner)), np.empty(len(c.owner))  # of the rows of ``c`` scored
    while True:
        grew = np.flatnonzero(take > done)
        new = c.order[spans(c.first[pending[grew]] + done[grew], take[grew] - done[grew])]
        violation[new], cost[new] = _score(routes, step, rows, agents, c, pending[grew], new,
                                           np.repeat(np.arange(len(grew)), take[grew] - done[grew]), near, seen, turn)
        done = take
        local = np.repeat(np.arange(len(pending)), take)
        scored = c.order[spans(c.first[pending], take)]  # (R,) rows of c, each chooser's in a run
        starts = np.cumsum(take) - take
        fine = np.logical_or.reduceat(violation[scored] == 0, starts)
        cheapest = np.minimum.reduceat(np.where(violation[scored] > 0, np.inf, cost[scored]), starts)  # (T,)
        runs = spans(c.first[pending], hopeful)  # every hopeful row of the pending choosers
        owner = np.repeat(np.arange(len(pending)), hopeful)
        needed = np.bincount(owner, c.least_cost[c.order[runs]] <= cheapest[owner], minlength=len(pending))
        wider = np.where(fine, np.maximum(take, needed.astype(int)),
                         np.where(take < hopeful, np.minimum(2 * take, hopeful), count))
        if (wider == take).all():
            break
        take = wider
    violation, cost = violation[scored], cost[scored]
    key = np.where(fine[local], np.where(violation > 0, np.inf, cost), violation)  # as np.argmin over all rows
    key = np.where(np.isnan(key), -np.inf, key)  # (np.argmin takes the first NaN)
    least = np.minimum.reduceat(key, starts)
    return np.minimum.reduceat(np.where(key == least[local], scored, len(c.owner)), starts)


def _score(routes: Routes, step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates, pending: np.ndarray,
           scored: np.ndarray, local: np.ndarray, near: tuple[np.ndarray, np.ndarray], seen: np.ndarray,
           turn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(violation, cost), (R,) each, of the candidate rows ``scored`` (R,) of the choosers ``pending`` (T,)
    (``local`` (R,): which of them a row is of), seeing the choices ``seen`` of those before them: ``violation``
    0 where it keeps every bound (a metre into a wall weighs ``WALL_WEIGHT``, into the robot's margin
    ``ROBOT_WEIGHT``), ``cost`` [-]."""
    score_alone(routes, step, rows, agents, c, scored)
    mine = np.full(len(agents), -1)
    mine[pending] = np.arange(len(pending))
    chooser, other = near
    pair = np.flatnonzero(mine[chooser] >= 0)
    too_close, pair_risk = _pair_terms(routes, step, rows[pending], agents[pending], c, scored, local,
                                       mine[chooser[pair]], other[pair],
                                       turn[rows[chooser[pair]], other[pair]] < chooser[pair], seen)
    violation = (c.too_fast[scored] + too_close + WALL_WEIGHT * c.too_deep[scored]
                 + ROBOT_WEIGHT * c.into_robot[scored])
    cost = (c.fixed_cost[scored] + RISK_COST * (c.risk[scored] + pair_risk) + c.stuck_cost[scored]
            + c.way_cost[scored])
    return violation, cost


def _pair_terms(routes: Routes, step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates, scored: np.ndarray,
                local: np.ndarray, chooser: np.ndarray, other: np.ndarray, earlier: np.ndarray,
                seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(too_close, pair_risk), (R,) each, of the candidate rows ``scored`` (R,) of the choosers ``rows``,
    ``agents`` (T,) (``local`` (R,): whose row, each chooser's rows in a run), scored against the pedestrians
    ``other`` (P,) of the pairs near enough to count (``chooser`` (P,) in 0..T-1; ``earlier`` (P,) bool: the
    other chose before, and ``seen`` (N, A, 2) has its choice):

    - too_close [m]: along the whole step it keeps ``PAIR_BODY_M`` from everybody else (or at least the gap it
      already had, and that much again by the end of the step where their logs are that far apart);
    - pair_risk [m^2]: the squared intrusions into the comfort gap round the others off their logs going on at
      their velocities over ``ANTICIPATION_STEPS``.

    The sums over the others come out as over all of them, those out of reach adding 0 (``exact_row_sums``)."""
    present, walks = step.present[rows], step.present[rows] & step.off_log[rows]  # (T, A)
    width, walk_width = present.sum(axis=1) - 1, walks.sum(axis=1) - 1  # (T,) others, those off their logs
    column = (np.cumsum(present, axis=1) - present)[chooser, other] - (agents[chooser] < other)  # sums' order
    walk_column = (np.cumsum(walks, axis=1) - walks)[chooser, other] - (agents[chooser] < other)
    # where each other is during the step: from, to, and walking on
    their_row = rows[chooser]
    their_from = step.start[their_row, other]
    their_to = np.where(earlier[:, None], seen[their_row, other], step.xy[their_row, other])  # (P, 2)
    ahead = np.arange(1, ANTICIPATION_STEPS + 1) * STEP_S
    future = their_to[:, None] + ahead[:, None] * step.velocity_mps[their_row, other][:, None]  # (P, H, 2)
    # the pairs whose other comes within reach of the box of the chooser's scored rows (steps and walks on)
    later = c.later_m[scored, :ANTICIPATION_STEPS]  # (R, H, 2)
    per_chooser = np.bincount(local, minlength=len(rows))
    place, starts = c.xy_m[scored], np.cumsum(per_chooser) - per_chooser
    low = np.minimum(place, np.minimum.reduce([later[:, k] for k in range(ANTICIPATION_STEPS)]))
    high = np.maximum(place, np.maximum.reduce([later[:, k] for k in range(ANTICIPATION_STEPS)]))
    start = step.start[rows, agents]  # (T, 2)
    box = np.concatenate([np.minimum(np.minimum.reduceat(low, starts), start),
                          np.maximum(np.maximum.reduceat(high, starts), start)], axis=1)
    their = np.concatenate([np.minimum(np.minimum(their_from, their_to), future.min(axis=1)),  # walking on or not
                            np.maximum(np.maximum(their_from, their_to), future.max(axis=1))], axis=1)
    counted = _within(box[chooser], their, PAIR_REACH_M)
    # every scored row of the pair's chooser
    sizes = np.where(counted, per_chooser[chooser], 0)
    pair = np.repeat(np.arange(len(chooser)), sizes)
    row = spans(starts[chooser], sizes)  # (E,) rows of ``scored``
    here = start[chooser]  # (P, 2)
    n_rows = len(scored)
    # along the step
    allowed = np.minimum(PAIR_BODY_M, length_m(their_from - here) - 1e-6)[pair]
    index = step.index[their_row]
    logged = length_m(routes.log_xy_m[index, agents[chooser]] - routes.log_xy_m[index, other])
    together = np.minimum(PAIR_BODY_M, np.nan_to_num(logged, nan=np.inf))[pair]  # closer now: part as the logs do
    to = their_to[pair]
    pair_gap, _ = closest_approach(here[pair] - their_from[pair], place[row] - to)
    too_close = (exact_row_sums(row, column[pair], np.maximum(allowed - pair_gap, 0.0), width[local], n_rows)
                 + exact_row_sums(row, column[pair], np.maximum(together - length_m(place[row] - to), 0.0),
                                  width[local], n_rows))
    # walking on, against those off their logs (those on their logs keep to them: the hard bounds cover them)
    walk = np.flatnonzero(walks[chooser, other][pair])
    gap = length_m(later[row[walk]] - future[pair[walk]])  # (Q, H)
    cols = (np.arange(ANTICIPATION_STEPS) * walk_width[chooser[pair[walk]]][:, None]
            + walk_column[pair[walk]][:, None])
    pair_risk = exact_row_sums(np.repeat(row[walk], ANTICIPATION_STEPS), cols.ravel(),
                               (np.maximum(PAIR_REACH_M - gap, 0.0) ** 2).ravel(),
                               ANTICIPATION_STEPS * walk_width[local], n_rows)
    return too_close, pair_risk


def _within(box_m: np.ndarray, other_m: np.ndarray, reach_m: float) -> np.ndarray:
    """(K,) bool: the boxes ``box_m`` (K, 4) (x low, y low, x high, y high) [m] come within ``reach_m`` [m] (plus
    ``NEAR_SLACK_M``) of the boxes ``other_m`` (K, 4)."""
    apart = np.maximum(np.maximum(other_m[:, :2] - box_m[:, 2:], box_m[:, :2] - other_m[:, 2:]), 0.0)
    return length_m(apart) < reach_m + NEAR_SLACK_M
