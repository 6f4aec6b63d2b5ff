"""The robot's body as reactive pedestrians keep clear of it (``st_sim.reactive.footprint``): exact swept gaps to a disc
or a box, checked against dense sampling."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from st_sim.reactive.footprint import Body, box_distance, segment_box_distance
from st_sim.sim.sweep import closest_approach

DRAWS = settings(max_examples=60, deadline=None)
coordinate = st.floats(-6.0, 6.0)
points = st.tuples(coordinate, coordinate).map(np.array)
bodies = st.builds(Body, length_m=st.floats(0.0, 4.0), width_m=st.floats(0.0, 2.0), radius_m=st.floats(0.0, 0.5))


@DRAWS
@given(a=points, b=points, body=bodies, heading=st.floats(-4.0, 4.0))
def test_the_swept_gap_is_the_least_gap_along_the_step(a: np.ndarray, b: np.ndarray, body: Body,
                                                      heading: float) -> None:
    """Exact: never above any sampled instant's gap, and within the sampling's resolution of the least of them."""
    swept = float(body.swept_gap_m(a, b, heading))
    t = np.linspace(0.0, 1.0, 4001)[:, None]
    sampled = body.gap_m(a + t * (b - a), heading)
    step_m = float(np.linalg.norm(b - a)) / 4000
    assert swept <= sampled.min() + 1e-9 and swept >= sampled.min() - step_m - 1e-9, (swept, sampled.min())


@DRAWS
@given(a=points, b=points, radius=st.floats(0.0, 1.0))
def test_a_disc_is_a_box_of_no_size_grown_by_its_radius(a: np.ndarray, b: np.ndarray, radius: float) -> None:
    distance, _ = closest_approach(a, b)
    assert np.isclose(Body(radius_m=radius).swept_gap_m(a, b, 0.7), distance - radius, atol=1e-12)


@DRAWS
@given(p=points, body=bodies, heading=st.floats(-4.0, 4.0), turn=st.floats(-4.0, 4.0))
def test_the_gap_turns_with_the_body(p: np.ndarray, body: Body, heading: float, turn: float) -> None:
    """Turning the point and the body together leaves the gap; the nearest point lies on the rectangle, as far as
    the gap says."""
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    assert np.isclose(body.gap_m(p, heading), body.gap_m(rotation @ p, heading + turn), atol=1e-9)
    nearest = body.nearest_point_m(p, heading)
    assert box_distance(body.to_body_frame(nearest, heading), body.half_m) < 1e-9
    assert np.isclose(np.linalg.norm(p - nearest) - body.radius_m, body.gap_m(p, heading), atol=1e-9)


def test_a_segment_through_the_box_touches_it_and_one_beside_it_does_not() -> None:
    half = np.array([1.2, 0.6])
    assert segment_box_distance(np.array([-5.0, 0.3]), np.array([5.0, 0.3]), half) == 0.0
    assert np.isclose(segment_box_distance(np.array([-5.0, 1.0]), np.array([5.0, 1.0]), half), 0.4)
    assert np.isclose(segment_box_distance(np.array([2.2, 1.6]), np.array([3.0, 3.0]), half), np.sqrt(2.0))
