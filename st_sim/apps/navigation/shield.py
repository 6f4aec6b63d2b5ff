"""A safety layer over a learned planner: its command stands unless the forecasts say it collides.

    planner = ShieldedPlanner(world, use_predictions=True, inner=PpoPlanner(world, True))
    planner.reset()
    action = planner.act(obs)              # the PPO policy's command, or the MPC's where the shield vetoed it

Each step the inner planner proposes a command; the sampling MPC (``mpc.MpcPlanner``) rolls it out with its own
candidates over the same forecasts and keeps it when its expected collisions stay within the MPC's risk limit and its
path goes no deeper into a wall than the robot is (``MpcPlanner.vet``); otherwise the MPC's own choice goes out
(braking where every candidate is above the limit). ``vetoes`` and ``decisions`` count what happened since the planner
was built.
Without predictions the MPC assumes everybody stands still, so the shield then only vetoes walking into people or
walls as they are now.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from st_sim.apps.navigation.mpc import MpcConfig, MpcPlanner
from st_sim.apps.navigation.world import NavWorld


class ShieldedPlanner:
    """``inner``'s commands, each vetted by a sampling MPC over the forecasts (module docstring).

    Args:
        world: the env's facts (limits, radii, map).
        use_predictions: the MPC reads the forecasts (False: pedestrians assumed to stand still).
        inner: the planner whose commands are vetted (``reset`` and ``act`` as ``planners.Planner``).
        cfg: the MPC's tunables (its risk limit and wall margin are the shield's); None: the MPC's defaults.
    """

    def __init__(self, world: NavWorld, use_predictions: bool, inner: Any, cfg: MpcConfig | None = None):
        self.inner = inner
        self.mpc = MpcPlanner(world, use_predictions, cfg)
        self.vetoes = 0
        self.decisions = 0

    def fingerprint(self) -> str:
        """The inner planner's fingerprint (its policy file), marked as shielded."""
        inner = getattr(self.inner, "fingerprint", None)
        return f"shielded by the sampling MPC: {inner() if callable(inner) else type(self.inner).__name__}"

    def reset(self) -> None:
        """Forget the last episode (both planners)."""
        self.inner.reset()
        self.mpc.reset()

    drives_robot = True
    """``act`` gives the robot's own command (the inner planner's velocity converted by ``NavWorld.command_for``)"""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) float32 command of the robot (a holonomic robot's velocity [m/s], world frame)."""
        proposal = self.mpc.world.command_for(obs, self.inner.act(obs))
        command, vetoed = self.mpc.vet(obs, proposal)
        self.decisions += 1
        self.vetoes += int(vetoed)
        return command
