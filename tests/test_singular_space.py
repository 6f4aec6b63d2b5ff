from __future__ import annotations

import itertools

import numpy as np
import pytest

from predictor.bspline import resampling_matrix
from predictor.normalize import SLOW_SPEED_M, agent_frames
from predictor.singular_space import fit_singular_space
from replays import load_windows


@pytest.fixture(scope="module")
def futures_local():
    w = load_windows("stochastic", "zara1", "train")
    frames = agent_frames(w.obs)
    return frames.to_agent(w.fut.astype(np.float64))[~frames.slow]


def test_reconstruction_error_falls_as_k_grows(futures_local):
    errors = []
    for k in (1, 2, 4, 6):
        space = fit_singular_space(futures_local, k)
        errors.append(np.abs(space.reconstruct(space.project(futures_local)) - futures_local).mean())
    assert all(a > b for a, b in itertools.pairwise(errors)), errors
    full = fit_singular_space(futures_local, 24)
    np.testing.assert_allclose(full.reconstruct(full.project(futures_local)), futures_local, atol=1e-9)


def test_basis_is_orthonormal_and_projection_round_trips(futures_local):
    space = fit_singular_space(futures_local, 4)
    np.testing.assert_allclose(space.basis.T @ space.basis, np.eye(4), atol=1e-10)
    coefs = np.random.default_rng(0).normal(size=(10, 4))
    np.testing.assert_allclose(space.project(space.reconstruct(coefs)), coefs, atol=1e-10)
    for steps in (2, 8):  # same coefficients survive a trip through another length
        np.testing.assert_allclose(space.project(space.reconstruct(coefs, steps)), coefs, atol=1e-8)


@pytest.mark.parametrize("steps", [2, 5, 8, 12, 20])
def test_length_adapter_maps_a_curve_to_the_same_curve(steps):
    t12, tt = np.linspace(0, 1, 12), np.linspace(0, 1, steps)
    quadratic = np.stack([3 * t12, 2 * t12**2 - t12], axis=1)  # a degree-2 spline reproduces it exactly
    np.testing.assert_allclose(resampling_matrix(steps) @ quadratic, np.stack([3 * tt, 2 * tt**2 - tt], axis=1),
                               atol=1e-9)
    smooth = np.stack([np.sin(2 * t12), np.cos(3 * t12)], axis=1)
    np.testing.assert_allclose(resampling_matrix(steps) @ smooth, np.stack([np.sin(2 * tt), np.cos(3 * tt)], 1),
                               atol=0.02)


def test_length_adapter_is_identity_at_twelve_steps():
    np.testing.assert_array_equal(resampling_matrix(12), np.eye(12))


def test_agent_frame_round_trip_and_heading():
    obs = np.cumsum(np.tile([[0.0, 0.5]], (8, 1)), axis=0)[None] + [2.0, 3.0]  # walking +y at 0.5 m/step
    frames = agent_frames(obs)
    local = frames.to_agent(obs)
    np.testing.assert_allclose(local[0, -1], [0, 0], atol=1e-12)
    np.testing.assert_allclose(local[0, -2], [-1, 0], atol=1e-12)  # one step back along -x, in speed units
    np.testing.assert_allclose(frames.to_world(local), obs, atol=1e-12)


def test_slow_agents_are_never_scaled():
    still = np.zeros((1, 8, 2)) + np.linspace(0, 0.1, 8)[None, :, None]  # about 0.02 m per step
    frames = agent_frames(still)
    assert frames.slow[0] and frames.scale_m[0] == 1.0
    assert pytest.approx(0.3) == SLOW_SPEED_M
