"""Physical sanity of a simulated crowd: body overlaps, wall intrusions and escapes, neighbour distances."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from st_sim.sim.config import WALL_RADIUS_M
from st_sim.sim.layout import Layout, Period
from st_sim.sim.pairs import Neighbours
from st_sim.sim.walls import point_segment


def max_overlap_m(xy_m: np.ndarray, radius_m: float, period: Period | None = None) -> float:
    """Deepest interpenetration of equal discs at xy_m (N, 2) [m]: max(2 r - centre distance, 0) [m]
    (across the seam of a periodic layout too)."""
    if len(xy_m) < 2:
        return 0.0
    nb = Neighbours.within(xy_m, np.full(len(xy_m), radius_m), 2 * radius_m, period)
    return float(max(0.0, 2 * radius_m - nb.dist_m.min(initial=np.inf)))


def escaped(layout: Layout, xy_m: np.ndarray) -> np.ndarray:
    """(N, 2) [m] -> (N,) bool, True where a centre lies outside the bounds or on a non-walkable map pixel."""
    xmin, ymin, xmax, ymax = layout.bounds_m
    inside = (xy_m[:, 0] >= xmin) & (xy_m[:, 0] <= xmax) & (xy_m[:, 1] >= ymin) & (xy_m[:, 1] <= ymax)
    return ~(inside & layout.scene.is_walkable(xy_m))


def wall_penetration_m(layout: Layout, xy_m: np.ndarray, radius_m: float) -> float:
    """Deepest intrusion of discs at xy_m (N, 2) [m] into any wall capsule: max(r + r_wall - distance, 0) [m]."""
    if len(xy_m) == 0 or len(layout.walls_m) == 0:
        return 0.0
    seg = layout.walls_m
    nearest = point_segment(xy_m[:, None, :], seg[None, :, 0], seg[None, :, 1])  # (N, W, 2)
    dist = np.linalg.norm(nearest - xy_m[:, None, :], axis=-1).min(axis=1)
    return float(max(0.0, radius_m + WALL_RADIUS_M - dist.min()))


def nearest_neighbour_m(xy_m: np.ndarray) -> np.ndarray:
    """(N, 2) [m] -> (N,) distance to the nearest other point [m] (empty when N < 2)."""
    if len(xy_m) < 2:
        return np.zeros(0)
    dist, _ = cKDTree(xy_m).query(xy_m, k=2)
    return dist[:, 1]
