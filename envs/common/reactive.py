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

**Batched, with the same walks.** One step of N crowds of a replay (``ReactiveCrowd.step_all``: the sub-envs of a
vector env; ``Routes`` holds the replay's tables, shared) is one pass over arrays (N, A): who notices the robot, who
leaves or rejoins its log. Every candidate of every pedestrian off its log, in every crowd, is placed and checked for
its pace and the robot's margin in one pass (``Routes._candidates``); its depth, its risk and the terms between
pedestrians are scored only for the candidates that could still be chosen (a candidate costs at least its cost with
no risk: ``Routes._best`` scores them least costly first until the cheapest within every bound is cheaper than every
one left). The pedestrians of each crowd choose in rounds (``Routes._choose_all``): all at once against the others
where they stand, then again only those that see, before them in their crowd's order, a pedestrian within reach whose
choice changed, until none changes; each has then chosen seeing the choices made before it, as one after another.
Terms are summed over the others as numpy sums them all (``exact_row_sums``): the walks are those of scoring every
pedestrian alone, to the last bit (``tests/test_reactive_batched.py``; ``benchmarks/bench_reactive.py --digest``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Final, Protocol

import numpy as np

from envs.common.detour import grid_cells, walking_distances_m
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
PAIR_REACH_M: Final[float] = 2 * BODY_RADIUS_M + COMFORT_M / 2  # the farthest two pedestrians' terms reach [m]
NEAR_SLACK_M: Final[float] = 1e-6  # a pair is left out of a step's terms only beyond PAIR_REACH_M plus this [m]
FIRST_LOOK: Final[int] = 32  # candidates each chooser scores in full at first, those least costly first [-]
CHUNK_VALUES: Final[int] = 1 << 21  # nearest-trace searches run in chunks of at most this many distances [-]


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
        """(N, 2) unit headings."""
        return np.stack([np.cos(self.heading_rad), np.sin(self.heading_rad)], axis=-1)

    def after(self) -> Robot:
        """The same robots over the next step, holding their velocities."""
        return Robot(self.to_m, 2 * self.to_m - self.from_m, self.heading_rad)


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
            keeps [m].
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


@dataclass(frozen=True, eq=False)
class Candidates:
    """The places every chooser (a pedestrian off its log, J of them in all crowds) may choose in one step, its C
    candidates in a row (M = sum of C in all, in the order of its own grid: progress, then side).

    Attributes:
        owner: (M,) chooser.  first: (J + 1,) where each chooser's rows start.  tau_now: (J,) the route point
            each chooser's place is taken from now.
        tau: (M,) route point.  offset_m: (M,) side [m].  xy_m: (M, 2) position [m].
        too_fast, into_robot: (M,) two of the bounds it breaks (``violation``).  too_deep: (M,) a third, NaN until
            scored (``Routes._settle``).
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


def stack_states(states: Sequence[ReactiveState]) -> ReactiveState:
    """The states of N crowds of one replay as one, every array with a leading crowd axis (N, A, ...)."""
    return ReactiveState(*(np.stack([getattr(state, field.name) for state in states])
                           for field in fields(ReactiveState)))


def unstack_state(state: ReactiveState, crowd: int) -> ReactiveState:
    """Row ``crowd`` of a stacked state."""
    return ReactiveState(*(getattr(state, field.name)[crowd] for field in fields(ReactiveState)))


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
        self.routes = Routes(log_xy_m, present, depth, body, touch_m, reaction)
        self.state = self.routes.on_log(0)

    @classmethod
    def on(cls, routes: Routes) -> ReactiveCrowd:
        """A crowd walking ``routes``, shared with other crowds of the same replay (the sub-envs of a vector env), so
        that ``step_all`` steps them together."""
        crowd = cls.__new__(cls)
        crowd.routes, crowd.state = routes, routes.on_log(0)
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

    def reset(self, index: int) -> np.ndarray:
        """Everybody on their log at frame ``index``, nobody has noticed the robot; returns the (A, 2) positions."""
        self.state = self.routes.on_log(index)
        return self.state.xy_m

    def deviation_m(self, index: int) -> np.ndarray:
        """(present agents,) distance of each pedestrian present now from its log at frame ``index`` (from where its
        log ended, for one still on its way out) [m]."""
        cols = np.flatnonzero(self.state.present)
        ended = self.routes.run_last[np.floor(self.state.tau[cols]).astype(int), cols]
        frames = np.where(self.routes.present[index, cols], index, ended)
        return np.linalg.norm(self.state.xy_m[cols] - self.routes.log_xy_m[frames, cols], axis=1)

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
                crowd.state = crowd.routes.on_log(indices[i])
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
            state = routes.advance(stack_states([crowds[i].state for i in members]),
                                   np.array([indices[i] for i in members]), robot)
            for row, i in enumerate(members):
                crowds[i].state = unstack_state(state, row)
        return [crowd.state.xy_m for crowd in crowds]


class Routes:
    """The logged routes of one replay as reactive pedestrians walk them: the tables built once (shared by every crowd
    of the replay, ``ReactiveCrowd.on``) and the step of N crowds on them at once (``advance``). Arguments as
    ``ReactiveCrowd``'s."""

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

    def on_log(self, index: int) -> ReactiveState:
        """Everybody on their log at frame ``index``, nobody has noticed the robot."""
        now = self.present[index]
        xy = np.where(now[:, None], self.log_xy_m[index], np.nan)
        agents = len(now)
        zero = np.zeros(agents)
        return ReactiveState(xy, np.zeros_like(xy), now.copy(), np.zeros(agents, bool), np.full(agents, float(index)),
                             zero, np.zeros(agents, int), np.zeros(agents, int), np.full(agents, float(index)),
                             np.full((agents, RECENT_STEPS), np.inf), np.zeros(agents, bool), zero, zero, zero)

    def advance(self, old: ReactiveState, index: np.ndarray, robot: Robot) -> ReactiveState:
        """The stacked state (N, A, ...) of N crowds after their step from frames ``index - 1`` to ``index`` (N,),
        each crowd's robot moving as ``robot`` (N rows) expects (``ReactiveCrowd.step``)."""
        frame = index[:, None].astype(np.float64)  # (N, 1)
        logged, log_now = self.present[index], self.log_xy_m[index]  # (N, A), (N, A, 2)
        walking = self._walking(old)
        noticed, unseen = attend(old.noticed_s, old.unseen_s, self._notices(old, robot, walking))
        weight = np.where(old.present, self.reaction.weight(noticed), 0.0)
        room = np.stack([self.reaction.room_m(robot.velocity_mps[n], robot.heading[n], walking[n],
                                              np.nan_to_num((old.xy_m[n] - robot.from_m[n]) @ robot.velocity_mps[n])
                                              > 0) for n in range(len(index))])
        lingering = old.present & old.off_log & ~logged & (old.linger < MAX_LINGER_STEPS)  # on their way out
        present = logged | lingering
        off_log = (old.off_log & old.present & logged & (old.linger == 0)) | lingering  # a log that starts again: on
        start = np.where(old.present[..., None], old.xy_m, log_now)  # (N, A, 2) where each one is before the step
        going = old.present & logged & ~off_log & (self._robot_in_the_way(index, robot, weight, room)
                                                   | self._others_in_the_way(index, old))
        off_log |= going
        tau = np.where(going, frame - 1.0, np.where(off_log, old.tau, frame))  # going: from their log's last frame
        farthest = np.where(off_log, np.where(going, tau, old.farthest), frame)
        recent = np.where((off_log & ~going)[..., None], old.recent_m, np.inf)
        detour = off_log & ~going & old.detour
        offset = np.where(off_log, old.offset_m, 0.0)
        xy = np.where(off_log[..., None], start, log_now)
        xy[~present] = np.nan
        step = Step(index, start, xy, present, off_log, np.zeros(present.shape, bool), old.velocity_mps, old.stuck,
                    farthest, recent, detour, robot, weight, room)
        clear = self.clear_of_robot(log_now, robot.from_m[:, None], robot.to_m[:, None], robot.heading_rad[:, None])
        self._place_newcomers(step, logged & ~old.present, clear, offset)
        self._choose_all(step, tau, offset)
        # back on the log: caught up, beside it, and nothing in the way; out of the scene: where the log ended
        ahead = ReactiveState(xy, velocity(xy, old.xy_m, old.present & present), present, off_log, tau, offset,
                              old.linger, old.stuck, farthest, recent, detour, noticed, unseen, weight)
        rejoin = (off_log & logged & (length_m(np.nan_to_num(xy - log_now, nan=np.inf)) <= REJOIN_M)
                  & ~self._robot_in_the_way(index + 1, robot.after(), weight, room)
                  & ~self._others_in_the_way(index + 1, ahead) & clear)
        xy[rejoin] = log_now[rejoin]
        off_log &= ~rejoin
        cols = np.arange(present.shape[1])
        log_end = self.log_xy_m[self.run_last[np.clip(np.floor(tau), 0, None).astype(int), cols], cols]
        to_end = length_m(np.nan_to_num(xy - log_end, nan=np.inf))
        blocked = length_m(np.nan_to_num(xy - start)) < STILL_M  # the robot or others stand there
        present &= ~(lingering & ((to_end <= REJOIN_M) | (blocked & (to_end <= LEAVE_BLOCKED_M))))
        off_log &= present
        xy[~present] = np.nan
        headway, farther = np.ones(present.shape, bool), np.ones(present.shape, bool)
        behind = np.full(tau.shape, np.inf)
        rows, agents = np.nonzero(off_log)
        gain, away = self.headway(agents, tau[rows, agents], offset[rows, agents], farthest[rows, agents],
                                  index[rows])
        farther[rows, agents] = gain >= HEADWAY_M
        headway[rows, agents] = farther[rows, agents] | (away <= recent[rows, agents].min(axis=-1) - HEADWAY_M)
        behind[rows, agents] = away
        stuck = np.where(off_log & ~headway, old.stuck + 1, 0)
        detour &= off_log & ~farther
        detour |= stuck >= DETOUR_AFTER_STEPS
        return ReactiveState(xy, velocity(xy, old.xy_m, old.present & present), present, off_log,
                             np.where(off_log, tau, frame), np.where(off_log, offset, 0.0),
                             np.where(present & lingering, old.linger + 1, 0), stuck,
                             np.where(off_log, np.maximum(farthest, tau), frame),
                             np.concatenate([recent[..., 1:], behind[..., None]], axis=-1), detour,
                             np.where(present, noticed, 0.0), np.where(present, unseen, 0.0), weight)

    # ------------------------------------------------------------------------------------------------ noticing
    def _walking(self, state: ReactiveState) -> np.ndarray:
        """(N, A, 2) unit walking directions: the velocity of those faster than ``MOVING_MPS``, else the route's
        direction where they are on it."""
        speed = length_m(state.velocity_mps)[..., None]
        frame = np.clip(np.floor(state.tau), 0, len(self.present) - 1).astype(int)
        route = self.tangent[frame, np.arange(frame.shape[-1])]
        return np.where(speed > MOVING_MPS, state.velocity_mps / np.maximum(speed, 1e-12), route)

    def _notices(self, state: ReactiveState, robot: Robot, walking: np.ndarray) -> np.ndarray:
        """(N, A) bool: the pedestrians present that notice their robot at the start of the step
        (``reaction.notices``)."""
        offset = state.xy_m - robot.from_m[:, None]
        heading = robot.heading_rad[:, None]
        toward = robot.from_m[:, None] + self.body.nearest_point_m(offset, heading) - state.xy_m
        bearing = np.arctan2(walking[..., 0] * toward[..., 1] - walking[..., 1] * toward[..., 0],
                             (walking * toward).sum(-1))
        gap = np.nan_to_num(self.body.gap_m(offset, heading), nan=np.inf)
        return state.present & notices(self.reaction, gap, np.nan_to_num(bearing, nan=np.pi))

    def clear_of_robot(self, xy_m: np.ndarray, from_m: np.ndarray, to_m: np.ndarray,
                       heading_rad: np.ndarray) -> np.ndarray:
        """(...) bool: points (..., 2) at least ``robot_reach_m`` from the robot's body where it stands (``from_m``)
        and where it is expected at the end of the step (``to_m``), both (..., 2) and ``heading_rad`` (...)
        broadcast against the points (NaN points are clear)."""
        gaps = [self.body.gap_m(xy_m - where, heading_rad) for where in (from_m, to_m)]
        return np.nan_to_num(np.minimum(*gaps), nan=np.inf) >= self.robot_reach_m

    def _robot_in_the_way(self, index: np.ndarray, robot: Robot, weight: np.ndarray, room_m: np.ndarray) -> np.ndarray:
        """(N, A) bool: agents whose log's step into frame ``index`` (N,) would take them within ``robot_reach_m`` of
        their robot's body (where it stands, for those that do not react; on its expected course, for those that
        do), or, for those that react, whose log from frame ``index`` on comes within their room (N, A) [m] of the
        robot's expected course over ``anticipation_s``. Only agents whose log is present then are looked at."""
        frames = len(self.present)
        ahead = np.arange(-1, self.reaction.anticipation_steps)  # frames from index on, from where it stands now
        seen = index[:, None] + ahead  # (N, H + 1)
        valid = (seen >= 0) & (seen < frames)
        clipped = np.clip(seen, 0, frames - 1)
        cols, real = leading(self.present[clipped].any(axis=1) & (index < frames)[:, None])  # (N, K) logs present
        rows = np.arange(len(index))[:, None]
        log = self.log_xy_m[clipped[:, :, None], cols[:, None, :]]  # (N, H + 1, K, 2)
        heading = robot.heading_rad[:, None]
        reacting = weight[rows, cols] > 0
        robot_to = np.where(reacting[..., None], robot.to_m[:, None], robot.from_m[:, None])
        gap = self.body.swept_gap_m(log[:, 0] - robot.from_m[:, None], log[:, 1] - robot_to, heading)
        hit = (index > 0)[:, None] & (np.nan_to_num(gap, nan=np.inf) < self.robot_reach_m)
        course = robot.to_m[:, None] + (ahead * STEP_S)[None, :, None] * robot.velocity_mps[:, None]  # (N, H + 1, 2)
        offset = log - course[:, :, None]  # (N, H + 1, K, 2)
        swept = self.body.swept_gap_m(offset[:, :-1], offset[:, 1:], heading[:, None])  # (N, H, K)
        swept = np.where((valid[:, :-1] & valid[:, 1:])[..., None], np.nan_to_num(swept, nan=np.inf), np.inf)
        alone = np.nan_to_num(self.body.gap_m(offset[:, 1], heading), nan=np.inf)  # the one frame of a 1-frame look
        least = np.where((valid.sum(axis=1) > 1)[:, None], swept.min(axis=1), alone)
        found = np.zeros(weight.shape, bool)
        found[rows, cols] = real & (hit | (reacting & (least < self.robot_reach_m + room_m[rows, cols])))
        return found

    def _others_in_the_way(self, index: np.ndarray, state: ReactiveState) -> np.ndarray:
        """(N, A) bool: agents whose log from frame ``index`` (N,) on comes within ``PAIR_CLEARANCE_M`` of a
        pedestrian of their crowd off its log (going on at its velocity) within ``PAIR_LOOK_AHEAD_STEPS``, where it
        comes closer than their own logs would. Only agents whose log is present then are looked at."""
        frames = len(self.present)
        found = np.zeros(state.present.shape, bool)
        who, real = leading(state.off_log & state.present)  # (N, O) the crowd's others, ascending
        if not who.shape[1] or (index >= frames).all():
            return found
        ahead = np.arange(PAIR_LOOK_AHEAD_STEPS)
        seen = index[:, None] + ahead  # (N, H)
        clipped = np.minimum(seen, frames - 1)
        cols, logged = leading(self.present[clipped].any(axis=1))  # (N, K) logs present then
        log = self.log_xy_m[clipped[:, :, None], cols[:, None, :]]  # (N, H, K, 2), NaN where absent
        rows = np.arange(len(index))[:, None]
        where = (state.xy_m[rows, who][:, None]
                 + (ahead * STEP_S)[None, :, None, None] * state.velocity_mps[rows, who][:, None])  # (N, H, O, 2)
        gap = length_m(log[:, :, :, None] - where[:, :, None])  # (N, H, K, O)
        their_log = self.log_xy_m[clipped[:, :, None], who[:, None, :]]  # (N, H, O, 2)
        logged_gap = length_m(log[:, :, :, None] - their_log[:, :, None])
        bound = np.minimum(2 * BODY_RADIUS_M + PAIR_CLEARANCE_M, np.nan_to_num(logged_gap, nan=np.inf) - PAIR_GIVE_M)
        apart = (real[:, None, None, :] & (seen < frames)[:, :, None, None]
                 & (who[:, None, None, :] != cols[:, None, :, None]))  # nobody is in their own way
        found[rows, cols] = logged & (apart & (np.nan_to_num(gap, nan=np.inf) < bound)).any(axis=(1, 3))
        return found

    # ------------------------------------------------------------------------------------------------ choosing
    def _place_newcomers(self, step: Step, appearing: np.ndarray, clear: np.ndarray, offset: np.ndarray) -> None:
        """Start each pedestrian appearing (N, A) where its robot (not ``clear``) or one off its log stands beside its
        log instead, just clear of them (``_clear_offset``): ``step`` and ``offset`` (N, A) are updated in place."""
        body_m = 2 * BODY_RADIUS_M - PAIR_GIVE_M
        for row in np.flatnonzero(appearing.any(axis=1)):
            for agent in np.flatnonzero(appearing[row]):  # in order: each sees those placed before it
                taken = step.start[row][step.off_log[row] & step.present[row]]
                log_now = self.log_xy_m[step.index[row], agent]
                if clear[row, agent] and not (np.linalg.norm(taken - log_now, axis=1) < body_m).any():
                    continue
                offset[row, agent] = self._clear_offset(agent, int(step.index[row]), step.robot, row, taken)
                step.xy[row, agent] = step.start[row, agent] = self.place(
                    np.array([agent]), np.array([float(step.index[row])]), offset[row, [agent]], step.index[row])[0]
                step.off_log[row, agent] = step.chosen[row, agent] = True

    def _clear_offset(self, agent: int, index: int, robot: Robot, row: int, others_m: np.ndarray) -> float:
        """The smallest side offset [m] at frame ``index`` that clears robot ``row`` (where it stands and where it is
        expected) and the pedestrians at ``others_m`` (K, 2), and stays as walkable as the log (0 if none does)."""
        offsets = OFFSETS_M[np.argsort(np.abs(OFFSETS_M), kind="stable")]
        places = self.place(np.full(len(offsets), agent), np.full(len(offsets), float(index)), offsets, index)
        apart = np.linalg.norm(places[:, None] - others_m[None], axis=-1).min(axis=1, initial=np.inf)
        fine = (self.clear_of_robot(places, robot.from_m[row], robot.to_m[row], robot.heading_rad[row])
                & (apart >= 2 * BODY_RADIUS_M - PAIR_GIVE_M) & (self.too_deep_m(agent, index, places, index) == 0))
        return float(offsets[np.argmax(fine)]) if fine.any() else 0.0

    def _choose_all(self, step: Step, tau: np.ndarray, offset: np.ndarray) -> None:
        """Every pedestrian off its log and not placed yet takes the cheapest of its candidates that keeps every
        bound (see the module docstring), or the one that breaks them the least; ``step.xy``, ``tau`` and ``offset``
        (N, A) are updated in place.

        In each crowd they choose one after another, the nearest to the robot first, each seeing the choices made
        before it. Here every candidate is scored in one pass, then the terms between pedestrians in rounds: the
        first round scores every chooser against the others where they stand, and each further round only those
        that see a pedestrian of their crowd before them whose choice changed in the last round. When no choice
        changes, each is the one it makes seeing the choices before it: the walks are those of one after another.
        """
        rows, agents = np.nonzero(step.off_log & ~step.chosen)
        if not len(agents):
            return
        gap = self.body.gap_m(step.start[rows, agents] - step.robot.from_m[rows], step.robot.heading_rad[rows])
        order = np.lexsort((gap, rows))  # by crowd, then the nearest to the robot first (stable: by agent on ties)
        rows, agents = rows[order], agents[order]
        c = self._candidates(step, rows, agents, tau[rows, agents], offset[rows, agents])
        turn = np.full(step.present.shape, len(agents))  # (N, A) each chooser's turn; the others' come last
        turn[rows, agents] = np.arange(len(agents))
        near = self._near_pairs(step, rows, agents, c)
        seen = step.xy.copy()  # (N, A, 2) the choices as they stand, for those whose turn comes later
        best = np.full(len(agents), -1)
        pending = np.arange(len(agents))
        while pending.size:
            choice = self._best(step, rows, agents, c, pending, near, seen, turn)
            moved = pending[(best[pending] < 0) | (c.xy_m[choice] != c.xy_m[best[pending]]).any(axis=-1)]
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

    def _near_pairs(self, step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates
                    ) -> tuple[np.ndarray, np.ndarray]:
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

    def _best(self, step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates, pending: np.ndarray,
              near: tuple[np.ndarray, np.ndarray], seen: np.ndarray, turn: np.ndarray) -> np.ndarray:
        """(T,) the candidate each of the choosers ``pending`` (T,) takes, seeing the choices ``seen`` (N, A, 2) of
        those whose ``turn`` (N, A) comes before theirs, the others where they stand (``step.xy``).

        A candidate's cost is at least its ``least_cost``, and one that breaks ``too_fast`` or ``into_robot`` breaks
        a bound: each chooser scores its candidates in full in the order of ``Candidates.order``, first
        ``FIRST_LOOK`` of them, until every hopeful one it has not scored costs at least more than the cheapest
        within every bound it has (all of them if none is). What it leaves unscored could not have been chosen."""
        count, hopeful = c.first[pending + 1] - c.first[pending], c.hopeful[pending]
        take = np.where(hopeful > 0, np.minimum(hopeful, FIRST_LOOK), count)
        while True:
            local = np.repeat(np.arange(len(pending)), take)
            scored = c.order[spans(c.first[pending], take)]  # (R,) rows of c, each chooser's in a run
            violation, cost = self._score(step, rows, agents, c, pending, scored, local, near, seen, turn)
            starts = np.r_[0, np.cumsum(take)[:-1]]
            fine = np.logical_or.reduceat(violation == 0, starts)
            cheapest = np.minimum.reduceat(np.where(violation > 0, np.inf, cost), starts)  # (T,)
            runs = spans(c.first[pending], hopeful)  # every hopeful row of the pending choosers
            owner = np.repeat(np.arange(len(pending)), hopeful)
            needed = np.bincount(owner, c.least_cost[c.order[runs]] <= cheapest[owner], minlength=len(pending))
            wider = np.where(fine, np.maximum(take, needed.astype(int)),
                             np.where(take < hopeful, np.minimum(2 * take, hopeful), count))
            if (wider == take).all():
                break
            take = wider
        key = np.where(fine[local], np.where(violation > 0, np.inf, cost), violation)  # as np.argmin over all rows
        key = np.where(np.isnan(key), -np.inf, key)  # (np.argmin takes the first NaN)
        least = np.minimum.reduceat(key, starts)
        return np.minimum.reduceat(np.where(key == least[local], scored, len(c.owner)), starts)

    def _score(self, step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates, pending: np.ndarray,
               scored: np.ndarray, local: np.ndarray, near: tuple[np.ndarray, np.ndarray], seen: np.ndarray,
               turn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(violation, cost), (R,) each, of the candidate rows ``scored`` (R,) of the choosers ``pending`` (T,)
        (``local`` (R,): which of them a row is of), seeing the choices ``seen`` of those before them: ``violation``
        0 where it keeps every bound (a metre into a wall weighs ``WALL_WEIGHT``, into the robot's margin
        ``ROBOT_WEIGHT``), ``cost`` [-]."""
        self._settle(step, rows, agents, c, scored)
        mine = np.full(len(agents), -1)
        mine[pending] = np.arange(len(pending))
        chooser, other = near
        pair = np.flatnonzero(mine[chooser] >= 0)
        too_close, pair_risk = self._pair_terms(step, rows[pending], agents[pending], c, scored, local,
                                                mine[chooser[pair]], other[pair],
                                                turn[rows[chooser[pair]], other[pair]] < chooser[pair], seen)
        violation = (c.too_fast[scored] + too_close + WALL_WEIGHT * c.too_deep[scored]
                     + ROBOT_WEIGHT * c.into_robot[scored])
        cost = (c.fixed_cost[scored] + RISK_COST * (c.risk[scored] + pair_risk) + c.stuck_cost[scored]
                + c.way_cost[scored])
        return violation, cost

    def _settle(self, step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates, scored: np.ndarray) -> None:
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
        c.too_deep[new] = self.too_deep_m(agent[:, None], tau[:, None], path, run_frame[:, None]).max(axis=1)
        c.later_m[new] = self.place(agent[:, None], c.tau[new][:, None] + np.arange(1, c.later_m.shape[1] + 1),
                                    c.offset_m[new][:, None], run_frame[:, None])  # along its route at its log's pace
        c.risk[new] = self._robot_risk(step, crowd, agent, np.concatenate([c.xy_m[new][:, None], c.later_m[new]],
                                                                          axis=1))

    def _pair_terms(self, step: Step, rows: np.ndarray, agents: np.ndarray, c: Candidates, scored: np.ndarray,
                    local: np.ndarray, chooser: np.ndarray, other: np.ndarray, earlier: np.ndarray,
                    seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(too_close, pair_risk), (R,) each, of the candidate rows ``scored`` (R,) of the choosers ``rows``,
        ``agents`` (T,) (``local`` (R,): whose row, each chooser's rows in a run), scored against the pedestrians
        ``other`` (P,) of the pairs near enough to count (``chooser`` (P,) in 0..T-1; ``earlier`` (P,) bool: the
        other chose before, and ``seen`` (N, A, 2) has its choice):

        - too_close [m]: along the whole step it keeps ``2 BODY_RADIUS_M - PAIR_GIVE_M`` from everybody else (or at
          least the gap it already had, and that much again by the end of the step where their logs are that far
          apart);
        - pair_risk [m^2]: the squared intrusions into the comfort gap round the others off their logs going on at
          their velocities over ``ANTICIPATION_STEPS``.

        The sums over the others come out as over all of them, those out of reach adding 0 (``exact_row_sums``)."""
        body_m = 2 * BODY_RADIUS_M - PAIR_GIVE_M
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
        place, starts = c.xy_m[scored], np.r_[0, np.cumsum(np.bincount(local, minlength=len(rows)))[:-1]]
        low = np.minimum(place, np.minimum.reduce([later[:, k] for k in range(ANTICIPATION_STEPS)]))
        high = np.maximum(place, np.maximum.reduce([later[:, k] for k in range(ANTICIPATION_STEPS)]))
        start = step.start[rows, agents]  # (T, 2)
        box = np.c_[np.minimum(np.minimum.reduceat(low, starts), start), np.maximum(np.maximum.reduceat(high, starts),
                                                                                    start)]
        their = np.c_[np.minimum(np.minimum(their_from, their_to), future.min(axis=1)),
                      np.maximum(np.maximum(their_from, their_to), future.max(axis=1))]  # walking on or not
        counted = within(box[chooser], their, PAIR_REACH_M)
        # every scored row of the pair's chooser
        per_chooser = np.bincount(local, minlength=len(rows))
        sizes = np.where(counted, per_chooser[chooser], 0)
        pair = np.repeat(np.arange(len(chooser)), sizes)
        row = spans(starts[chooser], sizes)  # (E,) rows of ``scored``
        here = start[chooser]  # (P, 2)
        n_rows = len(scored)
        # along the step
        allowed = np.minimum(body_m, length_m(their_from - here) - 1e-6)[pair]
        index = step.index[their_row]
        logged = length_m(self.log_xy_m[index, agents[chooser]] - self.log_xy_m[index, other])
        together = np.minimum(body_m, np.nan_to_num(logged, nan=np.inf))[pair]  # closer now: part as the logs do
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

    def _candidates(self, step: Step, rows: np.ndarray, agents: np.ndarray, tau: np.ndarray,
                    offset: np.ndarray) -> Candidates:
        """Every place the choosers ``rows``, ``agents`` (J,), now at route points ``tau`` and sides ``offset`` (J,),
        may choose, with the bounds and costs that do not need its depth, its risk or the others, in one pass."""
        index, run_frame = step.index[rows], tau.astype(int)
        here = step.start[rows, agents]  # (J, 2)
        first, last = self.run_first[run_frame, agents], self.run_last[run_frame, agents]
        cap = np.maximum(tau, np.minimum(index, last).astype(np.float64))  # never ahead of the log
        reach_m = np.maximum(CATCH_UP_MPS, CATCH_UP_FACTOR * self.log_speed_mps[run_frame, agents]) * STEP_S
        taus = self.tau_ahead(agents, tau, reach_m[:, None] * PROGRESS_SHARES, run_frame)
        taus = np.sort(np.clip(np.c_[taus, cap], first[:, None], cap[:, None]), axis=1)
        sides = np.sort(np.c_[np.broadcast_to(OFFSETS_M, (len(agents), len(OFFSETS_M))), offset], axis=1)
        grid = distinct(taus)[:, :, None] & distinct(sides)[:, None, :]  # (J, T, O): the tau-major grid of each
        owner, t_col, o_col = np.nonzero(grid)
        c_tau, c_off = taus[owner, t_col], sides[owner, o_col]
        a, rf, start = agents[owner], run_frame[owner], here[owner]
        places = self.place(a, c_tau, c_off, rf)  # (M, 2)
        too_fast = np.maximum(length_m(places - start) - reach_m[owner], 0.0)
        robot, heading = step.robot, step.robot.heading_rad[rows][owner]
        reacts = step.weight[rows, agents] > 0
        robot_to = np.where(reacts[:, None], robot.to_m[rows], robot.from_m[rows])[owner]  # noticed, or its body
        robot_gap = self.body.swept_gap_m(start - robot.from_m[rows][owner], places - robot_to, heading)
        into_robot = np.maximum(self.robot_reach_m - robot_gap, 0.0)
        gain, away = self.headway(a, c_tau, c_off, step.farthest[rows, agents][owner], index[owner])
        recent = step.recent_m[rows, agents].min(axis=1)[owner]
        staying = (gain < HEADWAY_M) & (away > recent - HEADWAY_M)  # stuck: try another way
        delay = np.minimum(index[owner] - c_tau, (away - np.abs(c_off)) / (STEP_S * LAG_PACE_MPS))  # [frame]
        fixed_cost = LAG_COST * delay + OFFSET_COST * np.abs(c_off) + SWAY_COST * np.abs(c_off - offset[owner])
        stuck_cost = STUCK_COST * step.stuck[rows, agents][owner] * staying
        firsts = np.r_[0, np.cumsum(grid.sum(axis=(1, 2)))]
        way_cost = np.zeros(len(owner))
        detour = np.flatnonzero(step.detour[rows, agents])
        if detour.size:
            way = self._way_round_m(step, rows[detour], agents[detour], tau[detour], run_frame[detour],
                                    [places[firsts[j]:firsts[j + 1]] for j in detour])
            for j, way_m in zip(detour, way, strict=True):
                way_cost[firsts[j]:firsts[j + 1]] = DETOUR_COST * way_m
        horizon = max(self.reaction.anticipation_steps, ANTICIPATION_STEPS)
        # where each may walk on to: its route's points over those frames (the log between them), moved aside
        ahead = np.clip(np.c_[np.minimum.reduceat(c_tau, firsts[:-1]) + 1, np.maximum.reduceat(c_tau, firsts[:-1])
                              + horizon], first[:, None], last[:, None])
        window, inside = self._frames_of(agents, np.floor(ahead[:, 0]).astype(int),
                                         np.minimum(np.floor(ahead[:, 1]).astype(int) + 1, last))
        route = self.log_xy_m[window]  # (J, W, 2)
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

    def _robot_risk(self, step: Step, rows: np.ndarray, agents: np.ndarray, walk: np.ndarray) -> np.ndarray:
        """(K,) squared intrusions [m^2], if ``agents`` in crowds ``rows`` (K,) walk on along their routes at their
        logs' pace through ``walk`` (K, H + 1, 2) [m] (from the candidate on, ``Candidates.later_m``): into their
        room round the robot going on at its velocity over ``anticipation_s`` (as far as they react), or into
        ``COMFORT_M`` round the robot's body standing where it is over ``ANTICIPATION_STEPS`` (as far as they do not:
        a body in the way)."""
        weight, robot, heading = step.weight[rows, agents], step.robot, step.robot.heading_rad[rows]
        robot_steps = self.reaction.anticipation_steps
        risk = np.zeros(len(rows))  # as far as it does not react (0 for those that react fully: 0 times a finite sum)
        body = np.flatnonzero(weight < 1.0)
        standing = walk[body, :ANTICIPATION_STEPS + 1] - robot.from_m[rows[body]][:, None]  # from the body standing
        gap = self.body.swept_gap_m(standing[:, :-1], standing[:, 1:], heading[body][:, None])  # (B, H_s)
        risk[body] = (1.0 - weight[body]) * (np.maximum(self.robot_reach_m + COMFORT_M - gap, 0.0) ** 2).sum(axis=1)
        react = np.flatnonzero(weight > 0)
        if react.size:
            ahead = np.arange(robot_steps + 1, dtype=np.float64)
            course = robot.to_m[rows[react]][:, None] + (ahead[:, None] * STEP_S)[None] \
                * robot.velocity_mps[rows[react]][:, None]  # (R, H_r + 1, 2)
            moving = walk[react, :robot_steps + 1] - course  # from the body on its course
            gap = self.body.swept_gap_m(moving[:, :-1], moving[:, 1:], heading[react][:, None])  # (R, H_r)
            room = self.robot_reach_m + step.room_m[rows[react], agents[react]]
            risk[react] = risk[react] + weight[react] * (np.maximum(room[:, None] - gap, 0.0) ** 2).sum(axis=1)
        return risk

    def _way_round_m(self, step: Step, rows: np.ndarray, agents: np.ndarray, tau: np.ndarray, run_frame: np.ndarray,
                     places: list[np.ndarray]) -> list[np.ndarray]:
        """For each of the choosers ``rows``, ``agents`` (D,) at route points ``tau`` (D,): (C,) how far [m] it would
        have to walk from each of its ``places`` (C, 2) to a point of its route ahead (``DETOUR_AHEAD_M``) round the
        robot's body (where it stands and where it is expected), over ground no deeper in the non-walkable area than
        its log there (its route from ``DETOUR_BACK_FRAMES`` behind route point ``tau`` to that point); counted from
        the nearest, and those cut off from that point 1 m beyond the farthest (0 for all when no such point is
        known). The shortest walks of all of them are found in one search."""
        robot = step.robot
        ends = (robot.from_m[rows], robot.to_m[rows], robot.heading_rad[rows])  # (D, 2), (D, 2), (D,)
        ahead = self.tau_ahead(agents, step.farthest[rows, agents], np.broadcast_to(DETOUR_AHEAD_M, (len(rows), 5)),
                               run_frame)  # (D, 5) to its run's end
        goals = self.place(agents[:, None], ahead, np.zeros(ahead.shape), run_frame[:, None])  # (D, 5, 2)
        clear = self.clear_of_robot(goals, *(end[:, None] for end in ends))
        pick = np.argmax(clear, axis=1)
        goal_tau, goal = ahead[np.arange(len(rows)), pick], goals[np.arange(len(rows)), pick]
        back = np.maximum(self.run_first[run_frame, agents].astype(np.float64), tau - DETOUR_BACK_FRAMES)
        planned = np.flatnonzero(clear.any(axis=1))
        way = [np.zeros(len(p)) for p in places]
        if not planned.size:
            return way
        grids, clear_cells = [], []
        for j in planned:
            route = self.log_xy_m[int(back[j]):int(np.ceil(goal_tau[j])) + 1, agents[j]]
            around = np.vstack([places[j], route, goal[j][None], step.start[rows[j], agents[j]][None]])
            grids.append(grid_cells(around.min(axis=0) - DETOUR_MARGIN_M, around.max(axis=0) + DETOUR_MARGIN_M))
            clear_cells.append(self.clear_of_robot(grids[-1].reshape(-1, 2), *(end[j] for end in ends)))
        cells = np.concatenate([grid.reshape(-1, 2) for grid in grids])
        whose = planned[np.repeat(np.arange(len(grids)), [grid.shape[0] * grid.shape[1] for grid in grids])]
        free = np.concatenate(clear_cells)
        free[free] = self.too_deep_m(agents[whose][free], back[whose][free], cells[free], run_frame[whose][free],
                                     through=goal_tau[whose][free]) == 0
        cuts = np.cumsum([grid.shape[0] * grid.shape[1] for grid in grids])[:-1]
        walks = walking_distances_m(grids, [f.reshape(g.shape[:2]) for f, g in zip(np.split(free, cuts), grids,
                                                                                      strict=True)],
                                    goal[planned], [places[j] for j in planned])
        for j, walk_m in zip(planned, walks, strict=True):
            known = np.isfinite(walk_m)
            if known.any():
                nearest, farthest = walk_m[known].min(), walk_m[known].max()
                way[j] = np.where(known, walk_m - nearest, farthest - nearest + 1.0)
        return way

    # ------------------------------------------------------------------------------------------------ the routes
    def route(self, agents: np.ndarray, tau: np.ndarray, run_frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Point of each agent's logged route at fractional frame ``tau`` and the left normal there; (..., 2) each
        for ``agents``/``tau``/``run_frame`` broadcast to one shape (...). ``tau`` is held within the run of the log
        that holds frame ``run_frame`` (where the agents are on their routes now)."""
        first, last = self.run_first[run_frame, agents], self.run_last[run_frame, agents]
        tau = np.clip(tau, first, last)
        frame = np.floor(tau).astype(int)
        after = np.minimum(frame + 1, last)
        share = (tau - frame)[..., None]
        point = (1 - share) * self.log_xy_m[frame, agents] + share * self.log_xy_m[after, agents]
        tangent = (1 - share) * self.tangent[frame, agents] + share * self.tangent[after, agents]
        tangent /= np.maximum(length_m(tangent)[..., None], 1e-9)
        return point, np.stack([-tangent[..., 1], tangent[..., 0]], axis=-1)

    def place(self, agents: np.ndarray, tau: np.ndarray, offset_m: np.ndarray, run_frame: np.ndarray) -> np.ndarray:
        """(..., 2) positions at route points ``tau`` (within the run holding ``run_frame``) moved ``offset_m`` to the
        side, all broadcast to one shape (...)."""
        point, normal = self.route(agents, tau, run_frame)
        return point + offset_m[..., None] * normal

    def arc(self, agents: np.ndarray, tau: np.ndarray, run_frame: np.ndarray) -> np.ndarray:
        """(...) metres along the agents' logged routes at fractional frames ``tau``, within the run of ``run_frame``,
        all broadcast to one shape (...)."""
        first, last = self.run_first[run_frame, agents], self.run_last[run_frame, agents]
        tau = np.clip(tau, first, last)
        frame = np.floor(tau).astype(int)
        return self.arc_m[frame, agents] + (tau - frame) * (self.arc_m[np.minimum(frame + 1, last), agents]
                                                            - self.arc_m[frame, agents])

    def tau_ahead(self, agents: np.ndarray, tau: np.ndarray, ahead_m: np.ndarray, run_frame: np.ndarray) -> np.ndarray:
        """(J, K) the latest fractional frames whose route points lie ``ahead_m`` (J, K) metres further along the
        logged routes of ``agents`` (J,) than ``tau`` (J,) (through any stretch where the log stood still), within the
        run of ``run_frame`` (J,)."""
        first, last = self.run_first[run_frame, agents][:, None], self.run_last[run_frame, agents][:, None]
        target = self.arc(agents, tau, run_frame)[:, None] + ahead_m
        who = agents[:, None]
        low, high = np.broadcast_to(first - 1, target.shape), np.broadcast_to(last, target.shape)
        while (low < high).any():  # the last frame of the run at most ``target`` along (``first - 1``: none)
            middle = (low + high + 1) // 2
            below = (low < high) & (self.arc_m[np.maximum(middle, first), who] <= target)
            low, high = np.where(below, middle, low), np.where(below | (low >= high), high, middle - 1)
        k = np.maximum(low, first)
        step = self.arc_m[np.minimum(k + 1, last), who] - self.arc_m[k, who]
        share = np.where(step > 0, np.clip((target - self.arc_m[k, who]) / np.where(step > 0, step, 1.0), 0.0, 1.0),
                         0.0)
        return k + share

    def headway(self, agents: np.ndarray, tau: np.ndarray, offset_m: np.ndarray, farthest: np.ndarray,
                index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For places at route points ``tau`` moved ``offset_m`` aside (all arguments (K,)): how much farther along the
        route than ``farthest`` they are [m], and how far from the log at frame ``index`` (metres behind it along the
        route plus metres aside) [m]."""
        run_frame = farthest.astype(int)
        now = np.minimum(index, self.run_last[run_frame, agents]).astype(np.float64)  # where its log is, or ended
        arc = self.arc(agents, tau, run_frame)
        return arc - self.arc(agents, farthest, run_frame), \
            np.maximum(self.arc(agents, now, run_frame) - arc, 0.0) + np.abs(offset_m)

    def too_deep_m(self, agents: np.ndarray | int, tau: np.ndarray | float, places: np.ndarray,
                   run_frame: np.ndarray | int, through: np.ndarray | None = None) -> np.ndarray:
        """(...) how much deeper in the non-walkable area each place (..., 2) is than its agent's log: than the point
        of its log nearest to it within ``DEPTH_WINDOW`` frames of route point ``tau``, or the log's deepest point
        within ``CROSSING_WINDOW`` frames of it (a crossing of a thin wall, beside it) [m]; with ``through``, than the
        point of its log nearest to it on the route from ``tau`` through ``through`` (and ``DEPTH_WINDOW`` frames
        beyond) alone, and only whether it is (inf) or not (0); 0 where that point is off the image, 1000 for a place
        off the image beside a log on it. ``agents``, ``tau``, ``run_frame`` (and ``through``) broadcast to the
        places' shape (...)."""
        depth = self.depth.at(places)
        excess = np.zeros(depth.shape)
        deep = depth > 0  # a place on walkable ground is never deeper than the log: compare only the others
        if not deep.any():
            return excess
        agents, tau, run_frame = (np.broadcast_to(value, depth.shape)[deep] for value in (agents, tau, run_frame))
        first, last = self.run_first[run_frame, agents], self.run_last[run_frame, agents]
        frame = np.floor(tau).astype(int)
        if through is None:
            low, high = np.maximum(first, frame - DEPTH_WINDOW), np.minimum(last, frame + DEPTH_WINDOW)
            crossing = self._window_depths(agents, np.maximum(first, frame - CROSSING_WINDOW),
                                           np.minimum(last, frame + CROSSING_WINDOW))[1]
        else:
            end = np.maximum(frame, np.floor(np.broadcast_to(through, depth.shape)[deep]).astype(int))
            low, high = np.maximum(first, frame), np.minimum(last, end + DEPTH_WINDOW)
            crossing = np.full(len(agents), -np.inf)
        # the nearest point of the window is looked for only where its depth matters: not where the place lies no
        # deeper than the window's shallowest point, nor where every point of the window lies as deep
        least, most = self._window_depths(agents, low, high)
        here = depth[deep]
        log_depth = np.maximum(least, crossing)  # exact where the window's points all lie equally deep
        search = (here > log_depth) & (least < most)
        if through is not None:  # whether, not how much: deeper than the window's deepest point is deeper
            search &= here <= np.maximum(most, crossing)
            log_depth = np.where((here > np.maximum(most, crossing)) & (least < most), most, log_depth)
        log_depth[search] = np.maximum(self._nearest_trace_depth(agents[search], low[search], high[search],
                                                                 places[deep][search]), crossing[search])
        over = np.minimum(np.maximum(here - log_depth - DEPTH_TOLERANCE_M, 0.0), 1e3)
        excess[deep] = np.where(np.isinf(log_depth), 0.0, over if through is None else np.where(over > 0, np.inf, 0.0))
        return excess

    def _window_depths(self, agents: np.ndarray, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(least, most) (P,) each: the depths [m] of the shallowest and the deepest point of each agent's log trace
        (``trace_depth_m``) between frames ``low`` and ``high`` (P,), found once per distinct window."""
        frames = len(self.present)
        windows, which = np.unique((agents.astype(np.int64) * frames + low) * frames + high, return_inverse=True)
        index, inside = self._frames_of(windows // (frames * frames), windows // frames % frames,
                                           windows % frames)
        depths = self.trace_depth_m[index]  # (U, W, K)
        least = np.where(inside[..., None], depths, np.inf).min(axis=(1, 2))
        most = np.where(inside[..., None], depths, -np.inf).max(axis=(1, 2))
        return least[which], most[which]

    def _frames_of(self, agents: np.ndarray, low: np.ndarray, high: np.ndarray
                  ) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
        """The (frame, agent) index (P, W) of frames ``low`` through ``high`` (P,) of each agent's log, padded to the
        longest window W with its last frame, and (P, W) bool, the frame is within the window."""
        span = np.arange(int((high - low).max(initial=0)) + 1)
        frames = low[:, None] + span
        return (np.minimum(frames, high[:, None]), agents[:, None]), frames <= high[:, None]

    def _nearest_trace_depth(self, agents: np.ndarray, low: np.ndarray, high: np.ndarray,
                             places: np.ndarray) -> np.ndarray:
        """(P,) depth [m] of the point of each agent's log trace (``trace_m``) between frames ``low`` and ``high``
        (P,) that is nearest to its place (P, 2) (the first of equals), in chunks of ``CHUNK_VALUES`` distances."""
        found = np.empty(len(places))
        width = (int((high - low).max(initial=0)) + 1) * len(TRACE_SHARES)
        size = max(1, CHUNK_VALUES // width)
        for at in range(0, len(places), size):
            part = slice(at, at + size)
            index, inside = self._frames_of(agents[part], low[part], high[part])
            trace = self.trace_m[index].reshape(len(inside), -1, 2)  # (P, W K, 2), frame by frame
            distance = length_m(places[part][:, None, :] - trace)
            distance[~np.repeat(inside, len(TRACE_SHARES), axis=1)] = np.inf
            nearest = np.argmin(distance, axis=-1)
            found[part] = self.trace_depth_m[index].reshape(len(inside), -1)[np.arange(len(inside)), nearest]
        return found


def leading(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(columns (N, K), real (N, K) bool): each row's True columns of ``mask`` (N, A) first, ascending, the rows cut
    to the most True columns of any, K (padded with False columns, ``real`` False)."""
    width = int(mask.sum(axis=1).max(initial=0))
    columns = np.argsort(~mask, axis=1, kind="stable")[:, :width]
    return columns, np.take_along_axis(mask, columns, axis=1)


def distinct(values: np.ndarray) -> np.ndarray:
    """(J, K) bool: the first of each run of equal values in the sorted rows ``values`` (J, K) (``np.unique``'s)."""
    return np.c_[np.ones(len(values), bool), values[:, 1:] != values[:, :-1]]


def within(box_m: np.ndarray, other_m: np.ndarray, reach_m: float) -> np.ndarray:
    """(K,) bool: the boxes ``box_m`` (K, 4) (x low, y low, x high, y high) [m] come within ``reach_m`` [m] (plus
    ``NEAR_SLACK_M``) of the boxes ``other_m`` (K, 4)."""
    apart = np.maximum(np.maximum(other_m[:, :2] - box_m[:, 2:], box_m[:, :2] - other_m[:, 2:]), 0.0)
    return length_m(apart) < reach_m + NEAR_SLACK_M


def spans(starts: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """(sum of counts,) the runs ``starts[i], ..., starts[i] + counts[i] - 1`` (K,) each, one after another."""
    return np.repeat(starts - np.r_[0, np.cumsum(counts)[:-1]], counts) + np.arange(counts.sum())


def exact_row_sums(row: np.ndarray, column: np.ndarray, value: np.ndarray, width: np.ndarray,
                   n_rows: int) -> np.ndarray:
    """(n_rows,) the row sums of a sparse matrix, each row as numpy sums it dense (zeros and the values at
    ``column`` of row ``row``, (E,) each, a row ``width[row]`` (n_rows,) long): a row with at most two non-zero
    values is their sum in any order; one with more is summed dense, so that the rounding is numpy's."""
    keep = value != 0
    row, column, value = row[keep], column[keep], value[keep]
    total = np.bincount(row, value, minlength=n_rows)
    many = np.flatnonzero(np.bincount(row, minlength=n_rows) > 2)
    for size in np.unique(width[many]):
        which = many[width[many] == size]
        mine = np.isin(row, which)
        dense = np.zeros((len(which), size))
        dense[np.searchsorted(which, row[mine]), column[mine]] = value[mine]
        total[which] = dense.sum(axis=1)
    return total


def length_m(vector_m: np.ndarray) -> np.ndarray:
    """(...) lengths [m] of vectors (..., 2) [m], rounded as ``np.linalg.norm(vector_m, axis=-1)`` rounds them."""
    return np.sqrt(vector_m[..., 0] * vector_m[..., 0] + vector_m[..., 1] * vector_m[..., 1])


def heading_of(from_m: np.ndarray, to_m: np.ndarray, heading_rad: float | None = None) -> float:
    """``heading_rad`` if given, else the direction of the move ``from_m`` -> ``to_m`` (2,) [rad] (0 for no move)."""
    if heading_rad is not None:
        return float(heading_rad)
    move = np.asarray(to_m, np.float64) - np.asarray(from_m, np.float64)
    return float(np.arctan2(move[1], move[0])) if np.hypot(*move) > 1e-9 else 0.0


def velocity(xy: np.ndarray, old_xy: np.ndarray, stays: np.ndarray) -> np.ndarray:
    """(..., 2) velocity over the step [m/s] of the agents present before and after it (0 for the others)."""
    return np.where(stays[..., None], np.nan_to_num(xy - old_xy) / STEP_S, 0.0)


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
