"""At-fault collisions as a constraint with a learned multiplier (PPO-Lagrangian, as SoNIC constrains collisions):
the charge for a collision the fault rule puts on the robot rises while the policy's at-fault rate is above its
target and falls (never below 0) while it is under.

    constraint = FaultConstraint(target=0.03, step=200.0, multiplier=20.0)
    charge = constraint.update(episodes=212, at_fault=19)     # after a rollout: 20 + 200 x (19/212 - 0.03) = 31.9

The charge is in reward units per at-fault collision (the training envs subtract it on that step:
``training_envs.FeatureVecEnv(fault_charge=...)``); ``step`` is how far one rollout's rate moves it per unit of rate
above the target [reward units].
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class FaultConstraint:
    """The multiplier of the at-fault constraint and how it moves.

    Attributes:
        target: at-fault collisions per ended episode the policy may have, in [0, 1).
        step: change of the multiplier per unit of (rate - target), per update, > 0 [reward units].
        multiplier: the current charge per at-fault collision, >= 0 [reward units].
    """

    target: float
    step: float
    multiplier: float

    def __post_init__(self) -> None:
        if not (0.0 <= self.target < 1.0 and math.isfinite(self.step) and self.step > 0
                and math.isfinite(self.multiplier) and self.multiplier >= 0):
            raise ValueError(f"FaultConstraint(target={self.target!r}, step={self.step!r}, "
                             f"multiplier={self.multiplier!r}): expected a target in [0, 1), a finite step > 0 and a "
                             "finite multiplier >= 0")

    def update(self, episodes: int, at_fault: int) -> float:
        """Move the multiplier by the at-fault rate of ``episodes`` ended episodes (``at_fault`` of them at fault;
        none ended: unchanged); returns it."""
        if not 0 <= at_fault <= episodes:
            raise ValueError(f"at_fault={at_fault} of episodes={episodes}: expected 0 <= at_fault <= episodes")
        if episodes:
            self.multiplier = max(0.0, self.multiplier + self.step * (at_fault / episodes - self.target))
        return self.multiplier
