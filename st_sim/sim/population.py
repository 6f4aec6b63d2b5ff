"""Who is in the crowd: per-body arrays in pymunk's body order, preferred speeds, exits, and where pedestrians
may be placed or appear."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from st_sim.sim.config import PopulationConfig
from st_sim.sim.exact import cos_sin, dot, length
from st_sim.sim.layout import MIN_ROUTE_M, Period, Region
from st_sim.sim.navigation import NavigationField

CANDIDATES_PER_SPAWN = 8  # random points tried per new pedestrian before giving up for this step
MIN_LATTICE_GAP_M = 0.01  # closest initial packing: gap between neighbouring bodies [m]
LATTICE_TRIES = 8  # lattice spacings tried when placing the initial crowd
PROGRESS_M = 0.5  # coming this much closer to one's exit counts as progress [m]


class PopulationError(ValueError):
    """A requested population does not fit: more than the layout holds, or more than the cap.

    Attributes:
        fits: how many pedestrians do fit, when the layout is what limits them; else None.
    """

    def __init__(self, message: str, fits: int | None = None):
        super().__init__(message)
        self.fits = fits


@dataclass
class Roster:
    """One row per pymunk body (pedestrians and, if present, the ego), in pymunk's iteration order.

    Attributes:
        body_id: (K,) int64 pymunk body ids.
        ped_id: (K,) int64 pedestrian ids (stable, never reused); -1 for the ego.
        exit_idx: (K,) int64 index of the exit each pedestrian heads to (0 for the ego).
        speed_mps: (K,) preferred speeds [m/s] (0 for the ego).
        radius_m: (K,) body radii [m].
        best_to_exit_m: (K,) shortest walking distance to the exit reached so far [m].
        progress_step: (K,) int64 step at which best_to_exit_m last dropped by PROGRESS_M.
        moved_mps: (K, 2) velocity each body last moved with [m/s] (pymunk's body velocity is the one asked for).
        group: (K,) int64 group id shared by pedestrians who walk together; -1 for those alone.
        stop_step: (K,) int64 step at which the pedestrian will stop and stand; -1: no stop planned.
        go_step: (K,) int64 step until which the pedestrian stands (it stands while step < go_step).
    """

    body_id: np.ndarray
    ped_id: np.ndarray
    exit_idx: np.ndarray
    speed_mps: np.ndarray
    radius_m: np.ndarray
    best_to_exit_m: np.ndarray
    progress_step: np.ndarray
    moved_mps: np.ndarray
    group: np.ndarray
    stop_step: np.ndarray
    go_step: np.ndarray

    @classmethod
    def of(cls, body_id: np.ndarray, ped_id: np.ndarray, exit_idx: np.ndarray, speed_mps: np.ndarray,
           radius_m: np.ndarray, moved_mps: np.ndarray, step: int, group: np.ndarray | None = None,
           stop_step: np.ndarray | None = None, go_step: np.ndarray | None = None) -> Roster:
        """New rows (M,) that have made no progress yet, as of step (alone, no stop planned, walking by default)."""
        m = len(body_id)
        return cls(np.asarray(body_id, np.int64), np.asarray(ped_id, np.int64), np.asarray(exit_idx, np.int64),
                   np.asarray(speed_mps, np.float64), np.asarray(radius_m, np.float64),
                   np.full(m, np.inf), np.full(m, step, np.int64), np.asarray(moved_mps, np.float64).reshape(-1, 2),
                   np.full(m, -1, np.int64) if group is None else np.asarray(group, np.int64),
                   np.full(m, -1, np.int64) if stop_step is None else np.asarray(stop_step, np.int64),
                   np.zeros(m, np.int64) if go_step is None else np.asarray(go_step, np.int64))

    @classmethod
    def empty(cls) -> Roster:
        return cls.of(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 2)), 0)

    def standing(self, step: int) -> np.ndarray:
        """(K,) bool, True for pedestrians standing at step."""
        return self.go_step > step

    def __len__(self) -> int:
        return len(self.body_id)

    def take(self, index: np.ndarray) -> Roster:
        """Rows selected by an index or bool array."""
        return Roster(*(getattr(self, name)[index] for name in ROSTER_FIELDS))

    def extend(self, other: Roster) -> Roster:
        """Rows of self followed by rows of other."""
        return Roster(*(np.concatenate([getattr(self, name), getattr(other, name)]) for name in ROSTER_FIELDS))

    def reorder(self, body_ids: np.ndarray) -> Roster:
        """Rows rearranged to follow body_ids (K,), pymunk's current order."""
        by_id = np.argsort(self.body_id)
        rows = by_id[np.minimum(np.searchsorted(self.body_id, body_ids, sorter=by_id), len(by_id) - 1)]
        assert np.array_equal(self.body_id[rows], body_ids), "roster and pymunk hold different bodies"
        return self.take(rows)


ROSTER_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(Roster))


def preferred_speeds(pop: PopulationConfig, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n,) preferred walking speeds ~ N(mean, std) clipped to pop.speed_range_mps [m/s]."""
    low, high = pop.speed_range_mps
    return np.clip(rng.normal(pop.speed_mean_mps, pop.speed_std_mps, n), low, high)


def choose_exits(nav: NavigationField, xy_m: np.ndarray, allowed: np.ndarray,
                 rng: np.random.Generator | Sequence[np.random.Generator], sizes: Sequence[int] | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Pick, for each point, an allowed exit reachable from it and not right there, uniformly at random.

    Args:
        xy_m: (M, 2) start points [m].  allowed: (E,) bool mask of permitted exits, or (E, M) one per point.
        rng: the generator of the draws; or, with ``sizes``, one generator per block of consecutive points (block b
            holds ``sizes[b]`` points; several crowds' points at once, each drawing from its own generator).

    Returns:
        exit_idx: (M,) int64 chosen exits.  ok: (M,) bool, False where no exit qualifies.
    """
    dist = nav.distance_at(xy_m)  # (E, M)
    valid = np.isfinite(dist) & (dist > MIN_ROUTE_M) & (allowed[:, None] if allowed.ndim == 1 else allowed)
    draws = rng.random(dist.shape) if sizes is None else \
        np.concatenate([g.random((len(dist), n)) for g, n in zip(rng, sizes, strict=True)], axis=1).reshape(dist.shape)
    keys = np.where(valid, draws, -1.0)
    return np.argmax(keys, axis=0).astype(np.int64), valid.any(axis=0)


def _lattice_sites(nav: NavigationField, spacing_m: float, blocked_m: np.ndarray,
                   blocked_gap_m: np.ndarray, period: Period | None, region: Region | None) -> np.ndarray:
    """(M, 2) sites of a hexagonal lattice with spacing_m on startable cells (inside region, if given), away
    from blocked_m (B, 2) [m].

    In a periodic layout the sites lie in [x0, x0 + length - spacing_m], so that they keep the spacing across
    the seam too.
    """
    (xmin, ymin), (xmax, ymax) = nav.origin_m, nav.origin_m + nav.cell_m * np.array(nav.free.shape[::-1])
    if region is not None:
        (xmin, ymin), (xmax, ymax) = region.polygon_m.min(axis=0), region.polygon_m.max(axis=0)
    if period is not None:
        xmin, xmax = period.x0_m, period.x0_m + period.length_m - spacing_m + 1e-9
    rows, cols = np.meshgrid(np.arange(ymin, ymax, spacing_m * np.sqrt(3) / 2), np.arange(xmin, xmax, spacing_m),
                             indexing="ij")
    cols = cols + (np.arange(rows.shape[0]) % 2)[:, None] * spacing_m / 2
    sites = np.stack([cols.ravel(), rows.ravel()], axis=-1)
    ok = nav.startable_at(sites)
    ok &= sites[:, 0] <= xmax
    if region is not None:
        ok &= region.contains(sites)
    for point, gap in zip(blocked_m, blocked_gap_m, strict=True):
        ok &= length(sites - point) >= gap
    return sites[ok]


def lattice_positions(nav: NavigationField, n: int, diameter_m: float, max_gap_m: float, blocked_m: np.ndarray,
                      blocked_gap_m: np.ndarray, rng: np.random.Generator, period: Period | None = None,
                      region: Region | None = None) -> np.ndarray:
    """Up to n non-overlapping positions: random sites of a hexagonal lattice on startable cells, jittered.

    The lattice gap (spacing minus diameter) is the largest of LATTICE_TRIES values from max_gap_m down to
    MIN_LATTICE_GAP_M that offers n sites; each site then moves by up to half the gap.

    Args:
        diameter_m: body diameter [m].  max_gap_m: widest gap between neighbouring bodies [m].
        blocked_m: (B, 2) points to keep away from (e.g. the ego) [m]; blocked_gap_m: (B,) distances [m].
        period: the layout's wrap-around, or None.  region: where to place them; None = anywhere startable.

    Returns:
        (min(n, available sites), 2) positions [m]; fewer than n when the layout is full.
    """
    for gap in np.linspace(max_gap_m, MIN_LATTICE_GAP_M, LATTICE_TRIES):
        spacing_m = float(diameter_m + gap)
        key = ("lattice", spacing_m, blocked_m.tobytes(), blocked_gap_m.tobytes(),
               None if period is None else (period.x0_m, period.length_m), None if region is None else id(region))
        sites = nav.kept(key, lambda s=spacing_m: _lattice_sites(nav, s, blocked_m, blocked_gap_m, period, region))
        if len(sites) >= n:
            break
    chosen = sites[rng.permutation(len(sites))[:n]]
    angle = rng.uniform(0.0, 2 * np.pi, len(chosen))
    reach = 0.5 * gap * np.sqrt(rng.random(len(chosen)))
    moved = chosen + reach[:, None] * np.stack(cos_sin(angle), axis=-1)
    inside = nav.startable_at(moved) & (True if region is None else region.contains(moved))
    placed = np.where(inside[:, None], moved, chosen)
    return placed if period is None else period.wrap(placed)


def spawn_points(regions: list[Region], counts: np.ndarray, allowed: np.ndarray, nav: NavigationField,
                 others_m: Sequence[np.ndarray], others_heading: Sequence[np.ndarray], clearance_m: np.ndarray,
                 lane_m: float, rngs: Sequence[np.random.Generator]) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Up to counts[c, r] random free points of each region r, with exits, for new pedestrians where there is room,
    for C crowds at once (crowd c drawing only from ``rngs[c]``, in the order it would alone).

    A point qualifies if it is at least clearance_m from every body present (and from the other new points)
    and no oncoming body (heading more than 90 degrees off) stands in the new pedestrian's path closer than
    lane_m: people do not step out right in front of others. All regions are handled at once.

    Args:
        regions: (R) entry regions.  counts: (C, R) pedestrians wanted at each; CANDIDATES_PER_SPAWN random points
            are tried for each.
        allowed: (R, E) bool, the exits each region leads to.
        others_m: per crowd, (K, 2) positions of the bodies present [m].  others_heading: per crowd, (K, 2) their
            desired directions.
        clearance_m: (C,) required centre distance to every body [m].  lane_m: free path length required [m].

    Returns:
        per crowd: xy_m (M, 2) positions [m], exit_idx (M,) int64 exits, region (M,) int64 region of each, ascending.
    """
    box = np.array([[r.polygon_m.min(axis=0), r.polygon_m.max(axis=0)] for r in regions])  # (R, 2, 2)
    origins = [np.repeat(np.arange(len(regions)), row * CANDIDATES_PER_SPAWN) for row in counts]
    origin = np.concatenate(origins)
    crowd = np.repeat(np.arange(len(counts)), [len(o) for o in origins])
    lo, hi = box[origin, 0], box[origin, 1]
    candidates = lo + np.concatenate([g.random((len(o), 2)) for g, o in zip(rngs, origins, strict=True)]
                                     ).reshape(-1, 2) * (hi - lo)
    inside = np.zeros(len(origin), bool)
    for r in np.flatnonzero(counts.any(axis=0)).tolist():
        mine = origin == r
        inside[mine] = regions[r].contains(candidates[mine])
    keep = inside & nav.startable_at(candidates)
    candidates, origin, crowd = candidates[keep], origin[keep], crowd[keep]
    exit_idx, reachable = choose_exits(nav, candidates, allowed[origin].T, rngs,
                                       np.bincount(crowd, minlength=len(counts)).tolist())
    candidates, exit_idx = candidates[reachable], exit_idx[reachable]
    origin, crowd = origin[reachable], crowd[reachable]
    heading = nav.direction_at(exit_idx, candidates)  # (M, 2)
    widest = max((len(o) for o in others_m), default=0)  # the crowds' bodies, padded far away and heading nowhere
    bodies = np.full((len(counts), widest, 2), 1e9)
    body_heading = np.zeros((len(counts), widest, 2))
    for c, (xy, direction) in enumerate(zip(others_m, others_heading, strict=True)):
        bodies[c, :len(xy)], body_heading[c, :len(xy)] = xy, direction
    offset = bodies[crowd] - candidates[:, None, :]  # (M, K, 2)
    ahead = dot(offset, heading[:, None])
    across = np.abs(offset[..., 0] * heading[:, None, 1] - offset[..., 1] * heading[:, None, 0])
    clear = clearance_m[crowd][:, None]
    oncoming = np.zeros(ahead.shape, bool)
    for c, direction in enumerate(others_heading):
        rows = crowd == c
        oncoming[rows, :len(direction)] = dot(heading[rows, None], direction[None]) < 0
    in_path = oncoming & (ahead > 0) & (ahead < lane_m) & (across < clear)
    roomy = (length(offset) >= clear).all(axis=1) & ~in_path.any(axis=1)
    candidates, exit_idx, origin, crowd = candidates[roomy], exit_idx[roomy], origin[roomy], crowd[roomy]
    chosen_by_crowd = []
    for c, row in enumerate(counts):  # first come, first served among each crowd's new ones
        rows = np.flatnonzero(crowd == c)
        apart = length(candidates[rows, None] - candidates[None, rows]) >= clearance_m[c]
        chosen, open_ = [], np.ones(len(rows), bool)
        for r in np.flatnonzero(row).tolist():
            mine, taken = origin[rows] == r, 0
            while taken < row[r] and (open_ & mine).any():
                first = int(np.argmax(open_ & mine))
                chosen.append(first)
                open_ &= apart[first]
                taken += 1
        chosen_by_crowd.append(rows[chosen])
    return [(candidates[c].reshape(-1, 2), exit_idx[c], origin[c]) for c in chosen_by_crowd]
