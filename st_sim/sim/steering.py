"""Social-force steering, vectorised over all agents: goal relaxation at a speed that drops with density and
queueing, anticipatory agent repulsion and wall repulsion.

Every force term is an acceleration [m/s^2] (force per unit mass). The new velocity is the old one plus the
summed acceleration times the substep, capped per agent; ``contacts.keep_apart`` then trims what would
overrun a gap, and pymunk resolves whatever contacts remain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from st_sim.sim.config import WALL_RADIUS_M, CrowdConfig
from st_sim.sim.walls import NearbyWalls

WEIDMANN_GAMMA_M2 = 1.913  # shape of Weidmann's speed-density relation [m^2]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (M, 2) arrays -> (M,)."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]


@dataclass(frozen=True)
class Neighbours:
    """Agent pairs closer than a cutoff, with their geometry.

    Attributes:
        i, j: (P,) int agent indices, i < j.
        offset_m: (P, 2) position of j minus position of i [m].
        dist_m: (P,) centre distance [m].
        unit: (P, 2) unit vector from i toward j.
        contact_m: (P,) sum of the two radii [m].
    """

    i: np.ndarray
    j: np.ndarray
    offset_m: np.ndarray
    dist_m: np.ndarray
    unit: np.ndarray
    contact_m: np.ndarray

    @classmethod
    def within(cls, xy_m: np.ndarray, radius_m: np.ndarray, cutoff_m: float) -> Neighbours:
        """All pairs of the discs at xy_m (N, 2) [m] with radii radius_m (N,) [m] whose centres are closer
        than cutoff_m [m] (k-d tree search)."""
        tree = cKDTree(xy_m, balanced_tree=False, compact_nodes=False)  # quicker to build for a few hundred points
        pairs = tree.query_pairs(cutoff_m, output_type="ndarray").reshape(-1, 2)
        i, j = pairs[:, 0], pairs[:, 1]
        offset = xy_m[j] - xy_m[i]
        dist = np.sqrt(dot(offset, offset))
        return cls(i, j, offset, dist, offset / np.maximum(dist, 1e-9)[:, None], radius_m[i] + radius_m[j])


@dataclass(frozen=True)
class Facing:
    """How each agent of a pair sees the other, relative to its own desired direction.

    Attributes:
        ahead_i, ahead_j: (P,) distance of the other agent along i's (j's) desired direction [m] (< 0: behind).
        across_i, across_j: (P,) distance of the other agent off i's (j's) line of walk [m].
        same_way: (P,) bool, desired directions less than 90 degrees apart.
    """

    ahead_i: np.ndarray
    ahead_j: np.ndarray
    across_i: np.ndarray
    across_j: np.ndarray
    same_way: np.ndarray

    @classmethod
    def of(cls, nb: Neighbours, direction: np.ndarray) -> Facing:
        """Facing of the pairs nb given unit desired directions (N, 2)."""
        e_i, e_j, off = direction[nb.i], direction[nb.j], nb.offset_m
        return cls(dot(off, e_i), -dot(off, e_j), np.abs(off[:, 0] * e_i[:, 1] - off[:, 1] * e_i[:, 0]),
                   np.abs(off[:, 0] * e_j[:, 1] - off[:, 1] * e_j[:, 0]), dot(e_i, e_j) > 0)


def goal_acceleration(velocity_mps: np.ndarray, direction: np.ndarray, speed_mps: np.ndarray,
                      relaxation_time_s: float) -> np.ndarray:
    """Relaxation toward the desired velocity: (v0 e - v) / tau, (N, 2) [m/s^2].

    Args:
        velocity_mps: (N, 2) current velocities [m/s].  direction: (N, 2) unit desired directions.
        speed_mps: (N,) desired speeds [m/s].
    """
    return (speed_mps[:, None] * direction - velocity_mps) / relaxation_time_s


def density_speed(nb: Neighbours, preferred_speed_mps: np.ndarray, cfg: CrowdConfig) -> np.ndarray:
    """Preferred speeds (N,) [m/s] slowed by the local density (Weidmann's fundamental diagram).

    Local density rho = agents (self included) within cfg.density_radius_m per area [1/m^2];
    v = v0 (1 - exp(-gamma (1 / rho - 1 / rho_jam))), zero at the jam density.
    """
    n = len(preferred_speed_mps)
    close = nb.dist_m < cfg.density_radius_m
    count = 1.0 + np.bincount(nb.i[close], minlength=n) + np.bincount(nb.j[close], minlength=n)
    rho = count / (np.pi * cfg.density_radius_m**2)
    factor = 1.0 - np.exp(-WEIDMANN_GAMMA_M2 * (1.0 / rho - 1.0 / cfg.jam_density_per_m2))
    return preferred_speed_mps * np.clip(factor, 0.0, 1.0)


def headway_speed(nb: Neighbours, facing: Facing, preferred_speed_mps: np.ndarray, time_gap_s: float) -> np.ndarray:
    """Preferred speeds (N,) [m/s] lowered to cover the free headway in time_gap_s (no pushing in queues).

    The headway of an agent is the gap to the nearest agent that walks the same way (desired directions less
    than 90 degrees apart) and whose disc lies across its path (ahead of it, less than the sum of radii off
    its line of walk); speed = min(v0, headway / time_gap_s). Oncoming agents do not stop each other: the
    repulsion steers them past.
    """
    headway = np.full(len(preferred_speed_mps), np.inf)
    for me, ahead, across in ((nb.i, facing.ahead_i, facing.across_i), (nb.j, facing.ahead_j, facing.across_j)):
        blocking = facing.same_way & (ahead > 0) & (across < nb.contact_m)
        np.minimum.at(headway, me[blocking], ahead[blocking] - nb.contact_m[blocking])
    return np.clip(headway / time_gap_s, 0.0, preferred_speed_mps)


def agent_repulsion(nb: Neighbours, facing: Facing, velocity_mps: np.ndarray, cfg: CrowdConfig) -> np.ndarray:
    """Anticipatory, anisotropic exponential repulsion between agent pairs, (N, 2) [m/s^2].

    Each pair is judged at its closest approach within cfg.look_ahead_s, extrapolating the current
    velocities: separation c at that moment (c = the current offset for pairs moving apart). Each agent is
    pushed along -c (away from where the other will be) with A exp((r_i + r_j - |c|) / B), weighted by
    lambda + (1 - lambda)(1 + cos phi) / 2, phi = angle between its desired direction and the direction to
    the other agent (agents ahead matter more than agents behind).

    Args:
        velocity_mps: (N, 2) [m/s].
    """
    n = len(velocity_mps)
    i, j = nb.i, nb.j
    closing = velocity_mps[j] - velocity_mps[i]
    t_near = np.clip(-dot(nb.offset_m, closing) / np.maximum(dot(closing, closing), 1e-9), 0.0, cfg.look_ahead_s)
    apart = nb.offset_m + t_near[:, None] * closing
    dist = np.sqrt(dot(apart, apart))
    magnitude = cfg.agent_strength_mps2 * np.exp((nb.contact_m - dist) / cfg.agent_range_m) / np.maximum(dist, 1e-6)
    half_lambda = (1.0 - cfg.anisotropy) / 2
    inv_dist = 1.0 / np.maximum(nb.dist_m, 1e-6)
    push_i = magnitude * (cfg.anisotropy + half_lambda * (1.0 + facing.ahead_i * inv_dist))
    push_j = magnitude * (cfg.anisotropy + half_lambda * (1.0 + facing.ahead_j * inv_dist))
    accel = np.empty((n, 2))
    for k in range(2):  # apart / |apart| is the unit vector from i toward j at the closest approach
        accel[:, k] = (np.bincount(j, push_j * apart[:, k], minlength=n)
                       - np.bincount(i, push_i * apart[:, k], minlength=n))
    return accel


def keep_right(nb: Neighbours, facing: Facing, direction: np.ndarray, cfg: CrowdConfig) -> np.ndarray:
    """Sidestep to the right of oncoming agents in one's path, (N, 2) [m/s^2].

    For every oncoming agent (desired directions more than 90 degrees apart) ahead and less than the sum of
    radii plus cfg.pass_margin_m off one's line of walk, accelerate to one's right with
    cfg.keep_right_mps2 x exp(-free distance ahead / cfg.agent_cutoff_m). Breaking the left-right symmetry
    of head-on encounters lets counter-flows settle into lanes instead of locking up.
    """
    n = len(direction)
    urge = np.zeros(n)
    for me, ahead, across in ((nb.i, facing.ahead_i, facing.across_i), (nb.j, facing.ahead_j, facing.across_j)):
        oncoming = ~facing.same_way & (ahead > 0) & (across < nb.contact_m + cfg.pass_margin_m)
        gap = np.maximum(ahead[oncoming] - nb.contact_m[oncoming], 0.0)
        urge += np.bincount(me[oncoming], np.exp(-gap / cfg.agent_cutoff_m), minlength=n)
    right = np.stack([direction[:, 1], -direction[:, 0]], axis=-1)
    return cfg.keep_right_mps2 * np.minimum(urge, 1.0)[:, None] * right


def wall_repulsion(walls: NearbyWalls, radius_m: np.ndarray, cfg: CrowdConfig) -> np.ndarray:
    """Exponential repulsion from the nearest wall, zero beyond cfg.wall_cutoff_m, (N, 2) [m/s^2]."""
    to_wall, dist = walls.nearest
    magnitude = np.where(dist < cfg.wall_cutoff_m,
                         cfg.wall_strength_mps2 * np.exp((radius_m + WALL_RADIUS_M - dist) / cfg.wall_range_m), 0.0)
    return -magnitude[:, None] * to_wall


def cap_speed(velocity_mps: np.ndarray, max_speed_mps: np.ndarray) -> np.ndarray:
    """Scale down rows of (N, 2) velocities whose norm exceeds max_speed_mps (N,) [m/s]."""
    speed = np.sqrt(dot(velocity_mps, velocity_mps))
    scale = np.minimum(1.0, max_speed_mps / np.maximum(speed, 1e-9))
    return velocity_mps * scale[:, None]


def steer(velocity_mps: np.ndarray, direction: np.ndarray, preferred_speed_mps: np.ndarray, radius_m: np.ndarray,
          nb: Neighbours, walls: NearbyWalls, cfg: CrowdConfig, dt_s: float) -> np.ndarray:
    """New velocities (N, 2) [m/s] after one substep of dt_s under the social forces.

    Args:
        velocity_mps, direction: (N, 2) velocities [m/s] and unit desired directions.
        preferred_speed_mps, radius_m: (N,) [m/s], [m].
        nb: pairs closer than cfg.agent_cutoff_m.  walls: the walls near every agent.
    """
    facing = Facing.of(nb, direction)
    speed_mps = headway_speed(nb, facing, density_speed(nb, preferred_speed_mps, cfg), cfg.time_gap_s)
    accel = (goal_acceleration(velocity_mps, direction, speed_mps, cfg.relaxation_time_s)
             + agent_repulsion(nb, facing, velocity_mps, cfg)
             + keep_right(nb, facing, direction, cfg)
             + wall_repulsion(walls, radius_m, cfg))
    return cap_speed(velocity_mps + dt_s * accel, cfg.max_speed_factor * preferred_speed_mps)
