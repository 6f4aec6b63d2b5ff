"""A sub-goal social force model of pedestrians round a vehicle, as a second family beside STCrowd's reactive
pedestrians, walked and fitted by the same harness (``vehicle_cases.walk``, ``reaction_search``).

After the sub-goal social force model (SG-SFM; Yang, Johora, Redmill, Ozguner, Muller 2021): each pedestrian is
pulled toward its goal, pushed by the vehicle and by the other pedestrians, and, when the vehicle is about to cross
its way, toward a sub-goal beside the vehicle instead of its goal. Here, written from that description:

- **Goal**: the point of its intent (``vehicle_cases.Intents``) ``lookahead_s`` ahead of now, at its intent's pace
  (a pedestrian pushed off its line walks back to it).
- **Conflict**: walking straight to its goal at its pace while the vehicle keeps its velocity, it would come within
  ``margin_m`` of the vehicle's body in the next ``conflict_s`` seconds.
- **Sub-goal**: in conflict, a corner of the vehicle's body grown by ``margin_m``, on the pedestrian's side of the
  vehicle's axis, where the vehicle will be at the predicted contact: the rear corner (passing behind it) or the
  front corner (passing ahead of it), whichever makes the shorter way to the goal, the front one longer by
  ``ahead_penalty_m``. A sub-goal behind a moving vehicle slows the pedestrian down until the vehicle has passed.
- **Forces** [m/s²]: (desired velocity - velocity) / ``tau_s``; from the vehicle ``vehicle_strength`` ·
  exp(-gap / ``vehicle_range_m``) away from its body; from each other pedestrian ``pedestrian_strength`` ·
  exp(-(distance - 0.5 m) / ``pedestrian_range_m``) away from it. Speed at most 1.5 times its pace (and 0.5 m/s).

Integrated in 0.1 s sub-steps (4 per 0.4 s step, the vehicle moving linearly between its recorded positions);
deterministic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Final

import numpy as np

from envs.common.config import Interval, check_fields
from replays.constants import STEP_S
from st_sim.reactive.footprint import Body

SUB_STEPS: Final[int] = 4  # integration sub-steps per 0.4 s step [-]
PAIR_M: Final[float] = 0.5  # two pedestrians' centres when their bodies touch [m]
SPEED_CAP: Final[float] = 1.5  # speed at most this many times a pedestrian's pace [-] ...
MIN_CAP_MPS: Final[float] = 0.5  # ... and at least this cap [m/s]
PROBE_M: Final[float] = 1e-3  # finite difference for the direction away from the vehicle's body [m]
PROBES: Final[np.ndarray] = np.array([[PROBE_M, 0.0], [0.0, PROBE_M]])


@dataclass(frozen=True)
class SubGoalForce:
    """The model's parameters (module docstring); the defaults are first guesses, not fitted."""

    tau_s: float = 0.5
    lookahead_s: float = 2.0
    conflict_s: float = 3.0
    margin_m: float = 1.0
    ahead_penalty_m: float = 2.0
    vehicle_strength: float = 2.0
    vehicle_range_m: float = 0.4
    pedestrian_strength: float = 1.0
    pedestrian_range_m: float = 0.3

    def __post_init__(self) -> None:
        check_fields(self, {f.name: Interval(0.0, math.inf, low_open=f.name == "tau_s", high_open=True)
                            for f in fields(self)})  # ConfigError (a ValueError) naming the field


def _away_from_body(body: Body, offset_m: np.ndarray, heading_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """(gap (N,) [m], unit direction (N, 2) of growing gap) of points at ``offset_m`` (N, 2) from the body's centre."""
    gap = body.gap_m(offset_m, heading_rad)
    grad = np.stack([body.gap_m(offset_m + probe, heading_rad) - gap for probe in PROBES], axis=-1)
    norm = np.linalg.norm(grad, axis=-1, keepdims=True)
    return gap, np.divide(grad, norm, out=np.zeros_like(grad), where=norm > 0)


def _sub_goals(model: SubGoalForce, body: Body, xy: np.ndarray, goal: np.ndarray, pace: np.ndarray,
               vehicle_xy: np.ndarray, vehicle_velocity: np.ndarray, heading: float) -> np.ndarray:
    """(N, 2) where each pedestrian heads now: its goal, or in conflict a corner beside the vehicle."""
    target = goal.copy()
    if model.conflict_s <= 0.0:
        return target
    to_goal = goal - xy
    distance = np.linalg.norm(to_goal, axis=-1, keepdims=True)
    velocity = np.divide(to_goal, distance, out=np.zeros_like(to_goal), where=distance > 0) * pace[:, None]
    times = np.arange(0.0, model.conflict_s + 1e-9, STEP_S / SUB_STEPS)  # (K,)
    relative = (xy - vehicle_xy)[None] + times[:, None, None] * (velocity - vehicle_velocity)[None]  # (K, N, 2)
    gaps = body.gap_m(relative, heading)  # (K, N)
    conflict = (gaps < model.margin_m).any(axis=0)
    if not conflict.any():
        return target
    first = np.argmax(gaps < model.margin_m, axis=0)  # (N,) first step of contact
    axis, side = np.array([np.cos(heading), np.sin(heading)]), np.array([-np.sin(heading), np.cos(heading)])
    half = body.half_m + body.radius_m + model.margin_m
    for n in np.flatnonzero(conflict):
        centre = vehicle_xy + times[first[n]] * vehicle_velocity
        lateral = np.sign((xy[n] - centre) @ side) or 1.0
        corners = [centre + sign * half[0] * axis + lateral * half[1] * side for sign in (-1.0, 1.0)]  # rear, front
        cost = [np.linalg.norm(c - xy[n]) + np.linalg.norm(goal[n] - c) + extra
                for c, extra in zip(corners, (0.0, model.ahead_penalty_m), strict=True)]
        target[n] = corners[int(np.argmin(cost))]
    return target


def walk_sub_goal(model: SubGoalForce, intent_xy_m: np.ndarray, vehicle_xy_m: np.ndarray,
                  vehicle_heading_rad: np.ndarray, body: Body) -> np.ndarray:
    """(T, N, 2) positions [m] of pedestrians walking their intents ``intent_xy_m`` (T, N, 2; NaN before each one's
    start, where it is placed on its intent) round a vehicle at ``vehicle_xy_m`` (T, 2) heading
    ``vehicle_heading_rad`` (T,), every 0.4 s."""
    steps, count = intent_xy_m.shape[:2]
    out = np.full_like(intent_xy_m, np.nan)
    started = ~np.isnan(intent_xy_m[..., 0])
    start = np.where(started.any(axis=0), np.argmax(started, axis=0), steps)
    pace = np.zeros(count)
    for n in range(count):  # the intent's speed: its line's step length
        if start[n] + 1 < steps:
            pace[n] = np.linalg.norm(intent_xy_m[start[n] + 1, n] - intent_xy_m[start[n], n]) / STEP_S
    cap = np.maximum(SPEED_CAP * pace, MIN_CAP_MPS)
    xy, velocity = np.full((count, 2), np.nan), np.zeros((count, 2))
    ahead = max(round(model.lookahead_s / STEP_S), 1)
    dt = STEP_S / SUB_STEPS
    for t in range(steps):
        new = start == t
        xy[new], velocity[new] = intent_xy_m[t, new], 0.0
        if new.any() and t + 1 < steps:
            velocity[new] = (intent_xy_m[t + 1, new] - intent_xy_m[t, new]) / STEP_S
        out[t] = xy
        if t + 1 >= steps:
            break
        live = np.flatnonzero(start <= t)
        if not live.size:
            continue
        goal = intent_xy_m[min(t + ahead, steps - 1), live]
        vehicle_velocity = (vehicle_xy_m[t + 1] - vehicle_xy_m[t]) / STEP_S
        heading = float(vehicle_heading_rad[t])
        for k in range(SUB_STEPS):
            here = vehicle_xy_m[t] + (k * dt) * vehicle_velocity
            p, v = xy[live], velocity[live]
            target = _sub_goals(model, body, p, goal, pace[live], here, vehicle_velocity, heading)
            to_target = target - p
            distance = np.linalg.norm(to_target, axis=-1, keepdims=True)
            desired = np.divide(to_target, distance, out=np.zeros_like(to_target), where=distance > 0) * \
                np.minimum(pace[live][:, None], distance / dt)
            force = (desired - v) / model.tau_s
            gap, away = _away_from_body(body, p - here, heading)
            force += model.vehicle_strength * np.exp(-np.maximum(gap, 0.0) / max(model.vehicle_range_m, 1e-6))[
                :, None] * away
            if len(live) > 1 and model.pedestrian_strength > 0.0:
                apart = p[:, None] - p[None]  # (L, L, 2)
                d = np.linalg.norm(apart, axis=-1)
                np.fill_diagonal(d, np.inf)
                push = model.pedestrian_strength * np.exp(-(d - PAIR_M) / max(model.pedestrian_range_m, 1e-6))
                force += (push[..., None] * apart / np.where(np.isfinite(d), d, 1.0)[..., None]).sum(axis=1)
            v = v + dt * force
            speed = np.linalg.norm(v, axis=-1, keepdims=True)
            v = np.where(speed > cap[live][:, None], v * cap[live][:, None] / np.maximum(speed, 1e-12), v)
            xy[live], velocity[live] = p + dt * v, v
    return out
