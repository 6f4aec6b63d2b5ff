"""Populations: fitted per scene, pedestrians who stand a while, groups that walk together."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from replays import SCENE_NAMES
from st_sim.sim import CrowdConfig, CrowdSim, PopulationConfig, make_layout


@pytest.mark.parametrize("scene", SCENE_NAMES, ids=SCENE_NAMES)
def test_every_scene_has_a_fitted_population(scene: str) -> None:
    pop = PopulationConfig.fitted(scene)
    low, high = pop.speed_range_mps
    assert low < pop.speed_mean_mps < high and 0 < pop.speed_std_mps < 1
    assert 0 <= pop.standing_share < 0.5 and 0 <= pop.group_share <= 1


def test_fitted_populations_differ_where_the_recordings_do() -> None:
    eth, univ = PopulationConfig.fitted("eth"), PopulationConfig.fitted("univ")
    assert eth.speed_mean_mps > 2 * univ.speed_mean_mps, "ETH walkers are recorded much faster than UNIV's"
    assert univ.standing_share > 3 * eth.standing_share


def test_unknown_scene_has_no_fitted_population() -> None:
    with pytest.raises(KeyError, match="zara1"):
        PopulationConfig.fitted("atrium")


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_the_standing_share_is_kept(seed: int) -> None:
    pop = PopulationConfig(standing_share=0.3, dwell_mean_s=20.0)
    sim = CrowdSim(make_layout("crossing"), CrowdConfig(max_pedestrians=60, spawn_rate_hz=2.0, population=pop),
                   np.random.default_rng(seed))
    shares = []
    for _ in range(150):
        sim.step()
        shares.append(sim.standing.mean())
    assert 0.15 < np.mean(shares[50:]) < 0.45, f"standing share {np.mean(shares[50:]):.2f}, asked for 0.3"


def test_groups_form_and_walk_together() -> None:
    pop = PopulationConfig(group_share=0.6)
    sim = CrowdSim(make_layout("corridor"), CrowdConfig(max_pedestrians=40, spawn_rate_hz=1.0, population=pop),
                   np.random.default_rng(1))
    assert (sim.groups >= 0).mean() > 0.4, "the initial crowd should have its groups"
    spread = []
    for _ in range(60):
        sim.step()
        groups, xy = sim.groups, sim.positions_m
        for g in np.unique(groups[groups >= 0]):
            members = xy[groups == g]
            if len(members) > 1:
                spread.append(np.linalg.norm(members - members.mean(axis=0), axis=1).max())
    assert np.median(spread) < 1.0, f"group members drift apart: median spread {np.median(spread):.2f} m"
