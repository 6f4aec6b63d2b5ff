"""Navigation fields: for every exit, the direction of the shortest walkable path to it, on a metric grid.

Straight-line goal attraction traps pedestrians behind walls (a bottleneck's door, a real scene's corners).
Instead each exit gets a geodesic distance field (Dijkstra over free grid cells, 8-connected, no corner
cutting) and a unit direction field that descends it; the steering model looks both up per pedestrian.
In a periodic layout the direction to an exit is simply along x, toward the exit's side, everywhere.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from st_sim.sim.checks import check_memory
from st_sim.sim.exact import length
from st_sim.sim.layout import MIN_ROUTE_M, Layout
from st_sim.sim.walls import WallGrid

DESCENT_REACH = 2  # direction = steepest descent over the (2R+1)^2 neighbourhood of a cell [cells]
CELL_BYTES = 600  # peak memory per grid cell: graph, Dijkstra, descent temporaries [B]
EXIT_CELL_BYTES = 24  # kept memory per grid cell and exit: distance (float32) and direction (2 x float64) [B]


class NavigationField:
    """Per-exit geodesic distance and direction on a grid of cell_m over the layout's bounds.

    Raises:
        LayoutTooLargeError: the grid would pass the memory budget (``checks.MEMORY_BUDGET_BYTES``, 1 GiB, at
            CELL_BYTES + EXIT_CELL_BYTES per exit per cell: about 60 000 m^2 with 4 exits at 0.2 m cells).

    Attributes:
        origin_m: (2,) world position of cell (0, 0)'s centre [m].
        cell_m: grid spacing [m].
        free: (Gy, Gx) bool, cells whose centre is walkable and at least clearance_m from every wall.
        startable: (Gy, Gx) bool, free cells with an exit reachable and farther than MIN_ROUTE_M: where a
            pedestrian may be placed or appear (``startable_at`` also checks the point's own wall distance).
        clearance_m: least distance of a free cell's centre, or of a startable point, from every wall [m].
        distance_m: (E, Gy, Gx) float32 geodesic distance to exit e [m]; inf if unreachable or not free.
        direction: (E, Gy, Gx, 2) float64 unit vectors toward exit e (zero where no path exists).
    """

    def __init__(self, layout: Layout, walls: WallGrid, clearance_m: float, cell_m: float):
        xmin, ymin, xmax, ymax = layout.bounds_m
        self.cell_m, self.clearance_m, self._walls = cell_m, clearance_m, walls
        self._kept: dict[tuple, np.ndarray] = {}
        self.origin_m = np.array([xmin, ymin]) + cell_m / 2
        rows, cols = (ymax - ymin) / cell_m + 1, (xmax - xmin) / cell_m + 1
        check_memory(f"the {cols:.0f} x {rows:.0f} navigation grid of layout {layout.name}",
                     rows * cols * (CELL_BYTES + EXIT_CELL_BYTES * len(layout.exits)))
        shape = (int(np.ceil((ymax - ymin) / cell_m)), int(np.ceil((xmax - xmin) / cell_m)))
        iy, ix = np.indices(shape)
        centres = self.origin_m + cell_m * np.stack([ix, iy], axis=-1)
        wall_gap_m = walls.distance_m(centres.reshape(-1, 2)).reshape(shape)
        self.free = layout.scene.is_walkable(centres) & (wall_gap_m >= clearance_m)
        self.distance_m = np.full((len(layout.exits), *shape), np.inf, np.float32)
        self.direction = np.zeros((len(layout.exits), *shape, 2))
        if layout.period is not None:
            self._along_the_period(layout)
        else:
            self._shortest_paths(layout, centres)
        self.startable = self.free & ((self.distance_m > MIN_ROUTE_M) & np.isfinite(self.distance_m)).any(axis=0)

    def _shortest_paths(self, layout: Layout, centres: np.ndarray) -> None:
        """Geodesic distance and descent direction of every exit (Dijkstra over the free cells)."""
        shape = self.free.shape
        graph = _grid_graph(self.free, self.cell_m)
        flat_free = np.flatnonzero(self.free)
        for e, region in enumerate(layout.exits):
            sources = flat_free[region.contains(centres.reshape(-1, 2)[flat_free])]
            if sources.size == 0:
                continue
            dist = dijkstra(graph, indices=sources, min_only=True)
            self.distance_m[e] = dist.reshape(shape)
            self.direction[e] = _descent_directions(self.distance_m[e], self.free, centres, region.centre_m)

    def _along_the_period(self, layout: Layout) -> None:
        """Periodic layout: head along x toward each exit's side of the middle, in every cell; distance = one
        period (never reached, never closer)."""
        middle = layout.period.x0_m + layout.period.length_m / 2
        for e, region in enumerate(layout.exits):
            self.distance_m[e] = layout.period.length_m
            self.direction[e] = [1.0 if region.centre_m[0] >= middle else -1.0, 0.0]

    def kept(self, key: tuple, build: Callable[[], np.ndarray]) -> np.ndarray:
        """An array derived from this field (lattice sites, a gate's free points), built once per key and kept."""
        if key not in self._kept:
            self._kept[key] = build()
        return self._kept[key]

    def cells(self, xy_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) metres -> row and column indices (N,), clipped to the grid."""
        ij = np.rint((xy_m - self.origin_m) / self.cell_m).astype(np.intp)
        return (np.minimum(np.maximum(ij[:, 1], 0), self.free.shape[0] - 1),
                np.minimum(np.maximum(ij[:, 0], 0), self.free.shape[1] - 1))

    def direction_at(self, exit_idx: np.ndarray, xy_m: np.ndarray) -> np.ndarray:
        """Unit direction (N, 2) toward exit exit_idx[i] (N,) at xy_m (N, 2) [m]."""
        iy, ix = self.cells(xy_m)
        return self.direction[exit_idx, iy, ix]

    def distance_at(self, xy_m: np.ndarray) -> np.ndarray:
        """Geodesic distance (E, N) from xy_m (N, 2) to every exit [m]; inf where unreachable."""
        iy, ix = self.cells(xy_m)
        return self.distance_m[:, iy, ix]

    def free_at(self, xy_m: np.ndarray) -> np.ndarray:
        """(N, 2) metres -> (N,) bool, True on a free cell."""
        iy, ix = self.cells(xy_m)
        return self.free[iy, ix]

    def startable_at(self, xy_m: np.ndarray) -> np.ndarray:
        """(N, 2) metres -> (N,) bool, True on a startable cell (see ``startable``) and at least clearance_m from
        every wall: a cell's centre keeps the clearance, but a point up to half a diagonal away from it need not,
        and a pedestrian placed there would start inside a wall."""
        iy, ix = self.cells(xy_m)
        return self.startable[iy, ix] & (self._walls.distance_m(xy_m) >= self.clearance_m)


def _grid_graph(free: np.ndarray, cell_m: float) -> coo_matrix:
    """Sparse graph over free cells: 4 straight and 4 diagonal moves; a diagonal needs both sides free."""
    height, width = free.shape
    index = np.arange(free.size).reshape(free.shape)
    rows, cols, weights = [], [], []
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = free[: height - dy, max(0, -dx): width - max(0, dx)]
        b = free[dy:, max(0, dx): width - max(0, -dx) or None]
        ok = a & b
        if dy and dx:
            ok &= free[: height - dy, max(0, dx): width - max(0, -dx) or None]
            ok &= free[dy:, max(0, -dx): width - max(0, dx)]
        ia = index[: height - dy, max(0, -dx): width - max(0, dx)][ok]
        ib = index[dy:, max(0, dx): width - max(0, -dx) or None][ok]
        rows += [ia, ib]
        cols += [ib, ia]
        weights += [np.full(2 * ia.size, cell_m * np.sqrt(dx * dx + dy * dy))]
    return coo_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(free.size, free.size)).tocsr()


def _descent_directions(dist: np.ndarray, free: np.ndarray, centres: np.ndarray, goal_m: np.ndarray) -> np.ndarray:
    """(Gy, Gx, 2) unit directions of steepest descent of dist, smoothed over 3x3 free cells.

    Cells at the exit (distance 0) point at goal_m; cells that are not free take the direction of the nearest
    free cell, so a pedestrian pressed against a wall still knows where to go.
    """
    reach = DESCENT_REACH
    padded = np.pad(dist, reach, constant_values=np.inf)
    best_slope = np.zeros(dist.shape)
    best = np.zeros((*dist.shape, 2))
    height, width = dist.shape
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            if dy == 0 and dx == 0:
                continue
            neighbour = padded[reach + dy: reach + dy + height, reach + dx: reach + dx + width]
            step = np.sqrt(dx * dx + dy * dy)
            with np.errstate(invalid="ignore"):
                slope = (dist - neighbour) / step
            better = slope > best_slope
            best_slope[better] = slope[better]
            best[better] = np.array([dx, dy]) / step
    at_goal = free & (dist == 0)
    to_goal = goal_m - centres[at_goal]
    best[at_goal] = to_goal / np.maximum(length(to_goal), 1e-9)[:, None]
    best[~np.isfinite(dist)] = 0.0
    smooth = np.stack([ndimage.uniform_filter(best[..., k], size=3, mode="constant") for k in range(2)], axis=-1)
    norm = length(smooth)[..., None]
    unit = np.where(norm > 1e-6, smooth / np.maximum(norm, 1e-9), 0.0)
    nearest = ndimage.distance_transform_edt(~free, return_distances=False, return_indices=True)
    return unit[nearest[0], nearest[1]]
