"""Steering pieces: free walk and headway, the speed model's choices, the social force's density slowdown,
speculative contacts and navigation fields."""

from __future__ import annotations

import numpy as np
import pytest

from st_sim.sim import CrowdConfig, CrowdSim, SocialForceConfig, SpeedModelConfig, make_layout
from st_sim.sim.config import WALL_RADIUS_M
from st_sim.sim.contacts import keep_apart
from st_sim.sim.layouts import corridor
from st_sim.sim.pairs import SQUEEZE_M, Directed, Facing, Neighbours, free_walk_m, headway_m
from st_sim.sim.social_force import density_speed
from st_sim.sim.spawning import Arrivals
from st_sim.sim.speed_model import plan, sidestep_urge, walk
from st_sim.sim.walls import WallGrid

RADIUS = 0.2
EAST, WEST = np.array([1.0, 0.0]), np.array([-1.0, 0.0])
OPEN_WALLS = WallGrid(np.array([[[-50.0, -20.0], [50.0, -20.0]]]), (-50.0, -21.0, 50.0, 21.0), 0.5, 1.0)


def _pairs(xy: list[list[float]]) -> tuple[np.ndarray, Neighbours]:
    xy_m = np.array(xy, dtype=np.float64)
    return xy_m, Neighbours.within(xy_m, np.full(len(xy_m), RADIUS), 3.0)


def test_free_walk_stops_at_contact_and_lets_neighbours_abreast_pass() -> None:
    _, nb = _pairs([[0.0, 0.0], [1.0, 0.0], [0.1, 0.39]])  # one straight ahead, one almost abreast
    pairs = Directed.of(nb)
    ahead, across = pairs.ahead_across(np.tile(EAST, (3, 1)))
    free = free_walk_m(pairs.me, ahead, across, pairs.contact_m, 3)
    contact = 2 * RADIUS - SQUEEZE_M
    assert free[0] == pytest.approx(1.0 - contact), "blocked by the walker straight ahead"
    assert free[2] == np.inf and free[1] == np.inf, "nobody is ahead of them"


def test_social_force_headway_counts_only_walkers_going_the_same_way() -> None:
    for heading_b, expected in ((EAST, 0.8 - 2 * RADIUS), (WEST, np.inf)):
        _, nb = _pairs([[0.0, 0.0], [0.8, 0.0]])
        facing = Facing.of(nb, np.stack([EAST, heading_b]))
        assert headway_m(nb, facing, 2, same_way_only=True)[0] == pytest.approx(expected)


def test_density_slows_pedestrians_in_a_packed_crowd() -> None:
    cfg = SocialForceConfig()
    sparse = np.array([[0.0, 0.0], [1.2, 0.0]])
    packed = np.random.default_rng(0).uniform(-0.9, 0.9, (40, 2))
    speeds = [density_speed(Neighbours.within(xy, np.full(len(xy), RADIUS), 1.5), np.full(len(xy), 1.3), cfg)[0]
              for xy in (sparse, packed)]
    assert speeds[0] > 1.25 and speeds[1] < 0.2


def test_sidestep_passes_oncoming_walkers_on_the_right_and_overtakes_away_from_the_other() -> None:
    v0 = np.full(2, 1.3)
    _, nb = _pairs([[0.0, 0.0], [1.5, 0.0]])  # face to face
    direction, velocity = np.stack([EAST, WEST]), np.stack([1.3 * EAST, 1.3 * WEST])
    pairs = Directed.of(nb)
    urge = sidestep_urge(pairs, *pairs.ahead_across(direction), direction, velocity, v0, 1.0)
    assert urge[0] > 0 and urge[1] > 0, f"both should step to their right, got {urge}"
    _, nb = _pairs([[0.0, 0.0], [1.0, 0.1]])  # a slow walker ahead, a little to the left
    direction, velocity = np.stack([EAST, EAST]), np.stack([1.3 * EAST, 0.5 * EAST])
    pairs = Directed.of(nb)
    urge = sidestep_urge(pairs, *pairs.ahead_across(direction), direction, velocity, v0, 1.0)
    assert urge[0] > 0 and urge[1] == 0, f"overtake on the right, leader unbothered; got {urge}"


def test_speed_model_walks_alone_at_its_preferred_speed_and_stops_behind_a_standing_crowd() -> None:
    cfg = SpeedModelConfig()
    xy, nb = _pairs([[0.0, 0.0]])
    walls = OPEN_WALLS.near(xy)
    heading = plan(np.zeros((1, 2)), EAST[None], np.array([1.2]), np.full(1, RADIUS), nb, walls, cfg)
    velocity = np.zeros((1, 2))
    for _ in range(20):
        velocity = walk(heading, velocity, np.array([1.2]), np.full(1, RADIUS), nb, walls, cfg, 0.2)
    assert velocity[0] == pytest.approx([1.2, 0.0], abs=1e-3)
    wall_of_people = [[0.0, 0.0]] + [[0.45, y] for y in np.arange(-3.0, 3.01, 0.4)]
    xy, nb = _pairs(wall_of_people)
    n = len(xy)
    v0 = np.r_[1.2, np.zeros(n - 1)]
    direction = np.tile(EAST, (n, 1))
    heading = plan(np.zeros((n, 2)), direction, v0, np.full(n, RADIUS), nb, OPEN_WALLS.near(xy), cfg)
    velocity = walk(heading, np.zeros((n, 2)), v0, np.full(n, RADIUS), nb, OPEN_WALLS.near(xy), cfg, 0.2)
    assert np.linalg.norm(velocity[0]) < 0.1 * 1.2, f"nowhere to go, yet walks at {velocity[0]}"


def test_speed_model_walker_passes_a_standing_pedestrian_in_its_line() -> None:
    layout = corridor(20.0, 4.0)  # social forces stay stuck here: the push is straight back, the headway zero
    sim = CrowdSim(layout, CrowdConfig(steering=SpeedModelConfig(), max_pedestrians=2, spawn_rate_hz=0.0),
                   np.random.default_rng(0), n_initial=0)
    sim.add(Arrivals(np.array([[3.0, 2.0], [8.0, 2.0]]), np.array([1, 1]), np.array([1.3, 1.3]),
                      np.array([-1, -1]), np.array([-1, -1]), np.array([0, 10_000])))
    for _ in range(25):
        sim.step()
    walker = sim.positions_m[sim.ids == 0][0]
    assert walker[0] > 10.0, f"the walker is stuck behind the standing one at {walker}"


def test_keep_apart_stops_a_head_on_pair_at_contact() -> None:
    xy = np.array([[0.0, 4.0], [0.6, 4.0]])
    v = np.array([[1.3, 0.0], [-1.3, 0.0]])
    radius = np.full(2, RADIUS)
    walls = WallGrid(np.array([[[-5.0, 0.0], [5.0, 0.0]]]), (-5.0, -1.0, 5.0, 9.0), 0.2, 1.0)
    dt = 0.1
    safe = keep_apart(v, radius, np.ones(2), Neighbours.within(xy, radius, 1.5), walls.near(xy), dt)
    after = xy + dt * safe
    assert np.linalg.norm(after[1] - after[0]) >= 2 * RADIUS - 1e-6
    assert safe[0, 0] > 0 and safe[1, 0] < 0, "they may still close the gap"


def test_keep_apart_stops_a_walker_at_the_wall_and_leaves_sideways_motion() -> None:
    xy = np.array([[0.0, 0.4]])
    radius = np.full(1, RADIUS)
    walls = WallGrid(np.array([[[-5.0, 0.0], [5.0, 0.0]]]), (-5.0, -1.0, 5.0, 9.0), 0.2, 1.0)
    safe = keep_apart(np.array([[1.0, -2.0]]), radius, np.ones(1), Neighbours.within(xy, radius, 1.5),
                      walls.near(xy), 0.1)
    gap = 0.4 - RADIUS - WALL_RADIUS_M
    assert safe[0] == pytest.approx([1.0, -gap / 0.1])


def test_navigation_leads_through_the_bottleneck_door() -> None:
    layout = make_layout("bottleneck")
    nav = CrowdSim(layout, CrowdConfig(max_pedestrians=0), np.random.default_rng(0)).nav
    exit_region = layout.exits[0]
    for start in ([2.0, 1.0], [2.0, 7.0], [7.5, 0.8]):
        xy = np.array([start])
        for _ in range(400):  # walk 0.1 m at a time along the field
            xy = xy + 0.1 * nav.direction_at(np.zeros(1, int), xy)
            if exit_region.contains(xy)[0]:
                break
        assert exit_region.contains(xy)[0], f"from {start} the field ends at {xy[0]}"
        assert nav.distance_at(np.array([start]))[0, 0] < 25.0
