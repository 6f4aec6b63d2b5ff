"""The sub-goal social force model (``st_sim.apps.subgoal_force``) on hand-made encounters."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from replays.constants import STEP_S
from st_sim.apps.subgoal_force import SubGoalForce, walk_sub_goal
from st_sim.reactive.footprint import Body

CART = Body(2.4, 1.2)
STEPS = 40


def line(start: np.ndarray, velocity: np.ndarray, begin: int = 0) -> np.ndarray:
    """(STEPS, 1, 2) an intent: from ``start`` at ``velocity`` [m/s] from step ``begin`` on, NaN before."""
    since = (np.arange(STEPS) - begin) * STEP_S
    xy = start + since[:, None] * velocity
    return np.where((since >= 0)[:, None], xy, np.nan)[:, None]


def parked(xy: tuple[float, float], heading: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    return np.tile(np.array(xy, float), (STEPS, 1)), np.full(STEPS, heading)


@settings(max_examples=60, deadline=None)
@given(start=st.tuples(st.floats(-5, 5), st.floats(-5, 5)), angle=st.floats(-np.pi, np.pi),
       pace=st.floats(0.3, 2.0), begin=st.integers(0, 10))
def test_with_the_vehicle_far_away_a_pedestrian_walks_its_intent(start, angle, pace, begin) -> None:
    intent = line(np.array(start), pace * np.array([np.cos(angle), np.sin(angle)]), begin)
    walked = walk_sub_goal(SubGoalForce(), intent, *parked((500.0, 500.0)), CART)
    assert np.isnan(walked[:begin]).all()
    np.testing.assert_allclose(walked[begin:], intent[begin:], atol=1e-6)


@pytest.mark.parametrize("side", [-1.0, 1.0])
@pytest.mark.parametrize("speed", [1.0, 2.0, 3.0])
def test_a_pedestrian_crossing_a_driving_vehicles_way_keeps_clear_of_it(side: float, speed: float) -> None:
    """The vehicle drives along x through the origin; the pedestrian walks across its way (along y) so that,
    blind, it would be hit; walked by the model, its centre never comes within 0.3 m of the body, and it gets across."""
    vehicle = np.c_[-speed * 4.0 + speed * STEP_S * np.arange(STEPS), np.zeros(STEPS)]
    heading = np.zeros(STEPS)
    intent = line(np.array([0.0, -4.0 * side]), np.array([0.0, side]))
    gap = CART.gap_m(intent[:, 0] - vehicle, 0.0)
    assert np.nanmin(gap) <= 0.0  # blind: inside the body
    walked = walk_sub_goal(SubGoalForce(), intent, vehicle, heading, CART)[:, 0]
    assert np.min(CART.swept_gap_m(walked[:-1] - vehicle[:-1], walked[1:] - vehicle[1:], heading[:-1])) > 0.3
    assert side * walked[-1, 1] > 4.0  # and gets across


@settings(max_examples=30, deadline=None)
@given(field=st.sampled_from(["tau_s", "margin_m", "vehicle_range_m", "pedestrian_strength"]),
       value=st.one_of(st.floats(max_value=-1e-9), st.just(float("nan")), st.just(float("inf"))))
def test_bad_parameters_are_refused_naming_the_field(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=f"SubGoalForce.{field}"):
        SubGoalForce(**{field: value})
