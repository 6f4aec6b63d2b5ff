"""Pedestrians who stop on their way and stand a while, so that a share of the crowd stands.

A new pedestrian (or group) is planned to stop while fewer than ``PopulationConfig.standing_share`` of the
pedestrians present stand or will stop. It stops after walking a random STOP_AFTER_S, once it (and every
member of its group) is out of the entry and exit strips, and stands for an exponential dwell time of mean
``dwell_mean_s`` before walking on to its exit. Members of a group stop and walk on together.
"""

from __future__ import annotations

import numpy as np

from replays.constants import STEP_S
from st_sim.sim.config import PopulationConfig
from st_sim.sim.population import Roster

STOP_AFTER_S = (2.0, 12.0)  # a planned stop comes after walking a uniform random time in this range [s]


def dwell_steps(pop: PopulationConfig, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n,) int64 standing times, in 0.4 s steps (at least one): exponential with mean pop.dwell_mean_s."""
    return np.maximum(np.rint(rng.exponential(pop.dwell_mean_s, n) / STEP_S), 1).astype(np.int64)


def plan_stops(pop: PopulationConfig, unit_sizes: np.ndarray, roster: Roster, step: int,
               rng: np.random.Generator) -> np.ndarray:
    """Stop steps (U,) int64 for arriving units of unit_sizes (U,) pedestrians (-1: no stop).

    Units are taken one by one; a unit stops while the share of the pedestrians present (roster, arrivals
    counted as they come) who stand or will stop is below pop.standing_share.
    """
    plan = np.full(len(unit_sizes), -1, np.int64)
    if pop.standing_share == 0:
        return plan
    is_ped = roster.ped_id >= 0
    stopping = int(np.count_nonzero(is_ped & (roster.standing(step) | (roster.stop_step >= 0))))
    present = int(np.count_nonzero(is_ped))
    after = rng.uniform(*STOP_AFTER_S, len(unit_sizes)) / STEP_S
    for u, size in enumerate(unit_sizes.tolist()):
        present += size
        if stopping < pop.standing_share * present:
            plan[u] = step + max(1, round(after[u]))
            stopping += size
    return plan


def start_standing(roster: Roster, step: int, in_gate: np.ndarray, pop: PopulationConfig,
                   rng: np.random.Generator) -> None:
    """Start the stops due at step, in place: members of a group stand together, for the same dwell time.

    A due stop waits while the pedestrian, or any member of its group, is inside an entry or exit strip
    (in_gate, (K,) bool).
    """
    due = (roster.stop_step >= 0) & (roster.stop_step <= step)
    if not due.any():
        return
    unit = np.where(roster.group >= 0, roster.group, -1 - np.arange(len(roster)))  # a unit id per row
    units, inverse = np.unique(unit, return_inverse=True)
    blocked = np.bincount(inverse, weights=in_gate, minlength=len(units)) > 0
    ready = due & ~blocked[inverse]
    roster.stop_step[due & ~ready] = step + 1
    dwell = dwell_steps(pop, len(units), rng)[inverse]
    roster.go_step[ready] = step + dwell[ready]
    roster.stop_step[ready] = -1
