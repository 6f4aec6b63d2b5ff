"""The terrain's compiled cost-to-go, path directions and goal fields (``Terrain.cost_to_go``,
``Terrain.directions_to``, ``GridGraph.geodesic``) equal the numpy and scipy code they replaced, bit for bit: an argmin
over headings that flipped on a tie would change a robot's path.

That code is kept here as the specification (``reference_cost_to_go``, ``reference_directions_to``,
``reference_geodesic``; also the old paths of ``benchmarks/bench_terrain.py``). Both run on the terrains of a
simulated layout (the bottleneck) and of a replay (ETH, from $STCROWD_DATA), for drawn points on and off the grid, at
and near their goals, at cell centres and between cells, toward goals that are shared, off the grid, on walls or cut
off by walls (bodies too wide for a gap); the goal fields also on random grids.
A point with no grid path whose goal lies halfway between two headings often ties them (its straight distances + 100 m
round to the same float): the first of them must win, as ``np.argmin`` has it.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

import envs  # noqa: F401  (registers the ids)
from envs.common import terrain as terrain_module
from envs.common.terrain import (
    HEADINGS,
    LOOKAHEAD_M,
    LOOKUP_CELLS,
    SOURCE_REACH_M,
    UNREACHABLE_PENALTY_M,
    GridGraph,
    Terrain,
)
from st_sim.apps.navigation.world import NavWorld, world_of

ENV_IDS = ("STCrowd-SimBottleneck-v1", "STCrowd-Eth-v0")
MAX_POINTS = 56  # the robots of a training run's vector env


def reference_cost_to_go(terrain: Terrain, xy_m: np.ndarray, goal_m: np.ndarray, body_m: float) -> np.ndarray:
    """``Terrain.cost_to_go`` as numpy computed it: (..., 2) points [m], (2,) goal [m] -> (...) metres."""
    cost = terrain._goal_field(np.asarray(goal_m, np.float64), body_m)
    xy_m = np.asarray(xy_m, np.float64)
    row, col, _ = terrain._cells(xy_m)
    best = np.full(xy_m.shape[:-1], np.inf)
    height, width = cost.shape
    reach = range(-LOOKUP_CELLS, LOOKUP_CELLS + 1)
    for dy in reach:
        for dx in reach:
            r, c = np.clip(row + dy, 0, height - 1), np.clip(col + dx, 0, width - 1)
            best = np.minimum(best, cost[r, c] + np.linalg.norm(xy_m - terrain.cell_centres_m[r, c], axis=-1))
    straight = np.linalg.norm(xy_m - goal_m, axis=-1)
    return np.where(np.isfinite(best), best, straight + UNREACHABLE_PENALTY_M)


def reference_directions_to(terrain: Terrain, xy_m: np.ndarray, goal_m: np.ndarray, body_m: float) -> np.ndarray:
    """``Terrain.directions_to`` as numpy computed it: (B, 2) points [m], (B, 2) goals [m] -> (B, 2) unit vectors."""
    to_goal = goal_m - xy_m
    reach_m = np.minimum(LOOKAHEAD_M, np.linalg.norm(to_goal, axis=1))  # (B,)
    ahead = xy_m[:, None] + reach_m[:, None, None] * HEADINGS  # (B, 64, 2)
    cost = np.empty(ahead.shape[:2])
    goals, which = np.unique(goal_m, axis=0, return_inverse=True)
    for g, goal in enumerate(goals):
        mine = which.reshape(-1) == g
        cost[mine] = reference_cost_to_go(terrain, ahead[mine], goal, body_m)
    return np.where((reach_m >= 1e-6)[:, None], HEADINGS[np.argmin(cost, axis=1)], 0.0)


def reference_geodesic(graph: GridGraph, centres_m: np.ndarray, goal_m: np.ndarray) -> np.ndarray:
    """``GridGraph.geodesic`` as scipy's Dijkstra computed it: (Gy, Gx) metres from the goal (2,) [m], the goal a
    node joined to the eligible cells within SOURCE_REACH_M (else the nearest) by their straight distance."""
    if graph.cells.size == 0:
        return np.full(graph.eligible.shape, np.inf)
    to_goal_m = np.linalg.norm(centres_m.reshape(-1, 2)[graph.cells] - goal_m, axis=1)
    near = to_goal_m <= SOURCE_REACH_M
    near = near if near.any() else to_goal_m == to_goal_m.min()
    goal_node = graph.eligible.size
    indptr = graph.moves.indptr.copy()
    indptr[-1] += int(near.sum())  # the goal's row, last: its edges go after every other row's
    moves = csr_matrix((np.r_[graph.moves.data, np.maximum(to_goal_m[near], 1e-6)],  # a zero weight: no edge
                        np.r_[graph.moves.indices, graph.cells[near]], indptr), shape=graph.moves.shape)
    return dijkstra(moves, directed=True, indices=goal_node)[:-1].reshape(graph.eligible.shape)


@cache
def world(env_id: str) -> NavWorld:
    """The env's navigation world, made once per test session."""
    return world_of(gym.make(env_id, predictor="none"))


def terrain_of(env_id: str) -> tuple[Terrain, float]:
    """The terrain of the env's world and its wall clearance [m]."""
    return world(env_id).terrain, world(env_id).wall_clearance_m


def bodies_of(env_id: str) -> tuple[float, ...]:
    """Body radii [m] to test on the env's terrain: its wall clearance, none, and wider ones (0.6 m: too wide for
    narrow gaps; from 0.1 m the grid's edge cells are out, so every point well off the grid has no path)."""
    _, clearance_m = terrain_of(env_id)
    return tuple(dict.fromkeys((clearance_m, 0.0, 0.3, 0.6)))


@st.composite
def place(draw: st.DrawFn, terrain: Terrain, goals: list[np.ndarray] | None = None) -> np.ndarray:
    """(2,) a point [m]: anywhere within the grid or 3 m beyond, a cell's centre, halfway between two cells, or (with
    ``goals``) at one of them, near one (its distance and offset drawn), or seeing one halfway between two
    HEADINGS."""
    low, high = terrain.origin_m - 3.0, terrain.cell_centres_m[-1, -1] + 3.0
    kinds = ["anywhere", "centre", "between"] + (["goal", "near goal", "between headings"] if goals else [])
    kind = draw(st.sampled_from(kinds))
    if kind == "anywhere":
        return np.array([draw(st.floats(low[0], high[0])), draw(st.floats(low[1], high[1]))])
    if kind in ("centre", "between"):
        height, width = terrain.free.shape
        row, col = draw(st.integers(0, height - 1)), draw(st.integers(0, width - 1))
        centre = terrain.cell_centres_m[row, col]
        return centre + (0.5 * terrain.cell_m * np.array([draw(st.sampled_from([-1, 0, 1])) for _ in range(2)])
                         if kind == "between" else 0.0)
    goal = goals[draw(st.integers(0, len(goals) - 1))]
    if kind == "goal":
        return goal.copy()
    if kind == "between headings":
        angle = (draw(st.integers(0, len(HEADINGS) - 1)) + 0.5) * 2 * np.pi / len(HEADINGS)
        return goal - draw(st.floats(0.6, 30.0)) * np.array([np.cos(angle), np.sin(angle)])
    distance_m = draw(st.sampled_from([1e-9, 1e-6, 0.05, LOOKAHEAD_M, 0.7]) | st.floats(0.0, 1.0))
    angle = draw(st.floats(0.0, 2 * np.pi))
    return goal + distance_m * np.array([np.cos(angle), np.sin(angle)])


@st.composite
def batch(draw: st.DrawFn, terrain: Terrain) -> tuple[np.ndarray, np.ndarray]:
    """((B, 2) points, (B, 2) goals) [m]: B up to MAX_POINTS points sharing up to 6 goals."""
    goals = draw(st.lists(place(terrain), min_size=1, max_size=6))
    size = draw(st.integers(1, MAX_POINTS))
    which = draw(st.lists(st.integers(0, len(goals) - 1), min_size=size, max_size=size))
    points = [draw(place(terrain, goals)) for _ in range(size)]
    return np.array(points), np.array([goals[g] for g in which])


@pytest.mark.parametrize("env_id", ENV_IDS)
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_directions_equal_the_numpy_code(env_id: str, data: st.DataObject) -> None:
    terrain, _ = terrain_of(env_id)
    body_m = data.draw(st.sampled_from(bodies_of(env_id)), label="body_m")
    xy_m, goal_m = data.draw(batch(terrain), label="points, goals")
    np.testing.assert_array_equal(terrain.directions_to(xy_m, goal_m, body_m),
                                  reference_directions_to(terrain, xy_m, goal_m, body_m))


@pytest.mark.parametrize("env_id", ENV_IDS)
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_cost_to_go_equals_the_numpy_code(env_id: str, data: st.DataObject) -> None:
    terrain, _ = terrain_of(env_id)
    body_m = data.draw(st.sampled_from(bodies_of(env_id)), label="body_m")
    goal_m = data.draw(place(terrain), label="goal")
    shape = data.draw(st.sampled_from([(), (0,), (7,), (3, 4)]), label="shape")
    points = [data.draw(place(terrain, [goal_m])) for _ in range(int(np.prod(shape)))]
    xy_m = np.array(points).reshape(*shape, 2)
    got, expected = terrain.cost_to_go(xy_m, goal_m, body_m), reference_cost_to_go(terrain, xy_m, goal_m, body_m)
    assert got.shape == expected.shape == shape
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_many_points_on_the_whole_grid_equal_the_numpy_code(env_id: str) -> None:
    """Thousands of points over the grid and beyond, 8 goals (some cut off for the widest body)."""
    terrain, _ = terrain_of(env_id)
    rng = np.random.default_rng(0)
    low, high = terrain.origin_m - 1.0, terrain.cell_centres_m[-1, -1] + 1.0
    goals = rng.uniform(low, high, (8, 2))
    xy_m = rng.uniform(low, high, (4000, 2))
    goal_m = goals[rng.integers(len(goals), size=len(xy_m))]
    for body_m in bodies_of(env_id):
        np.testing.assert_array_equal(terrain.directions_to(xy_m, goal_m, body_m),
                                      reference_directions_to(terrain, xy_m, goal_m, body_m))
        np.testing.assert_array_equal(terrain.cost_to_go(xy_m.reshape(40, 100, 2), goals[0], body_m),
                                      reference_cost_to_go(terrain, xy_m.reshape(40, 100, 2), goals[0], body_m))


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_points_and_goals_beyond_floats_reach_equal_the_numpy_code() -> None:
    """NaN, infinite and huge coordinates (beyond numpy's cast to intp) give what numpy gave."""
    terrain, body_m = terrain_of(ENV_IDS[0])
    odd = [np.nan, np.inf, -np.inf, 1e30, -1e30, 2.0 ** 63, -(2.0 ** 63), 9.2e17]
    xy_m = np.array([(x, y) for x in [*odd, 1.0] for y in [*odd, 2.0]])
    for goal in ([1.0, 2.0], [30.0, -4.0], [np.nan, 0.0], [np.inf, 1.0]):
        goal_m = np.array(goal)
        np.testing.assert_array_equal(terrain.cost_to_go(xy_m, goal_m, body_m),
                                      reference_cost_to_go(terrain, xy_m, goal_m, body_m))
        goals = np.broadcast_to(goal_m, xy_m.shape)
        np.testing.assert_array_equal(terrain.directions_to(xy_m, goals, body_m),
                                      reference_directions_to(terrain, xy_m, goals, body_m))
    np.testing.assert_array_equal(terrain.directions_to(xy_m[::-1], xy_m, body_m),
                                  reference_directions_to(terrain, xy_m[::-1], xy_m, body_m))


def test_points_just_at_the_goal_stay_and_just_beyond_it_move() -> None:
    """A point exactly 1e-6 m from its goal turns toward it; one a float nearer gets zeros."""
    terrain, body_m = terrain_of(ENV_IDS[0])
    goal_m = np.array([[0.0, 0.0]] * 4)
    xy_m = np.array([[1e-6, 0.0], [0.0, -1e-6], [np.nextafter(1e-6, 0.0), 0.0], [0.0, 0.0]])
    got = terrain.directions_to(xy_m, goal_m, body_m)
    np.testing.assert_array_equal(got, reference_directions_to(terrain, xy_m, goal_m, body_m))
    assert got[:2].any(axis=1).all() and not got[2:].any()


def test_goals_sharing_a_field_take_it_from_the_lowest_goal_as_before() -> None:
    """Goals less than 1e-6 m apart share a field (``Terrain._goal_field`` rounds them): on a fresh terrain both codes
    make it from the lexicographically lowest goal of a batch (np.unique's first), whatever the batch's order."""
    made, body_m = world(ENV_IDS[0]), world(ENV_IDS[0]).wall_clearance_m
    fresh, reference = (Terrain(made.scene, made.bounds_m) for _ in range(2))
    goal_m = np.array([[3.0, 4.0 + 2e-7], [3.0, 4.0]])
    xy_m = np.array([[9.0, 2.0], [1.0, 7.0]])
    np.testing.assert_array_equal(fresh.directions_to(xy_m, goal_m, body_m),
                                  reference_directions_to(reference, xy_m, goal_m, body_m))
    assert fresh._goal_fields.keys() == reference._goal_fields.keys()
    for key, field in fresh._goal_fields.items():
        np.testing.assert_array_equal(field, reference._goal_fields[key])


@pytest.mark.parametrize("env_id", ENV_IDS)
@settings(max_examples=15, deadline=None)
@given(data=st.data())
def test_goal_fields_equal_scipys(env_id: str, data: st.DataObject) -> None:
    terrain, _ = terrain_of(env_id)
    graph = terrain.grid_graph(data.draw(st.sampled_from(bodies_of(env_id)), label="body_m"))
    goal_m = data.draw(place(terrain), label="goal")
    np.testing.assert_array_equal(graph.geodesic(terrain.cell_centres_m, goal_m),
                                  reference_geodesic(graph, terrain.cell_centres_m, goal_m))


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@settings(max_examples=150, deadline=None)
@given(eligible=arrays(bool, st.tuples(st.integers(1, 12), st.integers(1, 12)), elements=st.booleans()),
       cell_m=st.sampled_from([0.1, 0.25, 1.0]),
       goal=st.tuples(st.floats(-5.0, 15.0), st.floats(-5.0, 15.0)) | st.sampled_from(
           [(np.nan, 0.0), (np.inf, 1.0), (1e300, 0.0), (1e17, -1e17)]))
def test_goal_fields_on_random_grids_equal_scipys(eligible: np.ndarray, cell_m: float, goal: tuple) -> None:
    iy, ix = np.indices(eligible.shape)
    centres_m = cell_m * np.stack([ix, iy], axis=-1).astype(np.float64)
    graph, goal_m = GridGraph.of(eligible, cell_m), np.array(goal)
    np.testing.assert_array_equal(graph.geodesic(centres_m, goal_m), reference_geodesic(graph, centres_m, goal_m))


def test_every_module_the_kernels_take_code_from_is_a_source_of_their_cache() -> None:
    """numba re-compiles a cached kernel only when its own file changes: the files whose functions it inlines must be
    in ``KERNEL_SOURCES`` (``drop_stale_caches`` drops the kernels when one changes)."""
    path = Path(terrain_module.__file__)
    compiled_from = {node.module.replace(".", "/") + ".py" for node in ast.walk(ast.parse(path.read_text()))
                     if isinstance(node, ast.ImportFrom) and node.module
                     and node.module.startswith("st_sim.reactive.compiled.")}
    assert compiled_from == {"st_sim/reactive/compiled/exact.py"}
    assert set(terrain_module.KERNEL_SOURCES) == compiled_from | {path.relative_to(path.parents[2]).as_posix()}
