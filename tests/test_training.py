"""A short training run on a small slice, checkpoint round trip and checkpoint errors."""

from __future__ import annotations

import json
import math
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from predictor.baselines import ConstantVelocity
from predictor.checkpoint import CheckpointError, content_hash, load, model_from_state, read_checkpoint
from predictor.model import window_batches
from predictor.refiner import linear_alpha_bar
from predictor.train import TrainConfig, TrainingError, lr_factor, main, with_task_defaults
from replays import load_scene, load_windows
from replays.constants import TASKS
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


def test_resume_refuses_a_changed_model_setting_and_names_it(trained):
    longer = TrainConfig(**{**trained.__dict__, "epochs": 3})
    with pytest.raises(TrainingError, match=r"other settings \(epochs\).*delete"):
        main(longer)  # a changed config is refused, never silently mixed
    state = read_checkpoint(f"{trained.out}/last.pt")
    assert state["epoch"] == 1 and len(state["history"]) == 2


def test_cosmetic_flags_do_not_block_a_resume(trained, monkeypatch):
    before = Path(f"{trained.out}/best.pt").read_bytes()
    data = str(Path(os.environ["STCROWD_DATA"]).resolve())  # the root given by flag instead of the variable
    monkeypatch.chdir(Path(trained.out).parent)
    relative = Path(trained.out).name  # the same folder, given relatively
    cosmetic = TrainConfig(**{**trained.__dict__, "out": relative, "threads": 2, "progress": True,
                              "data_root": data})
    assert main(cosmetic) == Path(relative) / "best.pt"  # a finished run: nothing to redo
    assert Path(f"{trained.out}/best.pt").read_bytes() == before
    summary = json.loads(Path(f"{trained.out}/train.json").read_text())
    assert summary["epochs"] == 2 and summary["best"]["epoch"] in (1, 2) and len(summary["history"]) == 2
    assert "out" not in summary["train_config"] and "threads" not in summary["train_config"]


@pytest.mark.parametrize("field, value", [("epochs", 0), ("epochs", -1), ("min_steps", -5), ("k", 0), ("steps", 0),
                                          ("lr", float("nan")), ("batch_agents", 1.5), ("seed", True),
                                          ("objective", "mse"), ("anchor_bend", "curl"), ("dim", 30),
                                          ("sampler", "ddpm"), ("lr_schedule", "linear"), ("lr_stages", 0),
                                          ("lr_gamma", 0.0), ("lr_gamma", 1.5), ("warmup_epochs", -1.0)])
def test_bad_training_settings_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"TrainConfig.{field}="):
        TrainConfig(**{field: value})


def test_damaged_or_non_finite_checkpoints_are_refused(trained, tmp_path):
    state = read_checkpoint(f"{trained.out}/best.pt")
    name = next(iter(state["model"]["weights"]))
    flipped = {**state, "model": {**state["model"], "weights": dict(state["model"]["weights"])}}
    flipped["model"]["weights"][name] = state["model"]["weights"][name] * 2
    torch.save(flipped, tmp_path / "flipped.pt")
    with pytest.raises(CheckpointError, match="content hash mismatch"):
        load(tmp_path / "flipped.pt")
    nan = {**state, "model": {**state["model"], "anchors": torch.full_like(state["model"]["anchors"], float("nan"))}}
    nan["model"]["content_sha256"] = content_hash(nan["model"])  # a consistent hash over NaN anchors
    torch.save(nan, tmp_path / "nan.pt")
    with pytest.raises(CheckpointError, match=r"non-finite values.*anchors"):
        load(tmp_path / "nan.pt")


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


def test_predicted_end_points_are_pulled_onto_walkable_pixels(trained):
    model = load(f"{trained.out}/best.pt")
    test = load_windows("stochastic", "eth", "test")  # ETH's camera sees a small part of a long walkway
    eth = load_scene("eth")
    ends = model.predict(test.obs, test.group, eth, 20)[:, :, -1]
    assert eth.is_walkable(ends).all()  # walls and off-image end points alike are pulled back
    model.cfg = replace(model.cfg, adapt_output=False)
    raw_ends = model.predict(test.obs, test.group, eth, 20)[:, :, -1]
    assert not eth.is_walkable(raw_ends).all()  # without the output adaptation some leave the walkway


def test_predicted_points_are_kept_on_walkable_ground(trained):
    """By default no predicted point lies deeper than on_map_tolerance_m inside a wall or off the image: moving
    the points onto the map again moves none of them; without it, HOTEL's forecasts leave the map."""
    from predictor.anchors import onto_walkable

    model = load(f"{trained.out}/best.pt")
    test = load_windows("stochastic", "hotel", "test")
    hotel = load_scene("hotel")
    tolerance_m = model.cfg.on_map_tolerance_m + 1e-3  # float32 outputs
    futures = model.predict(test.obs, test.group, hotel, 20).astype(np.float64)
    assert model.cfg.output_on_map and not onto_walkable(futures, hotel, tolerance_m)[1].any()
    model.cfg = replace(model.cfg, output_on_map=False)
    raw = model.predict(test.obs, test.group, hotel, 20).astype(np.float64)
    assert onto_walkable(raw, hotel, tolerance_m)[1].any()


@pytest.mark.parametrize("task", ["deterministic", "stochastic"])
def test_mirrored_paths_give_a_laterally_symmetric_space(task):
    """mirror_paths: the span of each Singular space is closed under y -> -y in the agent frame, and the single
    anchor of a one-sample task (the mean path) walks straight ahead."""
    from predictor.train import fit_model

    cfg = TrainConfig(task=task, scene="zara1", mirror_paths=True, progress=False)
    model = fit_model(cfg, load_windows(task, "zara1", "train").subset(np.arange(3000)))
    mirror = np.array([1.0, -1.0])
    paths = np.random.default_rng(0).normal(size=(50, 12, 2))
    for space in model.spaces:
        round_trip = space.reconstruct(space.project(paths * mirror))
        np.testing.assert_allclose(round_trip, space.reconstruct(space.project(paths)) * mirror, atol=1e-6)
    if task == "deterministic":
        for space, anchor in zip(model.spaces, model.anchors, strict=True):
            np.testing.assert_allclose(space.reconstruct(anchor)[..., 1], 0.0, atol=1e-9)


def test_averaged_weights_are_kept_and_a_stopped_run_continues_with_its_average(tmp_path, monkeypatch):
    """ema_decay > 0: best.pt holds the moving average of the weights (not the last ones), and a run killed during
    its second epoch and started again ends with the same checkpoint as one that ran through."""
    from predictor import train

    settings = {**SMALL, "ema_decay": 0.9}
    main(TrainConfig(task="stochastic", scene="zara1", out=str(tmp_path / "whole"), **settings))
    whole = read_checkpoint(tmp_path / "whole" / "last.pt")
    trained_w, average = whole["model"]["weights"], whole["average"]
    best = read_checkpoint(tmp_path / "whole" / "best.pt")["model"]["weights"]
    assert average and all(k in best for k in average)
    assert any(not torch.equal(best[k], trained_w[k]) for k in average), "best.pt holds the average"

    validate, calls = train.validate, []

    def killed_in_epoch_two(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return validate(*args, **kwargs)

    parts = TrainConfig(task="stochastic", scene="zara1", out=str(tmp_path / "parts"), **settings)
    monkeypatch.setattr(train, "validate", killed_in_epoch_two)
    with pytest.raises(KeyboardInterrupt):
        main(parts)
    monkeypatch.setattr(train, "validate", validate)
    main(parts)
    resumed = read_checkpoint(tmp_path / "parts" / "best.pt")["model"]["weights"]
    assert all(torch.equal(resumed[k], best[k]) for k in best), "resuming lost the average"


@pytest.fixture(scope="module")
def authors_run(tmp_path_factory) -> TrainConfig:
    """The authors' sampler (fixed noise) and step schedule on the small slice: 4 epochs in 2 stages, no warm-up."""
    cfg = TrainConfig(task="stochastic", scene="zara1", out=str(tmp_path_factory.mktemp("authors")),
                      **{**SMALL, "epochs": 4}, sampler="eps-linear", fixed_noise=True, lr_schedule="step",
                      lr_stages=2, warmup_epochs=0.0, seed=3)
    main(cfg)
    return cfg


def test_step_schedule_sets_each_epochs_rate(authors_run):
    history = read_checkpoint(f"{authors_run.out}/last.pt")["history"]
    assert [h["train/last_lr"] for h in history] == pytest.approx([1e-3, 1e-3, 5e-4, 5e-4])


def test_eps_linear_training_beats_constant_velocity_and_reloads_its_sampler(authors_run):
    model = load(f"{authors_run.out}/best.pt")
    assert model.cfg.sampler == model.refiner.cfg.sampler == "eps-linear"
    torch.testing.assert_close(model.refiner.alpha_bar, linear_alpha_bar(model.cfg.steps))
    test = load_windows("stochastic", "zara1", "test")
    scene = load_scene("zara1")
    ours, _ = ade_fde(model.predict(test.obs, test.group, scene, 20), test.fut)
    cvm, _ = ade_fde(ConstantVelocity().predict(test.obs, test.group, scene, 20), test.fut)
    assert ours.mean() < 0.8 * cvm.mean(), (ours.mean(), cvm.mean())


def test_a_loaded_checkpoint_samples_the_noise_its_validation_saw(authors_run):
    """The sampler's fixed noise is drawn from the run's seed (3 here) at training and after loading, so the
    loaded model reproduces the validation FDE that selected it."""
    from predictor.train import split_tensors, validate

    model = load(f"{authors_run.out}/best.pt")
    assert model.cfg.noise_seed == 3
    val = load_windows("stochastic", "zara1", "val")
    _, fde = validate(model, split_tensors(model, val, None), authors_run.batch_agents)
    assert fde == pytest.approx(read_checkpoint(f"{authors_run.out}/best.pt")["best"]["fde"], abs=1e-5)


@pytest.mark.parametrize("fixed_noise", [False, True])
def test_fixed_noise_trains_every_chain_from_the_samplers_draw(tmp_path, monkeypatch, fixed_noise):
    from predictor import train

    rollout, seeds = train.rollout, []

    def spy(model, t, idx, noise_seed, steps=None):
        seeds.append(noise_seed)
        return rollout(model, t, idx, noise_seed, steps)

    monkeypatch.setattr(train, "rollout", spy)
    main(TrainConfig(task="stochastic", scene="zara1", out=str(tmp_path), **{**SMALL, "epochs": 1},
                     fixed_noise=fixed_noise))
    training = seeds[:-len(window_batches(torch.from_numpy(load_windows("stochastic", "zara1", "val").group),
                                          SMALL["batch_agents"], None))]  # validation's calls come last
    assert training and all((seed is None) == fixed_noise for seed in training)


def test_checkpoints_without_a_sampler_field_load_with_the_x0_cosine_sampler(trained):
    """Checkpoints written before the sampler option was added keep the sampler they were trained with."""
    state = read_checkpoint(f"{trained.out}/best.pt")["model"]
    older = {**state, "config": {k: v for k, v in state["config"].items() if k != "sampler"}}
    assert "sampler" in state["config"] and model_from_state(older).refiner.cfg.sampler == "x0-cosine"


def test_authors_step_schedule_halves_every_64_of_256_epochs():
    cfg = TrainConfig(lr_schedule="step", warmup_epochs=0.0)
    rates = {epoch: lr_factor(epoch * 50 + 49, cfg, 50, 256) for epoch in (0, 63, 64, 127, 128, 191, 192, 255)}
    assert rates == {0: 1.0, 63: 1.0, 64: 0.5, 127: 0.5, 128: 0.25, 191: 0.25, 192: 0.125, 255: 0.125}


@settings(max_examples=60, deadline=None)
@given(per_epoch=st.integers(1, 40), epochs=st.integers(1, 60), stages=st.integers(1, 8),
       gamma=st.floats(0.1, 0.9), warmup=st.floats(0.0, 3.0))
def test_step_schedule_is_piecewise_constant_per_epoch_and_falls_by_gamma(per_epoch, epochs, stages, gamma, warmup):
    """The warm-up starts at 1 / its steps; after it the rate is constant within an epoch, never rises, and every
    value is gamma to a power; without a warm-up it takes one value per stage (one per epoch when there are fewer
    epochs than stages) and ends at gamma^(stages - 1)."""
    cfg = TrainConfig(lr_schedule="step", lr_stages=stages, lr_gamma=gamma, warmup_epochs=warmup)
    warmup_steps = max(1, int(warmup * per_epoch))
    assume(warmup_steps < epochs * per_epoch)
    rates = np.array([lr_factor(i, cfg, per_epoch, epochs) for i in range(epochs * per_epoch)])
    assert rates[0] == pytest.approx(1 / warmup_steps)
    after = rates.reshape(epochs, per_epoch)[math.ceil(warmup_steps / per_epoch):]
    assert np.all(after == after[:, :1]) and np.all(np.diff(after[:, 0]) <= 0)
    powers = np.log(np.unique(after[:, 0])) / math.log(gamma)
    np.testing.assert_allclose(powers, np.round(powers), atol=1e-9)
    cold = replace(cfg, warmup_epochs=0.0)
    full = np.array([lr_factor(e * per_epoch, cold, per_epoch, epochs) for e in range(epochs)])
    assert len(np.unique(full)) == min(stages, epochs) and full[0] == 1
    if stages <= epochs:
        assert full[-1] == pytest.approx(gamma ** (stages - 1))


def test_cosine_schedule_warms_up_then_falls_to_zero():
    cfg = TrainConfig(warmup_epochs=1.0)
    rates = np.array([lr_factor(i, cfg, 10, 6) for i in range(60)])
    np.testing.assert_allclose(rates[:10], np.arange(1, 11) / 10)
    assert np.all(np.diff(rates[10:]) < 0) and rates[-1] < 0.01


@pytest.mark.parametrize("task", list(TASKS))
def test_epochs_default_to_16_with_several_samples_and_6_with_one(task):
    cfg = TrainConfig(task=task, scene="A2B" if task.startswith("domain") else "zara1")
    assert cfg.epochs is None and with_task_defaults(cfg).epochs == (6 if TASKS[task]["num_samples"] == 1 else 16)
    assert with_task_defaults(replace(cfg, epochs=3)).epochs == 3


@pytest.mark.parametrize(("tolerance_m", "chosen"), [(None, 2), (0.0, 1)], ids=["default-2mm", "none"])
def test_a_later_epoch_wins_a_near_tie_on_validation_fde(tmp_path, monkeypatch, tolerance_m, chosen):
    """docs/training.md: the checkpoint is chosen on validation FDE, and a later epoch wins a near-tie (within
    ``select_tolerance_m``, 2 mm), so float differences between machines do not flip the choice. The validation
    FDEs are scripted: 0.500, 0.5015 (1.5 mm worse: a near-tie), 0.510 m."""
    from predictor import train

    scripted = iter([0.500, 0.5015, 0.510])
    monkeypatch.setattr(train, "validate", lambda *args, **kwargs: (0.25, next(scripted)))
    settings = {**SMALL, "epochs": 3} | ({} if tolerance_m is None else {"select_tolerance_m": tolerance_m})
    cfg = TrainConfig(task="stochastic", scene="zara1", out=str(tmp_path / "run"), **settings)
    assert cfg.select_tolerance_m == (0.002 if tolerance_m is None else tolerance_m)
    main(cfg)
    summary = json.loads((tmp_path / "run" / "train.json").read_text())
    assert summary["best"]["epoch"] == chosen, summary["best"]
    assert read_checkpoint(tmp_path / "run" / "best.pt")["best"]["epoch"] == chosen
