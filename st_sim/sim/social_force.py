"""Social-force steering, vectorised over all agents: goal relaxation at a speed that drops with density and
queueing, anticipatory agent repulsion, a sidestep to the right of oncoming walkers, and wall repulsion.

Every force term is an acceleration [m/s^2] (force per unit mass). The new velocity is the old one plus the
summed acceleration times the substep; the caller caps it per agent, ``contacts.keep_apart`` then trims what
would overrun a gap, and pymunk resolves whatever contacts remain.
"""

from __future__ import annotations

import numpy as np

from st_sim.sim.config import WALL_RADIUS_M, SocialForceConfig
from st_sim.sim.exact import exp, length
from st_sim.sim.pairs import (
    Facing,
    Neighbours,
    closest_approach,
    headway_m,
    oncoming_urge,
    pair_sum,
    right_of,
)
from st_sim.sim.walls import NearbyWalls

WEIDMANN_GAMMA_M2 = 1.913  # shape of Weidmann's speed-density relation [m^2]


def density_speed(nb: Neighbours, preferred_speed_mps: np.ndarray, cfg: SocialForceConfig) -> np.ndarray:
    """Preferred speeds (N,) [m/s] slowed by the local density (Weidmann's fundamental diagram).

    Local density rho = agents (self included) within cfg.density_radius_m per area [1/m^2];
    v = v0 (1 - exp(-gamma (1 / rho - 1 / rho_jam))), zero at the jam density.
    """
    n = len(preferred_speed_mps)
    close = nb.dist_m < cfg.density_radius_m
    count = 1.0 + np.bincount(nb.i[close], minlength=n) + np.bincount(nb.j[close], minlength=n)
    rho = count / (np.pi * cfg.density_radius_m * cfg.density_radius_m)
    factor = 1.0 - exp(-WEIDMANN_GAMMA_M2 * (1.0 / rho - 1.0 / cfg.jam_density_per_m2))
    return preferred_speed_mps * np.clip(factor, 0.0, 1.0)


def agent_repulsion(nb: Neighbours, facing: Facing, velocity_mps: np.ndarray, cfg: SocialForceConfig) -> np.ndarray:
    """Anticipatory, anisotropic exponential repulsion between agent pairs, (N, 2) [m/s^2].

    Each pair is judged at its closest approach within cfg.look_ahead_s (separation c). Each agent is
    pushed along -c with A exp((r_i + r_j - |c|) / B), weighted by lambda + (1 - lambda)(1 + cos phi) / 2,
    phi = angle between its desired direction and the direction to the other agent.
    """
    apart = closest_approach(nb, velocity_mps, cfg.look_ahead_s)
    dist = length(apart)
    magnitude = cfg.agent_strength_mps2 * exp((nb.contact_m - dist) / cfg.agent_range_m) / np.maximum(dist, 1e-6)
    half_lambda = (1.0 - cfg.anisotropy) / 2
    inv_dist = 1.0 / np.maximum(nb.dist_m, 1e-6)
    push_i = magnitude * (cfg.anisotropy + half_lambda * (1.0 + facing.ahead_i * inv_dist))
    push_j = magnitude * (cfg.anisotropy + half_lambda * (1.0 + facing.ahead_j * inv_dist))
    return pair_sum(nb, push_i, push_j, apart, len(velocity_mps))


def wall_repulsion(walls: NearbyWalls, radius_m: np.ndarray, cfg: SocialForceConfig) -> np.ndarray:
    """Exponential repulsion from the nearest wall, zero beyond cfg.wall_cutoff_m, (N, 2) [m/s^2]."""
    to_wall, dist = walls.nearest
    magnitude = np.where(dist < cfg.wall_cutoff_m,
                         cfg.wall_strength_mps2 * exp((radius_m + WALL_RADIUS_M - dist) / cfg.wall_range_m), 0.0)
    return -magnitude[:, None] * to_wall


def plan(velocity_mps: np.ndarray, direction: np.ndarray, preferred_speed_mps: np.ndarray, radius_m: np.ndarray,
         nb: Neighbours, walls: NearbyWalls, cfg: SocialForceConfig) -> np.ndarray:
    """The desired directions (N, 2) themselves: social forces decide afresh every substep (``walk``)."""
    return direction


def walk(direction: np.ndarray, velocity_mps: np.ndarray, preferred_speed_mps: np.ndarray, radius_m: np.ndarray,
         nb: Neighbours, walls: NearbyWalls, cfg: SocialForceConfig, dt_s: float) -> np.ndarray:
    """New velocities (N, 2) [m/s] after one substep of dt_s under the social forces (uncapped).

    Args:
        direction, velocity_mps: (N, 2) unit desired directions and velocities [m/s].
        preferred_speed_mps, radius_m: (N,) [m/s], [m].
        nb: pairs closer than cfg.agent_cutoff_m.  walls: the walls near every agent.
    """
    n = len(velocity_mps)
    facing = Facing.of(nb, direction)
    speed = np.maximum(np.minimum(density_speed(nb, preferred_speed_mps, cfg),
                                  headway_m(nb, facing, n, same_way_only=True) / cfg.time_gap_s), 0.0)
    sidestep = oncoming_urge(nb, facing, n, cfg.pass_margin_m, cfg.agent_cutoff_m)
    accel = ((speed[:, None] * direction - velocity_mps) / cfg.relaxation_time_s
             + agent_repulsion(nb, facing, velocity_mps, cfg)
             + cfg.keep_right_mps2 * sidestep[:, None] * right_of(direction)
             + wall_repulsion(walls, radius_m, cfg))
    return velocity_mps + dt_s * accel
