"""The logged routes reactive pedestrians walk (``st_sim.reactive.routes``): places along and beside them, and the route
point nearest to a place off their grid."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from st_sim.reactive.footprint import Body
from st_sim.reactive.routes import OpenGround, Routes

FRAMES = 30
DRAWS = settings(max_examples=30, deadline=None)


def _straight_route(heading: float, speed: float) -> Routes:
    """One log walking straight from the origin along ``heading`` [rad] at ``speed`` [m/s]."""
    step = 0.4 * speed * np.array([np.cos(heading), np.sin(heading)])
    log = (np.arange(FRAMES)[:, None] * step)[:, None]  # (F, 1, 2)
    return Routes(log, np.ones((FRAMES, 1), bool), OpenGround(), Body(radius_m=0.3), 0.25)


@DRAWS
@given(heading=st.floats(-np.pi, np.pi), speed=st.floats(0.3, 2.0), tau=st.floats(2.0, FRAMES - 3.0),
       offset=st.floats(-3.0, 3.0))
def test_a_place_beside_a_straight_route_is_found_again_at_its_route_point_and_side(heading: float, speed: float,
                                                                                    tau: float,
                                                                                    offset: float) -> None:
    routes = _straight_route(heading, speed)
    agent, frame = np.array([0]), np.array([int(tau)])
    place = routes.place(agent, np.array([tau]), np.array([offset]), frame)
    found_tau, found_offset = routes.nearest_on_route(agent, place, np.array([0]), np.array([FRAMES - 1]), frame)
    assert np.isclose(found_tau[0], tau, atol=1e-6), f"route point {found_tau[0]} instead of {tau}"
    assert np.isclose(found_offset[0], offset, atol=1e-6), f"side {found_offset[0]} instead of {offset}"


def test_the_nearest_route_point_is_sought_only_between_the_frames_given() -> None:
    routes = _straight_route(0.0, 1.0)  # along +x, 0.4 m per frame
    agent, frame = np.array([0]), np.array([5])
    tau, offset = routes.nearest_on_route(agent, np.array([[4.0, 1.0]]), np.array([2]), np.array([5]), frame)
    assert tau[0] == 5.0 and np.isclose(offset[0], 1.0), "not held to frames 2 to 5"
