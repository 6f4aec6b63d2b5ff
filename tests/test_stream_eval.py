"""Evaluation through the spectator environment equals the offline windowed evaluation."""

from __future__ import annotations

import numpy as np
import pytest

import predictor
from predictor.baselines import ConstantVelocity, ConstantVelocitySampler
from st_sim.apps.evaluate import StreamMismatchError, evaluate_scene
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


class BatchDependent:
    """Constant velocity moved by 1 mm per agent in the call: an agent's futures depend on who else is asked."""

    def predict(self, obs, group, scene, num_samples):
        futures = ConstantVelocity().predict(obs, group, scene, num_samples)
        return futures + np.float32(1e-3 * len(obs))


def test_a_predictor_whose_futures_depend_on_the_batch_is_refused():
    """docs/prediction-tasks.md: every row is scored offline and through the spectator env, and the two must agree;
    docs/plugins.md: an agent must get the same futures whether ``predict`` sees all windows or one scene moment."""
    with pytest.raises(StreamMismatchError, match=r"eth.*same futures"):
        evaluate_scene(BatchDependent(), "deterministic", "eth", stream=True)
    result = evaluate_scene(ConstantVelocity(), "deterministic", "eth", stream=True)
    assert result.stream_samples == result.samples == 181, "an agreeing predictor passes the same check"
