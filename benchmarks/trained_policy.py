"""A policy spec for a training run's own policy file, to score it with the benchmark before it is shipped.

    STCROWD_POLICY_FILE=runs/abl/B-benchmark/policy.pt PYTHONPATH=benchmarks \
        python -m st_sim benchmark --policy trained_policy:planner --suite val --out runs/abl/val/B

``planner`` is the PPO planner (``ppo.PpoPlanner``) acting with the ``train_ppo`` policy file that
``$STCROWD_POLICY_FILE`` names; the run's identity records that file's SHA-256 among the files it read, so another
file under the same name is refused on resume and by ``verify``.
"""

from __future__ import annotations

import os

from st_sim.apps.navigation.ppo import PpoPlanner
from st_sim.apps.navigation.world import NavWorld

POLICY_FILE_VAR = "STCROWD_POLICY_FILE"


def planner(world: NavWorld, use_predictions: bool = True) -> PpoPlanner:
    """The PPO planner with the policy file in ``$STCROWD_POLICY_FILE`` (a ``ValueError`` naming the variable when
    it is unset)."""
    path = os.environ.get(POLICY_FILE_VAR)
    if not path:
        raise ValueError(f"trained_policy:planner acts with the policy file that ${POLICY_FILE_VAR} names; set it")
    return PpoPlanner(world, use_predictions, policy=path)
