"""Layouts: synthetic geometry and its raster, real-scene walls and gates from the walkability maps."""

from __future__ import annotations

import numpy as np
import pytest

from replays import load_scene
from replays.scenes import Scene
from st_sim.sim import CrowdConfig, CrowdSim, Layout, Region, layout_from_scene, make_layout
from st_sim.sim.layouts import periodic_corridor
from st_sim.sim.pairs import Neighbours
from st_sim.sim.walls import WallGrid, point_segment

SYNTHETIC = ["corridor", "crossing", "bottleneck"]


@pytest.fixture(scope="module")
def zara1() -> Layout:
    return layout_from_scene(load_scene("zara1"))


@pytest.mark.parametrize("name", SYNTHETIC, ids=SYNTHETIC)
def test_synthetic_map_is_blocked_in_walls_and_open_in_corridors(name: str) -> None:
    layout = make_layout(name)
    scene = layout.scene
    midpoints = layout.walls_m.mean(axis=1)
    assert not scene.is_walkable(midpoints).any(), "wall lines must not be walkable"
    open_points = np.array([layout.ego_start_m, layout.ego_goal_m, *[g.centre_m for g in layout.entries]])
    assert scene.is_walkable(open_points).all(), "gates and the ego's route must be walkable"
    xmin, ymin, xmax, ymax = layout.bounds_m
    assert not scene.is_walkable(np.array([[xmin, ymin], [xmax, ymax]])).any(), "outside the walls"


def test_corridor_is_20_by_8_metres_with_a_gate_at_each_end() -> None:
    layout = make_layout("corridor")
    corners = layout.walls_m.reshape(-1, 2)
    assert np.allclose(corners.min(axis=0), [0, 0]) and np.allclose(corners.max(axis=0), [20, 8])
    assert [g.name for g in layout.entries] == ["west", "east"] and layout.routes == ((1,), (0,))
    assert layout.walkable_area_m2() == pytest.approx(160.0, rel=0.03)


def test_bottleneck_wall_block_is_not_walkable_but_its_door_is() -> None:
    scene = make_layout("bottleneck").scene
    assert not scene.is_walkable(np.array([[9.0, 1.0], [9.0, 7.0]])).any()
    assert scene.is_walkable(np.array([[9.0, 4.0]])).all()


def test_make_layout_unknown_name_lists_the_choices() -> None:
    with pytest.raises(KeyError, match="corridor"):
        make_layout("atrium")


def test_region_contains_points_inside_its_polygon() -> None:
    triangle = Region("t", np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]]))
    inside = triangle.contains(np.array([[1.0, 1.0], [3.0, 3.0], [-0.1, 1.0], [0.5, 3.0]]))
    assert inside.tolist() == [True, False, False, True]


def test_zara1_walls_follow_the_walkability_map(zara1: Layout) -> None:
    scene = zara1.scene
    assert scene is load_scene("zara1") and len(zara1.walls_m) >= 5
    # every wall runs along the map's boundary: a few pixels around its midpoint hold both map values
    uv = np.rint(scene.world_to_pixel(zara1.walls_m.mean(axis=1))).astype(int)
    padded = np.pad(scene.walkable, 3, constant_values=False)
    for k, (u, v) in enumerate(uv):
        patch = padded[v: v + 7, u: u + 7]
        assert patch.any() and not patch.all(), f"[wall {k}] midpoint {zara1.walls_m[k].mean(axis=0)} off the boundary"


def test_zara1_gates_open_onto_walkable_ground(zara1: Layout) -> None:
    assert len(zara1.entries) >= 2 and zara1.entries == zara1.exits
    for gate in zara1.entries:
        lo, hi = gate.polygon_m.min(axis=0), gate.polygon_m.max(axis=0)
        grid = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 20), np.linspace(lo[1], hi[1], 20)), -1).reshape(-1, 2)
        assert zara1.scene.is_walkable(grid[gate.contains(grid)]).mean() > 0.3, f"{gate} is mostly blocked"
    assert zara1.scene.is_walkable(np.array([zara1.ego_start_m, zara1.ego_goal_m])).all()


def test_zara1_simulated_pedestrians_stay_on_the_map(zara1: Layout) -> None:
    sim = CrowdSim(zara1, CrowdConfig(max_pedestrians=20, spawn_rate_hz=1.0), np.random.default_rng(0))
    for t in range(100):
        sim.step()
        assert zara1.scene.is_walkable(sim.positions_m).all(), f"[step {t}] off the map"
    assert sim.ids.max() >= 20, "pedestrians should come and go"


def test_layout_from_scene_without_border_openings_is_rejected(toy_scene) -> None:
    island = np.zeros_like(toy_scene.walkable)
    island[20:40, 20:40] = True  # an island that never reaches the image border
    with pytest.raises(ValueError, match="toy"):
        layout_from_scene(Scene("toy", toy_scene.H, island))


def test_wall_grid_distance_matches_brute_force(zara1: Layout) -> None:
    grid = WallGrid(zara1.walls_m, zara1.bounds_m, 0.2, 1.0)
    points = np.random.default_rng(0).uniform(zara1.bounds_m[:2], zara1.bounds_m[2:], (500, 2))
    seg = zara1.walls_m
    brute = np.linalg.norm(point_segment(points[:, None], seg[None, :, 0], seg[None, :, 1]) - points[:, None],
                           axis=-1).min(axis=1)
    near = brute < 1.0
    np.testing.assert_allclose(grid.distance_m(points)[near], brute[near], atol=1e-9)
    assert (grid.distance_m(points)[~near] >= 1.0 - 1e-9).all()


@pytest.mark.parametrize("bad", [{"gate_depth_m": 0.0}, {"max_gate_m": float("nan")}, {"simplify_m": -1.0}],
                         ids=["gate_depth", "max_gate", "simplify"])
def test_layout_from_scene_rejects_bad_parameters(toy_scene, bad: dict) -> None:
    with pytest.raises(ValueError, match=rf"layout_from_scene\.{next(iter(bad))} = "):
        layout_from_scene(toy_scene, **bad)


def test_periodic_corridor_wraps_bodies_and_finds_neighbours_across_the_seam() -> None:
    layout = periodic_corridor(10.0, 4.0)
    assert layout.period is not None and not layout.entries
    sim = CrowdSim(layout, CrowdConfig(max_pedestrians=30), np.random.default_rng(0))
    for t in range(60):
        sim.step()
        x = sim.positions_m[:, 0]
        assert ((x >= 0.0) & (x < 10.0)).all(), f"[step {t}] a pedestrian left the period"
    assert len(sim.ids) == 30, "nobody leaves a periodic corridor"
    nb = Neighbours.within(np.array([[0.1, 2.0], [9.9, 2.0]]), np.full(2, 0.2), 0.5, layout.period)
    assert len(nb.i) == 1 and nb.offset_m[0] == pytest.approx([-0.2, 0.0])
