"""The terrain's geodesic cost-to-go (``envs.common.terrain.GridGraph``): on random grids it equals shortest paths
found by plain relaxation, and one goal's edges never leak into the next goal's field."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from envs.common.terrain import MOVES, SOURCE_REACH_M, GridGraph

CELL_M = 0.1


def relaxed(eligible: np.ndarray, centres_m: np.ndarray, goal_m: np.ndarray) -> np.ndarray:
    """Reference: Bellman-Ford over the same moves (both ways, passed cells eligible), the goal feeding the eligible
    cells within SOURCE_REACH_M (or the nearest one) by their straight distance."""
    height, width = eligible.shape
    to_goal = np.linalg.norm(centres_m - goal_m, axis=-1)
    feeds = eligible & (to_goal <= SOURCE_REACH_M)
    if not feeds.any() and eligible.any():
        feeds = eligible & (to_goal == to_goal[eligible].min())
    cost = np.where(feeds, np.maximum(to_goal, 1e-6), np.inf)
    edges = []
    for (dy, dx), passed in MOVES.items():
        for sign in (1, -1):
            passed_here = [(sign * py, sign * px) for py, px in passed]
            edges.append((sign * dy, sign * dx, passed_here, CELL_M * np.hypot(dy, dx)))
    for _ in range(eligible.size):
        before = cost.copy()
        for y, x in zip(*np.nonzero(eligible), strict=True):
            for dy, dx, passed, length in edges:
                cells = [(y + dy, x + dx)] + [(y + py, x + px) for py, px in passed]
                if all(0 <= cy < height and 0 <= cx < width and eligible[cy, cx] for cy, cx in cells):
                    cost[y, x] = min(cost[y, x], cost[y + dy, x + dx] + length)
        if np.array_equal(before, cost):
            break
    return cost


@settings(max_examples=25, deadline=None)
@given(eligible=arrays(bool, st.tuples(st.integers(1, 7), st.integers(1, 7)), elements=st.booleans()),
       goals=st.lists(st.tuples(st.floats(-0.2, 0.8), st.floats(-0.2, 0.8)), min_size=2, max_size=3))
def test_goal_fields_are_shortest_paths_and_each_goal_starts_afresh(eligible: np.ndarray, goals: list) -> None:
    iy, ix = np.indices(eligible.shape)
    centres_m = CELL_M * np.stack([ix, iy], axis=-1).astype(np.float64)
    graph = GridGraph.of(eligible, CELL_M)
    for goal in goals:
        goal_m = np.array(goal)
        field = graph.geodesic(centres_m, goal_m)
        expected = relaxed(eligible, centres_m, goal_m)
        assert field.shape == eligible.shape
        assert np.array_equal(np.isfinite(field), np.isfinite(expected))
        np.testing.assert_allclose(field[np.isfinite(field)], expected[np.isfinite(expected)], rtol=1e-12, atol=1e-12)
    assert graph.moves[-1].nnz == 0, "the shared graph keeps no goal's edges"
