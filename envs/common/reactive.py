"""Reactive replay: recorded pedestrians walk their own logged routes, stepping aside or slowing down for a robot they
have noticed, and never into its body.

**What a pedestrian knows of the robot.** Where its body is (``footprint.Body``: a disc for STCrowd's robot, a box for
a vehicle) and how it moved in the last step: it expects the robot to hold that velocity over the step. **When it
reacts** (``reaction.Reaction``, fitted on CITR): it notices the robot within its field of view or hearing, reacts a
reaction time later, and from then on keeps room round the robot that grows with the robot's speed, depending on
whether it comes head-on, from behind or across.

Every pedestrian follows its recording exactly until either

- it reacts to the robot and its log over the next ``anticipation_s`` would bring it within its room of the robot's
  expected course, or its log comes within ``PAIR_CLEARANCE_M`` of a pedestrian already off its log; or
- (the **safety rule**, noticed or not) its log's step would take it within ``ROBOT_MARGIN_M`` of touching the
  robot's body where it stands: nobody walks into the robot.

From then on it stays on its logged *route* and only chooses where along it and how far to its side: its place is
the log at a fractional frame ``tau`` (never ahead of the log) moved ``offset_m`` to the left of the route's direction
there (a Frenet frame along the log). Each 0.4 s step it picks, among a grid of progress along its route (from half a
step back to as far as it can walk in one, or to where its log is now) and side offsets (up to ``MAX_OFFSET_M``), the
place that loses the least time and strays the least while

- it walks no faster than it can catch up (``CATCH_UP_MPS``, or ``CATCH_UP_FACTOR`` times its log's speed);
- along its step it is never deeper in the scene's non-walkable area, nor farther off the image, than the nearest
  point of its log (near that point of its route, ``DEPTH_WINDOW``) or its log close to that point of the route
  (``CROSSING_WINDOW``): a log that crosses a traced wall lets it cross there too and traps nobody, while nobody is
  pushed into a wall beside a log, nor jumps over a thin one;
- along the whole step, moving in a straight line, it keeps ``ROBOT_MARGIN_M`` beyond touching the robot's body (as
  it expects the robot to move once it reacts; as the robot stands before) and ``2 BODY_RADIUS_M - PAIR_GIVE_M`` from
  everybody else (or at least the gap it already had, and that much again by the end of the step where their logs
  are that far apart);
- once it reacts, it keeps its room from where the robot will be over the next ``anticipation_s``; before, it keeps
  ``COMFORT_M`` from the robot's body where it stands (a body in its way, not a robot it expects to move); and it
  keeps its body's width from where the others off their logs will be over ``ANTICIPATION_STEPS`` (costs, so that it
  steps aside early rather than at the last moment); one that has made no headway for a while (``HEADWAY_M``) pays
  ``STUCK_COST`` per such step for making none again, so that it tries another way round; after
  ``DETOUR_AFTER_STEPS`` such steps, and until it gets farther along its route, it also pays ``DETOUR_COST`` per
  metre it would have to walk from the place to its route a few metres ahead, round the robot's body and the walls
  (``detour.walking_distance_m``): from a pocket between the robot and a wall it walks back out and round.

When no place keeps every bound, it takes the one that breaks them least, a metre into the robot's margin weighing
``ROBOT_WEIGHT`` (it stands still rather than step into the robot), into a wall ``WALL_WEIGHT``, into the others or
beyond its pace 1.

The pedestrians off their log choose one after another, the one nearest the robot first, each seeing the choices
already made. Once a pedestrian is within ``REJOIN_M`` of where its log is now and nothing is in its way, it is on
its log again. A pedestrian whose log ends while it is behind walks on to where its log ends and leaves there (at most
``MAX_LINGER_STEPS`` later; within ``LEAVE_BLOCKED_M`` of it where the robot or others keep it away); one who
appears where the robot (or a pedestrian off its log) stands starts beside its log, just clear of them. With the robot
out of everyone's way, the replay is the recording exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Protocol

import numpy as np

from envs.common.detour import grid_cells, walking_distance_m
from envs.common.footprint import Body
from envs.common.reaction import MOVING_MPS, Reaction, attend, fitted_reaction, notices
from replays.constants import STEP_S
from st_sim.sim.sweep import closest_approach

PAIR_LOOK_AHEAD_STEPS: Final[int] = 3  # a pedestrian looks this many 0.4 s steps along its log for others off theirs
PAIR_CLEARANCE_M: Final[float] = 0.2  # ... and leaves its log if that path passes closer than this to a body [m]
REJOIN_M: Final[float] = 0.1  # back on its log (or out of the scene, at the log's end) when this close to it [m]
BODY_RADIUS_M: Final[float] = 0.2  # radius of a reactive pedestrian's body [m]
ROBOT_MARGIN_M: Final[float] = 0.05  # reactive pedestrians keep this much beyond touching the robot's body [m]
PAIR_GIVE_M: Final[float] = 0.05  # two pedestrians may come this far inside body contact (shoulders turn) [m]
CATCH_UP_MPS: Final[float] = 1.8  # fastest a pedestrian walks to catch up with its log [m/s] ...
CATCH_UP_FACTOR: Final[float] = 1.25  # ... or this multiple of its log's own speed, if that is faster [-]
MAX_OFFSET_M: Final[float] = 3.0  # farthest a pedestrian steps to the side of its route [m]
PROGRESS_SHARES: Final[np.ndarray] = np.linspace(-0.5, 1.0, 25)  # progress along the route it may choose per step,
"""as shares of the farthest it can walk in one (and catching up with its log at once); back up to half a step [-]"""
OFFSETS_M: Final[np.ndarray] = np.linspace(-MAX_OFFSET_M, MAX_OFFSET_M, 31)  # side offsets it may choose [m]
DEPTH_TOLERANCE_M: Final[float] = 0.0  # it may stand this much deeper in the non-walkable area than its log [m]
MAX_LINGER_STEPS: Final[int] = 25  # a pedestrian behind its log leaves at most this many steps after the log ends
LEAVE_BLOCKED_M: Final[float] = 0.9  # one who cannot get closer to where its log ends leaves this close to it [m]
ANTICIPATION_STEPS: Final[int] = 3  # it keeps clear of where the others off their logs will be over this many steps
COMFORT_M: Final[float] = 0.3  # ... by this much beyond contact, as from a robot's body it has not noticed [m]
LAG_COST: Final[float] = 1.0  # cost of a frame (0.4 s) of delay against its log [1/frame] ...
LAG_PACE_MPS: Final[float] = 1.0  # ... the delay being at most the time to walk what it is behind at this pace [m/s]
OFFSET_COST: Final[float] = 0.5  # cost of standing a metre to the side of its route [1/m]
SWAY_COST: Final[float] = 0.2  # cost of changing its side offset by a metre in one step [1/m]
RISK_COST: Final[float] = 10.0  # cost of the anticipated intrusions into the room round the robot and others [1/m^2]
STUCK_COST: Final[float] = 0.5  # cost of making no headway again, per step it already made none off its log [-]
HEADWAY_M: Final[float] = 0.05  # ... a step makes none that gets it less than this farther along its route than it has
"""been, or nearer to its log (metres behind it along the route plus metres aside) than in its last ``RECENT_STEPS``
[m]"""
RECENT_STEPS: Final[int] = 5  # ... steps (2 s)
STILL_M: Final[float] = 0.02  # a pedestrian moving less than this in a step stands still [m]
MIN_STEP_M: Final[float] = 0.01  # log steps shorter than this give no direction [m]
PATH_SAMPLES: Final[tuple[float, ...]] = (0.25, 0.5, 0.75, 1.0)  # where along a step the map bound is checked [-]
DEPTH_WINDOW: Final[int] = 8  # ... at its nearest point within this many frames either side of its route point [-]
CROSSING_WINDOW: Final[int] = 2  # ... or its deepest within this many frames of its route point [-]
TRACE_SHARES: Final[tuple[float, ...]] = (0.0, 0.25, 0.5, 0.75)  # points of a log between two frames it is traced at
TANGENT_WINDOW: Final[int] = 2  # a route's direction is averaged over this many frames either side [-]
WALL_WEIGHT: Final[float] = 100.0  # with no candidate within every bound: a metre into a wall weighs 100 of the rest
ROBOT_WEIGHT: Final[float] = 1e4  # ... and a metre into the robot's margin 10^4 (it stands still rather than step in)
DETOUR_AFTER_STEPS: Final[int] = 2  # one that has made no headway for this many steps plans a way round [-] ...
DETOUR_AHEAD_M: Final[tuple[float, ...]] = (3.0, 3.5, 4.0, 4.5, 5.0)  # ... to the first of these points of its route
"""beyond the farthest it has reached that is clear of the robot (or to where its log ends, if nearer) [m]"""
DETOUR_MARGIN_M: Final[float] = 1.5  # ... on a grid reaching this far round it, the goal and its candidates [m]
DETOUR_BACK_FRAMES: Final[int] = 16  # ... and round its route from this many frames behind its route point [-]
DETOUR_COST: Final[float] = 10.0  # ... and pays this per metre it would then have to walk to that point [1/m]


class Depth(Protocol):
    """How deep points lie in a scene's non-walkable area (``st_sim.sim.map_depth.MapDepth``, or ``OpenGround``)."""

    def at(self, xy_m: np.ndarray) -> np.ndarray:
        """(...) depth [m] of points (..., 2) [m]: 0 on walkable ground, inf off the scene's image."""
        ...


class OpenGround:
    """Ground walkable everywhere (a parking lot): every point at depth 0."""

    def at(self, xy_m: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(xy_m)[:-1])


@dataclass(frozen=True)
class Robot:
    """The robot's move over the step as the pedestrians expect it: from ``from_m`` to ``to_m`` (2,) [m] in a straight
    line, its body turned to ``heading_rad``."""

    from_m: np.ndarray
    to_m: np.ndarray
    heading_rad: float

    @property
    def velocity_mps(self) -> np.ndarray:
        return (self.to_m - self.from_m) / STEP_S

    @property
    def heading(self) -> np.ndarray:
        """(2,) unit heading."""
        return np.array([np.cos(self.heading_rad), np.sin(self.heading_rad)])


@dataclass(frozen=True, eq=False)
class Step:
    """What the pedestrians off their log see while they choose, one after another, within one step to frame
    ``index``: rows are the replay's agents.

    Attributes:
        start: (A, 2) positions before the step [m].  xy: (A, 2) positions after it, as far as chosen (the log for
            those on it, the choice for those who chose, the start for those yet to choose) [m].
        present, off_log, chosen: (A,) bool.  velocity_mps: (A, 2) velocities over the previous step [m/s].
        stuck: (A,) steps in a row each has made no headway off its log.  farthest: (A,) the farthest route point
            (fractional frame) each has reached since it left its log.  recent_m: (A, RECENT_STEPS) how near it was to
            its log after each of its last steps [m] (inf before it left its log).  detour: (A,) bool, planning a way
            round (``ReactiveState.detour``).
        weight: (A,) how far each reacts to the robot in this step, in [0, 1].  room_m: (A,) the room it keeps [m].
    """

    index: int
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


@dataclass(frozen=True, eq=False)
class Candidates:
    """The places a pedestrian off its log may choose in one step: route point ``tau`` (C,), side ``offset_m`` (C,),
    position ``xy_m`` (C, 2) [m], ``violation`` (C,) of the bounds (0: keeps them all; a metre into a wall weighs
    ``WALL_WEIGHT``, into the robot's margin ``ROBOT_WEIGHT``) and ``cost`` (C,) [-]."""

    tau: np.ndarray
    offset_m: np.ndarray
    xy_m: np.ndarray
    violation: np.ndarray
    cost: np.ndarray


@dataclass(frozen=True)
class ReactiveState:
    """Where the pedestrians of a replay are, one row per recorded agent (the replay's ``agents`` order).

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


class ReactiveCrowd:
    """The recorded pedestrians of one replay, reacting to a robot.

    Args:
        log_xy_m: (F, A, 2) logged positions [m], NaN where absent.  present: (F, A) bool.
        depth: the scene's non-walkable depth (``MapDepth``; ``OpenGround`` where nothing is out of bounds).
        body: the robot's footprint.
        touch_m: gap to the robot's body [m] within which a pedestrian's centre touches it (the pedestrian radius of
            the env's contact rule).
        reaction: when the pedestrians notice the robot and react, and the room they keep (default: the fitted one).
    """

    def __init__(self, log_xy_m: np.ndarray, present: np.ndarray, depth: Depth, body: Body, touch_m: float,
                 reaction: Reaction | None = None):
        self.log_xy_m, self.present, self.depth, self.body = log_xy_m, present, depth, body
        self.reaction = fitted_reaction() if reaction is None else reaction
        self.robot_reach_m = touch_m + ROBOT_MARGIN_M  # gap a pedestrian keeps from the robot's body
        agents = present.shape[1]
        step = np.diff(np.nan_to_num(log_xy_m), axis=0)  # (F - 1, A, 2)
        moving = present[:-1] & present[1:]
        length = np.where(moving, np.linalg.norm(step, axis=-1), 0.0)
        self.log_speed_mps = np.r_[length, np.zeros((1, agents))] / STEP_S  # (F, A), 0 at the end of a run
        self.run_first, self.run_last = run_bounds(present)
        arc = np.cumsum(np.r_[np.zeros((1, agents)), length], axis=0)  # (F, A) metres walked since the first frame
        self.arc_m = np.where(present, arc - arc[np.maximum(self.run_first, 0), np.arange(agents)], np.nan)
        """(F, A) metres along the log since the start of its run of presence (NaN where absent)"""
        on_log, ahead = np.where(present[..., None], log_xy_m, 0.0), np.r_[step, np.zeros((1, agents, 2))]
        self.trace_m = on_log[:, :, None] + np.array(TRACE_SHARES)[:, None] * ahead[:, :, None]
        """(F, A, K, 2) points of the log from frame f toward f + 1 [m] (a fast log may cross a thin wall between)"""
        self.trace_depth_m = self.depth.at(self.trace_m)
        """(F, A, K) how deep each of those lies in the non-walkable area [m]"""
        self.tangent = smoothed(route_tangents(step, moving & (length >= MIN_STEP_M), present), self.run_first,
                                self.run_last)  # (F, A, 2)
        self.state = self._on_log(0)

    @staticmethod
    def capacity(present: np.ndarray) -> int:
        """Most pedestrians present at once in reactive mode: those of the log and those still on their way out."""
        ended = np.zeros_like(present)
        ended[1:] = present[:-1] & ~present[1:]  # logs that ended just before frame f
        window = np.cumsum(ended, axis=0)
        lingering = window - np.r_[np.zeros((MAX_LINGER_STEPS, present.shape[1]), int),
                                   window[:-MAX_LINGER_STEPS]][: len(window)]
        return int((present.sum(axis=1) + ((lingering > 0) & ~present).sum(axis=1)).max())

    def _on_log(self, index: int) -> ReactiveState:
        now = self.present[index]
        xy = np.where(now[:, None], self.log_xy_m[index], np.nan)
        agents = len(now)
        zero = np.zeros(agents)
        return ReactiveState(xy, np.zeros_like(xy), now.copy(), np.zeros(agents, bool), np.full(agents, float(index)),
                             zero, np.zeros(agents, int), np.zeros(agents, int), np.full(agents, float(index)),
                             np.full((agents, RECENT_STEPS), np.inf), np.zeros(agents, bool), zero, zero, zero)

    def reset(self, index: int) -> np.ndarray:
        """Everybody on their log at frame ``index``, nobody has noticed the robot; returns the (A, 2) positions."""
        self.state = self._on_log(index)
        return self.state.xy_m

    def deviation_m(self, index: int) -> np.ndarray:
        """(present agents,) distance of each pedestrian present now from its log at frame ``index`` (from where its
        log ended, for one still on its way out) [m]."""
        cols = np.flatnonzero(self.state.present)
        ended = self.run_last[np.floor(self.state.tau[cols]).astype(int), cols]
        frames = np.where(self.present[index, cols], index, ended)
        return np.linalg.norm(self.state.xy_m[cols] - self.log_xy_m[frames, cols], axis=1)

    def step(self, index: int, robot_from_m: np.ndarray | None, robot_to_m: np.ndarray | None,
             robot_heading_rad: float | None = None) -> np.ndarray:
        """Advance from frame ``index - 1`` to ``index`` while, as the pedestrians expect, the robot moves from
        ``robot_from_m`` to ``robot_to_m`` (2,) [m] (None: no robot; the replay env passes the robot's last velocity
        held, not its command), its body turned to ``robot_heading_rad`` (default: along that move); returns the
        (A, 2) positions at ``index`` (NaN: absent; who is present is ``state.present``)."""
        old = self.state
        logged, log_now = self.present[index], self.log_xy_m[index]
        if robot_to_m is None:
            self.state = self._on_log(index)
            self.state.velocity_mps[:] = velocity(self.state.xy_m, old.xy_m, old.present & logged)
            return self.state.xy_m
        robot = Robot(np.asarray(robot_from_m, np.float64), np.asarray(robot_to_m, np.float64),
                      heading_of(robot_from_m, robot_to_m, robot_heading_rad))
        walking = self._walking(old)
        noticed, unseen = attend(old.noticed_s, old.unseen_s, self._notices(old, robot, walking))
        weight = np.where(old.present, self.reaction.weight(noticed), 0.0)
        room = self.reaction.room_m(robot.velocity_mps, robot.heading, walking,
                                    np.nan_to_num((old.xy_m - robot.from_m) @ robot.velocity_mps) > 0)
        lingering = old.present & old.off_log & ~logged & (old.linger < MAX_LINGER_STEPS)  # on their way out
        present = logged | lingering
        off_log = (old.off_log & old.present & logged & (old.linger == 0)) | lingering  # a log that starts again: on
        start = np.where(old.present[:, None], old.xy_m, log_now)  # (A, 2) where each one is before the step
        going = old.present & logged & ~off_log & (self._robot_in_the_way(index, robot, weight, room)
                                                   | self._others_in_the_way(index, old))
        off_log |= going
        tau = np.where(off_log, old.tau, float(index))
        tau[going] = index - 1.0  # from where they stood: their log at the previous frame
        farthest = np.where(off_log, np.where(going, tau, old.farthest), float(index))
        recent = np.where((off_log & ~going)[:, None], old.recent_m, np.inf)
        detour = off_log & ~going & old.detour
        offset = np.where(off_log, old.offset_m, 0.0)
        xy = np.where(off_log[:, None], start, log_now)
        xy[~present] = np.nan
        step = Step(index, start, xy, present, off_log, np.zeros(len(present), bool), old.velocity_mps, old.stuck,
                    farthest, recent, detour, robot, weight, room)
        clear = self._clear_of_robot(log_now, robot)
        for agent in np.flatnonzero(logged & ~old.present):  # appears where the robot or one off its log stands?
            taken = start[off_log & present]
            if clear[agent] and \
                    not (np.linalg.norm(taken - log_now[agent], axis=1) < 2 * BODY_RADIUS_M - PAIR_GIVE_M).any():
                continue
            offset[agent] = self._clear_offset(agent, index, robot, taken)
            xy[agent] = start[agent] = self._place(np.array([agent]), np.array([float(index)]), offset[[agent]],
                                                   index)[0]
            off_log[agent] = step.chosen[agent] = True
        order = np.flatnonzero(off_log & ~step.chosen)
        order = order[np.argsort(self.body.gap_m(start[order] - robot.from_m, robot.heading_rad), kind="stable")]
        for agent in order:  # the nearest to the robot first, each seeing the choices made before it
            tau[agent], offset[agent], xy[agent] = self._choose(agent, tau[agent], offset[agent], step)
            step.chosen[agent] = True
        # back on the log: caught up, beside it, and nothing in the way; out of the scene: where the log ended
        ahead = ReactiveState(xy, velocity(xy, old.xy_m, old.present & present), present, off_log, tau, offset,
                              old.linger, old.stuck, farthest, recent, detour, noticed, unseen, weight)
        after = Robot(robot.to_m, 2 * robot.to_m - robot.from_m, robot.heading_rad)
        rejoin = (off_log & logged & (np.linalg.norm(np.nan_to_num(xy - log_now, nan=np.inf), axis=1) <= REJOIN_M)
                  & ~self._robot_in_the_way(index + 1, after, weight, room) & ~self._others_in_the_way(index + 1, ahead)
                  & clear)
        xy[rejoin] = log_now[rejoin]
        off_log &= ~rejoin
        cols = np.arange(len(tau))
        log_end = self.log_xy_m[self.run_last[np.clip(np.floor(tau), 0, None).astype(int), cols], cols]
        to_end = np.linalg.norm(np.nan_to_num(xy - log_end, nan=np.inf), axis=1)
        blocked = np.linalg.norm(np.nan_to_num(xy - start), axis=1) < STILL_M  # the robot or others stand there
        present &= ~(lingering & ((to_end <= REJOIN_M) | (blocked & (to_end <= LEAVE_BLOCKED_M))))
        off_log &= present
        xy[~present] = np.nan
        headway, farther, behind = np.ones(len(tau), bool), np.ones(len(tau), bool), np.full(len(tau), np.inf)
        for agent in np.flatnonzero(off_log):
            gain, away = self._headway(agent, tau[[agent]], offset[[agent]], farthest[agent], index)
            farther[agent] = gain[0] >= HEADWAY_M
            headway[agent] = farther[agent] or away[0] <= recent[agent].min() - HEADWAY_M
            behind[agent] = away[0]
        stuck = np.where(off_log & ~headway, old.stuck + 1, 0)
        detour &= off_log & ~farther
        detour |= stuck >= DETOUR_AFTER_STEPS
        self.state = ReactiveState(xy, velocity(xy, old.xy_m, old.present & present), present, off_log,
                                   np.where(off_log, tau, float(index)), np.where(off_log, offset, 0.0),
                                   np.where(present & lingering, old.linger + 1, 0),
                                   stuck,
                                   np.where(off_log, np.maximum(farthest, tau), float(index)),
                                   np.c_[recent[:, 1:], behind], detour,
                                   np.where(present, noticed, 0.0), np.where(present, unseen, 0.0), weight)
        return xy

    # ------------------------------------------------------------------------------------------------ noticing
    def _walking(self, state: ReactiveState) -> np.ndarray:
        """(A, 2) unit walking directions: the velocity of those faster than ``MOVING_MPS``, else the route's
        direction where they are on it."""
        speed = np.linalg.norm(state.velocity_mps, axis=1, keepdims=True)
        frame = np.clip(np.floor(state.tau), 0, len(self.present) - 1).astype(int)
        route = self.tangent[frame, np.arange(len(frame))]
        return np.where(speed > MOVING_MPS, state.velocity_mps / np.maximum(speed, 1e-12), route)

    def _notices(self, state: ReactiveState, robot: Robot, walking: np.ndarray) -> np.ndarray:
        """(A,) bool: the pedestrians present that notice the robot at the start of the step (``reaction.notices``)."""
        offset = state.xy_m - robot.from_m
        toward = robot.from_m + self.body.nearest_point_m(offset, robot.heading_rad) - state.xy_m
        bearing = np.arctan2(walking[:, 0] * toward[:, 1] - walking[:, 1] * toward[:, 0], (walking * toward).sum(1))
        gap = np.nan_to_num(self.body.gap_m(offset, robot.heading_rad), nan=np.inf)
        return state.present & notices(self.reaction, gap, np.nan_to_num(bearing, nan=np.pi))

    def _clear_of_robot(self, xy_m: np.ndarray, robot: Robot) -> np.ndarray:
        """(A,) bool: points (A, 2) at least ``robot_reach_m`` from the robot's body where it stands and where it is
        expected at the end of the step (NaN points are clear)."""
        gaps = [self.body.gap_m(xy_m - where, robot.heading_rad) for where in (robot.from_m, robot.to_m)]
        return np.nan_to_num(np.minimum(*gaps), nan=np.inf) >= self.robot_reach_m

    # ------------------------------------------------------------------------------------------------ choosing
    def _route(self, agents: np.ndarray, tau: np.ndarray, run_frame: int) -> tuple[np.ndarray, np.ndarray]:
        """Point of each agent's logged route at fractional frame ``tau`` and the left normal there; (..., 2) each
        for ``agents``/``tau`` of the same shape (...). ``tau`` is held within the run of the log that holds frame
        ``run_frame`` (where the agents are on their routes now)."""
        first, last = self.run_first[run_frame, agents], self.run_last[run_frame, agents]
        tau = np.clip(tau, first, last)
        frame = np.floor(tau).astype(int)
        after = np.minimum(frame + 1, last)
        share = (tau - frame)[..., None]
        point = (1 - share) * self.log_xy_m[frame, agents] + share * self.log_xy_m[after, agents]
        tangent = (1 - share) * self.tangent[frame, agents] + share * self.tangent[after, agents]
        tangent /= np.maximum(np.linalg.norm(tangent, axis=-1, keepdims=True), 1e-9)
        return point, np.stack([-tangent[..., 1], tangent[..., 0]], axis=-1)

    def _tau_ahead(self, agent: int, tau: float, ahead_m: np.ndarray, run_frame: int) -> np.ndarray:
        """(K,) the latest fractional frames whose route points lie ``ahead_m`` (K,) metres further along the agent's
        logged route than ``tau`` (through any stretch where the log stood still), within the run of ``run_frame``."""
        first, last = self.run_first[run_frame, agent], self.run_last[run_frame, agent]
        arc = self.arc_m[first:last + 1, agent]
        target = self._arc(agent, np.array([tau]), run_frame)[0] + ahead_m
        k = np.clip(np.searchsorted(arc, target, side="right") - 1, 0, len(arc) - 1)
        step = np.diff(arc, append=arc[-1])[k]
        share = np.where(step > 0, np.clip((target - arc[k]) / np.where(step > 0, step, 1.0), 0.0, 1.0), 0.0)
        return first + k + share

    def _arc(self, agent: int, tau: np.ndarray, run_frame: int) -> np.ndarray:
        """(K,) metres along the agent's logged route at fractional frames ``tau`` (K,), within the run of
        ``run_frame``."""
        first, last = self.run_first[run_frame, agent], self.run_last[run_frame, agent]
        tau = np.clip(tau, first, last)
        frame = np.floor(tau).astype(int)
        arc = self.arc_m[:, agent]
        return arc[frame] + (tau - frame) * (arc[np.minimum(frame + 1, last)] - arc[frame])

    def _headway(self, agent: int, tau: np.ndarray, offset_m: np.ndarray, farthest: float,
                 index: int) -> tuple[np.ndarray, np.ndarray]:
        """For places at route points ``tau`` (K,) moved ``offset_m`` (K,) aside: how much farther along the route than
        ``farthest`` they are [m], and how far from the log at frame ``index`` (metres behind it along the route plus
        metres aside) [m]."""
        run_frame = int(farthest)
        now = min(float(index), float(self.run_last[run_frame, agent]))  # where its log is now, or where it ended
        arc = self._arc(agent, np.r_[tau, farthest, now], run_frame)
        return arc[:-2] - arc[-2], np.maximum(arc[-1] - arc[:-2], 0.0) + np.abs(offset_m)

    def _place(self, agents: np.ndarray, tau: np.ndarray, offset_m: np.ndarray, run_frame: int) -> np.ndarray:
        """(..., 2) positions at route points ``tau`` (within the run holding ``run_frame``) moved ``offset_m`` to the
        side."""
        point, normal = self._route(agents, tau, run_frame)
        return point + offset_m[..., None] * normal

    def _clear_offset(self, agent: int, index: int, robot: Robot, others_m: np.ndarray) -> float:
        """The smallest side offset [m] at frame ``index`` that clears the robot (where it stands and where it is
        expected) and the pedestrians at ``others_m`` (K, 2), and stays as walkable as the log (0 if none does)."""
        offsets = OFFSETS_M[np.argsort(np.abs(OFFSETS_M), kind="stable")]
        who, taus = np.full(len(offsets), agent), np.full(len(offsets), float(index))
        places = self._place(who, taus, offsets, index)
        apart = np.linalg.norm(places[:, None] - others_m[None], axis=-1).min(axis=1, initial=np.inf)
        fine = (self._clear_of_robot(places, robot) & (apart >= 2 * BODY_RADIUS_M - PAIR_GIVE_M)
                & (self._too_deep_m(agent, index, places, index) == 0))
        return float(offsets[np.argmax(fine)]) if fine.any() else 0.0

    def _too_deep_m(self, agent: int, tau: float, places: np.ndarray, run_frame: int,
                    through: float | None = None) -> np.ndarray:
        """(...) how much deeper in the non-walkable area each place (..., 2) is than the agent's log: than the point
        of its log nearest to it within ``DEPTH_WINDOW`` frames of route point ``tau``, or the log's deepest point
        within ``CROSSING_WINDOW`` frames of it (a crossing of a thin wall, beside it) [m]; with ``through``, than the
        point of its log nearest to it on the route from ``tau`` through ``through`` (and ``DEPTH_WINDOW`` frames
        beyond) alone; 0 where that point is off the image, 1000 for a place off the image beside a log on it."""
        depth = self.depth.at(places)
        excess = np.zeros(depth.shape)
        deep = depth > 0  # a place on walkable ground is never deeper than the log: compare only the others
        if not deep.any():
            return excess
        first, last = self.run_first[run_frame, agent], self.run_last[run_frame, agent]
        frame = int(np.floor(tau))
        start = frame - DEPTH_WINDOW if through is None else frame
        end = frame if through is None else max(frame, int(np.floor(through)))
        window = slice(max(first, start), min(last, end + DEPTH_WINDOW) + 1)
        trace = self.trace_m[window, agent].reshape(-1, 2)
        trace_depth = self.trace_depth_m[window, agent].reshape(-1)
        nearest = np.argmin(np.linalg.norm(places[deep][:, None, :] - trace, axis=-1), axis=-1)
        log_depth = trace_depth[nearest]
        if through is None:
            close = slice(max(first, frame - CROSSING_WINDOW), min(last, frame + CROSSING_WINDOW) + 1)
            log_depth = np.maximum(log_depth, self.trace_depth_m[close, agent].max())
        over = np.minimum(np.maximum(depth[deep] - log_depth - DEPTH_TOLERANCE_M, 0.0), 1e3)
        excess[deep] = np.where(np.isinf(log_depth), 0.0, over)
        return excess

    def _choose(self, agent: int, tau: float, offset: float, step: Step) -> tuple[float, float, np.ndarray]:
        """(tau, offset [m], position (2,)) of ``agent`` at frame ``step.index``: the cheapest candidate that keeps
        every bound (see the module docstring), or the one that breaks them the least."""
        c = self._candidates(agent, tau, offset, step)
        best = int(np.argmin(np.where(c.violation > 0, np.inf, c.cost))) if (c.violation == 0).any() else \
            int(np.argmin(c.violation))
        return float(c.tau[best]), float(c.offset_m[best]), c.xy_m[best]

    def _candidates(self, agent: int, tau: float, offset: float, step: Step) -> Candidates:
        """Every place ``agent`` may choose at frame ``step.index``, how far each breaks the bounds, and its cost."""
        run_frame = int(tau)
        cap = max(tau, min(float(step.index), float(self.run_last[run_frame, agent])))  # never ahead of the log
        reach_m = max(CATCH_UP_MPS, CATCH_UP_FACTOR * self.log_speed_mps[run_frame, agent]) * STEP_S
        first = float(self.run_first[run_frame, agent])
        taus = np.unique(np.r_[self._tau_ahead(agent, tau, reach_m * PROGRESS_SHARES, run_frame), cap].clip(first, cap))
        offsets = np.unique(np.r_[OFFSETS_M, offset])
        c_tau, c_off = np.repeat(taus, len(offsets)), np.tile(offsets, len(taus))
        who = np.full(len(c_tau), agent)
        places = self._place(who, c_tau, c_off, run_frame)  # (C, 2)
        here = step.start[agent]
        too_fast = np.maximum(np.linalg.norm(places - here, axis=1) - reach_m, 0.0)
        too_deep = np.max([self._too_deep_m(agent, tau, here + share * (places - here), run_frame)
                           for share in PATH_SAMPLES], axis=0)  # along the way: no jumping over a thin wall
        robot_to = step.robot.to_m if step.weight[agent] > 0 else step.robot.from_m  # noticed, or only its body
        robot_gap = self.body.swept_gap_m(here - step.robot.from_m, places - robot_to, step.robot.heading_rad)
        into_robot = np.maximum(self.robot_reach_m - robot_gap, 0.0)
        too_close = np.zeros(len(places))  # into the others
        others = np.flatnonzero(step.present & (np.arange(len(step.present)) != agent))
        if others.size:
            their_from, their_to = step.start[others], step.xy[others]  # the log now, a choice, or where they stand
            body_m = 2 * BODY_RADIUS_M - PAIR_GIVE_M
            allowed = np.minimum(body_m, np.linalg.norm(their_from - here, axis=1) - 1e-6)
            pair_gap, _ = closest_approach(here - their_from, places[:, None] - their_to[None])  # (C, O)
            too_close = too_close + np.maximum(allowed - pair_gap, 0.0).sum(axis=1)
            logged = np.linalg.norm(self.log_xy_m[step.index, agent] - self.log_xy_m[step.index, others], axis=1)
            apart = np.minimum(body_m, np.nan_to_num(logged, nan=np.inf))  # closer than that now: part as the logs do
            end_gap = np.linalg.norm(places[:, None] - their_to[None], axis=-1)  # (C, O)
            too_close = too_close + np.maximum(apart - end_gap, 0.0).sum(axis=1)
        gain, away = self._headway(agent, c_tau, c_off, step.farthest[agent], step.index)
        staying = (gain < HEADWAY_M) & (away > step.recent_m[agent].min() - HEADWAY_M)  # stuck: try another way
        delay = np.minimum(step.index - c_tau, (away - np.abs(c_off)) / (STEP_S * LAG_PACE_MPS))  # [frame]
        cost = (LAG_COST * delay + OFFSET_COST * np.abs(c_off) + SWAY_COST * np.abs(c_off - offset)
                + RISK_COST * self._risk(agent, c_tau, c_off, others, step, run_frame)
                + STUCK_COST * step.stuck[agent] * staying)
        if step.detour[agent]:
            cost = cost + DETOUR_COST * self._way_round_m(agent, tau, step, places, run_frame)
        violation = too_fast + too_close + WALL_WEIGHT * too_deep + ROBOT_WEIGHT * into_robot
        return Candidates(c_tau, c_off, places, violation, cost)

    def _way_round_m(self, agent: int, tau: float, step: Step, places: np.ndarray, run_frame: int) -> np.ndarray:
        """(C,) how far [m] the agent would have to walk from each of ``places`` (C, 2) to a point of its route ahead
        (``DETOUR_AHEAD_M``) round the robot's body (where it stands and where it is expected), over ground no deeper
        in the non-walkable area than its log there (its route from ``DETOUR_BACK_FRAMES`` behind route point ``tau``
        to that point); counted from the nearest, and those cut off from that point 1 m beyond the farthest (0 for all
        when no such point is known)."""
        ahead = self._tau_ahead(agent, step.farthest[agent], np.array(DETOUR_AHEAD_M), run_frame)  # to its run's end
        goals = self._place(np.full(len(ahead), agent), ahead, np.zeros(len(ahead)), run_frame)
        clear = self._clear_of_robot(goals, step.robot)
        if not clear.any():
            return np.zeros(len(places))
        goal_tau, goal = ahead[np.argmax(clear)], goals[np.argmax(clear)]
        back = max(float(self.run_first[run_frame, agent]), tau - DETOUR_BACK_FRAMES)
        route = self.log_xy_m[int(back):int(np.ceil(goal_tau)) + 1, agent]
        around = np.vstack([places, route, goal[None], step.start[[agent]]])
        cells = grid_cells(around.min(axis=0) - DETOUR_MARGIN_M, around.max(axis=0) + DETOUR_MARGIN_M)  # (H, W, 2)
        flat = cells.reshape(-1, 2)
        free = self._clear_of_robot(flat, step.robot)
        free[free] = self._too_deep_m(agent, back, flat[free], run_frame, through=goal_tau) == 0
        walk_m = walking_distance_m(cells, free.reshape(cells.shape[:2]), goal, places)
        known = np.isfinite(walk_m)
        if not known.any():
            return np.zeros(len(places))
        nearest, farthest = walk_m[known].min(), walk_m[known].max()
        return np.where(known, walk_m - nearest, farthest - nearest + 1.0)

    def _risk(self, agent: int, c_tau: np.ndarray, c_off: np.ndarray, others: np.ndarray, step: Step,
              run_frame: int) -> np.ndarray:
        """(C,) squared intrusions [m^2], if the agent walks on along its route at its log's pace from each candidate:
        into its room round the robot going on at its velocity over ``anticipation_s`` (as far as it reacts), or into
        ``COMFORT_M`` round the robot's body standing where it is over ``ANTICIPATION_STEPS`` (as far as it does not:
        a body in the way); and into the comfort gap round the others off their logs going on at their velocities
        over ``ANTICIPATION_STEPS``."""
        weight = step.weight[agent]
        robot_steps = self.reaction.anticipation_steps if weight > 0 else 0
        ahead = np.arange(max(robot_steps, ANTICIPATION_STEPS) + 1, dtype=np.float64)  # (H + 1,) from now on
        later = self._place(np.full((len(c_tau), len(ahead)), agent), c_tau[:, None] + ahead,
                            np.repeat(c_off[:, None], len(ahead), 1), run_frame)  # (C, H + 1, 2)
        heading = step.robot.heading_rad
        standing = later[:, :ANTICIPATION_STEPS + 1] - step.robot.from_m  # (C, H_s + 1, 2) from the body standing
        gap = self.body.swept_gap_m(standing[:, :-1], standing[:, 1:], heading)  # (C, H_s) along each step
        risk = (1.0 - weight) * (np.maximum(self.robot_reach_m + COMFORT_M - gap, 0.0) ** 2).sum(axis=1)
        if robot_steps:
            robot = step.robot.to_m + ahead[:robot_steps + 1, None] * STEP_S * step.robot.velocity_mps  # (H_r + 1, 2)
            moving = later[:, :robot_steps + 1] - robot  # (C, H_r + 1, 2) from the body on its course
            gap = self.body.swept_gap_m(moving[:, :-1], moving[:, 1:], heading)  # (C, H_r)
            room = self.robot_reach_m + step.room_m[agent]
            risk += weight * (np.maximum(room - gap, 0.0) ** 2).sum(axis=1)
        off_log = others[step.off_log[others]]  # those on their logs keep to them: the hard bounds cover them
        if off_log.size:
            pair_ahead = ahead[1:ANTICIPATION_STEPS + 1]
            moving = step.xy[off_log][None] + pair_ahead[:, None, None] * STEP_S * step.velocity_mps[off_log][None]
            pair = np.linalg.norm(later[:, 1:ANTICIPATION_STEPS + 1, None] - moving[None], axis=-1)  # (C, H, O)
            risk += (np.maximum(2 * BODY_RADIUS_M + COMFORT_M / 2 - pair, 0.0) ** 2).sum(axis=(1, 2))
        return risk

    def _robot_in_the_way(self, index: int, robot: Robot, weight: np.ndarray, room_m: np.ndarray) -> np.ndarray:
        """(A,) bool: agents whose log's step into frame ``index`` would take them within ``robot_reach_m`` of the
        robot's body (where it stands, for those that do not react; on its expected course, for those that do), or,
        for those that react, whose log from frame ``index`` on comes within their room (A,) [m] of the robot's
        expected course over ``anticipation_s``."""
        hit = np.zeros(len(weight), bool)
        if index >= len(self.present):
            return hit
        reacting = weight > 0
        robot_to = np.where(reacting[:, None], robot.to_m, robot.from_m)
        if index > 0:
            gap = self.body.swept_gap_m(self.log_xy_m[index - 1] - robot.from_m, self.log_xy_m[index] - robot_to,
                                        robot.heading_rad)
            hit |= np.nan_to_num(gap, nan=np.inf) < self.robot_reach_m
        frames = min(self.reaction.anticipation_steps, len(self.present) - index)
        first = max(index - 1, 0)  # along every step of the log ahead, from where it stands now
        course = robot.to_m + np.arange(first - index, frames)[:, None] * STEP_S * robot.velocity_mps  # (H', 2)
        offset = self.log_xy_m[first:index + frames] - course[:, None]  # (H', A, 2)
        if len(offset) > 1:
            gap = self.body.swept_gap_m(offset[:-1], offset[1:], robot.heading_rad)  # (H' - 1, A)
        else:
            gap = self.body.gap_m(offset, robot.heading_rad)
        return hit | (reacting & (np.nan_to_num(gap, nan=np.inf).min(axis=0) < self.robot_reach_m + room_m))

    def _others_in_the_way(self, index: int, state: ReactiveState) -> np.ndarray:
        """(A,) bool: agents whose log from frame ``index`` on comes within ``PAIR_CLEARANCE_M`` of a pedestrian off
        its log (going on at its velocity) within ``PAIR_LOOK_AHEAD_STEPS``, where it comes closer than their own
        logs would."""
        frames = min(PAIR_LOOK_AHEAD_STEPS, len(self.present) - index)
        others = np.flatnonzero(state.off_log & state.present)
        if frames <= 0 or not others.size:
            return np.zeros(len(state.off_log), bool)
        ahead = np.arange(frames)[:, None] * STEP_S  # (H, 1) seconds
        log = self.log_xy_m[index:index + frames]  # (H, A, 2), NaN where absent
        where = state.xy_m[others] + ahead[:, :, None] * state.velocity_mps[others]  # (H, O, 2)
        gap = np.linalg.norm(log[:, :, None] - where[:, None], axis=-1)  # (H, A, O)
        logged_gap = np.linalg.norm(log[:, :, None] - log[:, others][:, None], axis=-1)
        bound = np.minimum(2 * BODY_RADIUS_M + PAIR_CLEARANCE_M, np.nan_to_num(logged_gap, nan=np.inf) - PAIR_GIVE_M)
        gap[:, others, np.arange(others.size)] = np.inf  # nobody is in their own way
        return (np.nan_to_num(gap, nan=np.inf) < bound).any(axis=(0, 2))


def heading_of(from_m: np.ndarray, to_m: np.ndarray, heading_rad: float | None = None) -> float:
    """``heading_rad`` if given, else the direction of the move ``from_m`` -> ``to_m`` (2,) [rad] (0 for no move)."""
    if heading_rad is not None:
        return float(heading_rad)
    move = np.asarray(to_m, np.float64) - np.asarray(from_m, np.float64)
    return float(np.arctan2(move[1], move[0])) if np.hypot(*move) > 1e-9 else 0.0


def velocity(xy: np.ndarray, old_xy: np.ndarray, stays: np.ndarray) -> np.ndarray:
    """(A, 2) velocity over the step [m/s] of the agents present before and after it (0 for the others)."""
    return np.where(stays[:, None], np.nan_to_num(xy - old_xy) / STEP_S, 0.0)


def run_bounds(present: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, A) int first and last frame of the run of consecutive presence that holds frame f (-1 where absent)."""
    first, last = np.full(present.shape, -1), np.full(present.shape, -1)
    first[0] = np.where(present[0], 0, -1)
    for f in range(1, len(present)):
        first[f] = np.where(present[f], np.where(present[f - 1], first[f - 1], f), -1)
    last[-1] = np.where(present[-1], len(present) - 1, -1)
    for f in range(len(present) - 2, -1, -1):
        last[f] = np.where(present[f], np.where(present[f + 1], last[f + 1], f), -1)
    return first, last


def smoothed(tangent: np.ndarray, run_first: np.ndarray, run_last: np.ndarray) -> np.ndarray:
    """(F, A, 2) unit directions averaged over ``TANGENT_WINDOW`` frames either side within each run, so that a side
    offset turns smoothly round the log's corners."""
    frames = np.arange(len(tangent))[:, None]
    total = np.zeros_like(tangent)
    for shift in range(-TANGENT_WINDOW, TANGENT_WINDOW + 1):
        other = np.clip(frames + shift, 0, len(tangent) - 1)
        same_run = (run_first <= frames + shift) & (frames + shift <= run_last)
        total += np.where(same_run[..., None], np.take_along_axis(tangent, other[..., None].repeat(2, -1), 0), 0.0)
    norm = np.linalg.norm(total, axis=-1, keepdims=True)
    return np.where(norm > 1e-6, total / np.maximum(norm, 1e-12), tangent)


def route_tangents(step: np.ndarray, usable: np.ndarray, present: np.ndarray) -> np.ndarray:
    """(F, A, 2) unit direction of each log at every frame: its step to the next frame where that is at least
    ``MIN_STEP_M`` long, else the nearest such step before it in its run, else after it, else +x (a log that never
    moves)."""
    frames, agents = present.shape
    unit = np.zeros((frames, agents, 2))
    known = np.zeros((frames, agents), bool)
    unit[:-1][usable] = step[usable] / np.linalg.norm(step[usable], axis=-1, keepdims=True)
    known[:-1] = usable
    forward, backward = unit.copy(), unit.copy()
    have_f, have_b = known.copy(), known.copy()
    for f in range(1, frames):  # carry the last direction forward through a run
        carry = ~have_f[f] & have_f[f - 1] & present[f] & present[f - 1]
        forward[f][carry], have_f[f][carry] = forward[f - 1][carry], True
    for f in range(frames - 2, -1, -1):  # and the next one backward, for a run that starts standing
        carry = ~have_b[f] & have_b[f + 1] & present[f] & present[f + 1]
        backward[f][carry], have_b[f][carry] = backward[f + 1][carry], True
    return np.where(have_f[..., None], forward, np.where(have_b[..., None], backward, np.array([1.0, 0.0])))
