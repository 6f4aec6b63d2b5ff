"""The diffusion refiner: DDIM sampling matches its textbook form; widths and shapes; S = 1 defaults; forecasts of
some agents conditioned on all; anchor coefficients from their end points."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from predictor import load_pretrained
from predictor import model as predictor_model
from predictor.anchors import adaptive_anchors, anchor_paths, onto_walkable
from predictor.baselines import ConstantVelocity
from predictor.model import SINGLE_SAMPLE_STAND_SPEED_M
from predictor.normalize import agent_frames
from predictor.refiner import LINEAR_BETAS, SAMPLERS, Refiner, RefinerConfig, linear_alpha_bar
from predictor.singular_space import T_WIN
from predictor.train import (
    DETERMINISTIC_STATIC_M,
    SINGLE_SAMPLE_SCALE_FLOOR_M,
    SINGLE_SAMPLE_SLOW_SPEED_M,
    TrainConfig,
    TrainingError,
    fit_model,
)
from replays import load_scene, load_windows
from replays.constants import TASKS


def reference_ddim(refiner: Refiner, anchors: torch.Tensor, ctx: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
    """Deterministic DDIM written out step by step: x0 from the network, eps from x0, then the next x."""
    x = noise
    steps = refiner.cfg.steps
    for m, m_next in itertools.pairwise(range(steps, -1, -1)):
        a, a_next = refiner.alpha_bar[m], refiner.alpha_bar[m_next]
        x0 = refiner.predict_x0(x, torch.full((len(x),), m), anchors, ctx)
        eps = (x - a.sqrt() * x0) / (1 - a).sqrt()
        x = a_next.sqrt() * x0 + (1 - a_next).sqrt() * eps if m_next > 0 else x0
    return x


@settings(max_examples=25, deadline=None)
@given(windows=st.lists(st.integers(0, 6), min_size=1, max_size=40), seed=st.integers(0, 2**31 - 1),
       train=st.booleans())
def test_context_attends_within_each_window_only(windows: list[int], seed: int, train: bool) -> None:
    """The padded per-window attention equals attention over all agents with the other windows masked out, for
    window ids in any order and of any sizes (one agent, one window, ids with gaps), in training and eval mode."""
    torch.manual_seed(seed)
    cfg = RefinerConfig(history_dim=6, num_samples=3, k=4, dim=16, denoiser_dim=16, heads=2, steps=4)
    refiner = Refiner(cfg).train(train)
    group = torch.tensor(windows) * 3  # gaps between the ids
    history, anchors = torch.randn(len(group), 6), torch.randn(len(group), 3, 4)
    tokens = refiner.encode_history(torch.cat([history, anchors.flatten(1)], dim=1))
    masked = refiner.interact(tokens[None], mask=group[:, None] != group[None, :])[0]
    torch.testing.assert_close(refiner.context(history, anchors, group), masked, rtol=0, atol=1e-5)


@settings(max_examples=25, deadline=None)
@given(windows=st.lists(st.integers(0, 6), min_size=1, max_size=40), seed=st.integers(0, 2**31 - 1),
       layers=st.integers(1, 2), share=st.floats(0.0, 1.0))
def test_the_context_of_some_agents_is_theirs_in_the_context_of_all(windows: list[int], seed: int, layers: int,
                                                                     share: float) -> None:
    """``targets``: the last layer runs for the targets alone (the others lend keys and values), and gives them the
    context they get when every agent's is computed; any share of targets, windows without one."""
    torch.manual_seed(seed)
    cfg = RefinerConfig(history_dim=6, num_samples=3, k=4, dim=16, denoiser_dim=16, heads=2, layers=layers, steps=4)
    refiner = Refiner(cfg).eval()
    group = torch.tensor(windows) * 3
    history, anchors = torch.randn(len(group), 6), torch.randn(len(group), 3, 4)
    targets = torch.rand(len(group), generator=torch.Generator().manual_seed(seed)) < share
    every = refiner.context(history, anchors, group)
    torch.testing.assert_close(refiner.context(history, anchors, group, targets), every[targets], rtol=0, atol=1e-5)


@pytest.mark.parametrize("denoiser_dim, sampler", [(32, "x0-cosine"), (64, "x0-cosine"), (32, "eps-linear")])
def test_sampler_matches_textbook_ddim(denoiser_dim: int, sampler: str) -> None:
    torch.manual_seed(0)
    cfg = RefinerConfig(history_dim=10, num_samples=5, k=4, dim=32, denoiser_dim=denoiser_dim, heads=2, steps=6,
                        zero_start=False, sampler=sampler)
    refiner = Refiner(cfg).eval()
    history, anchors = torch.randn(7, 10), torch.randn(7, 5, 4)
    group = torch.tensor([0, 0, 0, 1, 1, 2, 2])
    noise = torch.randn(7, 5, 4)
    with torch.no_grad():
        ctx = refiner.context(history, anchors, group)
        fast = refiner.sample(anchors, ctx, noise)
        slow = reference_ddim(refiner, anchors, ctx, noise)
    assert fast.shape == (7, 5, 4)
    torch.testing.assert_close(fast, slow, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("steps", [1, 10, 37])
def test_linear_schedule_has_the_authors_betas(steps: int) -> None:
    alpha_bar = linear_alpha_bar(steps).double()
    betas = 1 - alpha_bar[1:] / alpha_bar[:-1]  # beta_m = 1 - alpha_bar_m / alpha_bar_(m-1)
    assert alpha_bar[0] == 1 and len(alpha_bar) == steps + 1
    expected = np.linspace(*LINEAR_BETAS, steps) if steps > 1 else [LINEAR_BETAS[0]]
    np.testing.assert_allclose(betas.numpy(), expected, rtol=1e-4, atol=1e-7)
    if steps == 10:  # the authors' M: x_M keeps most of the signal
        assert 0.77 < float(alpha_bar[-1]) < 0.79


def untrained(sampler: str) -> tuple[Refiner, torch.Tensor, torch.Tensor]:
    """A zero-start refiner of ``sampler`` with the context of 6 agents in two windows."""
    torch.manual_seed(1)
    refiner = Refiner(RefinerConfig(history_dim=6, num_samples=3, k=4, dim=16, denoiser_dim=16, heads=2,
                                    sampler=sampler)).eval()
    anchors = torch.randn(6, 3, 4)
    with torch.no_grad():
        ctx = refiner.context(torch.randn(6, 6), anchors, torch.tensor([0, 0, 0, 1, 1, 1]))
    return refiner, anchors, ctx


def test_untrained_eps_refiner_rescales_its_starting_noise_and_the_x0_one_returns_zero() -> None:
    """Zero output means epsilon = 0 for "eps-linear": every DDIM step only rescales x, so the chain ends at
    x_M / sqrt(alpha_bar_M); for "x0-cosine" it means x0 = 0."""
    noise = torch.randn(6, 3, 4)
    for sampler in SAMPLERS:
        refiner, anchors, ctx = untrained(sampler)
        with torch.no_grad():
            out = refiner.sample(anchors, ctx, noise)
        expected = noise / refiner.alpha_bar[-1].sqrt() if sampler == "eps-linear" else torch.zeros_like(noise)
        torch.testing.assert_close(out, expected, rtol=1e-5, atol=1e-6)


def test_eps_loss_of_an_untrained_eps_refiner_is_the_noise_power() -> None:
    """Zero epsilon predicted against the drawn noise: the loss is the mean square of that noise (the x0 sampler's
    loss also depends on the clean residual)."""
    x0 = torch.randn(6, 3, 4) * 3
    losses = {}
    for sampler in SAMPLERS:
        refiner, anchors, ctx = untrained(sampler)
        with torch.no_grad():
            losses[sampler] = refiner.eps_loss(x0, anchors, ctx, torch.Generator().manual_seed(5)).item()
    draws = torch.Generator().manual_seed(5)
    torch.randint(1, 11, (6,), generator=draws)  # the steps, drawn first
    noise_power = float(torch.randn(x0.shape, generator=draws).pow(2).mean())
    assert losses["eps-linear"] == pytest.approx(noise_power, rel=1e-6)
    assert abs(losses["x0-cosine"] - noise_power) > 0.1


def test_unknown_sampler_is_refused_naming_the_field() -> None:
    with pytest.raises(ValueError, match=r"RefinerConfig.sampler='ddpm'.*x0-cosine, eps-linear"):
        Refiner(RefinerConfig(history_dim=6, sampler="ddpm"))


def test_denoiser_width_sets_the_mlp_not_the_context() -> None:
    narrow = Refiner(RefinerConfig(history_dim=10, dim=64, denoiser_dim=32, heads=2))
    assert narrow.denoise[-1].in_features == 32 and narrow.interact.layers[0].linear1.in_features == 64


@pytest.mark.parametrize("task, scene, expected_m, floor_m", [
    ("deterministic", "zara1", DETERMINISTIC_STATIC_M["zara1"], 0.0),
    ("deterministic", "univ", DETERMINISTIC_STATIC_M["univ"], 0.0),
    ("domain", "A2B", SINGLE_SAMPLE_SLOW_SPEED_M, SINGLE_SAMPLE_SCALE_FLOOR_M),
    ("stochastic", "zara1", 0.3, 0.0)])
def test_single_sample_models_default_to_a_lower_slow_threshold(task: str, scene: str, expected_m: float,
                                                                floor_m: float) -> None:
    train = load_windows(task, scene, "train")
    train = train.subset(train.group < 100)
    model = fit_model(TrainConfig(task=task, scene=scene, dim=32), train)
    assert model.cfg.slow_speed_m == expected_m and model.cfg.slow_scale_floor_m == floor_m
    assert fit_model(TrainConfig(task=task, scene=scene, dim=32, slow_speed_m=0.2), train).cfg.slow_speed_m == 0.2


def test_a_population_too_small_to_fit_is_named() -> None:
    train = load_windows("deterministic", "zara1", "train")
    walking = np.linalg.norm(train.obs[:, -1] - train.obs[:, -3], axis=-1) > 0.1  # nobody without a heading
    with pytest.raises(TrainingError, match=r"only 0 training agents are slower than slow_speed_m=0.0"):
        fit_model(TrainConfig(task="deterministic", dim=32, slow_speed_m=0.0), train.subset(walking))


def test_untrained_refiner_returns_the_adapted_anchors() -> None:
    train = load_windows("stochastic", "zara1", "train")
    model = fit_model(TrainConfig(dim=32), train.subset(train.group < 100))
    test = load_windows("stochastic", "zara1", "test")
    keep = test.group < 20
    zara1 = load_scene("zara1")
    detail = model.predict_detailed(test.obs[keep], test.group[keep], zara1, 20)
    bent = np.abs(detail.adapted_anchors - detail.prototype_anchors).max(axis=(2, 3)) > 1e-6  # (N, S)
    assert 0 < bent.mean() < 0.5
    # then points deeper than the tolerance in a wall move onto the map (output_on_map)
    anchors_on_map, _ = onto_walkable(detail.adapted_anchors.astype(np.float64), zara1, model.cfg.on_map_tolerance_m)
    np.testing.assert_allclose(detail.futures[~bent], anchors_on_map[~bent], atol=1e-4)
    # a bent anchor is re-projected onto the K = 4 basis, which keeps it up to a small shape error
    assert np.abs(detail.futures[bent] - anchors_on_map[bent]).max() < 0.5
    assert not np.allclose(detail.futures[:, 0], detail.futures[:, 1])  # the 20 anchors differ


@pytest.mark.parametrize("task", ["deterministic", "stochastic"])
def test_only_single_sample_models_keep_standing_agents_at_constant_velocity(task: str) -> None:
    train = load_windows(task, "zara1", "train")
    model = fit_model(TrainConfig(task=task, dim=32), train.subset(train.group < 100))
    test = load_windows(task, "zara1", "test")
    test = test.subset(test.group < 300)
    standing = np.linalg.norm(test.obs[:, -1] - test.obs[:, -2], axis=-1) < SINGLE_SAMPLE_STAND_SPEED_M
    assert standing.any() and (~standing).any()
    samples = TASKS[task]["num_samples"]
    pred = model.predict(test.obs, test.group, load_scene("zara1"), samples)
    as_cvm = np.isclose(pred, ConstantVelocity().predict(test.obs, test.group, None, samples), atol=1e-5)
    as_cvm = as_cvm.all(axis=(1, 2, 3))  # (N,)
    assert as_cvm[standing].all() == (samples == 1)
    assert not as_cvm[~standing].any()


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), share=st.floats(0.0, 1.0),
       chunk=st.sampled_from([predictor_model.BATCH_AGENTS, 100]))
def test_forecasting_some_agents_gives_them_the_futures_of_forecasting_all(seed: int, share: float,
                                                                           chunk: int) -> None:
    """``targets``: the other agents only condition the forecast, and the targets' futures and anchors are those of a
    call that forecasts everyone (also when the interaction layer runs in chunks of whole windows)."""
    model = load_pretrained("stochastic/univ")
    test = load_windows("stochastic", "univ", "test")
    test = test.subset(test.group < 12)  # about 500 agents: several chunks of 100
    targets = np.random.default_rng(seed).random(len(test.obs)) < share
    univ = load_scene("univ")
    every = model.predict_detailed(test.obs, test.group, univ, 20)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(predictor_model, "BATCH_AGENTS", chunk)
        some = model.predict_detailed(test.obs, test.group, univ, 20, targets=targets)
    for name in ("futures", "prototype_anchors", "adapted_anchors"):
        np.testing.assert_allclose(getattr(some, name), getattr(every, name)[targets], rtol=0, atol=1e-4, err_msg=name)
    assert model.predict_detailed(test.obs, test.group, univ, 20, targets=targets, anchors=False).adapted_anchors \
        is None


@pytest.mark.parametrize("scene", ["eth", "univ", "zara1"])
def test_ramp_adapted_anchor_coefficients_are_those_of_the_bent_paths(scene: str) -> None:
    """The coefficients that ``adaptive_anchors`` derives from the end points alone equal the Singular-space projection
    of the whole bent paths (``anchor_paths``), bent or not."""
    model = load_pretrained(f"stochastic/{scene}")
    test = load_windows("stochastic", scene, "test")
    frames = agent_frames(test.obs, model.cfg.scale_by_speed, model.cfg.slow_speed_m)
    population = frames.slow.astype(np.int64)
    where = load_scene(scene)
    coefs = adaptive_anchors(model.anchors, frames, model.spaces, population, where)
    _, bent_m = anchor_paths(model.anchors, frames, model.spaces, population, where)
    local = frames.to_agent(bent_m)
    for p, space in enumerate(model.spaces):
        mask = population == p
        projected = space.project(local[mask].reshape(-1, T_WIN, 2)).reshape(coefs[mask].shape)
        np.testing.assert_allclose(coefs[mask], projected, rtol=0, atol=1e-9)
    assert (np.abs(coefs - model.anchors[population]).max(axis=2) > 1e-6).any(), "some anchors are bent"


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), moments=st.integers(2, 8))
def test_moments_of_several_scenes_in_one_call_get_their_own_scenes_forecasts(seed: int, moments: int) -> None:
    """``scene`` as one scene per group value: each moment is forecast on its own map, as a call for that scene alone
    forecasts it (futures and anchors; a larger torch batch rounds otherwise in the last bits); a predictor without
    ``predict_detailed`` gets one call per scene through ``predict_futures``, to the bit."""
    from envs.common.predictors import predict_futures

    model = load_pretrained("universal")
    scenes = {name: load_scene(name) for name in ("eth", "zara1")}
    rng = np.random.default_rng(seed)
    windows = {name: load_windows("stochastic", name, "test") for name in scenes}
    picks = [(str(rng.choice(list(scenes))), int(rng.integers(0, 40))) for _ in range(moments)]
    parts = [windows[name].subset(windows[name].group == g) for name, g in picks]
    obs = np.concatenate([part.obs for part in parts])
    group = np.repeat(np.arange(moments), [len(part.obs) for part in parts])
    targets = rng.random(len(obs)) < 0.7
    joint = model.predict_detailed(obs, group, [scenes[name] for name, _ in picks], 20, targets=targets)
    cuts = np.cumsum([int(targets[group == k].sum()) for k in range(moments)])[:-1]
    for k, (name, _) in enumerate(picks):
        alone = model.predict_detailed(parts[k].obs, np.zeros(len(parts[k].obs), np.int64), scenes[name], 20,
                                       targets=targets[group == k])
        for field in ("futures", "prototype_anchors", "adapted_anchors"):
            np.testing.assert_allclose(np.split(getattr(joint, field), cuts)[k], getattr(alone, field), rtol=0,
                                       atol=1e-4, err_msg=f"moment {k} ({name}): {field}")
    cvm = ConstantVelocity()
    futures, _ = predict_futures(cvm, obs, [scenes[name] for name, _ in picks], 20, group, targets)
    np.testing.assert_array_equal(futures, cvm.predict(obs, group, None, 20)[targets])
    with pytest.raises(ValueError, match="one scene per group value"):
        model.predict_detailed(obs, group, [scenes["eth"]], 20)
