"""CrowdSim: pedestrians steered by social forces through a layout, pymunk resolving their contacts.

One ``step`` advances 0.4 s (one ETH/UCY frame) as an explicit loop of pymunk substeps. Per substep:
read every body's state in one batched call; compute the social-force velocities of all pedestrians with
NumPy (``steering``) and the ego's velocity (its command within the acceleration limit); trim what would
overrun a gap (``contacts``); write velocities and forces back in one call; let pymunk move the bodies
and resolve the contacts. Between steps, pedestrians that reached their exit leave, those stuck for
``patience_s`` pick another exit, and new ones arrive at the entries (Poisson).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pymunk

from replays.constants import FRAME_STRIDE, STEP_S
from replays.recording import Recording, write_recording
from st_sim.sim import physics
from st_sim.sim.config import EGO_MASS_KG, PED_MASS_KG, WALL_RADIUS_M, CrowdConfig, EgoConfig
from st_sim.sim.contacts import contact_reach_m, keep_apart
from st_sim.sim.layout import Layout
from st_sim.sim.navigation import NavigationField
from st_sim.sim.population import (
    PROGRESS_M,
    Roster,
    choose_exits,
    lattice_positions,
    preferred_speeds,
    spawn_points,
)
from st_sim.sim.steering import Neighbours, cap_speed, steer
from st_sim.sim.walls import WallGrid

CONTACT_TOLERANCE_M = 0.01  # the ego counts as touching a wall this close [m]
NAV_SLACK_M = 0.15  # routes keep this much more than body + wall radius off the walls: no gaps under ~0.9 m [m]


class CrowdSim:
    """A pymunk crowd in a layout, with an optional ego robot.

    Args:
        layout: walls, entries, exits and map (``make_layout`` or ``layout_from_scene``).
        cfg: crowd tunables.
        rng: the only source of randomness (speeds, placement, spawning, exits).
        ego: ego robot settings; None = no ego.
        n_initial: pedestrians placed at the start, at most the population cap; None = the cap (fewer if they
            do not fit).

    Attributes:
        step_count: steps taken since construction.
        max_pedestrians: population cap (cfg.max_pedestrians, or density x walkable area).
    """

    def __init__(self, layout: Layout, cfg: CrowdConfig, rng: np.random.Generator, ego: EgoConfig | None = None,
                 n_initial: int | None = None):
        self.layout, self.cfg, self.rng, self.ego_cfg = layout, cfg, rng, ego
        self.step_count = 0
        self.max_pedestrians = (cfg.max_pedestrians if cfg.density_per_m2 is None
                                else round(cfg.density_per_m2 * layout.walkable_area_m2()))
        self._dt_s = STEP_S / cfg.n_substeps
        wall_reach_m = max(cfg.wall_cutoff_m, contact_reach_m(max(cfg.radius_m, ego.radius_m if ego else 0.0),
                                                              self._top_speed_mps(), self._dt_s))
        self._walls = layout.derived(("walls", cfg.nav_cell_m, wall_reach_m), lambda: WallGrid(
            layout.walls_m, layout.bounds_m, cfg.nav_cell_m, wall_reach_m))
        clearance_m = cfg.radius_m + WALL_RADIUS_M + NAV_SLACK_M
        self.nav = layout.derived(("navigation", clearance_m, cfg.nav_cell_m), lambda: NavigationField(
            layout, self._walls, clearance_m, cfg.nav_cell_m))
        self.space = physics.make_space(cfg)
        physics.add_walls(self.space, layout.walls_m)
        self._batch = physics.BodyBatch(self.space)
        self._bodies: dict[int, pymunk.Body] = {}
        self._roster = Roster.empty()
        self._next_ped_id = 0
        self._ego_body: pymunk.Body | None = None
        self._ego_command_mps = np.zeros(2)
        self._ego_collided = False
        keep_clear_m = np.zeros((0, 2))
        if ego is not None:
            start = layout.ego_start_m if ego.start_m is None else np.asarray(ego.start_m, dtype=np.float64)
            self._ego_body = physics.add_ego(self.space, start, ego.radius_m)
            self._admit(Roster.of([self._ego_body.id], [-1], [0], [0.0], [ego.radius_m], np.zeros(2), 0),
                        [self._ego_body])
            self.space.on_collision(physics.EGO_TYPE, None, pre_solve=self._on_ego_contact)
            keep_clear_m = start[None]
        self._place_initial(self.max_pedestrians if n_initial is None else min(n_initial, self.max_pedestrians),
                            keep_clear_m)
        self._settle_order()
        self._history: list[tuple[np.ndarray, np.ndarray]] = [(self.ids, self.positions_m)]

    def _top_speed_mps(self) -> float:
        """Fastest any body may move [m/s]: a pedestrian at its cap, or the ego."""
        pedestrian = self.cfg.max_speed_factor * self.cfg.preferred_speed_range_mps[1]
        return max(pedestrian, self.ego_cfg.max_speed_mps if self.ego_cfg else 0.0)

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
        return self._ego_collided

    # ---------------------------------------------------------------- stepping
    def step(self, ego_velocity_mps: np.ndarray | None = None) -> None:
        """Advance one 0.4 s step.

        Args:
            ego_velocity_mps: (2,) commanded ego velocity [m/s], clipped to the ego's max speed; the ego's
                velocity moves toward it by at most max_accel_mps2 per second. None = stop (command zero).
        """
        target = np.zeros(2)
        if self._ego_body is not None and ego_velocity_mps is not None:
            target = cap_speed(np.asarray(ego_velocity_mps, dtype=np.float64).reshape(1, 2),
                               np.array([self.ego_cfg.max_speed_mps]))[0]
        self._ego_collided = False
        roster = self._roster
        movable = roster.ped_id >= 0
        mass_kg = np.where(movable, PED_MASS_KG, EGO_MASS_KG)[:, None]
        for _ in range(self.cfg.n_substeps):
            xy_m, v_mps = self._batch.read()
            nb = Neighbours.within(xy_m, roster.radius_m, self.cfg.agent_cutoff_m)
            walls = self._walls.near(xy_m)
            direction = self.nav.direction_at(roster.exit_idx, xy_m)
            wanted_v = steer(v_mps, direction, roster.speed_mps, roster.radius_m, nb, walls, self.cfg, self._dt_s)
            if self._ego_slot is not None:
                self._ego_command_mps = self._ego_command_mps + cap_speed(
                    (target - self._ego_command_mps)[None], np.array([self.ego_cfg.max_accel_mps2 * self._dt_s]))[0]
                wanted_v[self._ego_slot] = v_mps[self._ego_slot] = self._ego_command_mps
            safe_v = keep_apart(v_mps, roster.radius_m, movable, nb, walls, self._dt_s)
            self._batch.write(safe_v, mass_kg * (wanted_v - safe_v) / self._dt_s)
            self.space.step(self._dt_s)
            self._ego_collided |= self._ego_touches_wall()
            roster.moved_mps[:] = safe_v
        self.step_count += 1
        xy_m, _ = self._batch.read()  # rows follow the roster: nothing was added or removed during the step
        self._reroute_stuck(xy_m)
        stay = self._remove_arrived(xy_m)
        self._spawn(xy_m[stay])
        self._settle_order()
        self._history.append((self.ids, self.positions_m))

    def _on_ego_contact(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: object) -> None:
        self._ego_collided = True

    def _ego_touches_wall(self) -> bool:
        """Walls stop the ego speculatively (no pymunk contact), so wall contact is a distance check."""
        if self._ego_body is None:
            return False
        xy = np.array([self._ego_body.position], dtype=np.float64)
        gap = self._walls.distance_m(xy)[0] - self.ego_cfg.radius_m - WALL_RADIUS_M
        return bool(gap < CONTACT_TOLERANCE_M)

    # ---------------------------------------------------------------- population
    def _admit(self, rows: Roster, bodies: list[pymunk.Body]) -> None:
        self._roster = self._roster.extend(rows)
        self._bodies.update({body.id: body for body in bodies})

    def _add_pedestrians(self, xy_m: np.ndarray, exit_idx: np.ndarray) -> None:
        """Add pedestrians at xy_m (M, 2) [m] heading to exit_idx (M,), walking at their preferred speed."""
        speed = preferred_speeds(self.cfg, len(xy_m), self.rng)
        velocity = speed[:, None] * self.nav.direction_at(exit_idx, xy_m)
        bodies = [physics.add_pedestrian(self.space, p, v, self.cfg.radius_m) for p, v in zip(xy_m, velocity,
                                                                                               strict=True)]
        ped_id = self._next_ped_id + np.arange(len(xy_m), dtype=np.int64)
        self._next_ped_id += len(xy_m)
        self._admit(Roster.of([b.id for b in bodies], ped_id, exit_idx, speed, np.full(len(xy_m), self.cfg.radius_m),
                              velocity, self.step_count), bodies)

    def _place_initial(self, n: int, keep_clear_m: np.ndarray) -> None:
        """Place up to n pedestrians on free lattice sites, away from the points keep_clear_m (B, 2) [m]."""
        gap = self.cfg.spawn_gap_m
        clear_gap = np.full(len(keep_clear_m), self.cfg.radius_m + self._roster.radius_m.max(initial=0.0) + gap)
        xy_m = lattice_positions(self.nav, n, 2 * self.cfg.radius_m, gap, keep_clear_m, clear_gap, self.rng)
        exit_idx, ok = choose_exits(self.nav, xy_m, np.ones(len(self.layout.exits), bool), self.rng)
        self._add_pedestrians(xy_m[ok], exit_idx[ok])

    def _reroute_stuck(self, xy_m: np.ndarray) -> None:
        """Pedestrians that came no closer to their exit for cfg.patience_s head for another exit.

        Args:
            xy_m: (K, 2) positions of the roster's bodies [m].
        """
        rows = self._roster
        iy, ix = self.nav.cells(xy_m)
        to_exit = self.nav.distance_m[rows.exit_idx, iy, ix]
        better = to_exit < rows.best_to_exit_m - PROGRESS_M
        rows.best_to_exit_m[better] = to_exit[better]
        rows.progress_step[better] = self.step_count
        stuck = np.flatnonzero((rows.ped_id >= 0)
                               & (self.step_count - rows.progress_step > self.cfg.patience_s / STEP_S))
        if stuck.size:
            exit_idx, ok = choose_exits(self.nav, xy_m[stuck], np.ones(len(self.layout.exits), bool), self.rng)
            rows.exit_idx[stuck[ok]] = exit_idx[ok]
            rows.best_to_exit_m[stuck] = np.inf
            rows.progress_step[stuck] = self.step_count

    def _remove_arrived(self, xy_m: np.ndarray) -> np.ndarray:
        """Remove pedestrians standing inside the exit they head to.

        Args:
            xy_m: (K, 2) positions of the roster's bodies [m].

        Returns:
            (K,) bool, True for the bodies that stay (the roster keeps only those, in the same order).
        """
        rows = self._roster
        gone = np.zeros(len(rows), bool)
        is_ped = rows.ped_id >= 0
        for e in np.unique(rows.exit_idx[is_ped]):
            mine = is_ped & (rows.exit_idx == e)
            gone[mine] = self.layout.exits[e].contains(xy_m[mine])
        for body_id in rows.body_id[gone].tolist():
            body = self._bodies.pop(body_id)
            self.space.remove(body, *body.shapes)
        self._roster = rows.take(~gone)
        return ~gone

    def _spawn(self, xy_m: np.ndarray) -> None:
        """Poisson arrivals at every entry, while below the cap and where there is room.

        Args:
            xy_m: (K, 2) positions of the roster's bodies [m].
        """
        counts = self.rng.poisson(self.cfg.spawn_rate_hz * STEP_S, len(self.layout.entries))
        rows = self._roster
        room = self.max_pedestrians - int(np.count_nonzero(rows.ped_id >= 0))
        if room <= 0 or not counts.any():
            return
        heading = self.nav.direction_at(rows.exit_idx, xy_m) * (rows.ped_id >= 0)[:, None]
        clearance = self.cfg.radius_m + rows.radius_m.max(initial=self.cfg.radius_m) + self.cfg.spawn_gap_m
        for entry, count in enumerate(counts.tolist()):
            count = min(count, room)
            if count <= 0:
                continue
            allowed = np.zeros(len(self.layout.exits), bool)
            allowed[list(self.layout.routes[entry])] = True
            new_xy, new_exit = spawn_points(self.layout.entries[entry], count, allowed, self.nav, xy_m, heading,
                                            clearance, self.cfg.spawn_lane_m, self.rng)
            if len(new_xy):
                self._add_pedestrians(new_xy, new_exit)
                room -= len(new_xy)
                xy_m = np.concatenate([xy_m, new_xy])
                heading = np.concatenate([heading, self.nav.direction_at(new_exit, new_xy)])

    def _settle_order(self) -> None:
        """Align the roster with pymunk's body order and cache positions, velocities and the id order."""
        self._roster = self._roster.reorder(self._batch.body_ids())
        self._xy_m, _ = self._batch.read()
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
