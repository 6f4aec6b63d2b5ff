"""Steering pieces: queueing, density slowdown, speculative contacts and navigation fields."""

from __future__ import annotations

import numpy as np
import pytest

from st_sim.sim import CrowdConfig, CrowdSim, make_layout
from st_sim.sim.config import WALL_RADIUS_M
from st_sim.sim.contacts import keep_apart
from st_sim.sim.steering import Facing, Neighbours, density_speed, headway_speed
from st_sim.sim.walls import WallGrid

CFG = CrowdConfig()
EAST, WEST = np.array([1.0, 0.0]), np.array([-1.0, 0.0])


def _pair(offset_m: float, heading_b: np.ndarray) -> tuple[Neighbours, Facing]:
    xy = np.array([[0.0, 0.0], [offset_m, 0.0]])
    nb = Neighbours.within(xy, np.full(2, CFG.radius_m), CFG.agent_cutoff_m)
    return nb, Facing.of(nb, np.stack([EAST, heading_b]))


def test_headway_slows_a_follower_but_not_the_leader_or_oncoming_walkers() -> None:
    v0 = np.full(2, 1.3)
    nb, facing = _pair(0.8, EAST)  # agent 1 walks 0.8 m ahead of agent 0, same way
    follower, leader = headway_speed(nb, facing, v0, CFG.time_gap_s)
    assert follower == pytest.approx((0.8 - 2 * CFG.radius_m) / CFG.time_gap_s) and leader == 1.3
    nb, facing = _pair(0.8, WEST)  # face to face
    assert headway_speed(nb, facing, v0, CFG.time_gap_s).tolist() == [1.3, 1.3]


def test_density_slows_pedestrians_in_a_packed_crowd() -> None:
    sparse = np.array([[0.0, 0.0], [1.2, 0.0]])
    packed = np.random.default_rng(0).uniform(-0.9, 0.9, (40, 2))
    speeds = [density_speed(Neighbours.within(xy, np.full(len(xy), 0.25), CFG.agent_cutoff_m), np.full(len(xy), 1.3),
                            CFG)[0] for xy in (sparse, packed)]
    assert speeds[0] > 1.25 and speeds[1] < 0.2


def test_keep_apart_stops_a_head_on_pair_at_contact() -> None:
    xy = np.array([[0.0, 4.0], [0.6, 4.0]])
    v = np.array([[1.3, 0.0], [-1.3, 0.0]])
    radius = np.full(2, CFG.radius_m)
    walls = WallGrid(np.array([[[-5.0, 0.0], [5.0, 0.0]]]), (-5.0, -1.0, 5.0, 9.0), 0.2, 1.0)
    dt = 0.1
    safe = keep_apart(v, radius, np.ones(2, bool), Neighbours.within(xy, radius, 1.5), walls.near(xy), dt)
    after = xy + dt * safe
    assert np.linalg.norm(after[1] - after[0]) >= 2 * CFG.radius_m - 1e-6
    assert safe[0, 0] > 0 and safe[1, 0] < 0, "they may still close the gap"


def test_keep_apart_stops_a_walker_at_the_wall_and_leaves_sideways_motion() -> None:
    xy = np.array([[0.0, 0.4]])
    radius = np.full(1, CFG.radius_m)
    walls = WallGrid(np.array([[[-5.0, 0.0], [5.0, 0.0]]]), (-5.0, -1.0, 5.0, 9.0), 0.2, 1.0)
    safe = keep_apart(np.array([[1.0, -2.0]]), radius, np.ones(1, bool), Neighbours.within(xy, radius, 1.5),
                      walls.near(xy), 0.1)
    gap = 0.4 - CFG.radius_m - WALL_RADIUS_M
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
