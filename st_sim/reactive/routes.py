"""The logged routes reactive pedestrians walk, as tables built once per replay (``Routes``), and where along them
and beside them a pedestrian may stand.

A pedestrian off its log stays on its logged *route*: its place is the log at a fractional frame ``tau`` (never
ahead of the log) moved ``offset_m`` to the left of the route's direction there (a Frenet frame along the log, its
direction averaged over ``TANGENT_WINDOW`` frames either side so that a side offset turns smoothly round corners).
``tau`` is held within the log's run of presence that holds the frame where the pedestrian is on its route now.

**The map bound.** A place must be no deeper in the scene's non-walkable area, nor farther off the image, than the
nearest point of its log near that point of the route (within ``DEPTH_WINDOW`` frames), or its log's deepest point
close to it (within ``CROSSING_WINDOW`` frames): a log that crosses a traced wall lets its pedestrian cross there too
and traps nobody, while nobody is pushed into a wall beside a log, nor jumps over a thin one (``Routes.too_deep_m``;
the log is traced at ``TRACE_SHARES`` of each step, as a fast log may cross a thin wall between two frames).
"""

from __future__ import annotations

import copy
from typing import Any, Final, Protocol

import numpy as np

from replays.constants import STEP_S
from st_sim.reactive.footprint import ROBOT_MARGIN_M, Body, length_m
from st_sim.reactive.reaction import Reaction, fitted_reaction

MIN_STEP_M: Final[float] = 0.01  # log steps shorter than this give no direction [m]
TANGENT_WINDOW: Final[int] = 2  # a route's direction is averaged over this many frames either side [-]
TRACE_SHARES: Final[tuple[float, ...]] = (0.0, 0.25, 0.5, 0.75)  # points of a log between two frames it is traced at
DEPTH_WINDOW: Final[int] = 8  # a place is no deeper than its log's nearest point within this many frames either side
"""of its route point [-] ..."""
CROSSING_WINDOW: Final[int] = 2  # ... or its log's deepest point within this many frames of its route point [-]
DEPTH_TOLERANCE_M: Final[float] = 0.0  # it may stand this much deeper in the non-walkable area than its log [m]
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


class Routes:
    """The logged routes of one replay as reactive pedestrians walk them round a robot: the tables built once, shared
    by every crowd of the replay (``ReactiveCrowd.on``), and the places along them.

    Args:
        log_xy_m: (F, A, 2) logged positions [m], NaN where absent.  present: (F, A) bool.
        depth: the scene's non-walkable depth (``MapDepth``; ``OpenGround`` where nothing is out of bounds).
        body: the robot's footprint.
        touch_m: gap to the robot's body [m] within which a pedestrian's centre touches it (the pedestrian radius of
            the env's contact rule).
        reaction: when the pedestrians notice the robot and react, and the room they keep (default: the fitted one).
        compiled: step the crowds with the compiled kernels (``st_sim.reactive.compiled``: the same walks, faster) where
            they read the depth (a ``MapDepth`` or ``OpenGround``); False: the plain numpy path, their reference.
    """

    def __init__(self, log_xy_m: np.ndarray, present: np.ndarray, depth: Depth, body: Body, touch_m: float,
                 reaction: Reaction | None = None, compiled: bool = True):
        self.log_xy_m, self.present, self.depth, self.body = log_xy_m, present, depth, body
        self.compiled = compiled
        self._tables: Any = None
        self.reaction = fitted_reaction() if reaction is None else reaction
        self.robot_reach_m = touch_m + ROBOT_MARGIN_M  # gap a pedestrian keeps from the robot's body
        agents = present.shape[1]
        step = np.diff(np.nan_to_num(log_xy_m), axis=0)  # (F - 1, A, 2)
        moving = present[:-1] & present[1:]
        length = np.where(moving, length_m(step), 0.0)
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

    def stepped(self, compiled: bool) -> Routes:
        """These routes (their tables shared, not copied) stepped by the compiled kernels or by the plain path."""
        routes = copy.copy(self)
        routes.compiled = compiled
        return routes

    def tables(self) -> Any:
        """The tables as the compiled kernels read them (``st_sim.reactive.compiled.tables.RouteTables``, built once),
        or None where they cannot read the depth."""
        if self._tables is None:
            from st_sim.reactive.compiled import announce_compiling
            from st_sim.reactive.compiled.tables import route_tables  # (the kernels import this module)

            announce_compiling()
            self._tables = route_tables(self) or False
        return self._tables or None

    def clear_of_robot(self, xy_m: np.ndarray, from_m: np.ndarray, to_m: np.ndarray,
                       heading_rad: np.ndarray) -> np.ndarray:
        """(...) bool: points (..., 2) at least ``robot_reach_m`` from the robot's body where it stands (``from_m``)
        and where it is expected at the end of the step (``to_m``), both (..., 2) and ``heading_rad`` (...)
        broadcast against the points (NaN points are clear)."""
        gaps = [self.body.gap_m(xy_m - where, heading_rad) for where in (from_m, to_m)]
        return np.nan_to_num(np.minimum(*gaps), nan=np.inf) >= self.robot_reach_m

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

    def nearest_on_route(self, agents: np.ndarray, xy_m: np.ndarray, low: np.ndarray, high: np.ndarray,
                         run_frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(tau (P,), offset_m (P,)): the point of each agent's log between frames ``low`` and ``high`` (P,) nearest to
        ``xy_m`` (P, 2) [m] (the first of equals), as a fractional frame, and how far left of the route's direction
        there ``xy_m`` lies [m] (within the run of ``run_frame`` (P,))."""
        (frame, who), inside = self.frames_of(agents, low, high)  # (P, W)
        point = self.log_xy_m[frame, who]
        step = self.log_xy_m[np.minimum(frame + 1, high[:, None]), who] - point
        length2 = (step * step).sum(axis=-1)
        share = np.clip(((xy_m[:, None] - point) * step).sum(axis=-1) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
        distance = length_m(xy_m[:, None] - point - share[..., None] * step)
        nearest = np.argmin(np.where(inside, distance, np.inf), axis=1)
        pick = np.arange(len(agents))
        tau = frame[pick, nearest] + share[pick, nearest]
        on_route, normal = self.route(agents, tau, run_frame)
        return tau, ((xy_m - on_route) * normal).sum(axis=-1)

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

    def progress(self, agents: np.ndarray, tau: np.ndarray, farthest: np.ndarray,
                 index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For route points ``tau`` (all arguments (K,)): how much farther along the route than ``farthest`` they are
        [m], and how far behind the log at frame ``index`` (or where it ended) along the route (0 for none) [m]."""
        run_frame = farthest.astype(int)
        now = np.minimum(index, self.run_last[run_frame, agents]).astype(np.float64)  # where its log is, or ended
        arc = self.arc(agents, tau, run_frame)
        return arc - self.arc(agents, farthest, run_frame), np.maximum(self.arc(agents, now, run_frame) - arc, 0.0)

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
        bounded = ~np.isinf(log_depth)  # an infinitely deep log bounds nothing (and inf - inf is no number)
        over = np.zeros(len(here))
        over[bounded] = np.minimum(np.maximum(here[bounded] - log_depth[bounded] - DEPTH_TOLERANCE_M, 0.0), 1e3)
        excess[deep] = over if through is None else np.where(over > 0, np.inf, 0.0)
        return excess

    def _window_depths(self, agents: np.ndarray, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(least, most) (P,) each: the depths [m] of the shallowest and the deepest point of each agent's log trace
        (``trace_depth_m``) between frames ``low`` and ``high`` (P,), found once per distinct window."""
        frames = len(self.present)
        windows, which = np.unique((agents.astype(np.int64) * frames + low) * frames + high, return_inverse=True)
        index, inside = self.frames_of(windows // (frames * frames), windows // frames % frames, windows % frames)
        depths = self.trace_depth_m[index]  # (U, W, K)
        least = np.where(inside[..., None], depths, np.inf).min(axis=(1, 2))
        most = np.where(inside[..., None], depths, -np.inf).max(axis=(1, 2))
        return least[which], most[which]

    def frames_of(self, agents: np.ndarray, low: np.ndarray, high: np.ndarray
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
            index, inside = self.frames_of(agents[part], low[part], high[part])
            trace = self.trace_m[index].reshape(len(inside), -1, 2)  # (P, W K, 2), frame by frame
            distance = length_m(places[part][:, None, :] - trace)
            distance[~np.repeat(inside, len(TRACE_SHARES), axis=1)] = np.inf
            nearest = np.argmin(distance, axis=-1)
            found[part] = self.trace_depth_m[index].reshape(len(inside), -1)[np.arange(len(inside)), nearest]
        return found


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
    norm = length_m(total)[..., None]
    return np.where(norm > 1e-6, total / np.maximum(norm, 1e-12), tangent)


def route_tangents(step: np.ndarray, usable: np.ndarray, present: np.ndarray) -> np.ndarray:
    """(F, A, 2) unit direction of each log at every frame: its step to the next frame where that is at least
    ``MIN_STEP_M`` long, else the nearest such step before it in its run, else after it, else +x (a log that never
    moves)."""
    frames, agents = present.shape
    unit = np.zeros((frames, agents, 2))
    known = np.zeros((frames, agents), bool)
    unit[:-1][usable] = step[usable] / length_m(step[usable])[..., None]
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
