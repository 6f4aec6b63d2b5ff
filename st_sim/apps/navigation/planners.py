"""The planners of the navigation benchmark by name, and what every planner offers.

    planner = make_planner("mpc", world_of(env), "singular")
    planner.reset()                        # at every episode start
    action = planner.act(obs)              # (2,) velocity command [m/s], world frame

Planner modules are imported on first use, so a planner's optional dependency (pyrvo for ORCA, navground or
PySocialForce for a peer) is only needed when that planner runs.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from predictor.plugins import is_plugin_spec
from st_sim.apps.navigation.predictors import NAMES

if TYPE_CHECKING:
    from st_sim.apps.navigation.world import NavWorld

PLANNERS: dict[str, str] = {
    "straight": "st_sim.apps.navigation.straight:StraightPlanner",
    "orca": "st_sim.apps.navigation.orca:OrcaPlanner",
    "mpc": "st_sim.apps.navigation.mpc:MpcPlanner",
    "ppo": "st_sim.apps.navigation.ppo:PpoPlanner",
    "ppo-reactive": "st_sim.apps.navigation.ppo:ReactivePpoPlanner",
    "ppo-suite": "st_sim.apps.navigation.ppo:SuitePpoPlanner",
    "ppo-suite-shield": "st_sim.apps.navigation.ppo:shielded_suite_ppo",
    "ppo-suite-2": "st_sim.apps.navigation.ppo:Suite2PpoPlanner",
}
"""planner name -> "module:class"; every class is built as ``cls(world, use_predictions, **options)``"""
PEERS: dict[str, str] = {
    "navground-hl": "st_sim.apps.navigation.peers:NavgroundHL",
    "navground-orca": "st_sim.apps.navigation.peers:NavgroundOrca",
    "navground-hrvo": "st_sim.apps.navigation.peers:NavgroundHrvo",
    "navground-sf": "st_sim.apps.navigation.peers:NavgroundSocialForce",
    "pysocialforce": "st_sim.apps.navigation.peers:PySocialForcePlanner",
}
"""planners of other projects (``peers``, the optional extra ``peers``) by name, built like the shipped ones"""
NAMED: dict[str, str] = {**PLANNERS, **PEERS}
"""every planner a policy spec can name: the shipped ones and the peers"""
USES_PREDICTIONS: dict[str, bool] = {"straight": False, "orca": False, "mpc": True, "ppo": True, "ppo-reactive": True,
                                     "ppo-suite": True, "ppo-suite-shield": True, "ppo-suite-2": True,
                                     **dict.fromkeys(PEERS, False)}
"""planners whose actions depend on the predicted futures (the others give the same episodes for any predictor)"""
READS_POLICY_FILE: tuple[str, ...] = ("ppo", "ppo-reactive", "ppo-suite", "ppo-suite-2")
"""planners that take a trained policy file (option ``policy``) in place of their shipped one"""


class Planner(Protocol):
    """A navigation policy: one velocity command per observation."""

    def reset(self) -> None:
        """Forget the last episode (called after every env reset)."""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) float32 ego velocity command [m/s], world frame, from an STCrowd observation."""


def make_planner(name: str, world: NavWorld, predictor: str = "singular", **options: Any) -> Planner:
    """Build planner ``name`` (shipped or a peer) for an env's ``world``; ``predictor`` is a name of ``NAMES`` or a
    plug-in ``package.module:name`` (the env runs it), and "none" means the futures are not used.

    ``options`` go to the planner's class (the MPC takes ``cfg=MpcConfig(...)``).
    """
    if name not in NAMED:
        raise ValueError(f"planner={name!r}: expected one of {', '.join(NAMED)}")
    if predictor not in NAMES and not is_plugin_spec(predictor):
        raise ValueError(f"predictor={predictor!r}: expected one of {', '.join(NAMES)} or a plug-in "
                         "package.module:name")
    module, cls = NAMED[name].split(":")
    return getattr(import_module(module), cls)(world, predictor != "none", **options)
