"""The walkability map as a robot sees it: a metric grid with wall clearance, range readings and a geodesic cost-to-go.

The scene's map is sampled at the centres of square cells (``cell_m``) over the env's bounds (``CrowdEnv.bounds_m``),
so distances are in metres even where the homography has perspective (ETH, HOTEL). Off-map points count as walls.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import dijkstra

from replays.scenes import Scene

CELL_M = 0.1  # grid spacing [m]
# 16-neighbourhood, one direction per pair: move (dy, dx) -> cells it passes, which must be eligible too;
# grid paths are then within 3 % of straight lines and never cut a wall's corner
MOVES: dict[tuple[int, int], tuple[tuple[int, int], ...]] = {
    (0, 1): (), (1, 0): (),
    (1, 1): ((0, 1), (1, 0)), (1, -1): ((0, -1), (1, 0)),
    (1, 2): ((0, 1), (1, 1)), (2, 1): ((1, 0), (1, 1)), (1, -2): ((0, -1), (1, -1)), (2, -1): ((1, 0), (1, -1)),
}
SOURCE_REACH_M = 1.0  # the goal feeds every eligible cell this close to it [m]
UNREACHABLE_PENALTY_M = 100.0  # cost-to-go of a point with no grid path: its straight distance plus this [m]
_ANGLES = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
HEADINGS = np.stack([np.cos(_ANGLES), np.sin(_ANGLES)], axis=1)  # (64, 2) candidate directions of direction_to
LOOKAHEAD_M = 0.5  # direction_to compares the cost-to-go this far ahead [m]
GOAL_FIELDS_KEPT = 16  # cost-to-go fields kept, one per goal (sub-envs of a vector env may head to different goals)
LOOKUP_CELLS = 1  # cost-to-go of a point = least (cell cost + distance to the cell) over (2R+1)^2 cells


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
        """Geodesic distance [m] from points to the goal along cells with ``body_m`` of wall clearance.

        Args:
            xy_m: (..., 2) points, metres.  goal_m: (2,) metres.  body_m: the robot's radius [m].

        Returns:
            (...) float64 metres; a point with no grid path gets its straight distance + 100 m.
        """
        cost = self._goal_field(np.asarray(goal_m, np.float64), body_m)
        xy_m = np.asarray(xy_m, np.float64)
        row, col, _ = self._cells(xy_m)
        best = np.full(xy_m.shape[:-1], np.inf)
        height, width = cost.shape
        reach = range(-LOOKUP_CELLS, LOOKUP_CELLS + 1)
        for dy in reach:
            for dx in reach:
                r, c = np.clip(row + dy, 0, height - 1), np.clip(col + dx, 0, width - 1)
                best = np.minimum(best, cost[r, c] + np.linalg.norm(xy_m - self.cell_centres_m[r, c], axis=-1))
        straight = np.linalg.norm(xy_m - goal_m, axis=-1)
        return np.where(np.isfinite(best), best, straight + UNREACHABLE_PENALTY_M)

    def direction_to(self, xy_m: np.ndarray, goal_m: np.ndarray, body_m: float) -> np.ndarray:
        """(2,) unit vector from ``xy_m`` (2,) along the shortest walkable path to the goal (zeros at the goal).

        The best of DIRECTIONS headings by the cost-to-go one LOOKAHEAD_M ahead (or at the goal, if nearer).
        """
        return self.directions_to(np.asarray(xy_m, np.float64)[None], np.asarray(goal_m, np.float64)[None],
                                  body_m)[0]

    def directions_to(self, xy_m: np.ndarray, goal_m: np.ndarray, body_m: float) -> np.ndarray:
        """(B, 2) ``direction_to`` of B points (B, 2) [m], each toward its own goal (B, 2) [m]."""
        to_goal = goal_m - xy_m
        reach_m = np.minimum(LOOKAHEAD_M, np.linalg.norm(to_goal, axis=1))  # (B,)
        ahead = xy_m[:, None] + reach_m[:, None, None] * HEADINGS  # (B, 64, 2)
        cost = np.empty(ahead.shape[:2])
        goals, which = np.unique(goal_m, axis=0, return_inverse=True)
        for g, goal in enumerate(goals):
            mine = which.reshape(-1) == g
            cost[mine] = self.cost_to_go(ahead[mine], goal, body_m)
        return np.where((reach_m >= 1e-6)[:, None], HEADINGS[np.argmin(cost, axis=1)], 0.0)

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
    goal's, whose edges each ``geodesic`` call adds.

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
            lengths.append(np.full(int(ok.sum()), cell_m * np.hypot(dy, dx)))
        heads, tails, lengths = np.concatenate(heads), np.concatenate(tails), np.concatenate(lengths)
        nodes = eligible.size + 1
        moves = coo_matrix((np.r_[lengths, lengths], (np.r_[heads, tails], np.r_[tails, heads])),
                           shape=(nodes, nodes)).tocsr()
        return cls(eligible, cell_m, cells, moves)

    def geodesic(self, centres_m: np.ndarray, goal_m: np.ndarray) -> np.ndarray:
        """(Gy, Gx) Dijkstra distance [m] from ``goal_m`` (2,) over the eligible cells (inf elsewhere), ``centres_m``
        (Gy, Gx, 2) the cells' centres.

        The goal is a node joined to every eligible cell within SOURCE_REACH_M (or to the nearest eligible cell) by
        its straight distance, so a goal beside a wall still gets a field.
        """
        if self.cells.size == 0:
            return np.full(self.eligible.shape, np.inf)
        to_goal_m = np.linalg.norm(centres_m.reshape(-1, 2)[self.cells] - goal_m, axis=1)
        near = to_goal_m <= SOURCE_REACH_M
        near = near if near.any() else to_goal_m == to_goal_m.min()
        goal_node = self.eligible.size
        indptr = self.moves.indptr.copy()
        indptr[-1] += int(near.sum())  # the goal's row, last: its edges go after every other row's
        graph = csr_matrix((np.r_[self.moves.data, np.maximum(to_goal_m[near], 1e-6)],  # a zero weight: no edge
                            np.r_[self.moves.indices, self.cells[near]], indptr), shape=self.moves.shape)
        return dijkstra(graph, directed=True, indices=goal_node)[:-1].reshape(self.eligible.shape)
