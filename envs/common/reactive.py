"""Reactive replay: recorded pedestrians who walk their own logs and step round the robot when it is in their way.

Every pedestrian follows its recording exactly until its logged path over the next ``LOOK_AHEAD_STEPS`` frames
would bring it within ``CLEARANCE_M`` of the robot's body (the robot taken at its current velocity) or of a
pedestrian already off its log. From then on it is simulated: each 0.4 s step it heads for where its log is now,
at the speed that catches up (at most ``CATCH_UP_MPS``, or 1.25 times its log's speed), steered by the simulator's
calibrated speed model round the robot, the other pedestrians and the scene's walls, with the contact rules of
the simulator (``st_sim.sim.contacts.keep_apart``: the robot and everybody on their logs are obstacles that do not
give way). Once it is back within ``REJOIN_M`` of its log and nothing is in the way, it is on its log again. A
pedestrian whose log ends leaves, off its log or not; one who appears where the robot stands starts just clear of
it. With the robot out of everyone's way, the replay is the recording exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from replays.constants import STEP_S
from st_sim.sim import speed_model
from st_sim.sim.config import SpeedModelConfig
from st_sim.sim.contacts import keep_apart, pair_reach_m
from st_sim.sim.pairs import Neighbours, cap_speed
from st_sim.sim.walls import WallGrid

LOOK_AHEAD_STEPS: Final[int] = 3  # a pedestrian looks this many 0.4 s steps along its log for the robot [-]
CLEARANCE_M: Final[float] = 0.2  # ... and leaves its log if that path passes closer than this to a body [m]
REJOIN_M: Final[float] = 0.1  # back on its log when this close to it and nothing is in the way [m]
BODY_RADIUS_M: Final[float] = 0.2  # radius of a reactive pedestrian's body among pedestrians and walls [m]
ROBOT_MARGIN_M: Final[float] = 0.05  # reactive pedestrians keep this much beyond the env's contact distance [m]
CATCH_UP_MPS: Final[float] = 1.8  # fastest a pedestrian walks to catch up with its log [m/s] ...
CATCH_UP_FACTOR: Final[float] = 1.25  # ... or this multiple of its log's own speed, if that is faster [-]
SUBSTEPS: Final[int] = 2  # steering substeps per 0.4 s step [-]


@dataclass(frozen=True)
class ReactiveState:
    """Where the pedestrians of a replay are, one row per recorded agent (the replay's ``agents`` order).

    Attributes:
        xy_m: (A, 2) positions [m]; NaN for agents absent now.
        velocity_mps: (A, 2) velocities over the last step [m/s].
        off_log: (A,) bool, simulated (not at their logged position).
    """

    xy_m: np.ndarray
    velocity_mps: np.ndarray
    off_log: np.ndarray


class ReactiveCrowd:
    """The recorded pedestrians of one replay, reacting to a robot.

    Args:
        log_xy_m: (F, A, 2) logged positions [m], NaN where absent.  present: (F, A) bool.
        walls: the scene's walls (``WallGrid`` with a reach of at least ``wall_reach_m()``).
        contact_m: centre distance at which the env counts a robot-pedestrian contact [m].
    """

    def __init__(self, log_xy_m: np.ndarray, present: np.ndarray, walls: WallGrid, contact_m: float):
        self.log_xy_m, self.present, self.walls = log_xy_m, present, walls
        self.robot_radius_m = contact_m + ROBOT_MARGIN_M - BODY_RADIUS_M  # as seen by the pedestrians
        self.steering = SpeedModelConfig()
        self.state = self._on_log(0)

    @staticmethod
    def wall_reach_m() -> float:
        """Least reach [m] of the wall grid: the steering's wall cutoff, or what a catching-up body can close."""
        return max(SpeedModelConfig().wall_cutoff_m, 2 * BODY_RADIUS_M + 4 * STEP_S * CATCH_UP_MPS)

    def _on_log(self, index: int) -> ReactiveState:
        xy = np.where(self.present[index][:, None], self.log_xy_m[index], np.nan)
        return ReactiveState(xy, np.zeros_like(xy), np.zeros(len(xy), bool))

    def reset(self, index: int) -> np.ndarray:
        """Everybody on their log at frame ``index``; returns the (A, 2) positions."""
        self.state = self._on_log(index)
        return self.state.xy_m

    def deviation_m(self, index: int) -> np.ndarray:
        """(present agents,) distance of each pedestrian present at frame ``index`` from its log [m]."""
        now = self.present[index]
        return np.linalg.norm(self.state.xy_m[now] - self.log_xy_m[index, now], axis=1)

    def step(self, index: int, robot_from_m: np.ndarray | None, robot_to_m: np.ndarray | None) -> np.ndarray:
        """Advance from frame ``index - 1`` to ``index`` while the robot moves from ``robot_from_m`` to
        ``robot_to_m`` (2,) [m] (None: no robot); returns the (A, 2) positions at ``index`` (NaN: absent)."""
        before, now = self.present[index - 1], self.present[index]
        log_now = self.log_xy_m[index]
        xy = np.where(now[:, None], log_now, np.nan)
        old = self.state
        stays = before & now
        off_log = old.off_log & stays  # a pedestrian whose log ends leaves
        if robot_to_m is None:
            self.state = ReactiveState(xy, self._velocity(xy, old.xy_m, stays), np.zeros(len(xy), bool))
            return xy
        robot_v = (robot_to_m - robot_from_m) / STEP_S
        off_log |= stays & self._in_the_way(index, robot_to_m, robot_v, old, off_log)
        if off_log.any():
            xy[off_log] = self._steer(index, off_log, old, robot_from_m, robot_to_m)
        reach_m = self.robot_radius_m + BODY_RADIUS_M
        newcomer = now & ~before
        xy, pushed = self._clear_of_robot(xy, newcomer, robot_to_m)
        off_log |= pushed
        back = off_log & ~self._in_the_way(index + 1, robot_to_m + robot_v * STEP_S, robot_v,
                                           ReactiveState(xy, old.velocity_mps, off_log), off_log)
        back &= np.linalg.norm(np.nan_to_num(xy - log_now), axis=1) < REJOIN_M
        back &= np.linalg.norm(np.nan_to_num(log_now - robot_to_m, nan=np.inf), axis=1) >= reach_m  # log is clear
        xy[back] = log_now[back]
        off_log &= ~back
        self.state = ReactiveState(xy, self._velocity(xy, old.xy_m, stays), off_log)
        return xy

    @staticmethod
    def _velocity(xy: np.ndarray, old_xy: np.ndarray, stays: np.ndarray) -> np.ndarray:
        return np.where(stays[:, None], (xy - old_xy) / STEP_S, 0.0)

    def _in_the_way(self, index: int, robot_m: np.ndarray, robot_v: np.ndarray, state: ReactiveState,
                    off_log: np.ndarray) -> np.ndarray:
        """(A,) bool: agents whose log from frame ``index`` on comes within CLEARANCE_M of the robot's body (at its
        velocity) or of a pedestrian off its log (at theirs) within LOOK_AHEAD_STEPS."""
        frames = min(LOOK_AHEAD_STEPS, len(self.present) - index)
        if frames <= 0:
            return np.zeros(len(off_log), bool)
        ahead = np.arange(frames)[:, None] * STEP_S  # (H, 1) seconds
        log = self.log_xy_m[index:index + frames]  # (H, A, 2), NaN where absent
        robot = robot_m + ahead * robot_v  # (H, 2)
        gap = np.linalg.norm(log - robot[:, None], axis=-1) - self.robot_radius_m - BODY_RADIUS_M
        hit = np.nan_to_num(gap, nan=np.inf).min(axis=0) < CLEARANCE_M
        others = np.flatnonzero(off_log)
        if others.size:
            where = state.xy_m[others] + ahead[:, :, None] * state.velocity_mps[others]  # (H, O, 2)
            gap = np.linalg.norm(log[:, :, None] - where[:, None], axis=-1) - 2 * BODY_RADIUS_M  # (H, A, O)
            gap[:, others, np.arange(others.size)] = np.inf  # nobody is in their own way
            hit |= np.nan_to_num(gap, nan=np.inf).min(axis=(0, 2)) < CLEARANCE_M
        return hit

    def _steer(self, index: int, off_log: np.ndarray, old: ReactiveState, robot_from_m: np.ndarray,
               robot_to_m: np.ndarray) -> np.ndarray:
        """(O, 2) positions at frame ``index`` of the agents off their log, after SUBSTEPS of steering."""
        before, now = self.log_xy_m[index - 1], self.log_xy_m[index]
        present = self.present[index - 1] & self.present[index]
        others = np.flatnonzero(present & ~off_log)
        mine = np.flatnonzero(off_log)
        n_mine, n_others = len(mine), len(others)
        radius = np.r_[np.full(n_mine + n_others, BODY_RADIUS_M), self.robot_radius_m]
        yielding = np.r_[np.ones(n_mine), np.zeros(n_others + 1)]
        xy = old.xy_m[mine]
        velocity = old.velocity_mps[mine]
        log_step = (now[mine] - before[mine]) / STEP_S
        dt = STEP_S / SUBSTEPS
        heading = None
        for sub in range(SUBSTEPS):
            share = sub / SUBSTEPS
            other_xy = before[others] + share * (now[others] - before[others])
            robot = robot_from_m + share * (robot_to_m - robot_from_m)
            bodies = np.concatenate([xy, other_xy, robot[None]])
            moving = np.concatenate([velocity, (now[others] - before[others]) / STEP_S,
                                     ((robot_to_m - robot_from_m) / STEP_S)[None]])
            to_log = now[mine] - xy
            distance = np.linalg.norm(to_log, axis=1)
            direction = np.where(distance[:, None] > 1e-6, to_log / np.maximum(distance, 1e-6)[:, None], 0.0)
            limit = np.maximum(CATCH_UP_MPS, CATCH_UP_FACTOR * np.linalg.norm(log_step, axis=1))
            speed = np.minimum(distance / (STEP_S * (1 - share)), limit)
            preferred = np.r_[speed, np.zeros(n_others + 1)]
            directions = np.concatenate([direction, np.zeros((n_others + 1, 2))])
            fastest = float(np.sqrt((moving ** 2).sum(axis=1).max(initial=0.0)))
            fastest = max(fastest, float(limit.max(initial=0.0)))
            nb = Neighbours.within(bodies, radius, max(self.steering.agent_cutoff_m,
                                                       pair_reach_m(2 * radius.max(), fastest, dt)))
            walls = self.walls.near(bodies)
            if heading is None:  # decide once per step, walk every substep (as the simulator does)
                heading = speed_model.plan(moving, directions, preferred, radius, nb, walls, self.steering)
            wanted = cap_speed(speed_model.walk(heading, moving, preferred, radius, nb, walls, self.steering, dt),
                               np.r_[limit, np.full(n_others + 1, np.inf)])
            wanted[n_mine:] = moving[n_mine:]  # the others move as logged, the robot as commanded
            safe = keep_apart(wanted, radius, yielding, nb, walls, dt)
            velocity = safe[:n_mine]
            xy = xy + dt * velocity
        return xy

    def _clear_of_robot(self, xy: np.ndarray, rows: np.ndarray, robot_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Move the pedestrians of ``rows`` (A,) bool that stand within the robot's reach radially out of it; returns
        the positions and which were moved."""
        offset = xy - robot_m
        distance = np.linalg.norm(np.nan_to_num(offset, nan=np.inf), axis=1)
        reach = self.robot_radius_m + BODY_RADIUS_M
        pushed = rows & (distance < reach)
        if pushed.any():
            unit = np.where(distance[pushed, None] > 1e-9, offset[pushed] / np.maximum(distance[pushed], 1e-9)[:, None],
                            np.array([1.0, 0.0]))
            xy = xy.copy()
            xy[pushed] = robot_m + unit * reach
        return xy, pushed
