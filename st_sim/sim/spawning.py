"""Where and who: the initial crowd on a lattice, and arrivals (alone or in groups) at the entries.

Both return ``Arrivals``: positions, exits, preferred speeds, groups and stop plans of new pedestrians.
A group shares its first member's exit and speed; the population config decides how many walk in groups
(``groups``) and how many stand (``stops``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from st_sim.sim.config import CrowdConfig, PopulationConfig
from st_sim.sim.exact import length
from st_sim.sim.groups import companion_offsets, form_groups, unit_sizes
from st_sim.sim.layout import Layout, Region
from st_sim.sim.navigation import NavigationField
from st_sim.sim.population import (
    PopulationError,
    Roster,
    choose_exits,
    lattice_positions,
    preferred_speeds,
    spawn_points,
)
from st_sim.sim.stops import dwell_steps, plan_stops


@dataclass(frozen=True)
class Arrivals:
    """New pedestrians (M of them).

    Attributes:
        xy_m: (M, 2) positions [m].  exit_idx: (M,) int64 exits.  speed_mps: (M,) preferred walking speeds [m/s].
        group: (M,) int64 group ids (-1 alone).  stop_step: (M,) int64 planned stop (-1 none).
        go_step: (M,) int64 step until which each stands (0: walking from the start).
    """

    xy_m: np.ndarray
    exit_idx: np.ndarray
    speed_mps: np.ndarray
    group: np.ndarray
    stop_step: np.ndarray
    go_step: np.ndarray


def _unit_of(group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row, the row of its unit's first member (itself when alone), and the unit index (U units)."""
    unit = np.where(group >= 0, group, -1 - np.arange(len(group)))
    _, first, inverse = np.unique(unit, return_index=True, return_inverse=True)
    return first[inverse], inverse


def initial_crowd(nav: NavigationField, layout: Layout, cfg: CrowdConfig, n: int, keep_clear_m: np.ndarray,
                  keep_clear_radius_m: float, first_group: int, rng: np.random.Generator,
                  region: Region | None = None) -> Arrivals:
    """n pedestrians on a jittered lattice; cfg.population decides groups and who stands from the start.

    Args:
        keep_clear_m: (B, 2) bodies already there (the ego) [m], of radius keep_clear_radius_m [m].
        first_group: the first free group id.  region: where to place them; None = anywhere startable.

    Raises:
        PopulationError: fewer than n fit in the layout; the message says how many do.
    """
    pop = cfg.population
    clear_gap = np.full(len(keep_clear_m), cfg.radius_m + keep_clear_radius_m + cfg.spawn_gap_m)
    xy_m = lattice_positions(nav, n, 2 * cfg.radius_m, cfg.spawn_gap_m, keep_clear_m, clear_gap, rng, layout.period,
                             region)
    if len(xy_m) < n:
        where = f"region {region.name} of layout {layout.name}" if region else f"layout {layout.name}"
        area = layout.walkable_area_m2()
        raise PopulationError(f"CrowdSim: {n} pedestrians asked for in {where}, but only {len(xy_m)} fit (discs of "
                              f"{cfg.radius_m} m; the layout has {area:.0f} m^2 walkable); ask for at most "
                              f"{len(xy_m)}", fits=len(xy_m))
    exit_idx, ok = choose_exits(nav, xy_m, np.ones(len(layout.exits), bool), rng)
    assert ok.all(), "lattice sites are startable, so every one has an exit"
    group = form_groups(xy_m, pop, rng, first_group)
    first, unit = _unit_of(group)
    speed = preferred_speeds(pop, n, rng)[first]
    standing_units = np.zeros(unit.max(initial=-1) + 1, bool)
    present = 0
    sizes = np.bincount(unit)
    for u in rng.permutation(len(sizes)).tolist():  # units stand until pop.standing_share of the crowd does
        if present < pop.standing_share * n:
            standing_units[u] = True
            present += sizes[u]
    go_step = np.where(standing_units[unit], dwell_steps(pop, len(sizes), rng)[unit], 0)
    return Arrivals(xy_m, exit_idx[first], speed, group, np.full(n, -1, np.int64), go_step)


def _clear(xy_m: np.ndarray, others_m: np.ndarray, clearance_m: float) -> bool:
    return bool(others_m.size == 0 or np.min(length(others_m - xy_m)) >= clearance_m)


def route_mask(layout: Layout) -> np.ndarray:
    """(entries, exits) bool: the exits each entry's pedestrians may head to (``Layout.routes``)."""
    allowed = np.zeros((len(layout.entries), len(layout.exits)), bool)
    for entry, exits in enumerate(layout.routes):
        allowed[entry, list(exits)] = True
    return allowed


@dataclass(frozen=True, eq=False)
class SpawnRequest:
    """One crowd's arrivals to place: ``counts`` (E_in,) units wanted per entry (its Poisson draw), at most ``room``
    pedestrians in all; the roster's bodies at ``xy_m`` (K, 2) [m] (for headings and stops), the current ``step``,
    the first free group id ``first_group`` and the crowd's own generator ``rng``."""

    counts: np.ndarray
    room: int
    xy_m: np.ndarray
    roster: Roster
    step: int
    first_group: int
    rng: np.random.Generator


def place_arrivals(nav: NavigationField, layout: Layout, cfg: CrowdConfig, requests: Sequence[SpawnRequest]
                   ) -> list[Arrivals]:
    """Arrivals at the entries of several crowds of one layout and config, each drawing from its own generator in
    the order it would alone, so that a crowd's arrivals do not depend on the others.

    A unit's first member appears at a free point of its entry (``population.spawn_points``, all entries and crowds
    at once); its companions (``groups.unit_sizes``) appear abreast of it where there is room, else the group is
    smaller.
    """
    pop: PopulationConfig = cfg.population
    rosters = [request.roster for request in requests]
    xy_m = np.concatenate([request.xy_m for request in requests]).reshape(-1, 2)
    heading = nav.direction_at(np.concatenate([r.exit_idx for r in rosters]), xy_m) * \
        np.concatenate([r.ped_id >= 0 for r in rosters])[:, None]
    cuts = np.cumsum([len(r) for r in rosters])[:-1]
    clearance_m = np.array([cfg.radius_m + r.radius_m.max(initial=cfg.radius_m) + cfg.spawn_gap_m for r in rosters])
    counts = np.array([np.minimum(request.counts, request.room) for request in requests]).reshape(len(requests), -1)
    points = spawn_points(layout.entries, counts, layout.derived(("routes",), lambda: route_mask(layout)), nav,
                          [request.xy_m for request in requests], np.split(heading, cuts), clearance_m,
                          cfg.spawn_lane_m, [request.rng for request in requests])
    leads = [(xy[:request.room], exits[:request.room])
             for (xy, exits, _), request in zip(points, requests, strict=True)]
    lead_heading = np.split(nav.direction_at(np.concatenate([e for _, e in leads]),
                                             np.concatenate([xy for xy, _ in leads]).reshape(-1, 2)),
                            np.cumsum([len(e) for _, e in leads])[:-1])
    return [_units(nav, pop, request, xy, exits, heading_c, clearance_c)
            for request, (xy, exits), heading_c, clearance_c in zip(requests, leads, lead_heading, clearance_m,
                                                                    strict=True)]


def _units(nav: NavigationField, pop: PopulationConfig, request: SpawnRequest, leads: np.ndarray, exits: np.ndarray,
           lead_heading: np.ndarray, clearance_m: float) -> Arrivals:
    """One crowd's arrivals from its units' first members ``leads`` (U, 2) [m] heading to ``exits`` (U,) along
    ``lead_heading`` (U, 2): companions abreast where there is room, speeds, groups and stops."""
    rng, room = request.rng, request.room
    member_xy, member_unit = [leads], [np.arange(len(leads))]
    taken = np.concatenate([request.xy_m, leads])
    room -= len(leads)
    sizes = unit_sizes(pop, len(leads), rng)
    for k in np.flatnonzero(sizes > 1).tolist():  # companions, abreast of the lead
        for spot in leads[k] + companion_offsets(lead_heading[k], int(sizes[k])):
            if room > 0 and nav.startable_at(spot[None])[0] and _clear(spot, taken, clearance_m):
                member_xy.append(spot[None])
                member_unit.append(np.array([k]))
                taken = np.concatenate([taken, spot[None]])
                room -= 1
    n_units = len(leads)
    xy = np.concatenate(member_xy)
    unit = np.concatenate(member_unit)
    sizes = np.bincount(unit, minlength=n_units)
    group_of_unit = np.where(sizes > 1, request.first_group + np.cumsum(sizes > 1) - 1, -1)
    speed = preferred_speeds(pop, n_units, rng)
    stop = plan_stops(pop, sizes, request.roster, request.step, rng)
    return Arrivals(xy_m=xy, exit_idx=exits[unit], speed_mps=speed[unit],
                    group=group_of_unit[unit], stop_step=stop[unit], go_step=np.zeros(len(xy), np.int64))
