"""Walking distances on a grid round obstacles (``st_sim.reactive.detour``)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from st_sim.reactive.detour import CELL_M, cells_near, grid_cells, nearest_free_m, walking_distance_m

CELLS = grid_cells(np.array([-3.0, -2.0]), np.array([3.0, 2.0]))  # (H, W, 2)
point = st.tuples(st.floats(-2.9, 2.9), st.floats(-1.9, 1.9)).map(np.array)
DRAWS = settings(max_examples=50, deadline=None)


@DRAWS
@given(start=point, goal=point)
def test_on_open_ground_the_walk_is_the_straight_line_within_the_grid_s_grain(start: np.ndarray,
                                                                               goal: np.ndarray) -> None:
    free = np.ones(CELLS.shape[:2], bool)
    walk = walking_distance_m(CELLS, free, goal, start[None])[0]
    straight = np.linalg.norm(goal - start)
    rounding = np.sqrt(2) * CELL_M  # both ends are moved to their cells' centres
    assert straight - rounding - 1e-9 <= walk <= np.sqrt(4 - 2 * np.sqrt(2)) * straight + rounding + 1e-9


@DRAWS
@given(start=point, goal=point, wall_x=st.floats(-2.5, 2.5))
def test_a_wall_across_the_grid_cuts_the_far_side_off(start: np.ndarray, goal: np.ndarray, wall_x: float) -> None:
    free = np.abs(CELLS[..., 0] - wall_x) > CELL_M  # a band two or three cells wide, top to bottom
    walk = walking_distance_m(CELLS, free, goal, start[None])[0]
    start_side, goal_side = np.sign(start[0] - wall_x), np.sign(goal[0] - wall_x)
    if abs(start[0] - wall_x) > 2 * CELL_M and abs(goal[0] - wall_x) > 2 * CELL_M:
        assert np.isinf(walk) == (start_side != goal_side)


@DRAWS
@given(start=point, gap_y=st.floats(-1.5, 1.5))
def test_a_walk_through_a_door_is_at_least_as_long_as_the_way_to_the_door_and_on(start: np.ndarray,
                                                                                   gap_y: float) -> None:
    free = (np.abs(CELLS[..., 0]) > CELL_M) | (np.abs(CELLS[..., 1] - gap_y) < 0.25)  # a wall at x = 0, a door
    goal = np.array([2.5, 0.0])
    walk = walking_distance_m(CELLS, free, goal, start[None])[0]
    if not np.isfinite(walk):
        assert abs(start[0]) <= 2 * CELL_M  # only a start inside the wall is cut off
        return
    door = np.array([0.0, gap_y])
    if start[0] < -2 * CELL_M:
        assert walk >= np.linalg.norm(door - start) + np.linalg.norm(goal - door) - 0.5 - 2 * CELL_M


def test_no_walk_to_a_goal_in_a_wall_nor_from_a_point_off_the_grid() -> None:
    free = np.ones(CELLS.shape[:2], bool)
    free[20, 30] = False
    goal_in_wall = CELLS[20, 30]
    assert np.isinf(walking_distance_m(CELLS, free, goal_in_wall, np.array([[0.0, 0.0], [1.0, 1.0]]))).all()
    walk = walking_distance_m(CELLS, np.ones(CELLS.shape[:2], bool), np.zeros(2),
                              np.array([[10.0, 0.0], [0.0, -5.0], [0.5, 0.0]]))
    assert np.isinf(walk[:2]).all() and np.isclose(walk[2], 0.5)


@DRAWS
@given(goal=point, seed=st.integers(0, 2**31), fill=st.floats(0.0, 1.0))
def test_a_goal_in_a_wall_moves_to_the_nearest_free_cell_and_a_free_one_stays(goal: np.ndarray, seed: int,
                                                                                fill: float) -> None:
    free = np.random.default_rng(seed).random(CELLS.shape[:2]) >= fill
    reachable = nearest_free_m(CELLS, free, goal)
    if not free.any():
        assert np.array_equal(reachable, goal), "with no free cell the goal stays"
        return
    if np.isfinite(walking_distance_m(CELLS, free, goal, goal[None])[0]):  # its own cell is free
        assert np.array_equal(reachable, goal)
        return
    nearest = np.linalg.norm(CELLS[free] - goal, axis=-1).min()
    assert np.isclose(np.linalg.norm(reachable - goal), nearest), "a free cell nearer than the one chosen"
    assert np.isfinite(walking_distance_m(CELLS, free, reachable, reachable[None])[0]), "the goal is not free"


@DRAWS
@given(seed=st.integers(0, 2**31), count=st.integers(0, 12), reach=st.floats(0.05, 0.6))
def test_the_cells_near_some_points_are_those_every_distance_finds(seed: int, count: int, reach: float) -> None:
    points = np.random.default_rng(seed).uniform([-3.5, -2.5], [3.5, 2.5], (count, 2))  # some off the grid
    offset = CELLS.reshape(-1, 2)[:, None] - points[None]
    every = (np.sqrt(offset[..., 0] * offset[..., 0] + offset[..., 1] * offset[..., 1]) < reach).any(axis=1)
    assert np.array_equal(cells_near(CELLS, points, reach).ravel(), every)
