"""Train where the policy fails: how many of a run's sub-envs each training scenario gets, from how often the policy
failed there lately.

    tally = FailureTally(("STCrowd-SimCrossing-v1", "STCrowd-Eth-v0:log"))
    tally.add("STCrowd-Eth-v0:log", failed=True)      # one ended training episode
    counts = allocate(tally.failure_rates(), num_envs=56, floor=1)

A scenario's failure rate is smoothed towards 1/2 (one failure and one success added: ``(failures + 1) /
(episodes + 2)``), so a scenario with few episodes in the window is neither starved nor flooded. Every scenario
keeps ``floor`` sub-envs (Arena-Rosnav's curriculum never drops a stage either); the rest are shared in proportion to
the rates by largest remainders (ties to the earlier scenario), so the counts are whole, sum to ``num_envs``, and a
scenario failed more often never gets fewer sub-envs than one failed less often.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def allocate(failure_rates: Sequence[float], num_envs: int, floor: int = 1) -> list[int]:
    """Sub-envs per scenario: ``floor`` each, the other ``num_envs - floor * K`` in proportion to ``failure_rates``
    (K values in [0, 1]; all zero: evenly).

    Raises:
        ValueError: a rate outside [0, 1] (or NaN), no scenario, or fewer than ``floor`` sub-envs per scenario.
    """
    rates = np.asarray(failure_rates, np.float64)
    if rates.ndim != 1 or rates.size == 0:
        raise ValueError(f"failure_rates: expected one rate per scenario, got shape {rates.shape}")
    if not np.all((rates >= 0.0) & (rates <= 1.0)):  # also refuses NaN
        raise ValueError(f"failure_rates: expected rates in [0, 1], got {rates.tolist()}")
    if floor < 0 or num_envs < floor * rates.size:
        raise ValueError(f"num_envs={num_envs}: fewer than floor={floor} sub-envs for each of {rates.size} scenarios")
    spare = num_envs - floor * rates.size
    weights = rates if rates.sum() > 0 else np.ones_like(rates)
    quotas = spare * weights / weights.sum()
    counts = np.floor(quotas).astype(np.int64)
    order = np.lexsort((np.arange(rates.size), -(quotas - counts)))  # largest remainder first, ties by position
    counts[order[:spare - int(counts.sum())]] += 1
    return (counts + floor).tolist()


class FailureTally:
    """Ended training episodes and failures (a collision or a timeout: anything but the goal) per scenario since the
    last ``clear``."""

    def __init__(self, scenarios: Sequence[str]):
        self.scenarios = tuple(scenarios)
        self.episodes = dict.fromkeys(self.scenarios, 0)
        self.failures = dict.fromkeys(self.scenarios, 0)

    def add(self, scenario: str, failed: bool) -> None:
        """Count one ended episode of ``scenario`` (KeyError for a scenario the tally does not hold)."""
        self.episodes[scenario] += 1
        self.failures[scenario] += bool(failed)

    def failure_rates(self) -> list[float]:
        """Smoothed failure rate of each scenario, in ``scenarios`` order: (failures + 1) / (episodes + 2)."""
        return [(self.failures[s] + 1) / (self.episodes[s] + 2) for s in self.scenarios]

    def as_dict(self) -> dict[str, dict[str, int]]:
        """{scenario: {"episodes": n, "failures": f}}, for the run's record."""
        return {s: {"episodes": self.episodes[s], "failures": self.failures[s]} for s in self.scenarios}

    def clear(self) -> None:
        """Start a new window."""
        self.episodes = dict.fromkeys(self.scenarios, 0)
        self.failures = dict.fromkeys(self.scenarios, 0)
