"""A simulated layout: wall segments, entry and exit regions, bounds and a walkability raster (Scene)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import TypeVar

import numpy as np

from replays.scenes import Scene
from st_sim.sim.config import MAP_PX_M, WALL_RADIUS_M

T = TypeVar("T")
MIN_ROUTE_M = 2.0  # an entry's pedestrians head only to exits whose centre is farther than this [m]


@dataclass(frozen=True, eq=False)
class Region:
    """A polygon where pedestrians appear (entry) or leave (exit).

    Attributes:
        name: short label, e.g. ``"west"``.
        polygon_m: (P, 2) float64 vertices in metres, world frame, in order (either orientation).
    """

    name: str
    polygon_m: np.ndarray

    def __repr__(self) -> str:
        return f"Region({self.name}, {len(self.polygon_m)} vertices)"

    @property
    def centre_m(self) -> np.ndarray:
        """(2,) vertex mean [m]."""
        return self.polygon_m.mean(axis=0)

    @cached_property
    def _edges(self) -> tuple[np.ndarray, np.ndarray]:
        """Start and end points (1, P, 2) of the polygon's edges."""
        return self.polygon_m[None], np.roll(self.polygon_m, -1, axis=0)[None]

    def contains(self, xy_m: np.ndarray) -> np.ndarray:
        """(M, 2) metres -> (M,) bool, True inside the polygon (even-odd rule)."""
        xy_m = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        a, b = self._edges
        x, y = xy_m[:, 0:1], xy_m[:, 1:2]
        straddles = (a[..., 1] > y) != (b[..., 1] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = a[..., 0] + (y - a[..., 1]) * (b[..., 0] - a[..., 0]) / (b[..., 1] - a[..., 1])
        return (np.count_nonzero(straddles & (x < x_cross), axis=1) % 2) == 1


@dataclass
class Layout:
    """Geometry of a simulated crowd: static walls, where pedestrians enter and leave, and the map.

    Attributes:
        name: layout name, e.g. ``"corridor"`` or ``"zara1"``.
        walls_m: (W, 2, 2) float64 wall segments (start, end) in metres, world frame.
        entries: regions where pedestrians spawn.
        exits: regions where pedestrians are removed; every pedestrian heads to one of them.
        bounds_m: (xmin, ymin, xmax, ymax) metres enclosing all walls.
        scene: walkability raster with its homography (world = H @ (u, v, 1)), for map metrics and predictors.
        ego_start_m: (2,) default start of the ego robot [m].
        ego_goal_m: (2,) default goal of the ego robot [m].
        routes: per entry, the indices of the exits its pedestrians may head to
            (default: every exit whose centre is more than MIN_ROUTE_M from the entry's).
    """

    name: str
    walls_m: np.ndarray
    entries: list[Region]
    exits: list[Region]
    bounds_m: tuple[float, float, float, float]
    scene: Scene
    ego_start_m: np.ndarray
    ego_goal_m: np.ndarray
    routes: tuple[tuple[int, ...], ...] = field(default=())
    _derived: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.walls_m = np.asarray(self.walls_m, dtype=np.float64).reshape(-1, 2, 2)
        self.ego_start_m = np.asarray(self.ego_start_m, dtype=np.float64)
        self.ego_goal_m = np.asarray(self.ego_goal_m, dtype=np.float64)
        if not self.routes:
            exit_centres = np.array([r.centre_m for r in self.exits]).reshape(-1, 2)
            self.routes = tuple(
                tuple(np.flatnonzero(np.linalg.norm(exit_centres - e.centre_m, axis=1) > MIN_ROUTE_M).tolist())
                for e in self.entries
            )
        if len(self.routes) != len(self.entries) or not all(self.routes):
            raise ValueError(f"layout {self.name}: every entry needs at least one exit, got routes {self.routes}")

    def __repr__(self) -> str:
        return (f"Layout({self.name}: {len(self.walls_m)} walls, {len(self.entries)} entries, "
                f"{len(self.exits)} exits, bounds {np.round(self.bounds_m, 2).tolist()} m)")

    def derived(self, key: tuple, build: Callable[[], T]) -> T:
        """Geometry derived from the layout (wall grid, navigation fields), built once per key and kept.

        A layout is treated as read-only once built: change its walls or gates and the kept values are stale.
        """
        if key not in self._derived:
            self._derived[key] = build()
        return self._derived[key]

    def walkable_area_m2(self) -> float:
        """Walkable area of the raster [m^2] (each pixel's footprint through the homography)."""
        height, width = self.scene.walkable.shape
        u, v = np.meshgrid(np.arange(width + 1.0) - 0.5, np.arange(height + 1.0) - 0.5)
        corners = self.scene.pixel_to_world(np.stack([u, v], axis=-1))  # (H+1, W+1, 2)
        d1 = corners[1:, 1:] - corners[:-1, :-1]
        d2 = corners[:-1, 1:] - corners[1:, :-1]
        pixel_area = 0.5 * np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
        return float(pixel_area[self.scene.walkable].sum())


def polygon_edges(polygon_m: np.ndarray) -> np.ndarray:
    """(P, 2) closed polygon -> (P, 2, 2) segments between consecutive vertices."""
    polygon_m = np.asarray(polygon_m, dtype=np.float64)
    return np.stack([polygon_m, np.roll(polygon_m, -1, axis=0)], axis=1)


def rasterise(name: str, free_polygon_m: np.ndarray,
              bounds_m: tuple[float, float, float, float]) -> tuple[Scene, np.ndarray]:
    """Walkability raster and walls of a synthetic layout.

    Args:
        free_polygon_m: (P, 2) polygon of the walkable space [m]; its edges are the walls.
        bounds_m: (xmin, ymin, xmax, ymax) of the raster [m]; row 0 is at ymax (north up).

    Returns:
        scene: MAP_PX_M metres per pixel; walls (capsules of radius WALL_RADIUS_M) are not walkable.
        walls_m: (P, 2, 2) the polygon's edges.
    """
    import cv2

    xmin, ymin, xmax, ymax = bounds_m
    H = np.array([[MAP_PX_M, 0.0, xmin], [0.0, -MAP_PX_M, ymax], [0.0, 0.0, 1.0]])
    width, height = int(np.ceil((xmax - xmin) / MAP_PX_M)) + 1, int(np.ceil((ymax - ymin) / MAP_PX_M)) + 1
    outline_px = np.rint(Scene(name, H, np.zeros((1, 1), bool)).world_to_pixel(free_polygon_m)).astype(np.int32)
    raster = np.zeros((height, width), np.uint8)
    cv2.fillPoly(raster, [outline_px], 1)
    cv2.polylines(raster, [outline_px], isClosed=True, color=0, thickness=max(1, round(2 * WALL_RADIUS_M / MAP_PX_M)))
    return Scene(name, H, raster.astype(bool)), polygon_edges(free_polygon_m)
