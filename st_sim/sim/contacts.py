"""Speculative contacts: trim velocities so that bodies do not sink into each other or into walls.

pymunk detects a contact only once two shapes overlap, so two pedestrians closing at 2.6 m/s would sink
some 35 cm into each other during one 0.13 s substep before pymunk pushed back. ``keep_apart`` looks one substep
ahead instead: for every pair (and every body and each wall near it) it removes the part of the closing speed
that would overrun the gap. Overlapping pairs may not close further and open at half their overlap per
substep. The correction is split equally between two pedestrians, or taken wholly by a pedestrian at a
wall; a few over-relaxed Jacobi sweeps settle bodies with several neighbours. Where they do not settle
(a dense jam), the bodies still closing a gap first give up their own approach along the contact normal
(they slide past each other), and those still closing after that stand still for the substep; where a queue
has no leader (a ring round a periodic corridor) both bodies of every constraint still closing stand still.
pymunk resolves the rest.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from st_sim.sim.config import WALL_RADIUS_M
from st_sim.sim.exact import dot, length, total
from st_sim.sim.pairs import Neighbours
from st_sim.sim.walls import NearbyWalls

SWEEPS = 4  # most Jacobi sweeps over all constraints per substep
OMEGA = 1.5  # over-relaxation of the averaged Jacobi corrections between bodies [-]
FREEZE_PASSES = 50  # most rounds of stopping the bodies left closing a gap (one round per follower in a queue)
SLIDE_PASSES = 3  # the first rounds only take away the closing bodies' approach (they slide), later ones stop them
FREEZE_TOLERANCE_MPS = 0.01  # closing speed beyond the allowed one that counts as closing [m/s]
GROW_ROUNDS = 4  # most times the constraints are chosen again for bodies that a correction sped up [-]
REACH_FACTOR = 2.0  # constraints cover gaps up to this multiple of the distance the bodies could close [-]
SKIN_M = 0.1  # ... plus this much, for bodies at rest that a correction may set moving [m]
OVERLAP_OPENING = 0.5  # share of an existing overlap opened per substep [-]


def contact_reach_m(radius_m: float, speed_mps: float, dt_s: float) -> float:
    """Farthest wall (centre-line distance) [m] that a body of radius_m at speed_mps may need as a constraint."""
    return radius_m + WALL_RADIUS_M + SKIN_M + REACH_FACTOR * dt_s * speed_mps


def pair_reach_m(contact_m: float, speed_mps: float, dt_s: float) -> float:
    """Farthest centre distance [m] at which two bodies touching at contact_m, each at speed_mps, may need a
    constraint."""
    return contact_m + SKIN_M + REACH_FACTOR * dt_s * 2 * speed_mps


def allowed_closing_mps(gap_m: np.ndarray, dt_s: float) -> np.ndarray:
    """Closing speed [m/s] that just closes gap_m within dt_s; for overlaps (gap < 0) a share opens."""
    return np.where(gap_m > 0, gap_m, OVERLAP_OPENING * gap_m) / dt_s


@dataclass(frozen=True)
class Constraints:
    """C one-sided constraints on closing speeds: body i and body j (row n = the walls, which never move) may
    close along unit (from i toward j) by at most allowed_mps within the substep.

    Attributes:
        i, j: (C,) int body rows.  unit: (C, 2) unit normals.  allowed_mps: (C,) closing speed allowed [m/s].
        share_i, share_j: (C,) how much of a correction each body takes.  relax: (C,) over-relaxation [-].
    """

    n: int
    i: np.ndarray
    j: np.ndarray
    unit: np.ndarray
    allowed_mps: np.ndarray
    share_i: np.ndarray
    share_j: np.ndarray
    relax: np.ndarray

    @classmethod
    def of(cls, reach_mps: np.ndarray, radius_m: np.ndarray, yielding: np.ndarray, nb: Neighbours,
           walls: NearbyWalls, dt_s: float, give_m: float) -> Constraints:
        """The constraints of every pair and body-wall gap that bodies moving at up to reach_mps (N,) [m/s]
        could close within dt_s (see ``keep_apart`` for the other arguments)."""
        n = len(reach_mps)
        # agent-agent: a body that never yields (the ego) stands in its pairs as the static row n, like a wall:
        # the other body keeps clear of it, but the ego's own motion is not trimmed, so an ego that drives into
        # somebody really touches them
        weight = yielding[nb.i] + yielding[nb.j]
        near = ((nb.dist_m < nb.contact_m + SKIN_M + REACH_FACTOR * dt_s * (reach_mps[nb.i] + reach_mps[nb.j]))
                & (weight > 0))
        flip = near & (yielding[nb.i] == 0)
        i, j = np.where(flip, nb.j, nb.i)[near], np.where(flip, nb.i, nb.j)[near]
        unit = np.where(flip[:, None], -nb.unit, nb.unit)[near]
        both = yielding[j] > 0
        gap = nb.dist_m[near] - nb.contact_m[near] + np.where(both, give_m, 0.0)
        share_pairs = np.where(both, yielding[i] / weight[near], 1.0)
        j = np.where(both, j, n)
        # agent-wall: the wall is body n
        wall_gap = walls.dist_m - radius_m[:, None] - WALL_RADIUS_M
        body, slot = np.nonzero(wall_gap < SKIN_M + REACH_FACTOR * dt_s * reach_mps[:, None])
        return cls(n=n, i=np.concatenate([i, body]), j=np.concatenate([j, np.full(len(body), n)]),
                   unit=np.concatenate([unit, walls.to_wall[body, slot]]),
                   allowed_mps=allowed_closing_mps(np.concatenate([gap, wall_gap[body, slot]]), dt_s),
                   share_i=np.concatenate([share_pairs, np.ones(len(body))]),
                   share_j=np.concatenate([1.0 - share_pairs, np.zeros(len(body))]),
                   relax=np.concatenate([np.full(len(gap), OMEGA), np.ones(len(body))]))  # walls: exact

    def settle(self, velocity_mps: np.ndarray, yielding: np.ndarray) -> np.ndarray:
        """Velocities (N, 2) [m/s] that keep every constraint (within FREEZE_TOLERANCE_MPS where a gap is still
        open; never closing further where it is already overrun): over-relaxed Jacobi sweeps, then the safety
        net of sliding and standing still."""
        n, i, j, unit, allowed = self.n, self.i, self.j, self.unit, self.allowed_mps
        # every constraint touches 4 entries of the flat velocity vector (vx of bodies 0..n, then vy): i's and
        # j's x and y; closing speed = sum of coef x those entries, a unit of excess changes them by push
        padded = np.concatenate([velocity_mps, np.zeros((1, 2))])
        excess = np.maximum(dot(padded[i] - padded[j], unit) - allowed, 0.0)
        if not excess.any():
            return velocity_mps.copy()  # the common case in free flow: nothing to trim
        size = 2 * (n + 1)
        slots = np.stack([i, i + n + 1, j, j + n + 1], axis=1).ravel()
        coef = np.stack([unit[:, 0], unit[:, 1], -unit[:, 0], -unit[:, 1]], axis=1)
        v = np.concatenate([padded[:, 0], padded[:, 1]])
        push = -np.stack([self.share_i, self.share_i, self.share_j, self.share_j], axis=1) * coef \
            * self.relax[:, None]  # i back, j ahead
        bodies = np.stack([i, j], axis=1).ravel()

        def closing() -> np.ndarray:
            """(C,) closing speed of every constraint at the current velocities v [m/s]."""
            return total(v[slots].reshape(-1, 4) * coef, axis=1)

        for _ in range(SWEEPS):
            load = np.maximum(np.bincount(bodies, np.repeat(excess > 0, 2), minlength=n + 1), 1.0)
            v += np.bincount(slots, (push * excess[:, None]).ravel(), minlength=size) / np.concatenate([load, load])
            excess = np.maximum(closing() - allowed, 0.0)
            if not excess.any():
                break
        # safety net where the sweeps did not settle (dense jams): first every body of a constraint still closing
        # gives up its own motion toward the other body (it slides past instead), then whoever still closes a
        # gap stands still, which can only relieve its neighbours' constraints, except those of followers;
        # repeat. The tolerance never lets an overrun gap close further, so no overlap creeps deeper step by step
        no_closer = np.maximum(allowed + FREEZE_TOLERANCE_MPS, 0.0)
        gives = np.r_[yielding > 0, False]  # bodies that may be slowed: not the walls' row, not the ego ...
        gives_at = np.concatenate([gives[i] | (j == n), gives[j]])  # ... except by the walls
        slot_gives = np.stack([gives_at[: len(i)]] * 2 + [gives_at[len(i):]] * 2, axis=1)  # (C, 4)
        for round_ in range(FREEZE_PASSES):
            stuck = closing() > no_closer
            if not stuck.any():
                break
            if round_ < SLIDE_PASSES:
                own = v[slots[stuck.repeat(4)]].reshape(-1, 4) * coef[stuck]  # (S, 4): i's and j's closing parts
                toward = np.maximum(np.stack([own[:, 0] + own[:, 1], own[:, 2] + own[:, 3]], axis=1), 0.0)
                give_up = np.repeat(toward, 2, axis=1) * coef[stuck] * slot_gives[stuck]  # approach, along the normal
                v -= np.bincount(slots[stuck.repeat(4)], give_up.ravel(), minlength=size)
                continue
            frozen = np.zeros(n + 1, bool)
            frozen[bodies.reshape(-1, 2)[stuck].ravel()[slot_gives[stuck][:, 1::2].ravel()]] = True
            v[np.concatenate([frozen, frozen])] = 0.0
        else:  # a queue with no leader (a ring round a periodic corridor) outlasts the rounds: both bodies of
            # every constraint still closing stand still, until none closes (each round freezes more bodies)
            frozen = np.zeros(n + 1, bool)
            while (stuck := closing() > no_closer).any():
                newly = bodies.reshape(-1, 2)[stuck].ravel()[slot_gives[stuck][:, ::2].ravel()]
                newly = newly[~frozen[newly]]
                if not newly.size:
                    break  # only bodies that may not be slowed (the ego) still close: outside the guarantee
                frozen[newly] = True
                v[np.concatenate([frozen, frozen])] = 0.0
        return np.stack([v[:n], v[n + 1: 2 * n + 1]], axis=-1)


def keep_apart(velocity_mps: np.ndarray, radius_m: np.ndarray, yielding: np.ndarray, nb: Neighbours,
               walls: NearbyWalls, dt_s: float, give_m: float = 0.0, crowd: np.ndarray | None = None) -> np.ndarray:
    """Velocities (N, 2) [m/s] trimmed so that no pair and no body-wall gap closes beyond contact within dt_s.

    Two bodies share a correction in proportion to how readily each yields: a walker (1) and a standing
    pedestrian (a small weight) share it mostly to the walker's cost. A body whose velocity is imposed (the ego,
    0) is an obstacle to the others, like a wall: they do not walk into it, but it is not held back by them
    (driving into somebody is a contact) and only walls stop it. Leave a pair out of nb and the two bodies
    ignore each other (pymunk still resolves their contact: an invisible ego is bumped into).

    A correction can set a body moving that stood still (a walker pushes it ahead), so the constraints are
    chosen by each body's speed before and after the correction: when a body came out faster than the margin of
    its constraints allows for (REACH_FACTOR, SKIN_M), they are chosen again with that speed and the correction
    is redone.

    Args:
        velocity_mps: (N, 2) proposed velocities [m/s].  radius_m: (N,) body radii [m].
        yielding: (N,) weights >= 0, how readily each body gives way (0: never, the ego).
        nb: pairs, any superset of those that can touch within dt_s.  walls: the walls near every body.
        give_m: two yielding bodies may overlap this much before they stop closing (soft bodies) [m]; walls and
            the ego stay hard.
        crowd: (N,) int, the crowd of each body when several crowds that never touch are solved at once (no pair
            joins two crowds); each crowd gets the velocities it would get alone. None: one crowd.
    """
    yielding = np.asarray(yielding, dtype=np.float64)
    speed = length(velocity_mps)
    # a push hands a body at most about the speed of whoever pushes it: start from the fastest body that can
    # reach it within the substep
    touching = nb.dist_m < nb.contact_m + SKIN_M + dt_s * (speed[nb.i] + speed[nb.j])
    reach_mps = speed.copy()
    np.maximum.at(reach_mps, nb.i[touching], speed[nb.j[touching]])
    np.maximum.at(reach_mps, nb.j[touching], speed[nb.i[touching]])
    crowd = np.zeros(len(speed), np.int64) if crowd is None else np.asarray(crowd)
    for _ in range(GROW_ROUNDS):
        system = Constraints.of(reach_mps, radius_m, yielding, nb, walls, dt_s, give_m)
        safe = system.settle(velocity_mps, yielding)
        speed = length(safe)
        outgrown = speed > REACH_FACTOR * reach_mps + SKIN_M / (2 * dt_s)
        if not outgrown.any():
            break  # no pair or wall left out of the constraints can be reached at these speeds
        again = np.isin(crowd, crowd[outgrown])  # only those crowds choose their constraints again
        reach_mps = np.where(again, np.maximum(reach_mps, speed), reach_mps)
    return safe
