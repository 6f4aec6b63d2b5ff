"""A short training run on a small slice, checkpoint round trip and checkpoint errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from predictor.baselines import ConstantVelocity
from predictor.checkpoint import CheckpointError, load, read_checkpoint
from predictor.model import window_batches
from predictor.train import TrainConfig, main
from replays import load_scene, load_windows
from st_sim.metrics import ade_fde

SMALL = {"epochs": 2, "min_steps": 0, "dim": 64, "denoiser_dim": 64, "max_train_windows": 400, "batch_agents": 256,
         "progress": False}


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> TrainConfig:
    cfg = TrainConfig(task="stochastic", scene="zara1", out=str(tmp_path_factory.mktemp("run")), **SMALL)
    main(cfg)
    return cfg


def test_short_training_beats_constant_velocity(trained):
    model = load(f"{trained.out}/best.pt")
    test = load_windows("stochastic", "zara1", "test")
    scene = load_scene("zara1")
    ours, _ = ade_fde(model.predict(test.obs, test.group, scene, 20), test.fut)
    cvm, _ = ade_fde(ConstantVelocity().predict(test.obs, test.group, scene, 20), test.fut)
    assert ours.mean() < 0.8 * cvm.mean(), (ours.mean(), cvm.mean())


def test_checkpoint_round_trip_gives_identical_predictions(trained, tmp_path):
    model = load(f"{trained.out}/best.pt")
    test = load_windows("stochastic", "hotel", "test")
    first = model.predict(test.obs[:50], test.group[:50], load_scene("hotel"), 20)
    again = load(f"{trained.out}/best.pt").predict(test.obs[:50], test.group[:50], load_scene("hotel"), 20)
    np.testing.assert_array_equal(first, again)
    assert first.shape == (50, 20, 12, 2) and np.isfinite(first).all()
    state = read_checkpoint(f"{trained.out}/best.pt")
    assert "eth/train/crowds_zara01_train.txt" not in state["data_checksums"]  # zara1 is never trained on
    assert all(len(v) == 64 for v in state["data_checksums"].values())


def test_resume_continues_from_last_epoch(trained, tmp_path):
    longer = TrainConfig(**{**trained.__dict__, "epochs": 3})
    with pytest.raises(ValueError, match="another configuration"):
        main(longer)  # a changed config is refused, never silently mixed
    state = read_checkpoint(f"{trained.out}/last.pt")
    assert state["epoch"] == 1 and len(state["history"]) == 2


def test_truncated_checkpoint_is_a_clear_error(trained, tmp_path):
    data = Path(f"{trained.out}/best.pt").read_bytes()
    bad = tmp_path / "truncated.pt"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="truncated"):
        load(bad)


def test_foreign_checkpoint_is_a_clear_error(tmp_path):
    foreign = tmp_path / "foreign.pt"
    torch.save({"state_dict": {"w": torch.zeros(2)}}, foreign)
    with pytest.raises(CheckpointError, match="not an STCrowd"):
        load(foreign)
    with pytest.raises(CheckpointError, match="no such checkpoint"):
        load(tmp_path / "missing.pt")


def test_checkpoint_for_another_task_is_refused(trained):
    with pytest.raises(CheckpointError, match="trained for task 'stochastic'"):
        load(f"{trained.out}/best.pt", task="momentary")


def test_model_rejects_wrong_history_length(trained):
    model = load(f"{trained.out}/best.pt")
    with pytest.raises(ValueError, match="observes 8 steps"):
        model.predict(np.zeros((3, 2, 2), np.float32), np.zeros(3), None, 20)
    with pytest.raises(ValueError, match="S = 20"):
        model.predict(np.zeros((3, 8, 2), np.float32), np.zeros(3), None, 21)


def test_small_training_sets_get_epochs_up_to_min_steps(tmp_path):
    cfg = TrainConfig(task="domain", scene="A2B", out=str(tmp_path), epochs=1, min_steps=5, dim=32, denoiser_dim=32,
                      batch_agents=512, progress=False)
    main(cfg)
    batches = len(window_batches(torch.from_numpy(load_windows("domain", "A2B", "train").group), 512, None))
    assert batches < 5  # ETH's own train portion is small: one epoch is fewer than five steps
    last = read_checkpoint(tmp_path / "last.pt")
    assert len(last["history"]) == last["epochs"] == math.ceil(5 / batches)
