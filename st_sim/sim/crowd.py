"""CrowdSim: pedestrians steered through a layout (speed model or social force), pymunk resolving their contacts.

One ``step`` advances 0.4 s (one ETH/UCY frame) as an explicit loop of pymunk substeps. Per substep:
read every body's state in one batched call (wrapping bodies round a periodic layout); find the pairs of
bodies within reach; bend group members' desired velocities toward their group; compute every pedestrian's
new velocity with the steering model (``speed_model`` or ``social_force``) and the ego's (its command within
the acceleration limit); trim what would overrun a gap (``contacts``); write velocities and forces back in
one call; let pymunk move the bodies and resolve the contacts. Between steps planned stops begin,
pedestrians that reached their exit leave, those stuck for ``patience_s`` pick another exit, and new ones
(alone or in groups) arrive at the entries (Poisson).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from itertools import pairwise
from pathlib import Path

import numpy as np
import pymunk

from replays.constants import FRAME_STRIDE, STEP_S
from replays.recording import Recording, write_recording
from st_sim.sim import physics, social_force, speed_model
from st_sim.sim.config import (
    EGO_MASS_KG,
    MAX_POPULATION,
    PED_MASS_KG,
    WALL_RADIUS_M,
    CrowdConfig,
    EgoConfig,
    SocialForceConfig,
    SpeedModelConfig,
)
from st_sim.sim.contacts import contact_reach_m, keep_apart, pair_reach_m
from st_sim.sim.exact import cap_speed, poisson_draws
from st_sim.sim.groups import PACE_RANGE, cohesion
from st_sim.sim.layout import Layout, Region
from st_sim.sim.navigation import NavigationField
from st_sim.sim.pairs import Neighbours
from st_sim.sim.population import PROGRESS_M, PopulationError, Roster, choose_exits
from st_sim.sim.robot import Robot
from st_sim.sim.spawning import Arrivals, SpawnRequest, initial_crowd, place_arrivals
from st_sim.sim.stops import start_standing
from st_sim.sim.sweep import Contact, closest_approach, first_contact, first_touch
from st_sim.sim.walls import WallGrid

CONTACT_TOLERANCE_M = 0.01  # the ego counts as touching a wall this close [m]
NAV_SLACK_M = 0.05  # routes keep this much more than body + wall radius off the walls: no gaps under ~0.6 m [m]
BODY_GIVE_M = 0.03  # two pedestrians may press this far into each other (soft bodies; pymunk's discs are smaller) [m]
STANDING_YIELD = 0.1  # a standing pedestrian takes this share of a contact correction relative to a walker [-]
STEERING = {SpeedModelConfig: speed_model, SocialForceConfig: social_force}  # modules with plan() and walk()
GROUP_STRIDE = 1 << 40  # group ids of crowd k are offset by k x this when crowds step together


def population_cap(cfg: CrowdConfig, layout: Layout) -> int:
    """Most pedestrians present at once: cfg.max_pedestrians, or density x the layout's walkable area.

    Raises:
        PopulationError: the density asks for more than MAX_POPULATION pedestrians.
    """
    if cfg.density_per_m2 is None:
        return int(cfg.max_pedestrians)
    cap = round(cfg.density_per_m2 * layout.walkable_area_m2())
    if cap > MAX_POPULATION:
        raise PopulationError(f"CrowdConfig.density_per_m2 = {cfg.density_per_m2} asks for {cap} pedestrians in "
                              f"layout {layout.name}; the simulator holds at most {MAX_POPULATION}")
    return cap


def step_crowds(sims: Sequence[CrowdSim], ego_commands: Sequence[np.ndarray | None]) -> None:
    """Advance crowds of one layout and one config by one 0.4 s step together, as one set of arrays.

    Per substep: every crowd's bodies are read (one batched pymunk call each) and stacked; one neighbour search
    (crowds apart, ``Neighbours.within(tile=...)``), one wall lookup, one steering call, one contact pass
    (``keep_apart(crowd=...)``) for them all; then each crowd's pymunk space takes its substep. Pairs come in a
    canonical order and no computation mixes crowds, so each crowd moves exactly as it would stepped alone.

    Args:
        sims: the crowds (the same ``Layout`` object and an equal ``CrowdConfig``).
        ego_commands: one command (2,) per crowd for its ego's robot (None: stop), as ``CrowdSim.step``.
    """
    if len(sims) != len(ego_commands):
        raise ValueError(f"step_crowds: {len(sims)} crowds but {len(ego_commands)} ego commands")
    if not sims:
        return
    first = sims[0]
    if any(sim.layout is not first.layout or sim.cfg != first.cfg for sim in sims):
        raise ValueError("step_crowds: every crowd must share one layout and one config")
    cfg, dt_s, period = first.cfg, first._dt_s, first.layout.period
    # what the step holds fixed, for all crowds at once: who is a pedestrian, masses, walking speeds (0 while
    # standing), readiness to give way (standing pedestrians yield little, the ego not at all), the egos' targets
    rosters = [sim._roster for sim in sims]
    sizes = np.array([len(r) for r in rosters])
    crowd = np.repeat(np.arange(len(sims)), sizes)  # (M,) which crowd each body belongs to
    bounds = np.r_[0, np.cumsum(sizes)]
    counts = sizes.tolist()  # bodies per crowd, fixed over the substeps (arrivals and exits come after them)
    radius_m, exit_idx, ped_id, go_step, preferred_mps = (np.concatenate([getattr(r, name) for r in rosters])
                                                          for name in ("radius_m", "exit_idx", "ped_id", "go_step",
                                                                       "speed_mps"))
    group = np.concatenate([np.where(r.group >= 0, r.group + k * GROUP_STRIDE, -1) for k, r in enumerate(rosters)])
    movable = ped_id >= 0
    standing = go_step > np.repeat([sim.step_count for sim in sims], sizes)
    mass_kg = np.where(movable, PED_MASS_KG, EGO_MASS_KG)
    walk_mps = np.where(standing, 0.0, preferred_mps)
    yielding = np.where(movable, np.where(standing, STANDING_YIELD, 1.0), 0.0)
    sees_ego = np.array([sim._ego_seen for sim in sims])[crowd]
    widest_m = np.array([sim._widest_m for sim in sims])
    ego_rows = np.array([bounds[k] + sim._ego_slot for k, sim in enumerate(sims) if sim._ego_slot is not None], int)
    egos = [sim for sim in sims if sim._ego_slot is not None]
    ego_moves = np.array([sim.robot.drive(command, cfg.n_substeps) for sim, command
                          in zip(sims, ego_commands, strict=True) if sim._ego_slot is not None]).reshape(
        len(egos), cfg.n_substeps, 2)  # each substep's ego velocity, from its robot model [m/s]
    for sim in egos:
        sim._ego_touched_wall = False
    model, walls_grid, nav = first._model, first._walls, first.nav
    marks = []  # (M, 2) positions of all crowds at the start of every substep, then at the end of the step
    for substep in range(cfg.n_substeps):
        xy_m, v_mps = read_crowds(sims, counts)
        marks.append(xy_m)
        speed2 = v_mps[:, 0] ** 2 + v_mps[:, 1] ** 2
        fastest_mps = np.sqrt(np.array([speed2[a:b].max(initial=0.0) for a, b in pairwise(bounds)]))
        cutoff_m = np.maximum(cfg.steering.agent_cutoff_m, pair_reach_m(2 * widest_m, fastest_mps, dt_s))
        nb = Neighbours.within(xy_m, radius_m, cutoff_m[crowd], period, tile=crowd)
        walls = walls_grid.near(xy_m)
        seen = nb.take(sees_ego[nb.i] | (movable[nb.i] & movable[nb.j]))
        if substep == 0:  # decide once per step; walk every substep
            direction, speed_mps = cohesion(xy_m, nav.direction_at(exit_idx, xy_m), walk_mps, group, period)
            heading = model.plan(v_mps, direction, speed_mps, radius_m, seen, walls, cfg.steering)
        wanted_v = cap_speed(model.walk(heading, v_mps, speed_mps, radius_m, seen, walls, cfg.steering, dt_s),
                             cfg.max_speed_factor * speed_mps)
        if egos:
            wanted_v[ego_rows] = v_mps[ego_rows] = ego_moves[:, substep]
        safe_v = keep_apart(v_mps, radius_m, yielding, seen, walls, dt_s, BODY_GIVE_M, crowd=crowd)
        force_n = mass_kg[:, None] * (wanted_v - safe_v) / dt_s
        physics.write_bodies([sim._batch for sim in sims], counts, safe_v, force_n)
        for sim in sims:
            sim.space.step(dt_s)
        if egos:
            ego_xy = np.array([sim._ego_body.position for sim in egos], np.float64).reshape(-1, 2)
            touched = walls_grid.distance_m(ego_xy) - np.array([sim.ego_cfg.radius_m for sim in egos]) \
                - WALL_RADIUS_M < CONTACT_TOLERANCE_M
            for sim, t in zip(egos, touched, strict=True):
                sim._ego_touched_wall |= bool(t)
    for k, sim in enumerate(sims):  # the velocities the bodies moved with in the last substep
        sim._roster.moved_mps[:] = safe_v[bounds[k]:bounds[k + 1]]
    xy_m = read_crowds(sims, counts)[0]
    marks.append(xy_m)
    sweep_egos(sims, marks, bounds, movable, dt_s)
    at_exit = np.zeros(len(xy_m), bool)
    for e, region in enumerate(first.layout.exits):
        heading_there = movable & (exit_idx == e)
        at_exit[heading_there] = region.contains(xy_m[heading_there])
    iy, ix = nav.cells(xy_m)
    to_exit_m = nav.distance_m[exit_idx, iy, ix]
    requests = [sim._end_step(xy_m[bounds[k]:bounds[k + 1]], at_exit[bounds[k]:bounds[k + 1]],
                              to_exit_m[bounds[k]:bounds[k + 1]]) for k, sim in enumerate(sims)]
    spawning = [k for k, request in enumerate(requests) if request is not None]
    arrivals = dict(zip(spawning, place_arrivals(nav, first.layout, cfg, [requests[k] for k in spawning]),
                        strict=True)) if spawning else {}
    for k, sim in enumerate(sims):
        sim._finish_step(arrivals.get(k))


def read_crowds(sims: Sequence[CrowdSim], sizes: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Positions (M, 2) [m] and velocities (M, 2) [m/s] of the bodies of crowds of one layout, crowd after crowd, each
    in roster order (``sizes``: each crowd's roster length); in a periodic layout, bodies that crossed the seam are
    moved to their image inside the period first."""
    state = physics.read_bodies([sim._batch for sim in sims], sizes)
    xy_m, v_mps = state[:, 0:2].copy(), state[:, 2:4].copy()  # contiguous, as the arithmetic downstream had them
    period = sims[0].layout.period
    if period is not None:
        wrapped = period.wrap(xy_m)
        first = np.cumsum([0, *sizes])
        for row in np.flatnonzero(wrapped[:, 0] != xy_m[:, 0]).tolist():
            k = int(np.searchsorted(first, row, side="right")) - 1
            sims[k]._bodies[int(sims[k]._roster.body_id[row - first[k]])].position = tuple(wrapped[row])
        xy_m = wrapped
    return xy_m, v_mps


def sweep_egos(sims: Sequence[CrowdSim], marks: list[np.ndarray], bounds: np.ndarray, pedestrian: np.ndarray,
               dt_s: float) -> None:
    """Each crowd's ego: its first pedestrian contact and least pedestrian distance over the step (``ego_contact``,
    ``ego_nearest_m``), every body moving in a straight line within a substep.

    Args:
        marks: (M, 2) positions of all crowds' bodies at every substep boundary [m].  bounds: (S + 1,) the rows of
            crowd k are bounds[k]:bounds[k + 1].  pedestrian: (M,) bool.
    """
    crowd = np.repeat(np.arange(len(sims)), np.diff(bounds))
    ego_row = np.array([-1 if sim._ego_slot is None else bounds[k] + sim._ego_slot for k, sim in enumerate(sims)])
    for sim in sims:
        sim._ego_contact, sim._ego_nearest_m = None, np.inf
    peds = np.flatnonzero(pedestrian & (ego_row[crowd] >= 0))
    if not peds.size:
        return
    mine = ego_row[crowd[peds]]  # each pedestrian's ego
    reach_m = np.array([sim.ego_cfg.radius_m + sim.cfg.radius_m if sim.ego_cfg else 0.0 for sim in sims])[crowd[peds]]
    nearest = np.full(len(sims), np.inf)
    first = sims[0]
    for substep, (start, end) in enumerate(pairwise(marks)):
        rel_from, rel_to = first._offset(start[peds] - start[mine]), first._offset(end[peds] - end[mine])
        np.minimum.at(nearest, crowd[peds], closest_approach(rel_from, rel_to)[0])
        touching = np.flatnonzero(~np.isnan(first_touch(rel_from, rel_to, reach_m)))
        for k in np.unique(crowd[peds[touching]]).tolist():
            sim = sims[k]
            if sim._ego_contact is None:
                own, ego = crowd[peds] == k, ego_row[k]
                sim._ego_contact = first_contact(start[ego], end[ego], start[ego] + rel_from[own],
                                                 end[ego] + rel_to[own], sim._roster.ped_id[peds[own] - bounds[k]],
                                                 reach_m[own][0], dt_s, substep * dt_s)
    for sim, value in zip(sims, nearest.tolist(), strict=True):
        sim._ego_nearest_m = value


class CrowdSim:
    """A pymunk crowd in a layout, with an optional ego robot.

    Args:
        layout: walls, entries, exits and map (``make_layout`` or ``layout_from_scene``).
        cfg: crowd tunables (population, steering model, contacts).
        rng: the only source of randomness (speeds, placement, groups, stops, spawning, exits).
        ego: ego robot settings (``pedestrians_see_ego`` among them); None = no ego.
        robot: the ego's robot model (its spec must be ``ego.robot``); None = a new one at rest facing +x. An env
            gives its own, facing the goal, with the robot's own generator for actuation noise.
        n_initial: pedestrians placed at the start, at most the population cap; None = the cap.
        start_region: where the initial crowd is placed; None = anywhere with a route to an exit.

    Raises:
        PopulationError: n_initial is above the cap, or the pedestrians asked for do not fit in the layout
            (the message says how many do).
        ValueError: the layout offers no room for a pedestrian, or an entry reaches none of its exits
            (a passage narrower than a pedestrian needs, a closed door).

    Attributes:
        step_count: steps taken since construction.
        max_pedestrians: population cap (``population_cap``).
    """

    def __init__(self, layout: Layout, cfg: CrowdConfig, rng: np.random.Generator, ego: EgoConfig | None = None,
                 n_initial: int | None = None, start_region: Region | None = None, robot: Robot | None = None):
        self.layout, self.cfg, self.rng, self.ego_cfg = layout, cfg, rng, ego
        self.step_count = 0
        self.max_pedestrians = population_cap(cfg, layout)
        n_initial = self.max_pedestrians if n_initial is None else int(n_initial)
        if not 0 <= n_initial <= self.max_pedestrians:
            raise PopulationError(f"CrowdSim: n_initial = {n_initial} must be between 0 and the population cap "
                                  f"{self.max_pedestrians}")
        self._dt_s = STEP_S / cfg.n_substeps
        self._model = STEERING[type(cfg.steering)]
        self._widest_m = widest_m = max(cfg.radius_m, ego.radius_m if ego else 0.0)
        wall_reach_m = max(cfg.steering.wall_cutoff_m, contact_reach_m(widest_m, self._top_speed_mps(), self._dt_s))
        self._walls = layout.derived(("walls", cfg.nav_cell_m, wall_reach_m), lambda: WallGrid(
            layout.walls_m, layout.bounds_m, cfg.nav_cell_m, wall_reach_m))
        clearance_m = cfg.radius_m + WALL_RADIUS_M + (NAV_SLACK_M if layout.period is None else 0.0)
        self.nav = layout.derived(("navigation", clearance_m, cfg.nav_cell_m), lambda: NavigationField(
            layout, self._walls, clearance_m, cfg.nav_cell_m))
        self._check_routes(clearance_m)
        self.space = physics.make_space(cfg)
        physics.add_walls(self.space, layout.walls_m)
        self._batch = physics.BodyBatch(self.space)
        self._bodies: dict[int, pymunk.Body] = {}
        self._roster = Roster.empty()
        self._next_ped_id = 0
        self._next_group = 0
        self._ego_body: pymunk.Body | None = None
        self.robot: Robot | None = None if ego is None else robot or Robot(ego.robot)
        """the ego's robot model: its motion, pending commands and noise (None without an ego)"""
        self._ego_contact: Contact | None = None
        self._ego_touched_wall = False
        self._ego_nearest_m = np.inf
        self._reordered = False  # somebody left during the step being finished (``_end_step``)
        keep_clear_m = np.zeros((0, 2))
        if ego is not None:
            start = layout.ego_start_m if ego.start_m is None else np.asarray(ego.start_m, dtype=np.float64)
            self._ego_body = physics.add_ego(self.space, start, ego.radius_m)
            self._admit(Roster.of([self._ego_body.id], [-1], [0], [0.0], [ego.radius_m], np.zeros(2), 0),
                        [self._ego_body])
            keep_clear_m = start[None]
        self.add(initial_crowd(self.nav, layout, cfg, n_initial, keep_clear_m,
                                self._roster.radius_m.max(initial=0.0), self._next_group, rng, start_region))
        self._history: list[tuple[np.ndarray, np.ndarray]] = [(self.ids, self.positions_m)]

    def _top_speed_mps(self) -> float:
        """Fastest any body may move [m/s]: a pedestrian at its cap (and a group's pace), or the ego."""
        return max(self.cfg.top_speed_mps * PACE_RANGE[1], self.ego_cfg.robot.max_speed_mps if self.ego_cfg else 0.0)

    def _check_routes(self, clearance_m: float) -> None:
        """Refuse layouts where no pedestrian fits, or no entry reaches any of its exits (a closed door); an
        entry that leads nowhere (a real scene's isolated border opening) only stays unused."""
        narrow = f"passages narrower than about {2 * clearance_m:.2f} m let no pedestrian through"
        if not self.nav.startable.any():
            raise ValueError(f"layout {self.layout.name}: no room for a pedestrian with a route to an exit ({narrow})")
        if self.layout.entries and not any(self._entry_reaches_exit(entry, exits) for entry, exits
                                           in zip(self.layout.entries, self.layout.routes, strict=True)):
            raise ValueError(f"layout {self.layout.name}: no entry reaches any of its exits; {narrow}")

    def _entry_reaches_exit(self, entry: Region, exits: tuple[int, ...]) -> bool:
        """True if some free point of entry has one of exits within reach (and farther than MIN_ROUTE_M)."""
        def free_points() -> np.ndarray:
            lo, hi = entry.polygon_m.min(axis=0), entry.polygon_m.max(axis=0)
            xy = np.stack(np.meshgrid(np.arange(lo[0], hi[0], self.cfg.nav_cell_m / 2),
                                      np.arange(lo[1], hi[1], self.cfg.nav_cell_m / 2)), -1).reshape(-1, 2)
            return xy[entry.contains(xy) & self.nav.free_at(xy)]

        xy = self.nav.kept(("entry", id(entry)), free_points)
        allowed = np.zeros(len(self.layout.exits), bool)
        allowed[list(exits)] = True
        return bool(choose_exits(self.nav, xy, allowed, self.rng)[1].any())

    def __repr__(self) -> str:
        ego = "" if self._ego_body is None else " + ego"
        return f"CrowdSim({self.layout.name}: {len(self.ids)} pedestrians{ego}, step {self.step_count})"

    # ---------------------------------------------------------------- public state (pedestrians sorted by id)
    @property
    def ids(self) -> np.ndarray:
        """(N,) int64 pedestrian ids, ascending; stable per pedestrian, never reused."""
        return self._roster.ped_id[self._order]

    @property
    def positions_m(self) -> np.ndarray:
        """(N, 2) float64 pedestrian positions [m], world frame, rows aligned with ``ids``."""
        return self._xy_m[self._order]

    @property
    def velocities_mps(self) -> np.ndarray:
        """(N, 2) float64 velocities [m/s] the pedestrians moved with in the last substep, aligned with ``ids``."""
        return self._roster.moved_mps[self._order]

    @property
    def goals_m(self) -> np.ndarray:
        """(N, 2) float64 centre of the exit each pedestrian heads to [m], rows aligned with ``ids``."""
        centres = np.array([region.centre_m for region in self.layout.exits])
        return centres[self._roster.exit_idx[self._order]]

    @property
    def preferred_speeds_mps(self) -> np.ndarray:
        """(N,) float64 preferred walking speeds [m/s] (while walking), rows aligned with ``ids``."""
        return self._roster.speed_mps[self._order]

    @property
    def groups(self) -> np.ndarray:
        """(N,) int64 group of each pedestrian (-1: alone), rows aligned with ``ids``."""
        return self._roster.group[self._order]

    @property
    def standing(self) -> np.ndarray:
        """(N,) bool, True for pedestrians standing still on purpose (a planned stop), aligned with ``ids``."""
        return self._roster.standing(self.step_count)[self._order]

    @property
    def ego_position_m(self) -> np.ndarray | None:
        """(2,) ego position [m], or None without an ego."""
        return None if self._ego_slot is None else self._xy_m[self._ego_slot].copy()

    @property
    def ego_velocity_mps(self) -> np.ndarray | None:
        """(2,) velocity [m/s] the ego moved with in the last substep, or None without an ego."""
        return None if self._ego_slot is None else self._roster.moved_mps[self._ego_slot].copy()

    @property
    def ego_collided(self) -> bool:
        """True if the ego touched a pedestrian or a wall during the last step."""
        return self._ego_contact is not None or self._ego_touched_wall

    @property
    def ego_contact(self) -> Contact | None:
        """The ego's first contact with pedestrians during the last step (bodies of ``EgoConfig.radius_m`` and
        ``CrowdConfig.radius_m`` overlapping at some instant of a substep, both moving in a straight line within
        it), with the bodies' state at the impact; None without one."""
        return self._ego_contact

    @property
    def ego_touched_wall(self) -> bool:
        """True if the ego came within ``CONTACT_TOLERANCE_M`` of a wall at the end of a substep of the last step."""
        return self._ego_touched_wall

    @property
    def ego_nearest_m(self) -> float:
        """Least centre distance between the ego and a pedestrian during the last step [m] (inf: nobody)."""
        return self._ego_nearest_m

    # ---------------------------------------------------------------- stepping
    def step(self, ego_command: np.ndarray | None = None) -> None:
        """Advance one 0.4 s step (``step_crowds`` with this crowd alone).

        Args:
            ego_command: (2,) finite command of the ego's robot (``robot.spec``: a velocity (vx, vy) [m/s] for a
                holonomic robot, (v [m/s], w [rad/s]) for a differential drive), followed within its limits
                (``st_sim.sim.robot``). None = stop (command zero).
        """
        step_crowds([self], [ego_command])

    def _end_step(self, xy_m: np.ndarray, at_exit: np.ndarray, to_exit_m: np.ndarray) -> SpawnRequest | None:
        """After the substeps, at the bodies' positions ``xy_m`` (K, 2) [m]: planned stops, rerouting, arrivals at the
        exits (``at_exit`` (K,): inside the exit one heads to; ``to_exit_m`` (K,): walking distance to it [m]); then
        the Poisson draw of new arrivals: what to place (``place_arrivals``, with the other crowds' arrivals), or None
        when nobody arrives. ``_finish_step`` completes the step."""
        self.step_count += 1
        roster = self._roster
        if (roster.stop_step >= 0).any():
            start_standing(roster, self.step_count, self._in_gate(xy_m), self.cfg.population, self.rng)
        self._xy_m, self._reordered = xy_m, False
        if self.layout.period is not None:
            return None
        rerouted = self._reroute_stuck(xy_m, to_exit_m)
        if rerouted.size:  # they head for another exit now
            at_exit = at_exit.copy()
            at_exit[rerouted] = self._inside_own_exit(xy_m[rerouted], roster.exit_idx[rerouted])
        stay = self._remove_arrived(at_exit)
        if not stay.all():
            self._xy_m, self._reordered = xy_m[stay], True
        counts = poisson_draws(self.rng, self.cfg.spawn_rate_hz * STEP_S, len(self.layout.entries))
        room = self.max_pedestrians - int(np.count_nonzero(self._roster.ped_id >= 0))
        if room <= 0 or not counts.any():
            return None
        return SpawnRequest(counts, room, self._xy_m, self._roster, self.step_count, self._next_group, self.rng)

    def _finish_step(self, arrivals: Arrivals | None) -> None:
        """Complete the step begun by ``_end_step`` with the new pedestrians placed for it (None: nobody arrives)."""
        if arrivals is not None and len(arrivals.xy_m):
            self.add(arrivals)
        elif self._reordered:  # somebody left: pymunk's body order changed
            self._settle_order()
        self._history.append((self.ids, self.positions_m))

    @property
    def _ego_seen(self) -> bool:
        return self.ego_cfg is not None and self.ego_cfg.pedestrians_see_ego

    def _in_gate(self, xy_m: np.ndarray) -> np.ndarray:
        """(K,) bool, True for bodies inside any entry or exit strip."""
        inside = np.zeros(len(xy_m), bool)
        for region in {id(r): r for r in [*self.layout.entries, *self.layout.exits]}.values():
            inside |= region.contains(xy_m)
        return inside

    def _offset(self, offset_m: np.ndarray) -> np.ndarray:
        """(M, 2) offsets [m] as nearest images in a periodic layout (unchanged otherwise)."""
        return offset_m if self.layout.period is None else self.layout.period.nearest_image(offset_m)

    # ---------------------------------------------------------------- population
    def _admit(self, rows: Roster, bodies: list[pymunk.Body]) -> None:
        self._roster = self._roster.extend(rows)
        self._bodies.update({body.id: body for body in bodies})

    def add(self, new: Arrivals) -> None:
        """Add the pedestrians of new (positions, exits, speeds, groups, stop plans) now, walking at their preferred
        speed or standing; the caller makes sure that they do not overlap anybody. Their ids are fresh. The roster
        follows pymunk's new body order afterwards."""
        n = len(new.xy_m)
        walking = (new.go_step <= self.step_count)[:, None]
        velocity = new.speed_mps[:, None] * self.nav.direction_at(new.exit_idx, new.xy_m) * walking
        bodies = physics.add_pedestrians(self.space, new.xy_m, velocity, self.cfg.radius_m - BODY_GIVE_M / 2)
        ped_id = self._next_ped_id + np.arange(n, dtype=np.int64)
        self._next_ped_id += n
        self._next_group = max(self._next_group, int(new.group.max(initial=-1)) + 1)
        self._admit(Roster.of([b.id for b in bodies], ped_id, new.exit_idx, new.speed_mps,
                              np.full(n, self.cfg.radius_m), velocity, self.step_count, new.group, new.stop_step,
                              new.go_step), bodies)
        self._settle_order()

    def _reroute_stuck(self, xy_m: np.ndarray, to_exit_m: np.ndarray) -> np.ndarray:
        """Walking pedestrians that came no closer to their exit for cfg.patience_s head for another exit.

        Args:
            xy_m: (K, 2) positions of the roster's bodies [m].  to_exit_m: (K,) their walking distance to their exit.

        Returns:
            (R,) rows that now head for another exit.
        """
        rows = self._roster
        better = (to_exit_m < rows.best_to_exit_m - PROGRESS_M) | rows.standing(self.step_count)
        rows.best_to_exit_m[better] = to_exit_m[better]
        rows.progress_step[better] = self.step_count
        stuck = np.flatnonzero((rows.ped_id >= 0)
                               & (self.step_count - rows.progress_step > self.cfg.patience_s / STEP_S))
        if not stuck.size:
            return stuck
        exit_idx, ok = choose_exits(self.nav, xy_m[stuck], np.ones(len(self.layout.exits), bool), self.rng)
        rows.exit_idx[stuck[ok]] = exit_idx[ok]
        rows.best_to_exit_m[stuck] = np.inf
        rows.progress_step[stuck] = self.step_count
        return stuck[ok]

    def _inside_own_exit(self, xy_m: np.ndarray, exit_idx: np.ndarray) -> np.ndarray:
        """(N,) bool: each point (N, 2) [m] lies inside exit ``exit_idx`` (N,)."""
        inside = np.zeros(len(xy_m), bool)
        for e in np.unique(exit_idx):
            mine = exit_idx == e
            inside[mine] = self.layout.exits[e].contains(xy_m[mine])
        return inside

    def _remove_arrived(self, at_exit: np.ndarray) -> np.ndarray:
        """Remove the pedestrians standing inside the exit they head to (``at_exit`` (K,) bool, per body).

        Returns:
            (K,) bool, True for the bodies that stay (the roster keeps only those, in the same order).
        """
        rows = self._roster
        gone = at_exit & (rows.ped_id >= 0)
        if not gone.any():
            return ~gone
        bodies = [self._bodies.pop(body_id) for body_id in rows.body_id[gone].tolist()]
        self.space.remove(*(part for body in bodies for part in (body, *body.shapes)))  # body by body, as one by one
        self._roster = rows.take(~gone)
        return ~gone

    def _settle_order(self) -> None:
        """Align the roster with pymunk's body order and cache positions, velocities and the id order."""
        order = self._batch.body_ids()
        if not np.array_equal(order, self._roster.body_id):
            self._roster = self._roster.reorder(order)
        self._xy_m = read_crowds([self], [len(self._roster)])[0]
        is_ped = self._roster.ped_id >= 0
        peds = np.flatnonzero(is_ped)
        self._order = peds[np.argsort(self._roster.ped_id[peds], kind="stable")]
        ego = np.flatnonzero(~is_ped)
        self._ego_slot = int(ego[0]) if ego.size else None

    # ---------------------------------------------------------------- recording
    def history(self) -> Recording:
        """Every step's pedestrian positions so far: frame = 10 x step (step 0 = the initial crowd)."""
        frames = [np.full(len(ids), FRAME_STRIDE * t, np.int64) for t, (ids, _) in enumerate(self._history)]
        return Recording(name=f"sim_{self.layout.name}", frame=np.concatenate(frames),
                         agent=np.concatenate([ids for ids, _ in self._history]),
                         xy_m=np.concatenate([xy for _, xy in self._history]).reshape(-1, 2))

    def save_recording(self, path: str | os.PathLike) -> Path:
        """Write ``history()`` in the ETH/UCY text format (readable by ``replays.read_recording``)."""
        rec = self.history()
        return write_recording(path, rec.frame, rec.agent, rec.xy_m)
