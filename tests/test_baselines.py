from __future__ import annotations

import numpy as np
import pytest

from predictor.baselines import ConstantVelocity, ConstantVelocitySampler, LinearFit
from st_sim.metrics import ade_fde


def straight_lines(n: int = 5, t_obs: int = 8):
    rng = np.random.default_rng(1)
    start, velocity = rng.normal(size=(n, 1, 2)), rng.normal(size=(n, 1, 2))
    steps = np.arange(t_obs + 12)[None, :, None]
    paths = (start + steps * velocity).astype(np.float32)
    return paths[:, :t_obs], paths[:, t_obs:]


@pytest.mark.parametrize("predictor", [ConstantVelocity(), LinearFit(), ConstantVelocitySampler(sigma_rad=0.0)],
                         ids=["cvm", "linear", "cvm-s-sigma0"])
def test_baselines_are_exact_on_straight_lines(predictor):
    obs, fut = straight_lines()
    pred = predictor.predict(obs, np.zeros(len(obs)), None, 3)
    assert pred.shape == (5, 3, 12, 2) and pred.dtype == np.float32
    np.testing.assert_allclose(pred, np.repeat(fut[:, None], 3, axis=1), atol=1e-4)


def test_cvm_s_is_seeded_and_spreads_samples():
    obs, _ = straight_lines()
    sampler = ConstantVelocitySampler(sigma_rad=0.3, seed=7)
    a, b = sampler.predict(obs, np.zeros(5), None, 20), sampler.predict(obs, np.zeros(5), None, 20)
    np.testing.assert_array_equal(a, b)
    assert np.ptp(a[:, :, -1], axis=1).max() > 0.1
    speeds = np.linalg.norm(np.diff(a, axis=2), axis=-1)
    np.testing.assert_allclose(speeds, speeds[..., :1].repeat(11, -1), rtol=1e-4)  # speed kept, heading changed


def test_cvm_s_fit_sigma_prefers_zero_on_straight_lines_and_more_on_turns():
    obs, fut = straight_lines(50)
    assert ConstantVelocitySampler().fit_sigma(obs, fut) == 0.0
    turned = obs[:, -1:] + (fut - obs[:, -1:]) @ np.array([[0.0, 1.0], [-1.0, 0.0]], np.float32)  # 90 degree turn
    assert ConstantVelocitySampler().fit_sigma(obs, turned) > 0.3


def test_linear_fit_averages_noise_better_than_cvm():
    obs, fut = straight_lines(200)
    noisy = obs + np.random.default_rng(0).normal(0, 0.05, obs.shape).astype(np.float32)
    cvm_ade, _ = ade_fde(ConstantVelocity().predict(noisy, np.zeros(200), None, 1), fut)
    lin_ade, _ = ade_fde(LinearFit().predict(noisy, np.zeros(200), None, 1), fut)
    assert lin_ade.mean() < cvm_ade.mean()


@pytest.mark.parametrize("obs, message", [
    (np.zeros((3, 1, 2)), "T_obs >= 2"), (np.zeros((3, 8)), "obs must be"),
    (np.full((3, 8, 2), np.nan), "NaN"),
])
def test_baselines_reject_bad_input(obs, message):
    with pytest.raises(ValueError, match=message):
        ConstantVelocity().predict(obs, np.zeros(len(obs)), None, 1)
