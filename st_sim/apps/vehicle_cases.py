"""People who walked round a recorded vehicle, the intent each had before it came near, and how a model of them walks
and scores against the recording (``python -m st_sim reactive-validate``, ``benchmarks/fit_reaction.py``).

Every experiment with a vehicle (CITR's layout, ``replays.citr``) is resampled at the env's 0.4 s step. The vehicle is
the robot: a box (``Body``) driven along its recorded path. Each pedestrian that came within ``NEAR_M`` of the
vehicle's body gets its **intent**, the same for every model: the straight line on from where it was, at its mean
velocity over the ``INTENT_STEPS`` before, when the vehicle first came within ``INTENT_GAP_M`` of it (at the earliest
``INTENT_STEPS`` into its track). From there a model walks it with the vehicle present (``walk``): blind, it walks its
intent and ignores the vehicle; reactive, it is STCrowd's reactive pedestrian (``st_sim.reactive.reactive``) with its
intent as its log and a reaction (``st_sim.reactive.reaction``), the pedestrians seeing the vehicle's body, position and
velocity at the start of each step.

Scored against the recording, per pedestrian (``score``): ADE [m] over the interaction window (from its intent to
``POST_STEPS`` after its recorded closest approach), the least gap between its centre and the vehicle's body [m]
along every step, whether the simulated pedestrian's centre entered the body (a collision), and the onset of its
reaction: the gap to the vehicle's body when it first strays ``ONSET_M`` from its intent (none if it never does).

**Rollouts** (``rollout``, for ``st_sim.apps.sim_agents``' realism score): the same walk with seeded variety
(``Variety``): each intent walked at a pace of its own, and each reactive pedestrian with traits of its own
(``st_sim.reactive.reaction.draw_traits``).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np

from replays.citr import Experiment, Grid, on_grid
from replays.constants import STEP_S
from st_sim.apps.subgoal_force import SubGoalForce, walk_sub_goal
from st_sim.reactive.footprint import BODY_RADIUS_M, Body
from st_sim.reactive.reaction import Reaction, Spread, draw_traits
from st_sim.reactive.reactive import ReactiveCrowd
from st_sim.reactive.routes import OpenGround

NEAR_M: Final[float] = 5.0  # pedestrians that come this close to the vehicle's body are scored [m]
INTENT_GAP_M: Final[float] = 15.0  # an intent is taken when the vehicle's body first comes this close [m] ...
INTENT_STEPS: Final[int] = 3  # ... from the mean velocity over this many 0.4 s steps before
POST_STEPS: Final[int] = 5  # the interaction window ends this many steps (2 s) after the recorded closest approach
ONSET_M: Final[float] = 0.5  # a reaction shows once a pedestrian strays this far from its intent [m]


@dataclass(frozen=True, eq=False)
class Intents:
    """The scored pedestrians of one experiment and what they meant to do.

    Attributes:
        columns: (N,) their columns in the grid.  start: (N,) the step each intent is taken at.
        last: (N,) each one's last recorded step.  xy_m: (T, N, 2) the intents [m], NaN before their start.
    """

    columns: np.ndarray
    start: np.ndarray
    last: np.ndarray
    xy_m: np.ndarray

    def paced(self, factor: np.ndarray) -> Intents:
        """The same intents walked at ``factor`` (N,) times their pace: each line from the same start point."""
        begin = self.xy_m[self.start, np.arange(len(self.start))]  # (N, 2)
        return Intents(self.columns, self.start, self.last, begin + factor[:, None] * (self.xy_m - begin))


def recorded_gap_m(grid: Grid, body: Body) -> np.ndarray:
    """(T, N) gap [m] between each recorded pedestrian and the vehicle's body at every step (NaN where absent)."""
    return body.gap_m(grid.xy_m - grid.vehicle_xy_m[:, None], grid.vehicle_heading_rad[:, None])


def intents(grid: Grid, body: Body) -> Intents:
    """The intents of the pedestrians of ``grid`` that came within ``NEAR_M`` of the vehicle (module docstring)."""
    gap = recorded_gap_m(grid, body)
    steps = np.arange(len(grid.times_s))
    columns, start, last = [], [], []
    for column in np.flatnonzero(np.nanmin(np.where(grid.present, gap, np.inf), axis=0) <= NEAR_M):
        seen = np.flatnonzero(grid.present[:, column])
        inside = seen[gap[seen, column] < INTENT_GAP_M]
        begin = min(max(int(inside[0]), seen[0] + INTENT_STEPS), seen[-1] - 1)
        if begin >= seen[0] + INTENT_STEPS:  # long enough to take a velocity and to walk one step
            columns.append(column)
            start.append(begin)
            last.append(int(seen[-1]))
    columns, start = np.array(columns, int), np.array(start, int)
    velocity = (grid.xy_m[start, columns] - grid.xy_m[start - INTENT_STEPS, columns]) / (INTENT_STEPS * STEP_S)
    since_s = (steps[:, None] - start[None]) * STEP_S  # (T, N)
    xy = grid.xy_m[start, columns][None] + since_s[..., None] * velocity[None]
    return Intents(columns, start, np.array(last, int), np.where((since_s >= 0)[..., None], xy, np.nan))


def walk(grid: Grid, intent: Intents, body: Body, reaction: Reaction | SubGoalForce | None,
         traits: np.ndarray | None = None) -> np.ndarray:
    """(T, N, 2) positions [m] of the scored pedestrians walking their intents with the vehicle driving its recorded
    path (``reaction`` None: blind, the intents themselves; a ``SubGoalForce``: that model instead of the reactive
    pedestrians); ``traits`` (N, 4): the reactive pedestrians' (default: the fitted pedestrian's)."""
    if reaction is None:
        return intent.xy_m.copy()
    if isinstance(reaction, SubGoalForce):
        return walk_sub_goal(reaction, intent.xy_m, grid.vehicle_xy_m, grid.vehicle_heading_rad, body)
    present = ~np.isnan(intent.xy_m[..., 0])
    crowd = ReactiveCrowd(intent.xy_m, present, OpenGround(), body, BODY_RADIUS_M, reaction)
    path = [crowd.reset(0, traits).copy()]
    for index in range(1, len(grid.times_s)):
        heading = grid.vehicle_heading_rad[index - 1]
        here = grid.vehicle_xy_m[index - 1]
        expected = here + STEP_S * grid.vehicle_speed_mps[index - 1] * np.array([np.cos(heading), np.sin(heading)])
        path.append(crowd.step(index, here, expected, heading).copy())
    return np.array(path)


def window_ends(grid: Grid, intent: Intents, body: Body) -> np.ndarray:
    """(N,) last step of each scored pedestrian's interaction window: ``POST_STEPS`` after its recorded closest
    approach to the vehicle's body, at most its last recorded step."""
    closest = recorded_gap_m(grid, body)[:, intent.columns]
    return np.array([min(begin + int(np.nanargmin(closest[begin:end + 1, n])) + POST_STEPS, end)
                     for n, (begin, end) in enumerate(zip(intent.start, intent.last, strict=True))], int)


def score(grid: Grid, intent: Intents, xy_m: np.ndarray, body: Body) -> list[dict[str, Any]]:
    """Per scored pedestrian of one experiment, how ``xy_m`` (T, N, 2) walked: ``ade_m`` against the recording over
    the interaction window (``window_ends``), ``min_clearance_m`` (least gap to the vehicle's body along the steps),
    ``collision`` (its centre inside the body) and ``onset_gap_m`` (gap when it first strayed ``ONSET_M`` from its
    intent, or None)."""
    recorded = grid.xy_m[:, intent.columns]
    vehicle, heading = grid.vehicle_xy_m, grid.vehicle_heading_rad
    rows = []
    for n, (begin, end, stop) in enumerate(zip(intent.start, intent.last, window_ends(grid, intent, body),
                                               strict=True)):
        span = slice(begin, end + 1)
        ade = float(np.linalg.norm(xy_m[begin:stop + 1, n] - recorded[begin:stop + 1, n], axis=-1).mean())
        swept = body.swept_gap_m(xy_m[begin:end, n] - vehicle[begin:end], xy_m[begin + 1:end + 1, n]
                                 - vehicle[begin + 1:end + 1], heading[begin:end])
        clearance = float(swept.min())
        strayed = np.flatnonzero(np.linalg.norm(xy_m[span, n] - intent.xy_m[span, n], axis=-1) > ONSET_M)
        onset = float(body.gap_m(xy_m[begin + strayed[0], n] - vehicle[begin + strayed[0]],
                                 heading[begin + strayed[0]])) if strayed.size else None
        rows.append({"ade_m": ade, "min_clearance_m": clearance, "collision": bool(clearance <= 0.0),
                     "onset_gap_m": onset})
    return rows


@dataclass(frozen=True, eq=False)
class Case:
    """One experiment ready to simulate: its grid, its scored pedestrians' intents and how they really walked."""

    name: str
    group: str
    """the experiment's top folder (``vci_front``), "." for an experiment at the top"""
    grid: Grid
    intent: Intents
    recorded: list[dict[str, Any]]


def cases(experiments: list[Experiment], body: Body) -> list[Case]:
    """The experiments with at least one scored pedestrian, resampled at 0.4 s, with their intents and recorded
    scores."""
    found = []
    for experiment in experiments:
        grid = on_grid(experiment, STEP_S)
        intent = intents(grid, body)
        if len(intent.columns):
            group = experiment.name.split("/")[0] if "/" in experiment.name else "."
            found.append(Case(experiment.name, group, grid, intent,
                              score(grid, intent, grid.xy_m[:, intent.columns], body)))
    return found


@dataclass(frozen=True)
class Variety:
    """How seeded rollouts of the same experiment differ (``rollout``): each scored pedestrian walks its intent at a
    pace drawn from N(1, ``pace_sigma``) (kept within ``PACE_RANGE``), blind and reactive alike, and a reactive
    pedestrian also draws its traits with ``spread`` (``reaction.draw_traits``; a sub-goal model has none). Zero
    sigmas: the deterministic models. The pace's default is chosen, not fitted: a tenth of a pedestrian's pace; the
    traits' default is no spread (``reactive-validate`` passes the environments', ``reaction.fitted_spread``)."""

    pace_sigma: float = 0.1
    spread: Spread = field(default_factory=Spread)


PACE_RANGE: Final[tuple[float, float]] = (0.5, 1.5)  # a rollout's pace factor is kept within this [-]


def rollout(case: Case, body: Body, reaction: Reaction | SubGoalForce | None, index: int, seed: int,
            variety: Variety) -> np.ndarray:
    """(T, N, 2) positions [m] of rollout ``index`` of the scored pedestrians of ``case`` (``walk`` with
    ``variety``, drawn from ``seed``, the index and the experiment's name: every model of rollout ``index`` walks the
    same paces)."""
    rng = np.random.default_rng([seed, index, zlib.crc32(case.name.encode())])
    pace = np.clip(rng.normal(1.0, variety.pace_sigma, len(case.intent.columns)), *PACE_RANGE)
    traits = draw_traits(rng, len(case.intent.columns), variety.spread) if isinstance(reaction, Reaction) else None
    return walk(case.grid, case.intent.paced(pace), body, reaction, traits)
