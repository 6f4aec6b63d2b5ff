"""A realism score for simulated pedestrians round a vehicle, in the style of the Waymo Open Sim Agents Challenge
(WOSAC; Montali et al. 2023): how likely the recorded people's motion is under the spread of K seeded rollouts of a
model of them (``python -m st_sim reactive-validate --realism``).

**Features**, per scored pedestrian and 0.4 s step of its window (``Scene``: from its intent to its last recorded
step), from positions alone:

- ``speed_mps``: its speed over the step [m/s];
- ``acceleration_mps2``: the change of that speed over a step [m/s^2];
- ``heading_rate_radps``: the turn of its walking direction over a step [rad/s], where it walks faster than
  ``MOVING_MPS`` over both steps (a standing pedestrian has no direction);
- ``nearest_pedestrian_m``: the distance between its centre and the nearest other pedestrian's [m] (the others as
  the rollout walks them, the people no model walks as recorded);
- ``vehicle_gap_m``: the gap between its centre and the vehicle's body [m];
- ``time_to_collision_s``: how long until its centre would enter the vehicle's body, both holding their velocity of
  the step (sampled every ``TTC_SAMPLE_S``), ``TTC_MAX_S`` when not within that;

and per pedestrian two **flags**: ``vehicle_contact`` (its centre entered the vehicle's body over a step of its
window) and ``non_walkable`` (it stood where the scene's ``Depth`` is not 0 at a step: off the walkable ground; on
open ground such as CITR's parking lot never, for the recording and every model alike).

**Likelihood.** For each pedestrian and feature, the values of its K rollouts over every step of its window fill one
histogram (``HISTOGRAMS``: fixed bins over a fixed range; a value beyond the range counts in the end bin) with
``PSEUDOCOUNT`` added to every bin; each recorded value is scored by the probability of its bin. A flag is one
Bernoulli per pedestrian: the share of its rollouts with the recorded flag, ``PSEUDOCOUNT`` added to both outcomes.
A feature's score is the exponential of the mean log-likelihood over every scored value of every pedestrian, in
(0, 1]; the **meta score** is the ``WEIGHTS``-weighted mean of the feature scores, in [0, 1]: the flags weigh most,
vehicle contact the most of all, as WOSAC weighs collisions (its 2024 weights: kinematic features 0.05 each, distance
to the nearest object 0.10, collision 0.25, time to collision 0.10, distance to the road edge 0.10, off-road 0.25).
minADE over the rollouts (``min_ade_m``) is reported beside it, not in it. The recording itself does not score 1
(its own histogram would be a spike), and a deterministic model scores low however close: the score asks for a
distribution.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
from tqdm import tqdm

from replays.constants import STEP_S
from st_sim.apps.vehicle_cases import Case, Variety, rollout, window_ends
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import MOVING_MPS, Reaction
from st_sim.reactive.routes import Depth, OpenGround

TTC_MAX_S: Final[float] = 5.0  # time to collision looked ahead, and the value when none comes within it [s]
TTC_SAMPLE_S: Final[float] = 0.1  # time to collision is found on samples this far apart [s]
PSEUDOCOUNT: Final[float] = 0.1  # added to every bin of a histogram and to both outcomes of a flag (WOSAC's)


@dataclass(frozen=True)
class Bins:
    """``count`` equal bins over [``low``, ``high``], each holding its lower edge (the last its upper edge too); a
    value beyond the range falls in the end bin on its side."""

    low: float
    high: float
    count: int

    @property
    def edges(self) -> np.ndarray:
        """(count + 1,) the bins' edges."""
        return np.linspace(self.low, self.high, self.count + 1)

    def index(self, values: np.ndarray) -> np.ndarray:
        """(...) int bin of each value (...); values must not be NaN."""
        return np.clip(np.searchsorted(self.edges, values, side="right") - 1, 0, self.count - 1)


HISTOGRAMS: Final[dict[str, Bins]] = {
    "speed_mps": Bins(0.0, 3.0, 10),
    "acceleration_mps2": Bins(-3.3, 3.3, 11),
    "heading_rate_radps": Bins(-2.2, 2.2, 11),
    "nearest_pedestrian_m": Bins(0.0, 5.0, 10),
    "vehicle_gap_m": Bins(0.0, 10.0, 10),
    "time_to_collision_s": Bins(0.0, TTC_MAX_S, 10),
}
FLAGS: Final[tuple[str, ...]] = ("vehicle_contact", "non_walkable")
WEIGHTS: Final[dict[str, float]] = {  # the meta score's weights, summing to 1
    "speed_mps": 0.05, "acceleration_mps2": 0.05, "heading_rate_radps": 0.05, "nearest_pedestrian_m": 0.10,
    "vehicle_gap_m": 0.15, "time_to_collision_s": 0.10, "vehicle_contact": 0.30, "non_walkable": 0.20}


@dataclass(frozen=True, eq=False)
class Scene:
    """What the pedestrians of one experiment are scored in.

    Attributes:
        vehicle_xy_m: (T, 2) the vehicle's centre [m].  vehicle_heading_rad: (T,) its heading [rad].
        vehicle_speed_mps: (T,) its speed along the heading [m/s].  body: its footprint.
        columns: (N,) the scored pedestrians' columns among everyone's (the crowd arrays' axis P).
        first: (N,) first step of each one's window.  last: (N,) its last step.
        ade_last: (N,) last step of each one's ADE window (from ``first``).
        depth: the scene's non-walkable depth (``routes.OpenGround`` where all is walkable).
    """

    vehicle_xy_m: np.ndarray
    vehicle_heading_rad: np.ndarray
    vehicle_speed_mps: np.ndarray
    body: Body
    columns: np.ndarray
    first: np.ndarray
    last: np.ndarray
    ade_last: np.ndarray
    depth: Depth

    def window(self, steps: int, after: int = 0) -> np.ndarray:
        """(T, N) bool: the steps of each pedestrian's window at least ``after`` steps past its first."""
        t = np.arange(steps)[:, None]
        return (t >= self.first[None] + after) & (t <= self.last[None])


def features(scene: Scene, crowd_xy_m: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The features of the scored pedestrians in K walks of the crowd ``crowd_xy_m`` (K, T, P, 2) [m] (NaN: absent):
    ``({name of HISTOGRAMS: (K, T, N), NaN where undefined}, {name of FLAGS: (K, N) bool})``."""
    crowd = np.asarray(crowd_xy_m, np.float64)
    steps = crowd.shape[1]
    xy = crowd[:, :, scene.columns]  # (K, T, N, 2)
    velocity = np.full_like(xy, np.nan)
    velocity[:, 1:] = np.diff(xy, axis=1) / STEP_S
    speed = np.linalg.norm(velocity, axis=-1)
    acceleration = np.full_like(speed, np.nan)
    acceleration[:, 1:] = np.diff(speed, axis=1) / STEP_S
    direction = np.where(speed > MOVING_MPS, np.arctan2(velocity[..., 1], velocity[..., 0]), np.nan)
    turn = np.full_like(speed, np.nan)
    turn[:, 1:] = (np.diff(direction, axis=1) + np.pi) % (2 * np.pi) - np.pi
    apart = np.linalg.norm(xy[:, :, :, None] - crowd[:, :, None], axis=-1)  # (K, T, N, P)
    apart[:, :, np.arange(len(scene.columns)), scene.columns] = np.nan  # nobody is its own neighbour
    nearest = np.where(np.isnan(apart), np.inf, apart).min(axis=-1, initial=np.inf)
    heading = scene.vehicle_heading_rad[None, :, None]
    offset = xy - scene.vehicle_xy_m[None, :, None]
    gap = scene.body.gap_m(offset, heading)
    values = {"speed_mps": speed, "acceleration_mps2": acceleration, "heading_rate_radps": turn / STEP_S,
              "nearest_pedestrian_m": np.where(np.isfinite(nearest), nearest, np.nan), "vehicle_gap_m": gap,
              "time_to_collision_s": time_to_collision_s(scene, offset, velocity)}
    windows = {name: scene.window(steps, after) for name, after in (
        ("speed_mps", 1), ("acceleration_mps2", 2), ("heading_rate_radps", 2), ("nearest_pedestrian_m", 0),
        ("vehicle_gap_m", 0), ("time_to_collision_s", 1))}
    values = {name: np.where(windows[name][None], value, np.nan) for name, value in values.items()}
    inside = scene.window(steps)
    swept = scene.body.swept_gap_m(offset[:, :-1], offset[:, 1:], heading[:, :-1])  # (K, T - 1, N)
    contact = np.any((swept <= 0.0) & inside[None, 1:] & inside[None, :-1], axis=1)
    off_ground = np.any((scene.depth.at(np.nan_to_num(xy)) > 0.0) & inside[None], axis=1)
    return values, {"vehicle_contact": contact, "non_walkable": off_ground}


def time_to_collision_s(scene: Scene, offset_m: np.ndarray, velocity_mps: np.ndarray) -> np.ndarray:
    """(K, T, N) time [s] until centres at ``offset_m`` (K, T, N, 2) from the vehicle's centre, moving at
    ``velocity_mps`` (K, T, N, 2), would enter its body with both velocities held (the vehicle's along its heading),
    to the ``TTC_SAMPLE_S`` sample; ``TTC_MAX_S`` when not within it, NaN where the velocity is unknown."""
    heading = scene.vehicle_heading_rad
    vehicle_velocity = scene.vehicle_speed_mps[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    relative = velocity_mps - vehicle_velocity[None, :, None]  # (K, T, N, 2)
    ahead = np.arange(0.0, TTC_MAX_S + TTC_SAMPLE_S / 2, TTC_SAMPLE_S)  # (S,)
    path = offset_m[..., None, :] + ahead[:, None] * relative[..., None, :]  # (K, T, N, S, 2)
    hit = scene.body.gap_m(path, heading[None, :, None, None]) <= 0.0
    ttc = np.where(hit.any(axis=-1), ahead[np.argmax(hit, axis=-1)], TTC_MAX_S)
    return np.where(np.isnan(relative[..., 0]), np.nan, ttc)


def log_likelihoods(scene: Scene, recorded_xy_m: np.ndarray, rollouts_xy_m: np.ndarray) -> dict[str, np.ndarray]:
    """Per feature and flag, the log-likelihood of every recorded value of the scored pedestrians (1-D: every defined
    step of every pedestrian; a flag: one per pedestrian) under the histograms of the K rollouts (module docstring).

    Args:
        recorded_xy_m: (T, P, 2) everyone as recorded [m].  rollouts_xy_m: (K, T, P, 2) everyone in each rollout.
    """
    logged, logged_flags = features(scene, recorded_xy_m[None])
    simulated, simulated_flags = features(scene, rollouts_xy_m)
    scores = {}
    for name, bins in HISTOGRAMS.items():
        found = []
        for n in range(len(scene.columns)):
            drawn = simulated[name][:, :, n]
            drawn = bins.index(drawn[~np.isnan(drawn)])
            counts = np.bincount(drawn, minlength=bins.count) + PSEUDOCOUNT
            values = logged[name][0, :, n]
            found.append(np.log(counts[bins.index(values[~np.isnan(values)])] / counts.sum()))
        scores[name] = np.concatenate(found) if found else np.zeros(0)
    k = rollouts_xy_m.shape[0]
    for name in FLAGS:
        agree = (simulated_flags[name] == logged_flags[name]).sum(axis=0)  # (N,)
        scores[name] = np.log((agree + PSEUDOCOUNT) / (k + 2 * PSEUDOCOUNT))
    return scores


def min_ade_m(scene: Scene, recorded_xy_m: np.ndarray, rollouts_xy_m: np.ndarray) -> np.ndarray:
    """(N,) per scored pedestrian, the least over the K rollouts of the mean distance [m] between rollout and
    recording over its ADE window (``first`` to ``ade_last``); arrays as ``log_likelihoods``'."""
    t = np.arange(recorded_xy_m.shape[0])[:, None]
    window = (t >= scene.first[None]) & (t <= scene.ade_last[None])  # (T, N)
    apart = np.linalg.norm(rollouts_xy_m[:, :, scene.columns] - recorded_xy_m[None, :, scene.columns], axis=-1)
    ade = np.where(window[None], apart, 0.0).sum(axis=1) / window.sum(axis=0)[None]  # (K, N)
    return ade.min(axis=0)


def realism(log_likelihood: dict[str, np.ndarray], min_ade: np.ndarray) -> dict[str, Any]:
    """``{"meta": ..., "features": {name: score}, "min_ade_m": ...}`` from the log-likelihoods of every scored value
    (``log_likelihoods``' of every experiment, concatenated per name) and the minADE of every pedestrian [m]. A
    feature with no value scored (nobody else in the scene: no nearest pedestrian) scores None and the meta score
    weighs the others."""
    scores = {name: float(np.exp(np.mean(values))) if len(values) else None for name, values in log_likelihood.items()}
    defined = {name: weight for name, weight in WEIGHTS.items() if scores.get(name) is not None}
    meta = sum(weight * scores[name] for name, weight in defined.items()) / sum(defined.values())
    return {"meta": float(meta), "features": scores, "min_ade_m": float(np.mean(min_ade))}


def scene_of(case: Case, body: Body, depth: Depth) -> Scene:
    """The scene of the scored pedestrians of ``case`` (``vehicle_cases``): their windows from their intents."""
    grid, intent = case.grid, case.intent
    return Scene(grid.vehicle_xy_m, grid.vehicle_heading_rad, grid.vehicle_speed_mps, body, intent.columns,
                 intent.start, intent.last, window_ends(grid, intent, body), depth)


def crowd_of(case: Case, walked_xy_m: np.ndarray) -> np.ndarray:
    """(T, P, 2) everyone of ``case``: the scored pedestrians walked as ``walked_xy_m`` (T, N, 2) over their windows,
    as recorded before; everybody else as recorded."""
    crowd = case.grid.xy_m.copy()
    t = np.arange(len(crowd))[:, None]
    window = (t >= case.intent.start[None]) & (t <= case.intent.last[None])
    crowd[:, case.intent.columns] = np.where(window[..., None], walked_xy_m, crowd[:, case.intent.columns])
    return crowd


def case_realism(cases: Sequence[Case], body: Body, reaction: Reaction | None, rollouts: int, seed: int,
                 variety: Variety, depth: Depth | None = None, progress: bool = False) -> dict[str, object]:
    """``realism`` of a model (``reaction``; None: blind) on the pedestrians of ``cases``: ``rollouts`` seeded
    rollouts each (``vehicle_cases.rollout``), ``depth`` the ground (default ``OpenGround``: all walkable)."""
    scored = [case_likelihoods(case, body, reaction, rollouts, seed, variety, depth)
              for case in tqdm(cases, desc="rollouts", unit="experiment", disable=not progress)]
    return pooled_realism(scored)


def case_likelihoods(case: Case, body: Body, reaction: Reaction | None, rollouts: int, seed: int, variety: Variety,
                     depth: Depth | None = None) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """(``log_likelihoods``, ``min_ade_m``) of one case's scored pedestrians under ``rollouts`` seeded rollouts of a
    model (arguments as ``case_realism``'s): what ``pooled_realism`` pools over cases."""
    scene = scene_of(case, body, OpenGround() if depth is None else depth)
    walked = np.stack([crowd_of(case, rollout(case, body, reaction, index, seed, variety))
                       for index in range(rollouts)])
    return log_likelihoods(scene, case.grid.xy_m, walked), min_ade_m(scene, case.grid.xy_m, walked)


def pooled_realism(scored: Sequence[tuple[dict[str, np.ndarray], np.ndarray]]) -> dict[str, object]:
    """``realism`` of the pedestrians of several cases together, from each case's ``case_likelihoods``."""
    names = scored[0][0] if scored else {}
    return realism({name: np.concatenate([values[name] for values, _ in scored]) for name in names},
                   np.concatenate([closest for _, closest in scored]))
