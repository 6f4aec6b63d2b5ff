"""The crowd's CPU-independent arithmetic (``st_sim.sim.exact``): within 1 ulp of libm, the special values right;
lengths and sums against exact rational arithmetic, Poisson draws against numpy's sampler."""

from __future__ import annotations

import math
from decimal import Decimal, localcontext
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

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


def _true_length(x: float, y: float) -> float:
    """The Euclidean length of (x, y): the exact square sum (fractions), its root to 60 digits, rounded to a float."""
    square = Fraction(x) ** 2 + Fraction(y) ** 2
    with localcontext() as context:
        context.prec = 60
        return float((Decimal(square.numerator) / Decimal(square.denominator)).sqrt())


def test_lengths_are_within_one_ulp_of_the_true_length_and_round_as_numpys_norm():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(5_000, 2)) * 10.0 ** rng.integers(-6, 6, (5_000, 1))
    reference = np.array([_true_length(x, y) for x, y in v.tolist()])
    assert _ulps(exact.length(v), reference).max() <= 1.0
    assert np.array_equal(exact.length(v), np.linalg.norm(v, axis=-1))  # as its docstring says
    assert exact.length(np.zeros(2)) == 0.0


def _added_in_order(values: list[float]) -> float:
    """The sum of ``values`` rounded after each addition, first to last (exact fractions, each sum rounded once)."""
    out = 0.0
    for value in values:
        out = float(Fraction(out) + Fraction(value))
    return out


def test_sums_add_in_index_order():
    v = np.random.default_rng(3).normal(size=(20, 9, 3)) * 10.0 ** np.arange(-4, 5)[:, None]
    sums = exact.total(v, axis=1)
    for i in range(20):
        for j in range(3):
            assert sums[i, j] == _added_in_order(v[i, :, j].tolist()), f"[{i}, {j}]"
    tiny = [1.0] + [2.0 ** -53] * 8  # in index order each tiny term rounds away; the exact sum keeps them
    assert exact.total(np.array(tiny), axis=0) == 1.0 != math.fsum(tiny)
    assert exact.total(np.array(tiny[::-1]), axis=0) == math.fsum(tiny)


@pytest.mark.parametrize("mean", [0.02, 0.2, 1.0, 4.0, 9.5])
def test_poisson_draws_are_numpys_below_a_mean_of_ten(mean):
    for seed in range(40):
        ours, numpys = np.random.default_rng(seed), np.random.default_rng(seed)
        assert np.array_equal(exact.poisson_draws(ours, mean, 6), numpys.poisson(mean, 6)), f"[seed {seed}]"
        assert ours.random() == numpys.random(), f"[seed {seed}] another number of uniform draws"


def test_poisson_draws_beyond_ten_have_their_mean_and_variance():
    draws = exact.poisson_draws(np.random.default_rng(4), 15.0, 20_000)
    assert abs(draws.mean() - 15.0) < 0.15 and abs(draws.var() - 15.0) < 0.6


def test_poisson_draws_of_a_zero_mean_draw_nothing():
    rng = np.random.default_rng(5)
    assert np.array_equal(exact.poisson_draws(rng, 0.0, 3), [0, 0, 0])
    assert rng.random() == np.random.default_rng(5).random()


def _true_cos_sin(angle: float, digits: int = 90) -> tuple[Decimal, Decimal]:
    """cos and sin of a float's exact value to ``digits`` digits (Taylor series, no reduction: |angle| <= 8)."""
    with localcontext(prec=digits):
        x, term, k, sums = Decimal(angle), Decimal(1), 0, [Decimal(0)] * 4
        while k < 8 or abs(term) > Decimal(10) ** -(digits - 2):
            sums[k % 4] += term
            k += 1
            term = term * x / k
        return sums[0] - sums[2], sums[1] - sums[3]


def _nearest(value: float, true: Decimal) -> bool:
    """Whether ``value`` is a float nearest to ``true``: no neighbour is closer."""
    with localcontext(prec=90):
        error = abs(Decimal(value) - true)
        return all(error <= abs(Decimal(float(np.nextafter(value, side))) - true) for side in (-np.inf, np.inf))


@settings(max_examples=200, deadline=None)
@given(angle=st.floats(-exact.TABLE_ANGLE_RAD, exact.TABLE_ANGLE_RAD))
def test_rounded_cos_sin_give_the_nearest_float_to_the_true_value(angle: float) -> None:
    cos, sin = exact.rounded_cos_sin(np.array([angle]))
    true_cos, true_sin = _true_cos_sin(angle)
    assert _nearest(float(cos[0]), true_cos) and _nearest(float(sin[0]), true_sin), angle


@pytest.mark.parametrize("angle", [8.001, -9.0, np.inf, np.nan])
def test_rounded_cos_sin_refuse_angles_beyond_their_table_range(angle: float) -> None:
    with pytest.raises(ValueError, match="rounded_cos_sin: angles must be finite"):
        exact.rounded_cos_sin(np.array([0.5, angle]))


def test_the_planners_direction_tables_are_the_rounded_ones() -> None:
    """The MPC's headings, the terrain's directions and the wall rays come from rounded_cos_sin (libm's on no CPU)."""
    from envs.common import terrain
    from envs.view import _ray_cos_sin

    angles = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
    assert np.array_equal(terrain.HEADINGS, np.stack(exact.rounded_cos_sin(angles), axis=1))
    assert all(np.array_equal(a, b) for a, b in zip(_ray_cos_sin(16), exact.rounded_cos_sin(np.arange(16) * 2 * np.pi
                                                                                              / 16), strict=True))
