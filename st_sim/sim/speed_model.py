"""Collision-free speed model with anticipation: a first-order model, vectorised over all agents.

Each substep an agent chooses a direction and a speed (after Tordeux, Chraibi and Seyfried's collision-free
speed model, with neighbours judged where they will be, a sidestep for passing and a short search of
headings):

- heading e = normalise(e0 + neighbour pushes + sidestep + wall pushes): a neighbour pushes with
  a exp((r_i + r_j - |c|) / D) along -c, c = the pair's offset at its closest approach within the look-ahead,
  weighted by (1 + cos phi) / 2 (phi = angle between e0 and the neighbour: those behind barely matter);
  whoever one would walk into adds a sidestep (to the right of oncoming walkers, so lanes form; away from a
  slower one ahead, to overtake); walls push with b exp((r + r_wall - d) / D_wall);
- speed v = min(v0, free walk along e / T): nobody walks into anybody and queues keep a time gap T;
- if turning the heading by one of TURNS_RAD makes better progress toward the goal (speed x cos of the angle
  to e0), the agent takes that heading instead: a blocked walker slides round whoever stands in its way,
  so arches at a door break up; where no heading makes progress, it stands still (nobody walks backwards).

The heading is chosen once per 0.4 s step (``plan``, a reaction time), the speed along it every substep
(``walk``), and the velocity moves toward v e within the relaxation time. The caller caps it,
``contacts.keep_apart`` trims what would still overrun a gap, and pymunk resolves the rest.
"""

from __future__ import annotations

import numpy as np

from st_sim.sim.config import WALL_RADIUS_M, SpeedModelConfig
from st_sim.sim.exact import cos_sin, dot, exp, length, total
from st_sim.sim.pairs import Directed, Neighbours, free_walk_m, pair_sum, right_of
from st_sim.sim.walls import NearbyWalls

PASS_MARGIN_M = 0.3  # a walker counts as in one's path up to this far beyond body contact, sideways [m]
TURNS_RAD = (0.0, 0.45, -0.45, 0.9, -0.9)  # headings tried, relative to the pushed one, first kept on ties [rad]
TURNS_COS, TURNS_SIN = (values[:, None] for values in cos_sin(np.array(TURNS_RAD)))  # (K, 1) each
MIN_PROGRESS_MPS = 1e-3  # a heading must bring one this fast toward the goal, else one stands still [m/s]


def neighbour_push(nb: Neighbours, ahead_m: np.ndarray, velocity_mps: np.ndarray,
                   cfg: SpeedModelConfig) -> np.ndarray:
    """(N, 2) sum of the neighbours' pushes on each agent's walking direction [-] (see the module docstring).

    Args:
        ahead_m: (2P,) ``Directed.of(nb)``'s distances of the other agent along me's desired direction [m].
    """
    closing = velocity_mps[nb.j] - velocity_mps[nb.i]
    t_near = np.minimum(np.maximum(-dot(nb.offset_m, closing) / np.maximum(dot(closing, closing), 1e-9), 0.0),
                        cfg.look_ahead_s)
    apart = nb.offset_m + t_near[:, None] * closing
    dist = length(apart)
    weight = cfg.agent_strength * exp((nb.contact_m - dist) / cfg.agent_range_m) / np.maximum(dist, 1e-6)
    dist_now = np.maximum(nb.dist_m, 1e-6)
    view = 0.5 * (1.0 + ahead_m / np.concatenate([dist_now, dist_now]))
    p = len(nb.i)
    return pair_sum(nb, weight * view[:p], weight * view[p:], apart, len(velocity_mps))


def sidestep_urge(pairs: Directed, ahead_m: np.ndarray, across_m: np.ndarray, direction: np.ndarray,
                  velocity_mps: np.ndarray, preferred_speed_mps: np.ndarray, horizon_s: float) -> np.ndarray:
    """(N,) signed urge in [-1, 1] to step to the right (+) or left (-) of whoever one would walk into.

    A neighbour counts when it is ahead, less than the sum of radii plus PASS_MARGIN_M off one's line of walk,
    and one would close in on it walking at one's preferred speed (so a follower held back in a queue still
    wants to pass); it weighs exp(-time to contact at that closing speed / horizon_s). One passes an oncoming
    walker on the right and overtakes on the side away from the other.

    Args:
        ahead_m, across_m: (2P,) the other agent's distance along and off me's desired direction [m].
    """
    near = (ahead_m > 0) & (np.abs(across_m) < pairs.contact_m + PASS_MARGIN_M)
    me, other = pairs.me[near], pairs.other[near]
    closing = preferred_speed_mps[me] - dot(velocity_mps[other], direction[me])
    blocking = closing > 1e-3
    me, other, closing = me[blocking], other[blocking], closing[blocking]
    gap = np.maximum(ahead_m[near][blocking] - pairs.contact_m[near][blocking], 0.0)
    oncoming = dot(direction[me], direction[other]) < 0
    side = np.where(oncoming | (across_m[near][blocking] > 0), 1.0, -1.0)
    urge = np.bincount(me, side * exp(-gap / closing / horizon_s), minlength=len(direction))
    return np.minimum(np.maximum(urge, -1.0), 1.0)


def wall_push(walls: NearbyWalls, radius_m: np.ndarray, cfg: SpeedModelConfig) -> np.ndarray:
    """(N, 2) push of the walls on each agent's walking direction [-]: the sum over distinct walls closer than
    cfg.wall_cutoff_m (both sides of a door push)."""
    near = walls.distinct() & (walls.dist_m < cfg.wall_cutoff_m)
    gap = np.where(near, walls.dist_m, np.inf) - radius_m[:, None] - WALL_RADIUS_M
    weight = cfg.wall_strength * exp(-gap / cfg.wall_range_m)
    return -total(weight[..., None] * walls.to_wall, axis=1)


def best_heading(pairs: Directed, walls: NearbyWalls, heading: np.ndarray, direction: np.ndarray,
                 preferred_speed_mps: np.ndarray, radius_m: np.ndarray, time_gap_s: float) -> np.ndarray:
    """Of the headings TURNS_RAD off each unit heading (N, 2), the one (N, 2) with the best progress along the
    desired direction (N, 2): speed x cos(angle), speed = min(v0, free walk / time gap); zero (stand still)
    where no heading makes progress. All turns are evaluated at once, (K, ...) arrays for K turns.

    Only neighbours closer than contact + v0 x time gap can hold an agent below v0, so only they are looked at.
    """
    n, k = len(heading), len(TURNS_RAD)
    near = speed_limiting(pairs, preferred_speed_mps, time_gap_s)
    ahead0, across0 = near.ahead_across(heading)
    normal = np.stack([-heading[:, 1], heading[:, 0]], axis=-1)  # heading turned 90 degrees to the left
    c, s = TURNS_COS, TURNS_SIN
    row = (np.arange(k)[:, None] * n + near.me[None, :]).ravel()
    people = free_walk_m(row, (c * ahead0 + s * across0).ravel(), (c * across0 - s * ahead0).ravel(),
                         np.tile(near.contact_m, k), k * n).reshape(k, n)
    toward = (c[:, :, None] * dot(walls.to_wall, heading[:, None])[None]
              + s[:, :, None] * dot(walls.to_wall, normal[:, None])[None])  # (K, N, W)
    free = np.minimum(people, walls.free_walk_m(toward, radius_m + WALL_RADIUS_M))
    speed = np.minimum(np.maximum(free / time_gap_s, 0.0), preferred_speed_mps)
    score = speed * (c * dot(heading, direction) + s * dot(normal, direction))
    best = np.argmax(score, axis=0)
    picked = score[best, np.arange(n)] > MIN_PROGRESS_MPS
    turned = c[best] * heading + s[best] * normal
    return np.where(picked[:, None], turned, 0.0)


def speed_limiting(pairs: Directed, preferred_speed_mps: np.ndarray, time_gap_s: float) -> Directed:
    """The directed pairs whose other agent is close enough to hold me below my preferred speed (closer than
    contact + v0 x time gap)."""
    return pairs.take(pairs.dist_m < pairs.contact_m + preferred_speed_mps[pairs.me] * time_gap_s)


def plan(velocity_mps: np.ndarray, direction: np.ndarray, preferred_speed_mps: np.ndarray, radius_m: np.ndarray,
         nb: Neighbours, walls: NearbyWalls, cfg: SpeedModelConfig) -> np.ndarray:
    """Unit headings (N, 2) chosen for the coming step (zero for agents without a goal).

    Args:
        velocity_mps, direction: (N, 2) velocities [m/s] and unit desired directions (zero: no goal).
        preferred_speed_mps, radius_m: (N,) [m/s], [m].
        nb: pairs closer than cfg.agent_cutoff_m.  walls: the walls near every agent.
    """
    pairs = Directed.of(nb)
    ahead, across = pairs.ahead_across(direction)
    sidestep = sidestep_urge(pairs, ahead, across, direction, velocity_mps, preferred_speed_mps, cfg.look_ahead_s)
    heading = (direction + neighbour_push(nb, ahead, velocity_mps, cfg) + wall_push(walls, radius_m, cfg)
               + cfg.keep_right * sidestep[:, None] * right_of(direction))
    norm = length(heading)
    heading = np.where(norm[:, None] > 1e-9, heading / np.maximum(norm, 1e-9)[:, None], 0.0)
    return best_heading(pairs, walls, heading, direction, preferred_speed_mps, radius_m, cfg.time_gap_s)


def walk(heading: np.ndarray, velocity_mps: np.ndarray, preferred_speed_mps: np.ndarray, radius_m: np.ndarray,
         nb: Neighbours, walls: NearbyWalls, cfg: SpeedModelConfig, dt_s: float) -> np.ndarray:
    """New velocities (N, 2) [m/s] after one substep of dt_s along the planned unit headings (N, 2) (uncapped):
    toward min(v0, free walk / time gap) x heading within the relaxation time."""
    near = speed_limiting(Directed.of(nb), preferred_speed_mps, cfg.time_gap_s)
    ahead, across = near.ahead_across(heading)
    toward = dot(walls.to_wall, heading[:, None])
    free = np.minimum(free_walk_m(near.me, ahead, across, near.contact_m, len(heading)),
                      walls.free_walk_m(toward, radius_m + WALL_RADIUS_M))
    speed = np.minimum(np.maximum(free / cfg.time_gap_s, 0.0), preferred_speed_mps)
    follow = 1.0 if cfg.relaxation_time_s <= dt_s else dt_s / cfg.relaxation_time_s
    return velocity_mps + follow * (speed[:, None] * heading - velocity_mps)
