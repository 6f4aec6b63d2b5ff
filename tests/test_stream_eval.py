"""Evaluation through the spectator environment equals the offline windowed evaluation."""

from __future__ import annotations

import pytest

import predictor
from predictor.baselines import ConstantVelocity, ConstantVelocitySampler
from st_sim.apps.evaluate import evaluate_scene
from st_sim.apps.stream_eval import evaluate_stream

CASES = {
    "cvm-s/stochastic/hotel": (ConstantVelocitySampler(sigma_rad=0.3), "stochastic", "hotel"),
    "cvm/momentary/zara1": (ConstantVelocity(), "momentary", "zara1"),
    "cvm/deterministic/univ (two recordings)": (ConstantVelocity(), "deterministic", "univ"),
}


@pytest.mark.parametrize("case", list(CASES), ids=list(CASES))
def test_stream_equals_offline_for_baselines(case):
    model, task, scene = CASES[case]
    offline = evaluate_scene(model, task, scene)
    streamed = evaluate_stream(model, task, scene)
    assert streamed["samples"] == offline.samples
    assert streamed["ade"] == pytest.approx(offline.ade, abs=1e-6)
    assert streamed["fde"] == pytest.approx(offline.fde, abs=1e-6)


def test_stream_equals_offline_for_singular_trajectory():
    result = evaluate_scene(predictor.load_pretrained("stochastic/eth"), "stochastic", "eth", stream=True)
    assert result.stream_samples == result.samples == 181
    assert result.stream_ade == pytest.approx(result.ade, abs=1e-6)
    assert result.stream_fde == pytest.approx(result.fde, abs=1e-6)


def test_benchmark_windows_mode_is_spectator_only():
    import gymnasium as gym

    import envs  # noqa: F401

    with pytest.raises(ValueError, match="ego=False"):
        gym.make("STCrowd-Eth-v0", benchmark_windows=True)
