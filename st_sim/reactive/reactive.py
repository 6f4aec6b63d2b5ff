"""Reactive replay: recorded pedestrians walk their own logged routes, stepping aside or slowing down for a robot they
have noticed, and never into its body.

**What a pedestrian knows of the robot.** Where its body is (``footprint.Body``: a disc for STCrowd's robot, a box for
a vehicle) and how it moved in the last step: it expects the robot to hold that velocity over the step
(``footprint.Robot``). **When it reacts** (``reaction.Reaction``, fitted on CITR): it notices the robot within its
field of view or hearing, reacts a reaction time later, and from then on keeps room round the robot that grows with
the robot's speed, depending on whether it comes head-on, from behind or across; each pedestrian scales its noticing
distance, reaction time, room and cost of standing aside by its own traits (``ReactiveState.traits``, given at the
reset, ``ReactiveCrowd.reset``; the replay env draws them with ``reaction_traits="drawn"``).

Every pedestrian follows its recording exactly until either

- it reacts to the robot and its log over the next ``anticipation_s`` would bring it within its room of the robot's
  expected course, or its log comes within ``PAIR_CLEARANCE_M`` of a pedestrian already off its log; or
- (the **safety rule**, noticed or not) its log's step would take it within ``ROBOT_MARGIN_M`` of touching the
  robot's body where it stands: nobody walks into the robot.

From then on it stays on its logged route (``st_sim.reactive.routes``) and each 0.4 s step chooses where along it and
how far to its side it walks (``st_sim.reactive.candidates``: the places and what each costs;
``st_sim.reactive.choosing``: the terms between pedestrians and the choice). One that has made no headway for
``DETOUR_AFTER_STEPS`` steps plans a way round, until it gets farther along its route than it had been.

The pedestrians off their log choose one after another, the one nearest the robot first, each seeing the choices
already made. Once a pedestrian is within ``REJOIN_M`` of where its log is now and nothing is in its way, it is on
its log again. A pedestrian whose log ends while it is behind walks on to where its log ends and leaves there (at most
``MAX_LINGER_STEPS`` later; within ``LEAVE_BLOCKED_M`` of it where the robot or others keep it away); one who
appears where the robot (or a pedestrian off its log) stands starts beside its log, just clear of them. With the robot
out of everyone's way, the replay is the recording exactly.

**Batched.** One step of N crowds of a replay (``ReactiveCrowd.step_all``: the sub-envs of a vector env; ``Routes``
holds the replay's tables, shared) is one pass over arrays (N, A): who notices the robot, who leaves or rejoins its
log, and every choice (``choosing.choose_all``), with the walks of every crowd stepped alone, to the last bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Final

import numpy as np

from replays.constants import STEP_S
from st_sim.reactive.candidates import HEADWAY_M, OFFSETS_M, RECENT_STEPS, Step, no_headway
from st_sim.reactive.choosing import choose_all
from st_sim.reactive.compiled.choose import choose_compiled
from st_sim.reactive.compiled.geometry import robot_rows
from st_sim.reactive.compiled.step import attention, leave, settle
from st_sim.reactive.footprint import BODY_RADIUS_M, PAIR_BODY_M, PAIR_GIVE_M, Body, Robot, heading_of, length_m
from st_sim.reactive.ragged import leading
from st_sim.reactive.reaction import (
    MOVING_MPS,
    NOTICING,
    PATIENCE,
    REACTION_TIME,
    ROOM,
    TRAITS,
    Reaction,
    attend,
    notices,
    typical,
)
from st_sim.reactive.routes import Depth, Routes
from st_sim.sim.exact import atan2, cos_sin, dot

PAIR_LOOK_AHEAD_STEPS: Final[int] = 3  # a pedestrian looks this many 0.4 s steps along its log for others off theirs
PAIR_CLEARANCE_M: Final[float] = 0.2  # ... and leaves its log if that path passes closer than this to a body [m]
REJOIN_M: Final[float] = 0.1  # back on its log (or out of the scene, at the log's end) when this close to it [m]
MAX_LINGER_STEPS: Final[int] = 25  # a pedestrian behind its log leaves at most this many steps after the log ends
LEAVE_BLOCKED_M: Final[float] = 0.9  # one who cannot get closer to where its log ends leaves this close to it [m]
STILL_M: Final[float] = 0.02  # a pedestrian moving less than this in a step stands still [m]
DETOUR_AFTER_STEPS: Final[int] = 2  # one that has made no headway for this many steps plans a way round [-]


@dataclass(frozen=True)
class ReactiveState:
    """Where the pedestrians of a replay are, one row per recorded agent (the replay's ``agents`` order); the arrays
    of N crowds stepped together carry a leading crowd axis (N, A, ...).

    Attributes:
        xy_m: (A, 2) positions [m]; NaN for agents absent now.
        velocity_mps: (A, 2) velocities over the last step [m/s].
        present: (A,) bool, in the scene now: present in the log, or still on the way to where the log ended.
        off_log: (A,) bool, not at their logged position now.
        tau: (A,) fractional frame index of the log point that a pedestrian's place is taken from (off its log).
        offset_m: (A,) how far left of the route's direction at ``tau`` it stands [m] (off its log).
        linger: (A,) steps since its log ended (a pedestrian still on its way out), 0 otherwise.
        stuck: (A,) steps in a row a pedestrian off its log has made no headway (got neither ``HEADWAY_M`` farther
            along its route nor nearer to its log than it had been), standing still or stepping to and fro.
        farthest: (A,) the farthest route point (fractional frame) it has reached since it left its log.
        recent_m: (A, RECENT_STEPS) how near it was to its log after each of its last steps (metres behind along the
            route plus aside) [m]; inf before it left its log.
        detour: (A,) bool, a pedestrian off its log that made no headway for ``DETOUR_AFTER_STEPS`` and has not got
            farther along its route since: it plans a way round the robot.
        noticed_s: (A,) how long it has had the robot in mind [s] (0: it has not noticed it).
        unseen_s: (A,) how long since it last noticed the robot, while it keeps it in mind [s].
        weight: (A,) how far it reacted to the robot in the last step, in [0, 1].
        traits: (A, 4) its factors on the fitted reaction (``reaction.TRAITS``), set at the reset (all 1: the fitted
            pedestrian).
    """

    xy_m: np.ndarray
    velocity_mps: np.ndarray
    present: np.ndarray
    off_log: np.ndarray
    tau: np.ndarray
    offset_m: np.ndarray
    linger: np.ndarray
    stuck: np.ndarray
    farthest: np.ndarray
    recent_m: np.ndarray
    detour: np.ndarray
    noticed_s: np.ndarray
    unseen_s: np.ndarray
    weight: np.ndarray
    traits: np.ndarray


def stack_states(states: Sequence[ReactiveState]) -> ReactiveState:
    """The states of N crowds of one replay as one, every array with a leading crowd axis (N, A, ...)."""
    return ReactiveState(*(np.stack([getattr(state, field.name) for state in states])
                           for field in fields(ReactiveState)))


def unstack_state(state: ReactiveState, crowd: int) -> ReactiveState:
    """Row ``crowd`` of a stacked state."""
    return ReactiveState(*(getattr(state, field.name)[crowd] for field in fields(ReactiveState)))


class ReactiveCrowd:
    """The recorded pedestrians of one replay, reacting to a robot. Arguments as ``Routes``' (the replay's tables,
    built here for this crowd alone; ``on`` shares them)."""

    def __init__(self, log_xy_m: np.ndarray, present: np.ndarray, depth: Depth, body: Body, touch_m: float,
                 reaction: Reaction | None = None, compiled: bool = True):
        self.routes = Routes(log_xy_m, present, depth, body, touch_m, reaction, compiled)
        self.state = on_log(self.routes, 0)

    @classmethod
    def on(cls, routes: Routes) -> ReactiveCrowd:
        """A crowd walking ``routes``, shared with other crowds of the same replay (the sub-envs of a vector env), so
        that ``step_all`` steps them together."""
        crowd = cls.__new__(cls)
        crowd.routes, crowd.state = routes, on_log(routes, 0)
        return crowd

    @staticmethod
    def capacity(present: np.ndarray) -> int:
        """Most pedestrians present at once in reactive mode: those of the log and those still on their way out."""
        ended = np.zeros_like(present)
        ended[1:] = present[:-1] & ~present[1:]  # logs that ended just before frame f
        window = np.cumsum(ended, axis=0)
        lingering = window - np.r_[np.zeros((MAX_LINGER_STEPS, present.shape[1]), int),
                                   window[:-MAX_LINGER_STEPS]][: len(window)]
        return int((present.sum(axis=1) + ((lingering > 0) & ~present).sum(axis=1)).max())

    def reset(self, index: int, traits: np.ndarray | None = None) -> np.ndarray:
        """Everybody on their log at frame ``index``, nobody has noticed the robot, each with its ``traits`` (A, 4)
        from now on (``reaction.draw_traits``; default: ``reaction.typical``, the fitted pedestrian); returns the
        (A, 2) positions."""
        agents = self.routes.present.shape[1]
        if traits is not None and np.shape(traits) != (agents, len(TRAITS)):
            raise ValueError(f"traits of shape {np.shape(traits)}: expected ({agents}, {len(TRAITS)}), one row per "
                             "agent")
        self.state = on_log(self.routes, index, traits)
        return self.state.xy_m

    def deviation_m(self, index: int) -> np.ndarray:
        """(present agents,) distance of each pedestrian present now from its log at frame ``index`` (from where its
        log ended, for one still on its way out) [m]."""
        cols = np.flatnonzero(self.state.present)
        ended = self.routes.run_last[np.floor(self.state.tau[cols]).astype(int), cols]
        frames = np.where(self.routes.present[index, cols], index, ended)
        return length_m(self.state.xy_m[cols] - self.routes.log_xy_m[frames, cols])

    def step(self, index: int, robot_from_m: np.ndarray | None, robot_to_m: np.ndarray | None,
             robot_heading_rad: float | None = None) -> np.ndarray:
        """Advance from frame ``index - 1`` to ``index`` while, as the pedestrians expect, the robot moves from
        ``robot_from_m`` to ``robot_to_m`` (2,) [m] (None: no robot; the replay env passes the robot's last velocity
        held, not its command), its body turned to ``robot_heading_rad`` (default: along that move); returns the
        (A, 2) positions at ``index`` (NaN: absent; who is present is ``state.present``)."""
        return self.step_all([self], [index], [robot_from_m], [robot_to_m], [robot_heading_rad])[0]

    @staticmethod
    def step_all(crowds: Sequence[ReactiveCrowd], indices: Sequence[int], robots_from_m: Sequence[np.ndarray | None],
                 robots_to_m: Sequence[np.ndarray | None], robots_heading_rad: Sequence[float | None]
                 ) -> list[np.ndarray]:
        """``step`` of several crowds, each with its own frame index and robot (the arguments one per crowd): the
        crowds on the same ``routes`` in one batched pass, every pedestrian as it would walk stepped alone; returns
        each crowd's (A, 2) positions."""
        groups: dict[int, list[int]] = {}
        for i, crowd in enumerate(crowds):
            if robots_to_m[i] is None:  # no robot: everybody on their log
                old = crowd.state
                crowd.state = on_log(crowd.routes, indices[i], old.traits)
                crowd.state.velocity_mps[:] = velocity(crowd.state.xy_m, old.xy_m,
                                                       old.present & crowd.routes.present[indices[i]])
            else:
                groups.setdefault(id(crowd.routes), []).append(i)
        for members in groups.values():
            robot = Robot(np.array([robots_from_m[i] for i in members], np.float64),
                          np.array([robots_to_m[i] for i in members], np.float64),
                          np.array([heading_of(robots_from_m[i], robots_to_m[i], robots_heading_rad[i])
                                    for i in members]))
            routes = crowds[members[0]].routes
            step = advance_compiled if routes.compiled and routes.tables() is not None else advance
            state = step(routes, stack_states([crowds[i].state for i in members]),
                         np.array([indices[i] for i in members]), robot)
            for row, i in enumerate(members):
                crowds[i].state = unstack_state(state, row)
        return [crowd.state.xy_m for crowd in crowds]


def on_log(routes: Routes, index: int, traits: np.ndarray | None = None) -> ReactiveState:
    """Everybody on their log at frame ``index``, nobody has noticed the robot, with ``traits`` (A, 4) (default:
    ``reaction.typical``)."""
    now = routes.present[index]
    xy = np.where(now[:, None], routes.log_xy_m[index], np.nan)
    agents = len(now)
    zero = np.zeros(agents)
    return ReactiveState(xy, np.zeros_like(xy), now.copy(), np.zeros(agents, bool), np.full(agents, float(index)),
                         zero, np.zeros(agents, int), np.zeros(agents, int), np.full(agents, float(index)),
                         np.full((agents, RECENT_STEPS), np.inf), np.zeros(agents, bool), zero, zero, zero,
                         typical(agents) if traits is None else np.array(traits, np.float64))


def advance(routes: Routes, old: ReactiveState, index: np.ndarray, robot: Robot) -> ReactiveState:
    """The stacked state (N, A, ...) of N crowds after their step from frames ``index - 1`` to ``index`` (N,),
    each crowd's robot moving as ``robot`` (N rows) expects (``ReactiveCrowd.step``)."""
    frame = index[:, None].astype(np.float64)  # (N, 1)
    logged, log_now = routes.present[index], routes.log_xy_m[index]  # (N, A), (N, A, 2)
    walking = _walking(routes, old)
    noticed, unseen = attend(old.noticed_s, old.unseen_s, _notices(routes, old, robot, walking))
    weight = np.where(old.present, routes.reaction.weight(noticed, old.traits), 0.0)
    room = _room(routes, old, robot, walking)
    lingering = old.present & old.off_log & ~logged & (old.linger < MAX_LINGER_STEPS)  # on their way out
    present = logged | lingering
    off_log = (old.off_log & old.present & logged & (old.linger == 0)) | lingering  # a log that starts again: on
    start = np.where(old.present[..., None], old.xy_m, log_now)  # (N, A, 2) where each one is before the step
    going = old.present & logged & ~off_log & (_robot_in_the_way(routes, index, robot, weight, room)
                                               | _others_in_the_way(routes, index, old))
    off_log |= going
    tau = np.where(going, frame - 1.0, np.where(off_log, old.tau, frame))  # going: from their log's last frame
    farthest = np.where(off_log, np.where(going, tau, old.farthest), frame)
    recent = np.where((off_log & ~going)[..., None], old.recent_m, np.inf)
    detour = off_log & ~going & old.detour
    offset = np.where(off_log, old.offset_m, 0.0)
    xy = np.where(off_log[..., None], start, log_now)
    xy[~present] = np.nan
    step = Step(index, start, xy, present, off_log, np.zeros(present.shape, bool), old.velocity_mps, old.stuck,
                farthest, recent, detour, robot, weight, room, _aside_cost(routes, old))
    clear = routes.clear_of_robot(log_now, robot.from_m[:, None], robot.to_m[:, None], robot.heading_rad[:, None])
    _place_newcomers(routes, step, logged & ~old.present, clear, offset)
    choose_all(routes, step, tau, offset)
    # back on the log: caught up, beside it, and nothing in the way; out of the scene: where the log ended
    ahead = ReactiveState(xy, velocity(xy, old.xy_m, old.present & present), present, off_log, tau, offset,
                          old.linger, old.stuck, farthest, recent, detour, noticed, unseen, weight, old.traits)
    rejoin = (off_log & logged & (length_m(np.nan_to_num(xy - log_now, nan=np.inf)) <= REJOIN_M)
              & ~_robot_in_the_way(routes, index + 1, robot.after(), weight, room)
              & ~_others_in_the_way(routes, index + 1, ahead) & clear)
    xy[rejoin] = log_now[rejoin]
    off_log &= ~rejoin
    cols = np.arange(present.shape[1])
    log_end = routes.log_xy_m[routes.run_last[np.clip(np.floor(tau), 0, None).astype(int), cols], cols]
    to_end = length_m(np.nan_to_num(xy - log_end, nan=np.inf))
    blocked = length_m(np.nan_to_num(xy - start)) < STILL_M  # the robot or others stand there
    present &= ~(lingering & ((to_end <= REJOIN_M) | (blocked & (to_end <= LEAVE_BLOCKED_M))))
    off_log &= present
    xy[~present] = np.nan
    headway, farther = np.ones(present.shape, bool), np.ones(present.shape, bool)
    behind = np.full(tau.shape, np.inf)
    rows, agents = np.nonzero(off_log)
    gain, lag = routes.progress(agents, tau[rows, agents], farthest[rows, agents], index[rows])
    away = lag + np.abs(offset[rows, agents])
    farther[rows, agents] = gain >= HEADWAY_M
    headway[rows, agents] = ~no_headway(gain, away, recent[rows, agents].min(axis=-1))
    behind[rows, agents] = away
    stuck = np.where(off_log & ~headway, old.stuck + 1, 0)
    detour &= off_log & ~farther
    detour |= stuck >= DETOUR_AFTER_STEPS
    return ReactiveState(xy, velocity(xy, old.xy_m, old.present & present), present, off_log,
                         np.where(off_log, tau, frame), np.where(off_log, offset, 0.0),
                         np.where(present & lingering, old.linger + 1, 0), stuck,
                         np.where(off_log, np.maximum(farthest, tau), frame),
                         np.concatenate([recent[..., 1:], behind[..., None]], axis=-1), detour,
                         np.where(present, noticed, 0.0), np.where(present, unseen, 0.0), weight, old.traits)


def advance_compiled(routes: Routes, old: ReactiveState, index: np.ndarray, robot: Robot) -> ReactiveState:
    """``advance``, compiled (``st_sim.reactive.compiled``): the same state, bit for bit, in three passes round the room
    each keeps, the newcomers and the choice."""
    tables, reaction, rows = routes.tables(), routes.reaction, robot_rows(robot)
    walking, noticed, unseen, weight = attention(
        tables, old.present, old.xy_m, old.velocity_mps, old.tau, old.noticed_s, old.unseen_s, rows,
        np.stack(cos_sin(-robot.heading_rad), axis=-1), float(np.radians(reaction.fov_deg)),
        reaction.hearing_m * old.traits[..., NOTICING], reaction.reaction_s * old.traits[..., REACTION_TIME])
    room = _room(routes, old, robot, walking)
    lingering, present, off_log, start, tau, farthest, recent, detour, offset, xy, clear = leave(
        tables, routes.present, index, rows, weight, room, old.xy_m, old.velocity_mps, old.present, old.off_log,
        old.linger, old.tau, old.farthest, old.recent_m, old.detour, old.offset_m, MAX_LINGER_STEPS,
        PAIR_LOOK_AHEAD_STEPS, PAIR_CLEARANCE_M)
    step = Step(index, start, xy, present, off_log, np.zeros(present.shape, bool), old.velocity_mps, old.stuck,
                farthest, recent, detour, robot, weight, room, _aside_cost(routes, old))
    appearing = routes.present[index] & ~old.present
    if appearing.any():
        _place_newcomers(routes, step, appearing, clear, offset)
    choose_compiled(routes, step, tau, offset)
    state = settle(tables, routes.present, index, robot_rows(robot.after()), weight, room, xy, present, off_log,
                   lingering, start, clear, tau, offset, farthest, recent, detour, old.xy_m, old.present, old.linger,
                   old.stuck, REJOIN_M, STILL_M, LEAVE_BLOCKED_M, DETOUR_AFTER_STEPS, PAIR_LOOK_AHEAD_STEPS,
                   PAIR_CLEARANCE_M)
    return ReactiveState(*state, np.where(present, noticed, 0.0), np.where(present, unseen, 0.0), weight,
                         old.traits)


def _room(routes: Routes, state: ReactiveState, robot: Robot, walking: np.ndarray) -> np.ndarray:
    """(N, A) the room each pedestrian keeps from its crowd's robot this step [m] (``Reaction.room_m`` times its
    room trait; crowd by crowd, in both paths)."""
    return np.stack([routes.reaction.room_m(robot.velocity_mps[n], robot.heading[n], walking[n],
                                            np.nan_to_num(dot(state.xy_m[n] - robot.from_m[n], robot.velocity_mps[n]))
                                            > 0) for n in range(len(robot.heading_rad))]) * state.traits[..., ROOM]


def _aside_cost(routes: Routes, state: ReactiveState) -> np.ndarray:
    """(N, A) what a metre aside costs each pedestrian (``Reaction.aside_cost`` times its patience trait)."""
    return routes.reaction.aside_cost * state.traits[..., PATIENCE]


def _walking(routes: Routes, state: ReactiveState) -> np.ndarray:
    """(N, A, 2) unit walking directions: the velocity of those faster than ``MOVING_MPS``, else the route's
    direction where they are on it."""
    speed = length_m(state.velocity_mps)[..., None]
    frame = np.clip(np.floor(state.tau), 0, len(routes.present) - 1).astype(int)
    route = routes.tangent[frame, np.arange(frame.shape[-1])]
    return np.where(speed > MOVING_MPS, state.velocity_mps / np.maximum(speed, 1e-12), route)


def _notices(routes: Routes, state: ReactiveState, robot: Robot, walking: np.ndarray) -> np.ndarray:
    """(N, A) bool: the pedestrians present that notice their robot at the start of the step
    (``reaction.notices``)."""
    offset = state.xy_m - robot.from_m[:, None]
    heading = robot.heading_rad[:, None]
    toward = robot.from_m[:, None] + routes.body.nearest_point_m(offset, heading) - state.xy_m
    bearing = atan2(walking[..., 0] * toward[..., 1] - walking[..., 1] * toward[..., 0], (walking * toward).sum(-1))
    gap = np.nan_to_num(routes.body.gap_m(offset, heading), nan=np.inf)
    return state.present & notices(routes.reaction, gap, np.nan_to_num(bearing, nan=np.pi), state.traits)


def _robot_in_the_way(routes: Routes, index: np.ndarray, robot: Robot, weight: np.ndarray,
                      room_m: np.ndarray) -> np.ndarray:
    """(N, A) bool: agents whose log's step into frame ``index`` (N,) would take them within ``robot_reach_m`` of
    their robot's body (where it stands, for those that do not react; on its expected course, for those that
    do), or, for those that react, whose log from frame ``index`` on comes within their room (N, A) [m] of the
    robot's expected course over ``anticipation_s``. Only agents whose log is present then are looked at."""
    frames = len(routes.present)
    ahead = np.arange(-1, routes.reaction.anticipation_steps)  # frames from index on, from where it stands now
    seen = index[:, None] + ahead  # (N, H + 1)
    valid = (seen >= 0) & (seen < frames)
    clipped = np.clip(seen, 0, frames - 1)
    cols, real = leading(routes.present[clipped].any(axis=1) & (index < frames)[:, None])  # (N, K) logs present
    rows = np.arange(len(index))[:, None]
    log = routes.log_xy_m[clipped[:, :, None], cols[:, None, :]]  # (N, H + 1, K, 2)
    heading = robot.heading_rad[:, None]
    reacting = weight[rows, cols] > 0
    robot_to = np.where(reacting[..., None], robot.to_m[:, None], robot.from_m[:, None])
    gap = routes.body.swept_gap_m(log[:, 0] - robot.from_m[:, None], log[:, 1] - robot_to, heading)
    hit = (index > 0)[:, None] & (np.nan_to_num(gap, nan=np.inf) < routes.robot_reach_m)
    course = robot.to_m[:, None] + (ahead * STEP_S)[None, :, None] * robot.velocity_mps[:, None]  # (N, H + 1, 2)
    offset = log - course[:, :, None]  # (N, H + 1, K, 2)
    swept = routes.body.swept_gap_m(offset[:, :-1], offset[:, 1:], heading[:, None])  # (N, H, K)
    swept = np.where((valid[:, :-1] & valid[:, 1:])[..., None], np.nan_to_num(swept, nan=np.inf), np.inf)
    alone = np.nan_to_num(routes.body.gap_m(offset[:, 1], heading), nan=np.inf)  # the one frame of a 1-frame look
    least = np.where((valid.sum(axis=1) > 1)[:, None], swept.min(axis=1), alone)
    found = np.zeros(weight.shape, bool)
    found[rows, cols] = real & (hit | (reacting & (least < routes.robot_reach_m + room_m[rows, cols])))
    return found


def _others_in_the_way(routes: Routes, index: np.ndarray, state: ReactiveState) -> np.ndarray:
    """(N, A) bool: agents whose log from frame ``index`` (N,) on comes within ``PAIR_CLEARANCE_M`` of a
    pedestrian of their crowd off its log (going on at its velocity) within ``PAIR_LOOK_AHEAD_STEPS``, where it
    comes closer than their own logs would. Only agents whose log is present then are looked at."""
    frames = len(routes.present)
    found = np.zeros(state.present.shape, bool)
    who, real = leading(state.off_log & state.present)  # (N, O) the crowd's others, ascending
    if not who.shape[1] or (index >= frames).all():
        return found
    ahead = np.arange(PAIR_LOOK_AHEAD_STEPS)
    seen = index[:, None] + ahead  # (N, H)
    clipped = np.minimum(seen, frames - 1)
    cols, logged = leading(routes.present[clipped].any(axis=1))  # (N, K) logs present then
    log = routes.log_xy_m[clipped[:, :, None], cols[:, None, :]]  # (N, H, K, 2), NaN where absent
    rows = np.arange(len(index))[:, None]
    where = (state.xy_m[rows, who][:, None]
             + (ahead * STEP_S)[None, :, None, None] * state.velocity_mps[rows, who][:, None])  # (N, H, O, 2)
    gap = length_m(log[:, :, :, None] - where[:, :, None])  # (N, H, K, O)
    their_log = routes.log_xy_m[clipped[:, :, None], who[:, None, :]]  # (N, H, O, 2)
    logged_gap = length_m(log[:, :, :, None] - their_log[:, :, None])
    bound = np.minimum(2 * BODY_RADIUS_M + PAIR_CLEARANCE_M, np.nan_to_num(logged_gap, nan=np.inf) - PAIR_GIVE_M)
    apart = (real[:, None, None, :] & (seen < frames)[:, :, None, None]
             & (who[:, None, None, :] != cols[:, None, :, None]))  # nobody is in their own way
    found[rows, cols] = logged & (apart & (np.nan_to_num(gap, nan=np.inf) < bound)).any(axis=(1, 3))
    return found


def _place_newcomers(routes: Routes, step: Step, appearing: np.ndarray, clear: np.ndarray, offset: np.ndarray) -> None:
    """Start each pedestrian appearing (N, A) where its robot (not ``clear``) or one off its log stands beside its
    log instead, just clear of them and of everybody else (``_clear_offset``): ``step`` and ``offset`` (N, A) are
    updated in place."""
    for row in np.flatnonzero(appearing.any(axis=1)):
        for agent in np.flatnonzero(appearing[row]):  # in order: each sees those placed before it
            taken = step.start[row][step.off_log[row] & step.present[row]]
            log_now = routes.log_xy_m[step.index[row], agent]
            if clear[row, agent] and not (length_m(taken - log_now) < PAIR_BODY_M).any():
                continue
            others = step.present[row] & (np.arange(len(step.present[row])) != agent)
            offset[row, agent] = _clear_offset(routes, agent, int(step.index[row]), step.robot, row,
                                               step.xy[row][others])
            step.xy[row, agent] = step.start[row, agent] = routes.place(
                np.array([agent]), np.array([float(step.index[row])]), offset[row, [agent]], step.index[row])[0]
            step.off_log[row, agent] = step.chosen[row, agent] = True


def _clear_offset(routes: Routes, agent: int, index: int, robot: Robot, row: int, others_m: np.ndarray) -> float:
    """The smallest side offset [m] at frame ``index`` that clears robot ``row`` (where it stands and where it is
    expected) and the pedestrians at ``others_m`` (K, 2), and stays as walkable as the log (0 if none does)."""
    offsets = OFFSETS_M[np.argsort(np.abs(OFFSETS_M), kind="stable")]
    places = routes.place(np.full(len(offsets), agent), np.full(len(offsets), float(index)), offsets, index)
    apart = length_m(places[:, None] - others_m[None]).min(axis=1, initial=np.inf)
    fine = (routes.clear_of_robot(places, robot.from_m[row], robot.to_m[row], robot.heading_rad[row])
            & (apart >= PAIR_BODY_M) & (routes.too_deep_m(agent, index, places, index) == 0))
    return float(offsets[np.argmax(fine)]) if fine.any() else 0.0


def velocity(xy: np.ndarray, old_xy: np.ndarray, stays: np.ndarray) -> np.ndarray:
    """(..., 2) velocity over the step [m/s] of the agents present before and after it (0 for the others)."""
    return np.where(stays[..., None], np.nan_to_num(xy - old_xy) / STEP_S, 0.0)
