"""The crowd's CPU-independent arithmetic (``st_sim.sim.exact``): within 1 ulp of libm, the special values right."""

from __future__ import annotations

import math

import numpy as np
import pytest

from st_sim.sim import exact


def _ulps(value: np.ndarray, reference: np.ndarray) -> np.ndarray:
    return np.abs(value - reference) / np.spacing(np.abs(reference))


def test_exp_is_within_one_ulp_of_libm():
    x = np.concatenate([np.random.default_rng(0).uniform(-745.0, 709.0, 20_000),
                        np.random.default_rng(1).uniform(-30.0, 5.0, 20_000), np.linspace(-1e-6, 1e-6, 101)])
    assert _ulps(exact.exp(x), np.array([math.exp(v) for v in x.tolist()])).max() <= 1.0


def test_exp_of_special_values():
    x = np.array([-np.inf, np.inf, np.nan, 0.0, -0.0, 709.7, 709.8, 1e4, -745.2, -1e4])
    assert np.array_equal(exact.exp(x), [0.0, np.inf, np.nan, 1.0, 1.0, math.exp(709.7), np.inf, np.inf, 0.0, 0.0],
                          equal_nan=True)
    assert exact.exp(-746.0 + 1.0) > 0.0  # subnormal, not flushed


def test_cos_sin_are_within_one_ulp_of_libm():
    rng = np.random.default_rng(2)
    angle = np.concatenate([rng.uniform(0.0, 2 * np.pi, 20_000), rng.uniform(-1e5, 1e5, 5_000),
                            np.array([0.0, 0.45, -0.9, np.pi / 2, np.pi, 1e-300])])
    cos, sin = exact.cos_sin(angle)
    assert _ulps(cos, np.array([math.cos(v) for v in angle.tolist()])).max() <= 1.0
    assert _ulps(sin, np.array([math.sin(v) for v in angle.tolist()])).max() <= 1.0


@pytest.mark.parametrize("angle", [np.inf, np.nan, 2.0 ** 19])
def test_cos_sin_refuse_angles_they_cannot_reduce(angle):
    with pytest.raises(ValueError, match="cos_sin"):
        exact.cos_sin(np.array([0.0, angle]))


def test_sums_and_lengths_are_written_out():
    v = np.random.default_rng(3).normal(size=(50, 7, 2))
    assert np.array_equal(exact.length(v), np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1]))
    assert np.array_equal(exact.total(v, axis=1), sum((v[:, k] for k in range(1, 7)), v[:, 0]))
