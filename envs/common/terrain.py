"""The walkability map as a robot sees it: a metric grid with wall clearance, range readings and a geodesic cost-to-go.

The scene's map is sampled at the centres of square cells (``cell_m``) over the env's bounds (``CrowdEnv.bounds_m``),
so distances are in metres even where the homography has perspective (ETH, HOTEL). Off-map points count as walls.

The cost-to-go of points, the directions along the path and the goal fields are compiled (numba: ``_costs``,
``_directions``, ``_geodesic``): every number is rounded as the numpy and scipy code before them rounded it
(``st_sim.reactive.compiled.exact``), so that an argmin over headings never flips on a tie;
``tests/test_terrain_compiled.py`` holds that code and checks the kernels against it, bit for bit. The kernels are
cached on disk (this package's ``__pycache__``) and dropped when a file of ``KERNEL_SOURCES`` changes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit
from scipy import ndimage
from scipy.sparse import coo_matrix, csr_matrix

from replays.scenes import Scene
from st_sim.reactive.compiled import drop_stale_caches
from st_sim.reactive.compiled.exact import first_of_least, length, maximum, minimum
from st_sim.sim.exact import rounded_cos_sin

KERNEL_SOURCES = ("envs/common/terrain.py", "st_sim/reactive/compiled/exact.py")
"""the files the kernels take code from: numba re-compiles a kernel when its own file changes, not when a function it
inlined from another does (``drop_stale_caches``)"""
drop_stale_caches(Path(__file__).parent, Path(__file__).parents[2], KERNEL_SOURCES)

CELL_M = 0.1  # grid spacing [m]
# 16-neighbourhood, one direction per pair: move (dy, dx) -> cells it passes, which must be eligible too;
# grid paths are then within 3 % of straight lines and never cut a wall's corner
MOVES: dict[tuple[int, int], tuple[tuple[int, int], ...]] = {
    (0, 1): (), (1, 0): (),
    (1, 1): ((0, 1), (1, 0)), (1, -1): ((0, -1), (1, 0)),
    (1, 2): ((0, 1), (1, 1)), (2, 1): ((1, 0), (1, 1)), (1, -2): ((0, -1), (1, -1)), (2, -1): ((1, 0), (1, -1)),
}
LONGEST_MOVE = max(float(np.sqrt(dy * dy + dx * dx)) for dy, dx in MOVES)  # the longest move's length [cells]
SOURCE_REACH_M = 1.0  # the goal feeds every eligible cell this close to it [m]
UNREACHABLE_PENALTY_M = 100.0  # cost-to-go of a point with no grid path: its straight distance plus this [m]
_ANGLES = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
HEADINGS = np.stack(rounded_cos_sin(_ANGLES), axis=1)  # (64, 2) candidate directions of direction_to
LOOKAHEAD_M = 0.5  # direction_to compares the cost-to-go this far ahead [m]
GOAL_FIELDS_KEPT = 16  # cost-to-go fields kept, one per goal (sub-envs of a vector env may head to different goals)
LOOKUP_CELLS = 1  # cost-to-go of a point = least (cell cost + distance to the cell) over (2R+1)^2 cells
_INTP_RANGE = 2.0 ** 63  # numpy casts floats beyond [-2^63, 2^63), and NaN, to the least intp (x86-64): cell 0


class Terrain:
    """Wall clearance of a scene on a metric grid, and geodesic cost-to-go fields to goals.

    Args:
        scene: walkability map with its homography.
        bounds_m: (xmin, ymin, xmax, ymax) metres covered by the grid (the env's arena or layout bounds).
        cell_m: grid spacing [m].

    Attributes:
        origin_m: (2,) centre of cell (0, 0) [m].
        free: (Gy, Gx) bool, walkable cell centres.
        clearance_m: (Gy, Gx) float64 distance from each cell centre to the nearest non-walkable cell [m]
            (0 on non-walkable cells; the grid's outside counts as non-walkable).
        cell_centres_m: (Gy, Gx, 2) the cells' centres [m].
    """

    def __init__(self, scene: Scene, bounds_m: tuple[float, float, float, float], cell_m: float = CELL_M):
        xmin, ymin, xmax, ymax = (float(b) for b in bounds_m)
        self.cell_m = cell_m
        self.origin_m = np.array([xmin, ymin])
        shape = (int(np.ceil((ymax - ymin) / cell_m)) + 1, int(np.ceil((xmax - xmin) / cell_m)) + 1)
        iy, ix = np.indices(shape)
        self.cell_centres_m = self.origin_m + cell_m * np.stack([ix, iy], axis=-1)
        self.free = scene.is_walkable(self.cell_centres_m)
        padded = np.pad(self.free, 1, constant_values=False)
        self.clearance_m = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * cell_m
        self._goal_fields: dict[tuple, np.ndarray] = {}  # goal key -> cost-to-go field, least recently used first
        self._grids: dict[float, GridGraph] = {}  # body radius -> the moves between its eligible cells

    def __repr__(self) -> str:
        return f"Terrain({self.free.shape[1]}x{self.free.shape[0]} cells of {self.cell_m} m)"

    def _cells(self, xy_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(..., 2) metres -> row, column (...) clipped to the grid, and (...) bool inside the grid."""
        ij = np.rint((np.asarray(xy_m, np.float64) - self.origin_m) / self.cell_m).astype(np.intp)
        height, width = self.free.shape
        inside = (ij[..., 0] >= 0) & (ij[..., 0] < width) & (ij[..., 1] >= 0) & (ij[..., 1] < height)
        return np.clip(ij[..., 1], 0, height - 1), np.clip(ij[..., 0], 0, width - 1), inside

    def clearance_at(self, xy_m: np.ndarray) -> np.ndarray:
        """(..., 2) metres -> (...) distance to the nearest wall [m]; 0 off the grid."""
        row, col, inside = self._cells(xy_m)
        return np.where(inside, self.clearance_m[row, col], 0.0)

    def free_distances_m(self, xy_m: np.ndarray, directions: np.ndarray, body_m: float, range_m: float,
                         step_m: float) -> np.ndarray:
        """Range readings: how far each point can go along each direction before a body of radius ``body_m`` would
        touch a wall (0: before its centre leaves walkable ground), sampled every ``step_m`` up to ``range_m``.

        Args:
            xy_m: (B, 2) points [m].  directions: (B, R, 2) unit vectors, world frame.

        Returns:
            (B, R) float64 metres in [0, range_m]: the last free sample before the first blocked one, ``range_m``
            if none is blocked.
        """
        reach = np.arange(1, int(range_m / step_m) + 1) * step_m  # (D,)
        points = xy_m[:, None, None] + directions[:, :, None] * reach[:, None]  # (B, R, D, 2)
        blocked = self.clearance_at(points) <= body_m
        return np.where(blocked.any(axis=2), reach[np.argmax(blocked, axis=2)] - step_m, range_m)

    def cost_to_go(self, xy_m: np.ndarray, goal_m: np.ndarray, body_m: float) -> np.ndarray:
        """Geodesic distance [m] from points to the goal along cells with ``body_m`` of wall clearance: the least
        (cell's cost-to-go + distance to its centre) over the (2 LOOKUP_CELLS + 1)^2 cells round the point's.

        Args:
            xy_m: (..., 2) points, metres.  goal_m: (2,) metres.  body_m: the robot's radius [m].

        Returns:
            (...) float64 metres; a point with no grid path gets its straight distance + 100 m.
        """
        goal_m = np.asarray(goal_m, np.float64)
        cost = self._goal_field(goal_m, body_m)
        xy_m = np.asarray(xy_m, np.float64)
        points = np.ascontiguousarray(xy_m.reshape(-1, 2))
        return _costs(points, goal_m, cost, self.origin_m, self.cell_m, self.cell_centres_m).reshape(xy_m.shape[:-1])

    def direction_to(self, xy_m: np.ndarray, goal_m: np.ndarray, body_m: float) -> np.ndarray:
        """(2,) unit vector from ``xy_m`` (2,) along the shortest walkable path to the goal (zeros at the goal).

        The first of the least of HEADINGS by the cost-to-go one LOOKAHEAD_M ahead (or at the goal, if nearer).
        """
        return self.directions_to(np.asarray(xy_m, np.float64)[None], np.asarray(goal_m, np.float64)[None],
                                  body_m)[0]

    def directions_to(self, xy_m: np.ndarray, goal_m: np.ndarray, body_m: float) -> np.ndarray:
        """(B, 2) ``direction_to`` of B points (B, 2) [m], each toward its own goal (B, 2) [m] (float64)."""
        xy_m, goal_m = np.ascontiguousarray(xy_m, np.float64), np.ascontiguousarray(goal_m, np.float64)
        out = np.zeros_like(xy_m)
        rows: dict[tuple[float, float], list[int]] = {}  # goal -> the points heading to it
        for b, goal in enumerate(goal_m.tolist()):
            rows.setdefault(tuple(goal), []).append(b)
        for goal in sorted(rows):  # the fields in the order of the goals, as np.unique has them
            _directions(xy_m, goal_m, np.array(rows[goal], np.intp), self._goal_field(np.array(goal), body_m),
                        self.origin_m, self.cell_m, self.cell_centres_m, out)
        return out

    def grid_graph(self, body_m: float) -> GridGraph:
        """The moves between the cells with ``body_m`` of wall clearance, built on first use and kept."""
        if body_m not in self._grids:
            spacing_m = (self.origin_m[0] + self.cell_m) - self.origin_m[0]  # as the centres have it, to the bit
            self._grids[body_m] = GridGraph.of(self.clearance_m >= body_m, float(spacing_m))
        return self._grids[body_m]

    def _goal_field(self, goal_m: np.ndarray, body_m: float) -> np.ndarray:
        """(Gy, Gx) geodesic distance to ``goal_m`` [m] over cells with ``body_m`` of clearance; the last
        ``GOAL_FIELDS_KEPT`` goals' fields are kept."""
        key = (*np.round(goal_m, 6).tolist(), body_m)
        field = self._goal_fields.pop(key, None)
        if field is None:
            field = self.grid_graph(body_m).geodesic(self.cell_centres_m, goal_m)
        self._goal_fields[key] = field  # most recently used last
        while len(self._goal_fields) > GOAL_FIELDS_KEPT:
            self._goal_fields.pop(next(iter(self._goal_fields)))
        return field


@dataclass(frozen=True)
class GridGraph:
    """The moves (``MOVES``, both ways) between the eligible cells of a grid, as a CSR graph with one more node, the
    goal's, whose edges (to the cells near each goal) are not stored: ``geodesic`` feeds those cells directly.

    Attributes:
        eligible: (Gy, Gx) bool cells a path may use.
        cell_m: the cells' spacing [m].
        cells: (C,) their flat indices.
        moves: (N + 1, N + 1) CSR over the N = Gy * Gx cells and the goal's node, last and without edges.
    """

    eligible: np.ndarray
    cell_m: float
    cells: np.ndarray
    moves: csr_matrix

    @classmethod
    def of(cls, eligible: np.ndarray, cell_m: float) -> GridGraph:
        """The graph of ``eligible`` (Gy, Gx) cells ``cell_m`` [m] apart."""
        cells = np.flatnonzero(eligible)
        width = eligible.shape[1]
        padded = np.pad(eligible, 2, constant_values=False)
        y, x = np.divmod(cells, width)
        heads, tails, lengths = [], [], []
        for (dy, dx), passed in MOVES.items():
            ok = padded[y + 2 + dy, x + 2 + dx]
            for py, px in passed:
                ok &= padded[y + 2 + py, x + 2 + px]
            heads.append(cells[ok])
            tails.append(cells[ok] + dy * width + dx)
            lengths.append(np.full(int(ok.sum()), cell_m * np.sqrt(dy * dy + dx * dx)))
        heads, tails, lengths = np.concatenate(heads), np.concatenate(tails), np.concatenate(lengths)
        nodes = eligible.size + 1
        moves = coo_matrix((np.r_[lengths, lengths], (np.r_[heads, tails], np.r_[tails, heads])),
                           shape=(nodes, nodes)).tocsr()
        return cls(eligible, cell_m, cells, moves)

    def geodesic(self, centres_m: np.ndarray, goal_m: np.ndarray) -> np.ndarray:
        """(Gy, Gx) Dijkstra distance [m] from ``goal_m`` (2,) over the eligible cells (inf elsewhere), ``centres_m``
        (Gy, Gx, 2) the cells' centres.

        The goal is a node joined to every eligible cell within SOURCE_REACH_M (or to the nearest eligible cell) by
        its straight distance, so a goal beside a wall still gets a field. Compiled (``_geodesic``): the same floats
        as ``scipy.sparse.csgraph.dijkstra`` on the graph with the goal's edges.
        """
        centres_m = np.ascontiguousarray(centres_m, np.float64).reshape(-1, 2)
        return _geodesic(self.moves.indptr, self.moves.indices, self.moves.data, self.cells, centres_m,
                         np.asarray(goal_m, np.float64), self.cell_m).reshape(self.eligible.shape)


@njit(cache=True, inline="always")
def _cell(x_m: float, origin_m: float, cell_m: float, size: int) -> int:
    """The grid index [0, size) of the coordinate ``x_m`` [m] as ``Terrain._cells`` has it: ``np.rint`` (half to
    even), numpy's cast to intp, clipped."""
    rounded = np.rint((x_m - origin_m) / cell_m)
    index = int(rounded) if -_INTP_RANGE <= rounded < _INTP_RANGE else 0
    return min(max(index, 0), size - 1)


@njit(cache=True, inline="always")
def _cost_at(x_m: float, y_m: float, goal_x_m: float, goal_y_m: float, cost: np.ndarray, origin_m: np.ndarray,
             cell_m: float, centres_m: np.ndarray) -> float:
    """``Terrain.cost_to_go`` [m] of the point (x, y) [m] toward the goal, ``cost`` (Gy, Gx) the goal's field [m],
    ``centres_m`` (Gy, Gx, 2) the cells' centres [m]."""
    height, width = cost.shape
    row, col = _cell(y_m, origin_m[1], cell_m, height), _cell(x_m, origin_m[0], cell_m, width)
    best = np.inf
    for dy in range(-LOOKUP_CELLS, LOOKUP_CELLS + 1):
        r = min(max(row + dy, 0), height - 1)
        for dx in range(-LOOKUP_CELLS, LOOKUP_CELLS + 1):
            c = min(max(col + dx, 0), width - 1)
            best = minimum(best, cost[r, c] + length(x_m - centres_m[r, c, 0], y_m - centres_m[r, c, 1]))
    if np.isfinite(best):
        return best
    return length(x_m - goal_x_m, y_m - goal_y_m) + UNREACHABLE_PENALTY_M


@njit(cache=True)
def _costs(xy_m: np.ndarray, goal_m: np.ndarray, cost: np.ndarray, origin_m: np.ndarray, cell_m: float,
           centres_m: np.ndarray) -> np.ndarray:
    """(P,) ``Terrain.cost_to_go`` [m] of P points (P, 2) [m] toward ``goal_m`` (2,) [m], whose field is ``cost``."""
    out = np.empty(xy_m.shape[0])
    for p in range(xy_m.shape[0]):
        out[p] = _cost_at(xy_m[p, 0], xy_m[p, 1], goal_m[0], goal_m[1], cost, origin_m, cell_m, centres_m)
    return out


@njit(cache=True)
def _directions(xy_m: np.ndarray, goal_m: np.ndarray, rows: np.ndarray, cost: np.ndarray, origin_m: np.ndarray,
                cell_m: float, centres_m: np.ndarray, out: np.ndarray) -> None:
    """Write into ``out`` (B, 2) ``Terrain.direction_to`` of the points ``xy_m[rows]`` (B, 2) [m] toward their goals
    ``goal_m[rows]`` (B, 2) [m], which share the field ``cost`` (Gy, Gx) [m]: the first of the least HEADINGS by the
    cost-to-go at most LOOKAHEAD_M ahead, zeros within 1e-6 m of the goal (or for NaN)."""
    for b in rows:
        x_m, y_m, goal_x_m, goal_y_m = xy_m[b, 0], xy_m[b, 1], goal_m[b, 0], goal_m[b, 1]
        reach_m = minimum(LOOKAHEAD_M, length(goal_x_m - x_m, goal_y_m - y_m))
        if not reach_m >= 1e-6:
            out[b, 0], out[b, 1] = 0.0, 0.0
            continue
        chosen, least = 0, np.inf
        for k in range(HEADINGS.shape[0]):
            value = _cost_at(x_m + reach_m * HEADINGS[k, 0], y_m + reach_m * HEADINGS[k, 1], goal_x_m, goal_y_m,
                             cost, origin_m, cell_m, centres_m)
            if first_of_least(value, least, k > 0):
                chosen, least = k, value
        out[b, 0], out[b, 1] = HEADINGS[chosen, 0], HEADINGS[chosen, 1]


@njit(cache=True)
def _geodesic(indptr: np.ndarray, indices: np.ndarray, lengths: np.ndarray, cells: np.ndarray,
              centres_m: np.ndarray, goal_m: np.ndarray, cell_m: float) -> np.ndarray:
    """(N,) ``GridGraph.geodesic`` [m] of the N cells, ``indptr``, ``indices``, ``lengths`` the CSR of their moves
    [m] (N + 1 rows: the goal's node, last, has none), ``cells`` (C,) the eligible ones, ``centres_m`` (N, 2) their
    centres [m], ``goal_m`` (2,) [m].

    Dial's buckets, ``cell_m`` wide (the shortest move), with a node whose distance drops while queued moved to its
    new bucket, and one whose distance drops after it was expanded queued again. The distances settle on the one
    fixed point dist[v] = min(source[v], min over moves u -> v of dist[u] + length) (positive lengths, each sum
    rounded), which every correct shortest-path search reaches, scipy's Dijkstra included: the same floats.
    """
    dist = np.full(centres_m.shape[0], np.inf)
    near, nearest_m = False, np.inf  # some cell within SOURCE_REACH_M; the least straight distance [m]
    for i in range(cells.size):
        to_goal_m = length(centres_m[cells[i], 0] - goal_m[0], centres_m[cells[i], 1] - goal_m[1])
        near = near or to_goal_m <= SOURCE_REACH_M
        nearest_m = minimum(nearest_m, to_goal_m)
    base_m, top_m = np.inf, 0.0  # the least and the greatest distance fed [m]
    for i in range(cells.size):  # the goal's edges: 0 + their length < inf, as Dijkstra relaxes them
        to_goal_m = length(centres_m[cells[i], 0] - goal_m[0], centres_m[cells[i], 1] - goal_m[1])
        if (to_goal_m <= SOURCE_REACH_M if near else to_goal_m == nearest_m) and to_goal_m < np.inf:
            dist[cells[i]] = maximum(to_goal_m, 1e-6)  # a zero weight would be no edge
            base_m, top_m = min(base_m, dist[cells[i]]), max(top_m, dist[cells[i]])
    # the queue: a ring of buckets (absolute bucket b at b & mask), each a doubly linked list of nodes (after,
    # before: -1 at its ends); slot: a queued node's absolute bucket, -1 for a node not queued
    mask = (1 << int(np.ceil(np.log2(max((top_m - base_m) / cell_m, LONGEST_MOVE) + 3)))) - 1
    head = np.full(mask + 1, -1, np.int32)
    after, before = np.empty(dist.size, np.int32), np.empty(dist.size, np.int32)
    slot = np.full(dist.size, -1, np.int64)
    queued, bucket = 0, 0
    for i in range(cells.size):
        v = cells[i]
        if dist[v] < np.inf:
            slot[v] = int((dist[v] - base_m) / cell_m)
            after[v], before[v] = head[slot[v] & mask], -1
            if after[v] >= 0:
                before[after[v]] = v
            head[slot[v] & mask] = v
            queued += 1
    while queued:
        u = head[bucket & mask]
        if u < 0:
            bucket += 1
            continue
        head[bucket & mask] = after[u]  # u leaves the queue, first of its bucket
        if after[u] >= 0:
            before[after[u]] = -1
        slot[u] = -1
        queued -= 1
        from_m = dist[u]
        for e in range(indptr[u], indptr[u + 1]):
            v, reached_m = indices[e], from_m + lengths[e]
            if reached_m >= dist[v]:
                continue
            dist[v] = reached_m
            if slot[v] >= 0:  # v leaves its bucket
                if before[v] >= 0:
                    after[before[v]] = after[v]
                else:
                    head[slot[v] & mask] = after[v]
                if after[v] >= 0:
                    before[after[v]] = before[v]
            else:
                queued += 1
            slot[v] = max(int((reached_m - base_m) / cell_m), bucket)  # v joins its bucket, first
            after[v], before[v] = head[slot[v] & mask], -1
            if after[v] >= 0:
                before[after[v]] = v
            head[slot[v] & mask] = v
    return dist
