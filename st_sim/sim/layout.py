"""A simulated layout: wall segments, entry and exit regions, bounds, a walkability raster (Scene) and, for
periodic layouts, the wrap-around period."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import TypeVar

import numpy as np

from replays.scenes import Scene
from st_sim.sim.checks import check_memory
from st_sim.sim.config import MAP_PX_M, WALL_RADIUS_M
from st_sim.sim.exact import length, total

T = TypeVar("T")
MIN_ROUTE_M = 2.0  # an entry's pedestrians head only to exits whose centre is farther than this [m]
RASTER_BYTES_PER_PX = 8  # peak memory of rasterising per pixel: raster, mask and OpenCV's temporaries [B]
AREA_ROWS = 256  # raster rows per chunk when summing the walkable area


@dataclass(frozen=True)
class Period:
    """Wrap-around along x: a body that leaves at x0_m + length_m reappears at x0_m, and the other way round.

    Attributes:
        x0_m: west end of the period [m].  length_m: period [m], > 0.
    """

    x0_m: float
    length_m: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.x0_m) and np.isfinite(self.length_m) and self.length_m > 0):
            raise ValueError(f"Period(x0_m={self.x0_m!r}, length_m={self.length_m!r}): expected finite numbers, "
                             "length_m > 0")

    def wrap(self, xy_m: np.ndarray) -> np.ndarray:
        """(N, 2) positions [m] with x brought into [x0_m, x0_m + length_m)."""
        out = np.array(xy_m, dtype=np.float64)
        out[:, 0] = self.x0_m + self._into_period(out[:, 0] - self.x0_m)
        return out

    def nearest_image(self, offset_m: np.ndarray) -> np.ndarray:
        """(P, 2) offsets [m] replaced by their nearest periodic image (x in [-length/2, length/2])."""
        out = np.array(offset_m, dtype=np.float64)
        out[:, 0] -= self.length_m * np.rint(out[:, 0] / self.length_m)
        return out

    def tree_input(self, xy_m: np.ndarray, cutoff_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Coordinates (N, 2) and box sizes (2,) for a periodic k-d tree: x wraps, y never does within cutoff_m."""
        coordinates = np.stack([self._into_period(xy_m[:, 0] - self.x0_m), xy_m[:, 1] - xy_m[:, 1].min(initial=0.0)],
                               axis=-1)
        return coordinates, np.array([self.length_m, coordinates[:, 1].max(initial=0.0) + 2 * cutoff_m + 1.0])

    def _into_period(self, x_m: np.ndarray) -> np.ndarray:
        wrapped = np.mod(x_m, self.length_m)
        return np.where(wrapped >= self.length_m, 0.0, wrapped)  # np.mod(-1e-18, L) rounds to L


@dataclass(frozen=True, eq=False)
class Region:
    """A polygon where pedestrians appear (entry) or leave (exit).

    Attributes:
        name: short label, e.g. ``"west"``.
        polygon_m: (P, 2) float64 vertices in metres, world frame, in order (either orientation).
    """

    name: str
    polygon_m: np.ndarray

    def __post_init__(self) -> None:
        polygon = np.asarray(self.polygon_m, dtype=np.float64)
        if polygon.ndim != 2 or polygon.shape[1] != 2 or len(polygon) < 3 or not np.isfinite(polygon).all():
            raise ValueError(f"Region {self.name}: polygon_m must be (P >= 3, 2) finite metres, got shape "
                             f"{polygon.shape}")
        x, y = polygon[:, 0], polygon[:, 1]
        if abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) <= 1e-12:
            raise ValueError(f"Region {self.name}: polygon_m encloses no area")
        object.__setattr__(self, "polygon_m", polygon)

    def __repr__(self) -> str:
        return f"Region({self.name}, {len(self.polygon_m)} vertices)"

    @property
    def centre_m(self) -> np.ndarray:
        """(2,) vertex mean [m]."""
        return total(self.polygon_m, axis=0) / len(self.polygon_m)

    @cached_property
    def _edges(self) -> tuple[np.ndarray, np.ndarray]:
        """Start and end points (1, P, 2) of the polygon's edges."""
        return self.polygon_m[None], np.roll(self.polygon_m, -1, axis=0)[None]

    @cached_property
    def _box(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, hi) corners if the polygon is an axis-aligned rectangle, else None."""
        a, b = self._edges
        axis_aligned = np.all((a[0, :, 0] == b[0, :, 0]) | (a[0, :, 1] == b[0, :, 1]))
        if len(self.polygon_m) != 4 or not axis_aligned:
            return None
        return self.polygon_m.min(axis=0), self.polygon_m.max(axis=0)

    def contains(self, xy_m: np.ndarray) -> np.ndarray:
        """(M, 2) metres -> (M,) bool, True inside the polygon (even-odd rule; a bounds test for rectangles)."""
        xy_m = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        if self._box is not None:
            lo, hi = self._box
            return (xy_m[:, 0] > lo[0]) & (xy_m[:, 0] < hi[0]) & (xy_m[:, 1] > lo[1]) & (xy_m[:, 1] < hi[1])
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
        period: wrap-around along x (a periodic corridor), or None. A periodic layout has no entries;
            its pedestrians never arrive and walk toward their exit's side for ever.
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
    period: Period | None = None
    _derived: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.walls_m = np.asarray(self.walls_m, dtype=np.float64).reshape(-1, 2, 2)
        self.ego_start_m = np.asarray(self.ego_start_m, dtype=np.float64).reshape(2)
        self.ego_goal_m = np.asarray(self.ego_goal_m, dtype=np.float64).reshape(2)
        xmin, ymin, xmax, ymax = self.bounds_m
        finite = all(np.isfinite(a).all() for a in (self.walls_m, self.ego_start_m, self.ego_goal_m, self.bounds_m))
        if not finite or not (xmin < xmax and ymin < ymax):
            raise ValueError(f"layout {self.name}: walls, ego start/goal and bounds must be finite and the bounds "
                             f"(xmin, ymin, xmax, ymax) ordered, got bounds {self.bounds_m}")
        if not self.exits:
            raise ValueError(f"layout {self.name}: needs at least one exit")
        if self.period is not None and self.entries:
            raise ValueError(f"layout {self.name}: a periodic layout has no entries (pedestrians never leave)")
        if not self.routes:
            exit_centres = np.array([r.centre_m for r in self.exits]).reshape(-1, 2)
            self.routes = tuple(
                tuple(np.flatnonzero(length(exit_centres - e.centre_m) > MIN_ROUTE_M).tolist())
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
        """Walkable area of the raster [m^2] (each pixel's footprint through the homography, AREA_ROWS rows at
        a time)."""
        height, width = self.scene.walkable.shape
        area = 0.0
        for top in range(0, height, AREA_ROWS):
            rows = min(AREA_ROWS, height - top)
            u, v = np.meshgrid(np.arange(width + 1.0) - 0.5, top + np.arange(rows + 1.0) - 0.5)
            corners = self.scene.pixel_to_world(np.stack([u, v], axis=-1))  # (rows+1, W+1, 2)
            d1 = corners[1:, 1:] - corners[:-1, :-1]
            d2 = corners[:-1, 1:] - corners[1:, :-1]
            pixel_area = 0.5 * np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
            area += float(pixel_area[self.scene.walkable[top: top + rows]].sum())
        return area


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

    Raises:
        LayoutTooLargeError: the raster would pass the memory budget (``checks.MEMORY_BUDGET_BYTES``, 1 GiB, at
            RASTER_BYTES_PER_PX per pixel: about 0.3 km^2 of layout at 0.05 m pixels).
    """
    import cv2

    xmin, ymin, xmax, ymax = bounds_m
    H = np.array([[MAP_PX_M, 0.0, xmin], [0.0, -MAP_PX_M, ymax], [0.0, 0.0, 1.0]])
    width, height = (xmax - xmin) / MAP_PX_M + 2, (ymax - ymin) / MAP_PX_M + 2
    check_memory(f"the {width:.0f} x {height:.0f} px raster of layout {name}", RASTER_BYTES_PER_PX * width * height)
    width, height = int(np.ceil((xmax - xmin) / MAP_PX_M)) + 1, int(np.ceil((ymax - ymin) / MAP_PX_M)) + 1
    outline_px = np.rint(Scene(name, H, np.zeros((1, 1), bool)).world_to_pixel(free_polygon_m)).astype(np.int32)
    raster = np.zeros((height, width), np.uint8)
    cv2.fillPoly(raster, [outline_px], 1)
    cv2.polylines(raster, [outline_px], isClosed=True, color=0, thickness=max(1, round(2 * WALL_RADIUS_M / MAP_PX_M)))
    return Scene(name, H, raster.astype(bool)), polygon_edges(free_polygon_m)
