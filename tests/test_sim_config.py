"""Config validation: every field of the simulator's config dataclasses and every layout parameter either works or
raises a ValueError that names it; nothing aborts, hangs or runs out of memory (hypothesis)."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from st_sim.sim import (
    CrowdConfig,
    CrowdSim,
    EgoConfig,
    LayoutTooLargeError,
    PopulationConfig,
    SocialForceConfig,
    SpeedModelConfig,
)
from st_sim.sim.layouts import bottleneck, corner, corridor, crossing, periodic_corridor

NASTY = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1.0, max_value=10.0),
    st.integers(min_value=-10, max_value=10**12),
    st.sampled_from([0, 1, -1, 0.0, 1e-300, None, "3", True, (1.0, 2.0), (2.0, 1.0), (float("nan"), 1.0)]),
)
SMALL_LAYOUT = corridor(6.0, 3.0)
CONFIGS = [CrowdConfig, EgoConfig, PopulationConfig, SpeedModelConfig, SocialForceConfig]


def _numeric_fields(kind: type) -> list[str]:
    return [f.name for f in fields(kind) if "bounds" in f.metadata]


def _check_message(err: ValueError, kind: str, names: set[str]) -> None:
    assert any(f"{kind}.{name} = " in str(err) for name in names), f"{err} names none of {sorted(names)}"


@pytest.mark.parametrize("kind", CONFIGS, ids=[k.__name__ for k in CONFIGS])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_config_accepts_or_names_the_bad_field(kind: type, data: st.DataObject) -> None:
    names = data.draw(st.sets(st.sampled_from(_numeric_fields(kind)), min_size=1, max_size=3))
    kwargs = {name: data.draw(NASTY, label=name) for name in names}
    try:
        kind(**kwargs)
    except ValueError as err:
        _check_message(err, kind.__name__, set(names))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_any_accepted_crowd_config_runs_or_raises_value_error(data: st.DataObject) -> None:
    names = data.draw(st.sets(st.sampled_from(_numeric_fields(CrowdConfig)), min_size=1, max_size=4))
    kwargs = {name: data.draw(NASTY, label=name) for name in names}
    try:
        cfg = CrowdConfig(**kwargs)
    except ValueError as err:
        _check_message(err, "CrowdConfig", set(names))
        return
    try:
        sim = CrowdSim(SMALL_LAYOUT, cfg, np.random.default_rng(0), ego=EgoConfig(start_m=(3.0, 1.5)))
    except ValueError:
        return  # e.g. more pedestrians than fit: refused with a message, never an abort
    for _ in range(2):
        sim.step(np.array([0.5, 0.0]))
    assert np.isfinite(sim.positions_m).all()


@pytest.mark.parametrize("bad", [{"solver_iterations": 0}, {"solver_iterations": -3}, {"collision_slop_m": -0.1},
                                 {"nav_cell_m": 0.0}, {"radius_m": float("nan")}, {"n_substeps": 0},
                                 {"density_per_m2": float("inf")}, {"max_pedestrians": 10**9}],
                         ids=["iterations0", "iterations-3", "slop", "cell", "radius_nan", "substeps", "density_inf",
                              "population"])
def test_crowd_config_rejects_the_values_that_used_to_abort(bad: dict) -> None:
    name = next(iter(bad))
    with pytest.raises(ValueError, match=rf"CrowdConfig\.{name} = .*expected"):
        CrowdConfig(**bad)


def test_population_speed_range_must_be_ordered() -> None:
    with pytest.raises(ValueError, match=r"PopulationConfig\.speed_range_mps"):
        PopulationConfig(speed_range_mps=(2.0, 1.0))


def test_crowd_config_rejects_a_steering_config_of_the_wrong_kind() -> None:
    with pytest.raises(ValueError, match=r"CrowdConfig\.steering"):
        CrowdConfig(steering=PopulationConfig())


LAYOUTS = {
    "corridor": (corridor, ("length_m", "width_m")),
    "crossing": (crossing, ("size_m", "arm_width_m")),
    "bottleneck": (bottleneck, ("room_m", "wall_m", "height_m", "door_m")),
    "corner": (corner, ("arm_m", "width_m")),
    "periodic_corridor": (periodic_corridor, ("length_m", "width_m")),
}
SIZES = st.one_of(st.floats(min_value=-5.0, max_value=40.0), st.floats(min_value=1e5, max_value=1e300),
                  st.sampled_from([0.0, -0.0, float("nan"), float("inf"), -float("inf")]))


@pytest.mark.parametrize("name", list(LAYOUTS), ids=list(LAYOUTS))
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_layout_builds_or_names_the_bad_parameter(name: str, data: st.DataObject) -> None:
    build, params = LAYOUTS[name]
    chosen = data.draw(st.sets(st.sampled_from(params), min_size=1))
    kwargs = {p: data.draw(SIZES, label=p) for p in chosen}
    try:
        layout = build(**kwargs)
    except LayoutTooLargeError as err:
        assert "memory budget" in str(err)
        return
    except ValueError as err:
        assert any(f"{name}.{p} = " in str(err) for p in chosen), str(err)
        return
    assert layout.walkable_area_m2() > 0


@pytest.mark.parametrize("build", [lambda: corridor(4.0, 0.5), lambda: crossing(4.0, 0.5), lambda: crossing(4.0, 3.99),
                                   lambda: bottleneck(4.0, 0.05, 0.5, 0.01), lambda: corner(4.0, 2.5),
                                   lambda: periodic_corridor(4.0, 0.5)],
                         ids=["corridor", "crossing_narrow", "crossing_wide", "bottleneck", "corner", "periodic"])
def test_the_smallest_layouts_have_a_route_from_every_entry(build) -> None:
    layout = build()  # a 3 m corridor had none (its gates' centres 1.5 m apart): refused since, found in CI
    assert layout.walkable_area_m2() > 0 and all(layout.routes)


def test_a_huge_layout_is_refused_before_it_is_allocated() -> None:
    with pytest.raises(LayoutTooLargeError, match="memory budget"):
        corridor(1e5, 8.0)


@pytest.mark.parametrize("build", [lambda: corridor(20.0, 0.0), lambda: corridor(-5.0, 8.0),
                                   lambda: bottleneck(door_m=0.0)], ids=["zero_width", "negative_length",
                                                                          "closed_door"])
def test_degenerate_layout_is_an_error(build) -> None:
    with pytest.raises(ValueError, match="expected"):
        build()


@pytest.mark.parametrize("build", [lambda: corridor(20.0, 0.55), lambda: bottleneck(door_m=0.3)],
                         ids=["too_narrow", "door_too_narrow"])
def test_layout_that_lets_nobody_through_is_refused_by_the_simulator(build) -> None:
    with pytest.raises(ValueError, match="no pedestrian through"):
        CrowdSim(build(), CrowdConfig(), np.random.default_rng(0))
