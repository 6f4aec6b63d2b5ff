"""When reactive pedestrians notice the robot, when they react and how much room they keep
(``st_sim.reactive.reaction``), and the fitted values that ship."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from envs.common.errors import ConfigError
from st_sim.reactive.reaction import (
    FIT_PATH,
    MEMORY_S,
    NOTICING,
    REACTION_TIME,
    SPREAD_PATH,
    TRAIT_RANGE,
    TRAITS,
    Reaction,
    Spread,
    attend,
    draw_traits,
    fitted_reaction,
    fitted_spread,
    notices,
    read_fitted_on,
    read_reaction,
    read_spread,
    typical,
)

DRAWS = settings(max_examples=50, deadline=None)
reactions = st.builds(Reaction, fov_deg=st.floats(0.0, 180.0), hearing_m=st.floats(0.0, 10.0),
                      reaction_s=st.floats(0.0, 3.0), anticipation_s=st.floats(0.0, 5.0),
                      clearance_m=st.floats(0.0, 2.0), head_on_s=st.floats(0.0, 2.0), behind_s=st.floats(0.0, 2.0),
                      crossing_s=st.floats(0.0, 2.0), delay_cost=st.floats(0.0, 4.0), aside_cost=st.floats(0.0, 4.0))


@DRAWS
@given(reaction=reactions, noticed_s=st.floats(0.0, 10.0), slowness=st.floats(*TRAIT_RANGE))
def test_the_reaction_starts_a_reaction_time_after_noticing_and_grows_over_one_step(reaction: Reaction,
                                                                                   noticed_s: float,
                                                                                   slowness: float) -> None:
    traits = typical(1)
    traits[0, REACTION_TIME] = slowness  # its own reaction time: the fitted one times this
    weight = float(reaction.weight(np.array([noticed_s]), traits)[0])
    reaction_s = reaction.reaction_s * slowness
    assert 0.0 <= weight <= 1.0
    assert (weight == 0.0) == (noticed_s <= reaction_s)
    assert (weight == 1.0) == (noticed_s >= reaction_s + 0.4)
    assert reaction.anticipation_steps >= 1


@DRAWS
@given(reaction=reactions, gap=st.floats(0.0, 30.0), bearing=st.floats(-np.pi, np.pi),
       keenness=st.floats(*TRAIT_RANGE))
def test_the_robot_is_noticed_in_view_or_within_hearing(reaction: Reaction, gap: float, bearing: float,
                                                       keenness: float) -> None:
    traits = typical(1)
    traits[0, NOTICING] = keenness  # it hears the robot this many times as far as the fitted pedestrian
    seen = bool(notices(reaction, np.array([gap]), np.array([bearing]), traits)[0])
    assert seen == (gap <= reaction.hearing_m * keenness or abs(bearing) <= np.radians(reaction.fov_deg))


@DRAWS
@given(pattern=st.lists(st.booleans(), min_size=1, max_size=40))
def test_attention_lasts_while_noticing_and_a_memory_after(pattern: list[bool]) -> None:
    noticed, unseen = np.zeros(1), np.zeros(1)
    held, since = 0.0, None
    for noticing in pattern:
        noticed, unseen = attend(noticed, unseen, np.array([noticing]))
        if noticing:
            since = 0.0
        elif since is not None:
            since += 0.4
        if since is not None and since > MEMORY_S + 1e-9:
            since = None
        held = 0.0 if since is None else held + 0.4
        assert np.isclose(noticed[0], held), (pattern, noticed[0], held)


@DRAWS
@given(reaction=reactions, speed=st.floats(0.0, 5.0), angle=st.floats(-np.pi, np.pi))
def test_the_room_grows_with_the_robots_speed_by_its_approach(reaction: Reaction, speed: float,
                                                              angle: float) -> None:
    heading = np.array([1.0, 0.0])
    walking = np.array([[np.cos(angle), np.sin(angle)]])
    coming, leaving = (reaction.room_m(speed * heading, heading, walking, np.array([flag]))[0]
                       for flag in (True, False))
    assert np.isclose(leaving, reaction.clearance_m)
    cosine = np.cos(angle)
    per_mps = (reaction.head_on_s * max(-cosine, 0.0) + reaction.behind_s * max(cosine, 0.0)
               + reaction.crossing_s * (1 - abs(cosine)))
    assert np.isclose(coming, reaction.clearance_m + speed * per_mps)
    coefficients = (reaction.head_on_s, reaction.behind_s, reaction.crossing_s)  # blended, never beyond them
    assert min(coefficients) * speed - 1e-9 <= coming - reaction.clearance_m <= max(coefficients) * speed + 1e-9


def test_the_shipped_reaction_is_fitted_and_says_how() -> None:
    table = json.loads(FIT_PATH.read_text())
    reaction = fitted_reaction()
    assert dataclasses.asdict(reaction) == table["params"]
    assert table["fitted_by"].startswith("benchmarks/fit_reaction.py")
    assert table["fitted_on"] == ["vci_back", "vci_front", "vci_lat_uni"] and table["held_out"] == ["vci_lat_bi"]
    assert 0.0 <= reaction.fov_deg <= 180.0 and reaction.reaction_s >= 0.0 and reaction.clearance_m >= 0.0


FIELDS = [field.name for field in dataclasses.fields(Reaction)]


@settings(max_examples=40, deadline=None)
@given(damage=st.one_of(
    st.tuples(st.just("drop"), st.sampled_from(FIELDS)),
    st.tuples(st.just("value"), st.sampled_from(FIELDS),
              st.sampled_from([float("nan"), float("inf"), -0.5, "fast", None, [1.0]])),
    st.tuples(st.just("text"), st.sampled_from(["", "{", "[]", '{"params": 3}', "\x00\xff"]))))
def test_a_bad_reaction_fit_file_is_refused_naming_the_file(tmp_path_factory: pytest.TempPathFactory,
                                                            damage: tuple) -> None:
    """Every class of damage to a fit file (a field missing, a field not a finite number >= 0, not JSON, no params)
    gets ``ConfigError`` naming the file, never a KeyError or a Reaction with NaN in it."""
    path = tmp_path_factory.mktemp("fit") / "fit.json"
    table = json.loads(FIT_PATH.read_text())
    if damage[0] == "drop":
        del table["params"][damage[1]]
    elif damage[0] == "value":
        table["params"][damage[1]] = damage[2]
    text = damage[1] if damage[0] == "text" else json.dumps(table)
    path.write_text(text)
    with pytest.raises(ConfigError, match=str(path)):
        read_reaction(path)


def test_a_fit_file_round_trips_and_a_missing_one_is_named(tmp_path: Path) -> None:
    assert read_reaction(FIT_PATH) == fitted_reaction()
    with pytest.raises(ConfigError, match="no such reaction fit file"):
        read_reaction(tmp_path / "absent.json")


@pytest.mark.parametrize("folders, expected", [(["a", "b"], ("a", "b")), (None, None), ("absent", None),
                                               ("vci_front", ConfigError), ([1, 2], ConfigError)],
                         ids=["list", "null", "absent", "string", "numbers"])
def test_a_fit_file_names_the_folders_it_was_fitted_on_or_is_refused(tmp_path: Path, folders: object,
                                                                     expected: object) -> None:
    table = json.loads(FIT_PATH.read_text())
    if folders == "absent":
        del table["fitted_on"]
    else:
        table["fitted_on"] = folders
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(table))
    if expected is ConfigError:
        with pytest.raises(ConfigError, match=f"{path}: fitted_on"):
            read_fitted_on(path)
    else:
        assert read_fitted_on(path) == expected
    assert read_fitted_on(FIT_PATH) == ("vci_back", "vci_front", "vci_lat_uni")


spreads = st.builds(Spread, *(st.floats(0.0, 2.0) for _ in TRAITS))


@DRAWS
@given(spread=spreads, agents=st.integers(0, 40), seed=st.integers(0, 2**32 - 1))
def test_traits_are_drawn_from_the_seed_within_their_range_and_a_spread_of_zeros_is_the_fitted_pedestrian(
        spread: Spread, agents: int, seed: int) -> None:
    traits = draw_traits(np.random.default_rng(seed), agents, spread)
    assert traits.shape == (agents, len(TRAITS))
    assert np.array_equal(traits, draw_traits(np.random.default_rng(seed), agents, spread))
    assert ((traits >= TRAIT_RANGE[0]) & (traits <= TRAIT_RANGE[1])).all()
    assert np.array_equal(traits[:, spread.sigmas() == 0], np.ones((agents, int((spread.sigmas() == 0).sum()))))
    assert np.array_equal(draw_traits(np.random.default_rng(seed), agents, Spread()), typical(agents))


def test_wider_spreads_draw_people_who_differ_more() -> None:
    narrow, wide = (np.log(draw_traits(np.random.default_rng(3), 4000, Spread.even(sigma))).std(axis=0)
                    for sigma in (0.1, 0.4))
    assert np.allclose(narrow, 0.1, rtol=0.1) and np.allclose(wide, 0.4, rtol=0.1)


@DRAWS
@given(value=st.one_of(st.floats(allow_nan=True).filter(lambda v: not 0 <= v <= 2), st.booleans(), st.text()),
       trait=st.sampled_from(TRAITS))
def test_a_spread_outside_zero_to_two_is_refused_naming_the_trait(value: object, trait: str) -> None:
    with pytest.raises(ConfigError, match=f"Spread.{trait}"):
        Spread(**{trait: value})


def test_a_spread_file_is_read_or_refused_naming_the_file_and_the_trait(tmp_path: Path) -> None:
    assert fitted_spread() == read_spread(SPREAD_PATH)
    good = {name: 0.1 for name in TRAITS}
    path = tmp_path / "spread.json"
    path.write_text(json.dumps({"spread": good}))
    assert read_spread(path) == Spread.even(0.1)
    for body, problem in ((json.dumps({"spread": {**good, "room": -1}}), "Spread.room"),
                          (json.dumps({"spread": {k: v for k, v in good.items() if k != "patience"}}),
                           "no spread.patience"), ("{", "not a readable JSON spread"), ("[1]", "not a readable")):
        path.write_text(body)
        with pytest.raises(ConfigError, match=str(path)) as err:
            read_spread(path)
        assert problem in str(err.value)
    with pytest.raises(ConfigError, match="no such spread file"):
        read_spread(tmp_path / "missing.json")
