"""Ways round: how far a pedestrian has to walk to a goal when a standing body and walls are in the way.

A pedestrian that chooses its next place one step at a time can walk into a pocket (between a robot and a wall) from
which no single step makes headway. ``walking_distance_m`` gives the length of the shortest walk on a local grid of
free cells, so that a pedestrian stuck in such a pocket can prefer the places from which the goal is nearest on foot
rather than as the crow flies.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Final

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from st_sim.reactive.footprint import length_m

CELL_M: Final[float] = 0.1  # side of a grid cell [m]
NEIGHBOURS: Final[tuple[tuple[int, int], ...]] = ((0, 1), (1, 0), (1, 1), (1, -1))  # with their mirrors: 8 of them


def edge_m(d_row: int, d_col: int) -> float:
    """Length [m] of the edge between two neighbouring cells ``d_row`` rows and ``d_col`` columns apart."""
    return CELL_M * math.sqrt(d_row * d_row + d_col * d_col)


def grid_cells(low_m: np.ndarray, high_m: np.ndarray) -> np.ndarray:
    """(H, W, 2) centres [m] of the ``CELL_M`` cells covering the box from ``low_m`` to ``high_m`` (2,) [m]."""
    xs = np.arange(low_m[0], high_m[0] + CELL_M, CELL_M)
    ys = np.arange(low_m[1], high_m[1] + CELL_M, CELL_M)
    return np.stack(np.meshgrid(xs, ys, indexing="xy"), axis=-1)


def walking_distance_m(cells_m: np.ndarray, free: np.ndarray, goal_m: np.ndarray, points_m: np.ndarray) -> np.ndarray:
    """(P,) length [m] of the shortest walk through ``free`` cells (H, W) bool of the grid ``cells_m`` (H, W, 2) [m]
    (eight neighbours) from each of ``points_m`` (P, 2) [m] to ``goal_m`` (2,) [m], counted from the cells holding
    them; inf for points off the grid, in a cell that is not free or cut off from the goal (all inf when the goal's
    cell is not free)."""
    return walking_distances_m([cells_m], [free], np.asarray(goal_m, np.float64)[None], [points_m])[0]


def walking_distances_m(cells_m: Sequence[np.ndarray], free: Sequence[np.ndarray], goals_m: np.ndarray,
                        points_m: Sequence[np.ndarray]) -> list[np.ndarray]:
    """``walking_distance_m`` on G grids at once: grid g is ``cells_m[g]`` (H_g, W_g, 2) [m] with ``free[g]``
    (H_g, W_g) bool, its goal ``goals_m[g]`` (G, 2) [m] and its points ``points_m[g]`` (P_g, 2) [m]. The grids are
    parts of one graph that share no edge, searched from all their goals in one pass: each cell's walk is to the goal
    of its own grid, as alone."""
    shapes = np.array([open_.shape for open_ in free]).reshape(-1, 2)  # (G, 2) rows, columns
    base = np.r_[0, np.cumsum(shapes.prod(axis=1))]  # where each grid's cells start, row by row
    sources, where = [], []
    for g, (cells, open_, goal, points) in enumerate(zip(cells_m, free, goals_m, points_m, strict=True)):
        rows, cols = _cell(cells[0, 0], points)
        inside = (rows >= 0) & (rows < shapes[g, 0]) & (cols >= 0) & (cols < shapes[g, 1])
        goal_row, goal_col = _cell(cells[0, 0], goal)
        reachable = (0 <= goal_row[0] < shapes[g, 0] and 0 <= goal_col[0] < shapes[g, 1]
                     and open_[goal_row[0], goal_col[0]])
        where.append((base[g] + (rows * shapes[g, 1] + cols) * inside, inside & reachable))
        if reachable:
            sources.append(int(base[g] + goal_row[0] * shapes[g, 1] + goal_col[0]))
    distance = np.full(base[-1], np.inf)
    if sources:
        starts, ends, lengths = [], [], []
        for g, open_ in enumerate(free):
            node = base[g] + np.arange(open_.size).reshape(open_.shape)
            for d_row, d_col in NEIGHBOURS:  # the edges between free cells, each once, from each cell to its neighbour
                there = (slice(max(d_row, 0), open_.shape[0] + min(d_row, 0)),
                         slice(max(d_col, 0), open_.shape[1] + min(d_col, 0)))
                here = (slice(max(-d_row, 0), open_.shape[0] + min(-d_row, 0)),
                        slice(max(-d_col, 0), open_.shape[1] + min(-d_col, 0)))
                both = open_[here] & open_[there]
                starts.append(node[here][both])
                ends.append(node[there][both])
                lengths.append(np.full(len(starts[-1]), edge_m(d_row, d_col)))
        graph = csr_matrix((np.concatenate(lengths), (np.concatenate(starts), np.concatenate(ends))),
                           shape=(base[-1], base[-1]))
        distance = dijkstra(graph, directed=False, indices=sources, min_only=True)
    return [np.where(found, distance[nodes], np.inf) for nodes, found in where]


def cells_near(cells_m: np.ndarray, points_m: np.ndarray, reach_m: float) -> np.ndarray:
    """(H, W) bool: the cells of the grid ``cells_m`` (H, W, 2) [m] whose centres lie closer than ``reach_m`` [m] to
    any of ``points_m`` (K, 2) [m] (each looked for only in the cells round it)."""
    near = np.zeros(cells_m.shape[:2], bool)
    span = np.arange(-int(np.ceil(reach_m / CELL_M)) - 1, int(np.ceil(reach_m / CELL_M)) + 2)
    d_row, d_col = (d.ravel() for d in np.meshgrid(span, span, indexing="ij"))
    row, col = _cell(cells_m[0, 0], points_m)
    rows, cols = row[:, None] + d_row, col[:, None] + d_col  # (K, S) the cells round each point
    inside = (rows >= 0) & (rows < near.shape[0]) & (cols >= 0) & (cols < near.shape[1])
    rows, cols, which = rows[inside], cols[inside], np.nonzero(inside)[0]
    offset = cells_m[rows, cols] - points_m[which]
    close = np.sqrt(offset[:, 0] * offset[:, 0] + offset[:, 1] * offset[:, 1]) < reach_m
    near[rows[close], cols[close]] = True
    return near


def nearest_free_m(cells_m: np.ndarray, free: np.ndarray, point_m: np.ndarray) -> np.ndarray:
    """(2,) ``point_m`` (2,) [m] if its cell of the grid ``cells_m`` (H, W, 2) [m] is ``free`` (H, W) bool, else the
    centre of the free cell nearest to it (the point itself where no cell is free): a goal a walk can reach."""
    row, col = _cell(cells_m[0, 0], point_m)
    if (0 <= row[0] < free.shape[0] and 0 <= col[0] < free.shape[1] and free[row[0], col[0]]) or not free.any():
        return np.asarray(point_m, np.float64)
    centres = cells_m[free]
    return centres[np.argmin(length_m(centres - point_m))]


def _cell(origin_m: np.ndarray, xy_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row, column) (P,) each of the cells holding points ``xy_m`` (P, 2) or (2,) [m] of a grid whose first cell's
    centre is ``origin_m`` (2,) [m]."""
    col, row = np.rint((np.atleast_2d(np.asarray(xy_m, np.float64)) - origin_m) / CELL_M).astype(np.intp).T
    return row, col
