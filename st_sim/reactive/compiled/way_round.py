"""The way round compiled: how far a pedestrian planning a way round the robot would walk from each of its candidate
places to a point of its route ahead (``candidates._way_round_m``), on the grid of ``st_sim.reactive.detour`` with the
same cells and, from a Dijkstra search of its own, the same distances (a shortest walk's length is the one fixed point
of ``d(v) = min over neighbours u of d(u) + edge``, whatever the search's order; the search stops once the cells of
the candidate places are settled)."""

from __future__ import annotations

import numpy as np
from numba import njit

from st_sim.reactive.candidates import DETOUR_AHEAD_M, DETOUR_BACK_FRAMES, DETOUR_LEAD_STEPS, DETOUR_MARGIN_M
from st_sim.reactive.compiled.exact import arange, first_of_least, length, maximum, minimum
from st_sim.reactive.compiled.tables import RouteTables, clear_of_robot, depth_window, place, tau_ahead, too_deep
from st_sim.reactive.detour import CELL_M, edge_m
from st_sim.reactive.footprint import PAIR_BODY_M

AHEAD_M = np.array(DETOUR_AHEAD_M)
STRAIGHT_M = edge_m(0, 1)  # the edges of ``detour.walking_distances_m`` [m]
DIAGONAL_M = edge_m(1, 1)
NEAR_CELLS = int(np.ceil(PAIR_BODY_M / CELL_M)) + 1  # cells each side of a point that ``detour.cells_near`` looks at


@njit(cache=True, inline="always")
def _cell(origin: float, value: float) -> int:
    """Column (x) or row (y) of the grid cell holding ``value`` [m], the first cell's centre at ``origin`` [m]."""
    return int(np.rint((value - origin) / CELL_M))


@njit(cache=True)
def _shortest_walks(free: np.ndarray, goal_row: int, goal_col: int, wanted: np.ndarray) -> np.ndarray:
    """(H, W) length [m] of the shortest walk through the ``free`` cells (H, W) bool (eight neighbours) from each
    cell to the goal's (inf where none), exact at least for the cells ``wanted`` (H, W) bool.

    Cells wait in buckets ``CELL_M`` wide by their distance, nearest first (no step is shorter: a cell is settled
    when its bucket comes, as in Dijkstra's search, without a heap); one whose distance drops again (a rounding at a
    bucket's edge) waits again, so that every distance ends at the fixed point. The search stops once the bucket
    reached lies beyond every ``wanted`` cell's distance."""
    rows, cols = free.shape
    size = rows * cols
    distance = np.full(size, np.inf)
    slot = np.full(size, -1, np.int64)  # the bucket each cell waits in, -1 none
    buckets = int(np.ceil((rows + cols) * DIAGONAL_M / STRAIGHT_M)) + 2
    head = np.full(buckets, -1, np.int64)
    entry_node, entry_next = np.empty(8 * size + 1, np.int64), np.empty(8 * size + 1, np.int64)
    wanted_nodes = (wanted & free).ravel()
    goal = goal_row * cols + goal_col
    distance[goal], slot[goal], entries = 0.0, 0, 1
    entry_node[0], entry_next[0], head[0] = goal, -1, 0
    for bucket in range(buckets):
        while head[bucket] >= 0:
            entry = head[bucket]
            head[bucket] = entry_next[entry]
            node = entry_node[entry]
            if slot[node] != bucket:  # it waits elsewhere now
                continue
            slot[node] = -1
            row, col = node // cols, node % cols
            for d_row in range(-1, 2):
                for d_col in range(-1, 2):
                    r, c = row + d_row, col + d_col
                    if (d_row == 0 and d_col == 0) or r < 0 or r >= rows or c < 0 or c >= cols or not free[r, c]:
                        continue
                    there = r * cols + c
                    walked = distance[node] + (STRAIGHT_M if d_row == 0 or d_col == 0 else DIAGONAL_M)
                    if not walked < distance[there]:
                        continue
                    distance[there] = walked
                    slot[there] = min(max(int(walked / STRAIGHT_M), bucket), buckets - 1)
                    entry_node[entries], entry_next[entries] = there, head[slot[there]]
                    head[slot[there]] = entries
                    entries += 1
        settled = True  # every wanted cell nearer than the next bucket, and none waiting to be nearer
        for node in range(size):
            if wanted_nodes[node] and (slot[node] >= 0 or not distance[node] < (bucket + 1) * STRAIGHT_M):
                settled = False
                break
        if settled:
            break
    return distance.reshape(rows, cols)


@njit(cache=True)
def way_round(t: RouteTables, agent: int, index: int, tau: float, farthest: float, places: np.ndarray,
              start: np.ndarray, robot: np.ndarray, standing: np.ndarray) -> np.ndarray:
    """(C,) how far [m] the chooser ``agent`` at route point ``tau`` (its farthest ``farthest``, ``start`` (2,) where
    it stands) would walk from each of its ``places`` (C, 2) to its route ahead round the robot (``robot``: from x,
    y, to x, y, cos, sin of its heading, ...) and the others standing at ``standing`` (S, 2), counted from the
    nearest (``candidates._way_round_m``)."""
    log, tangent, arc_m = t.log_xy_m[:, agent], t.tangent[:, agent], t.arc_m[:, agent]
    trace, trace_depth = t.trace_m[:, agent], t.trace_depth_m[:, agent]
    depth_m, to_pixel, affine, open_ground = t.depth_m, t.to_pixel, t.affine, t.open_ground
    half_m, radius_m, reach_m = t.half_m, t.radius_m, t.robot_reach_m
    run_frame = int(tau)
    first, last = t.run_first[run_frame, agent], t.run_last[run_frame, agent]
    pick, goal_tau, goal_x, goal_y = -1, 0.0, 0.0, 0.0
    for k in range(len(AHEAD_M)):  # the first point ahead clear of the robot, else the farthest
        ahead = minimum(tau_ahead(arc_m, first, last, farthest, AHEAD_M[k]), float(index + DETOUR_LEAD_STEPS))
        x, y = place(log, tangent, first, last, ahead, 0.0)
        if pick < 0 and (clear_of_robot(half_m, radius_m, reach_m, x, y, robot) or k == len(AHEAD_M) - 1):
            pick, goal_tau, goal_x, goal_y = k, ahead, x, y
    back = maximum(float(first), tau - DETOUR_BACK_FRAMES)
    low_x, low_y = minimum(goal_x, start[0]), minimum(goal_y, start[1])
    high_x, high_y = maximum(goal_x, start[0]), maximum(goal_y, start[1])
    for c in range(places.shape[0]):
        low_x, low_y = minimum(low_x, places[c, 0]), minimum(low_y, places[c, 1])
        high_x, high_y = maximum(high_x, places[c, 0]), maximum(high_y, places[c, 1])
    for frame in range(int(back), min(int(np.ceil(goal_tau)) + 1, log.shape[0])):
        low_x, low_y = minimum(low_x, log[frame, 0]), minimum(low_y, log[frame, 1])
        high_x, high_y = maximum(high_x, log[frame, 0]), maximum(high_y, log[frame, 1])
    xs = arange(low_x - DETOUR_MARGIN_M, high_x + DETOUR_MARGIN_M + CELL_M, CELL_M)
    ys = arange(low_y - DETOUR_MARGIN_M, high_y + DETOUR_MARGIN_M + CELL_M, CELL_M)
    rows, cols = len(ys), len(xs)
    free = np.empty((rows, cols), np.bool_)
    for r in range(rows):
        for c in range(cols):
            free[r, c] = clear_of_robot(half_m, radius_m, reach_m, xs[c], ys[r], robot)
    for s in range(standing.shape[0]):  # those standing there block their cells, as close as a step may come
        row, col = _cell(ys[0], standing[s, 1]), _cell(xs[0], standing[s, 0])
        for r in range(max(row - NEAR_CELLS, 0), min(row + NEAR_CELLS + 1, rows)):
            for c in range(max(col - NEAR_CELLS, 0), min(col + NEAR_CELLS + 1, cols)):
                if length(xs[c] - standing[s, 0], ys[r] - standing[s, 1]) < PAIR_BODY_M:
                    free[r, c] = False
    any_free = False
    window = depth_window(trace_depth, first, last, back, goal_tau, True)  # over ground no deeper than its log
    for r in range(rows):
        for c in range(cols):
            if free[r, c]:
                free[r, c] = too_deep(trace, trace_depth, window, depth_m, to_pixel, affine, open_ground, xs[c], ys[r],
                                      True) == 0
                any_free = any_free or free[r, c]
    # the goal a walk can reach: its cell if free, else the centre of the free cell nearest to it
    row, col = _cell(ys[0], goal_y), _cell(xs[0], goal_x)
    if any_free and not (0 <= row < rows and 0 <= col < cols and free[row, col]):
        best, found, near_x, near_y = np.inf, False, goal_x, goal_y
        for r in range(rows):
            for c in range(cols):
                if free[r, c]:
                    distance = length(xs[c] - goal_x, ys[r] - goal_y)
                    if first_of_least(distance, best, found):
                        best, near_x, near_y, found = distance, xs[c], ys[r], True
        row, col = _cell(ys[0], near_y), _cell(xs[0], near_x)
    walk = np.full(places.shape[0], np.inf)
    if 0 <= row < rows and 0 <= col < cols and free[row, col]:
        wanted = np.zeros((rows, cols), np.bool_)
        for c in range(places.shape[0]):
            r, k = _cell(ys[0], places[c, 1]), _cell(xs[0], places[c, 0])
            if 0 <= r < rows and 0 <= k < cols:
                wanted[r, k] = True
        walks = _shortest_walks(free, row, col, wanted)
        for c in range(places.shape[0]):
            r, k = _cell(ys[0], places[c, 1]), _cell(xs[0], places[c, 0])
            if 0 <= r < rows and 0 <= k < cols:
                walk[c] = walks[r, k]
    nearest, farthest_m, known = np.inf, -np.inf, False
    for c in range(places.shape[0]):
        if np.isfinite(walk[c]):
            nearest, farthest_m, known = minimum(nearest, walk[c]), maximum(farthest_m, walk[c]), True
    way = np.zeros(places.shape[0])
    if known:
        for c in range(places.shape[0]):
            way[c] = walk[c] - nearest if np.isfinite(walk[c]) else farthest_m - nearest + 1.0
    return way
