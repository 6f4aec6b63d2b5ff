"""Which walls are near a point, and how far: exact point-to-segment geometry through a grid lookup.

Every grid cell lists the few walls that come within reach of it, so a query costs one lookup and a
(N, K) segment-distance computation, whatever the number of walls in the layout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from st_sim.sim.checks import check_memory
from st_sim.sim.exact import dot, length

MAX_WALLS_PER_CELL = 8  # a cell keeps at most this many walls, the nearest ones
DISTINCT_M = 0.01  # two walls whose nearest points are closer than this are one wall for a push [m]


def point_segment(xy_m: np.ndarray, a_m: np.ndarray, b_m: np.ndarray) -> np.ndarray:
    """Nearest points (..., 2) [m] of segments a_m-b_m (..., 2) to points xy_m (..., 2)."""
    ab, ap = b_m - a_m, xy_m - a_m
    t = dot(ap, ab) / np.maximum(dot(ab, ab), 1e-12)
    return a_m + np.minimum(np.maximum(t, 0.0), 1.0)[..., None] * ab


@dataclass(frozen=True)
class NearbyWalls:
    """The walls within reach of N points.

    Attributes:
        to_wall: (N, K, 2) unit vectors from each point toward its K nearest-listed walls' nearest points.
        dist_m: (N, K) distances to the walls' centre lines [m]; inf for empty slots.
    """

    to_wall: np.ndarray
    dist_m: np.ndarray

    def distinct(self) -> np.ndarray:
        """(N, K) bool: listed walls whose nearest point differs (by DISTINCT_M) from those of the walls listed
        before it, so that two segments meeting at a joint count once."""
        finite = np.isfinite(self.dist_m)
        point = np.where(finite[..., None], self.to_wall * np.where(finite, self.dist_m, 0.0)[..., None], 1e9)
        gap = length(point[:, :, None] - point[:, None, :])  # (N, K, K); empty slots far away
        earlier = np.tril(np.ones(gap.shape[1:], bool), k=-1)
        return finite & ~((gap < DISTINCT_M) & earlier).any(axis=2)

    def free_walk_m(self, toward: np.ndarray, clearance_m: np.ndarray) -> np.ndarray:
        """(..., N) how far each point can move along a heading before coming within clearance_m (N,) [m] of a
        listed wall, each wall taken as the line through its nearest point [m]; inf if none is ahead.

        Args:
            toward: (..., N, K) cosine between the heading and the direction to each listed wall.
        """
        ahead = np.isfinite(self.dist_m) & (toward > 1e-6)
        room = np.where(ahead, self.dist_m - clearance_m[:, None], np.inf) / np.where(ahead, toward, 1.0)
        return np.maximum(room.min(axis=-1, initial=np.inf), 0.0)

    @property
    def nearest(self) -> tuple[np.ndarray, np.ndarray]:
        """Nearest wall of every point: unit direction (N, 2) toward it and distance (N,) [m] (inf if none)."""
        k = np.argmin(self.dist_m, axis=1)
        rows = np.arange(len(k))
        return self.to_wall[rows, k], self.dist_m[rows, k]


class WallGrid:
    """Grid over the bounds whose cells list the walls within reach_m of the cell.

    Args:
        walls_m: (W, 2, 2) segments [m].  bounds_m: (xmin, ymin, xmax, ymax) [m].
        cell_m: grid spacing [m].  reach_m: queries see every wall closer than this [m].

    Raises:
        LayoutTooLargeError: the cell-wall distance table would pass the memory budget
            (``checks.MEMORY_BUDGET_BYTES``; 8 bytes per cell and wall, and per cell and 64-wall chunk).
    """

    def __init__(self, walls_m: np.ndarray, bounds_m: tuple[float, float, float, float], cell_m: float,
                 reach_m: float):
        xmin, ymin, xmax, ymax = bounds_m
        self.walls_m = np.asarray(walls_m, dtype=np.float64).reshape(-1, 2, 2)
        self.origin_m = np.array([xmin, ymin])
        self.cell_m = cell_m
        rows, cols = (ymax - ymin) / cell_m + 2, (xmax - xmin) / cell_m + 2
        check_memory(f"the {cols:.0f} x {rows:.0f} wall grid of {len(self.walls_m)} walls",
                     8 * rows * cols * (max(len(self.walls_m), 1) + 6 * 64))
        shape = (int(np.ceil((ymax - ymin) / cell_m)) + 1, int(np.ceil((xmax - xmin) / cell_m)) + 1)
        iy, ix = np.indices(shape)
        centres = (self.origin_m + cell_m * (np.stack([ix, iy], axis=-1) + 0.5)).reshape(-1, 1, 2)
        dist = np.full((centres.shape[0], max(len(self.walls_m), 1)), np.inf)
        for w0 in range(0, len(self.walls_m), 64):  # chunks keep the (cells, walls, 2) temporaries small
            seg = self.walls_m[w0: w0 + 64]
            dist[:, w0: w0 + len(seg)] = length(centres - point_segment(centres, seg[:, 0], seg[:, 1]))
        order = np.argsort(dist, axis=1, kind="stable")[:, :MAX_WALLS_PER_CELL]  # ties in index order, on any CPU
        within = np.take_along_axis(dist, order, axis=1) <= reach_m + cell_m / np.sqrt(2)
        k_used = max(int(within.sum(axis=1).max(initial=0)), 1)
        self.cell_walls = np.where(within, order, -1)[:, :k_used].reshape(*shape, k_used)  # (Gy, Gx, K), -1 = empty

    def near(self, xy_m: np.ndarray) -> NearbyWalls:
        """Walls near the points xy_m (N, 2) [m] (points off the grid see the walls of the nearest cell)."""
        ij = np.floor((xy_m - self.origin_m) / self.cell_m).astype(np.intp)
        iy = np.minimum(np.maximum(ij[:, 1], 0), self.cell_walls.shape[0] - 1)
        ix = np.minimum(np.maximum(ij[:, 0], 0), self.cell_walls.shape[1] - 1)
        walls = self.cell_walls[iy, ix]  # (N, K)
        seg = self.walls_m[np.maximum(walls, 0)]  # (N, K, 2, 2)
        offset = point_segment(xy_m[:, None, :], seg[..., 0, :], seg[..., 1, :]) - xy_m[:, None, :]
        dist = length(offset)
        dist[walls < 0] = np.inf
        return NearbyWalls(offset / np.maximum(dist, 1e-9)[..., None], dist)

    def distance_m(self, xy_m: np.ndarray) -> np.ndarray:
        """(N, 2) [m] -> (N,) distance to the nearest wall's centre line [m]; inf beyond reach."""
        return self.near(xy_m).dist_m.min(axis=1, initial=np.inf)
