"""The sample prior: one per shipped checkpoint, kept in step with its hash, handed to planners by ``world_of``."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
from predictor.checkpoint import pretrained_manifest
from replays.constants import TASKS
from st_sim.apps.navigation import sample_prior as prior_module
from st_sim.apps.navigation.sample_prior import sample_prior
from st_sim.apps.navigation.world import world_of

# checkpoints with S = 20 samples to weigh (a single-sample model has nothing to weigh)
SHIPPED = sorted(name for name, entry in pretrained_manifest()["checkpoints"].items()
                 if TASKS[entry["train_config"]["task"]]["num_samples"] > 1)


@pytest.mark.parametrize("name", SHIPPED, ids=SHIPPED)
def test_every_shipped_checkpoint_has_a_current_prior_that_favours_its_first_samples(name: str) -> None:
    prior = sample_prior(f"shipped:{name}", 20)
    assert prior is not None, f"{name}: no prior, or the checkpoint was re-shipped; run python -m " \
                              "st_sim.apps.navigation.sample_prior"
    assert prior.shape == (20,) and prior.sum() == pytest.approx(1.0) and (prior > 0).all()
    assert prior[0] > 2 * prior[-5:].sum() / 5, f"{name}: sample 0 (largest cluster) is not the likeliest"
    assert prior[:5].sum() > prior[-5:].sum()


def test_no_prior_for_unordered_unknown_or_stale_predictors(monkeypatch: pytest.MonkeyPatch) -> None:
    assert sample_prior(None, 20) is None
    assert sample_prior("runs/stochastic/zara1/seed0/best.pt", 20) is None, "a file of unknown samples"
    assert sample_prior("shipped:no/such", 20) is None
    assert sample_prior("shipped:universal", 21) is None, "more samples than the table has"
    stale = {"checkpoints": {"universal": {"sha256": "0" * 64, "weights": [0.05] * 20}}}
    monkeypatch.setattr(prior_module, "_table", lambda: stale)
    assert sample_prior("shipped:universal", 20) is None, "a re-shipped checkpoint's old prior must not be used"


@pytest.mark.parametrize(("env_id", "name"), [("STCrowd-SimCrossing-v1", "universal"),
                                              ("STCrowd-Zara1-v0", "stochastic/zara1")], ids=["sim", "replay"])
def test_world_of_hands_the_envs_checkpoint_prior_to_the_planners(env_id: str, name: str) -> None:
    world = world_of(gym.make(env_id, predictor="singular"))
    assert np.array_equal(world.sample_prior, sample_prior(f"shipped:{name}", 20))
    for other in ("cvm-s", "none"):
        assert world_of(gym.make(env_id, predictor=other)).sample_prior is None, f"{other}: samples are unordered"


def test_the_table_command_weighs_every_multi_sample_checkpoint_and_skips_single_sample_ones(tmp_path) -> None:
    out = tmp_path / "prior.json"
    assert prior_module.main(["--max-windows", "3", "--out", str(out)]) == 0
    table = json.loads(out.read_text())["checkpoints"]
    assert sorted(table) == SHIPPED  # deterministic models (S = 1) have nothing to weigh
    assert all(len(entry["weights"]) == 20 and entry["windows"] == 3 for entry in table.values())
