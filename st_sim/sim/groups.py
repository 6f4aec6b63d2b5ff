"""Small groups that walk together: how many arrive together, forming groups in the initial crowd, where
companions appear, and the pull that keeps members abreast.

A group shares its exit, its preferred speed and its stops. Walking, each member turns toward the line of
the group's centre and walks faster when the centre is ahead of it, slower when it is behind; the steering
model then keeps the members apart like any pedestrians.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from st_sim.sim.config import PopulationConfig
from st_sim.sim.exact import dot, length
from st_sim.sim.layout import Period
from st_sim.sim.pairs import right_of

ABREAST_M = 0.7  # centre distance of neighbouring members walking abreast [m]
LATERAL_PULL_PER_M = 1.0  # turn toward the group's centre line, per metre of sideways offset [1/m]
PACE_PER_M = 0.6  # relative speed change per metre the group's centre is ahead (+) or behind (-) of a member [1/m]
PACE_RANGE = (0.4, 1.4)  # a member's speed stays within this range of the group's preferred speed [-]
FORM_RADIUS_M = 1.5  # members of an initial group stand within this distance of its first member [m]


def unit_sizes(pop: PopulationConfig, n_units: int, rng: np.random.Generator) -> np.ndarray:
    """(n_units,) int sizes (1, 2 or 3) of arriving units, so that pop.group_share of the pedestrians walk in
    groups and pop.triple_share of the groups have three members."""
    mean_size = 2.0 + pop.triple_share
    share = pop.group_share
    unit_is_group = share / max(mean_size - share * (mean_size - 1.0), 1e-9)
    grouped = rng.random(n_units) < unit_is_group
    return np.where(grouped, 2 + (rng.random(n_units) < pop.triple_share), 1).astype(np.int64)


def form_groups(xy_m: np.ndarray, pop: PopulationConfig, rng: np.random.Generator, first_id: int) -> np.ndarray:
    """Group ids (N,) int64 for pedestrians at xy_m (N, 2) [m] (-1 alone): in random order, each pedestrian not
    yet in a group draws a unit size and takes that many unassigned neighbours within FORM_RADIUS_M.

    Ids count up from first_id. Where too few neighbours are free the group is smaller (or nobody's).
    """
    n = len(xy_m)
    group = np.full(n, -1, np.int64)
    if n < 2 or pop.group_share == 0:
        return group
    sizes = unit_sizes(pop, n, rng)
    tree = cKDTree(xy_m)
    taken = np.zeros(n, bool)
    next_id = first_id
    for k, i in enumerate(rng.permutation(n).tolist()):
        if taken[i] or sizes[k] == 1:
            continue
        _, near = tree.query(xy_m[i], k=min(n, sizes[k] + 4), distance_upper_bound=FORM_RADIUS_M)
        members = [j for j in np.atleast_1d(near).tolist() if j < n and not taken[j]][: sizes[k]]
        if len(members) > 1:
            group[members] = next_id
            taken[members] = True
            next_id += 1
    return group


def companion_offsets(heading: np.ndarray, size: int) -> np.ndarray:
    """(size - 1, 2) offsets [m] of a unit's companions from its first member at unit heading (2,): abreast,
    alternately to its right and its left."""
    right = right_of(heading[None])[0]
    sides = [ABREAST_M, -ABREAST_M]
    return np.array([sides[k % 2] * right for k in range(size - 1)]).reshape(-1, 2)


def cohesion(xy_m: np.ndarray, direction: np.ndarray, speed_mps: np.ndarray, group: np.ndarray,
             period: Period | None) -> tuple[np.ndarray, np.ndarray]:
    """Desired directions (N, 2) and speeds (N,) [m/s] of group members bent toward their group's centre.

    Args:
        xy_m: (N, 2) positions [m].  direction: (N, 2) unit desired directions.  speed_mps: (N,) [m/s].
        group: (N,) group ids, -1 alone.  period: the layout's wrap-around, or None.
    """
    member = np.flatnonzero(group >= 0)
    if member.size == 0:
        return direction, speed_mps
    _, first, inverse = np.unique(group[member], return_index=True, return_inverse=True)
    anchor = member[first][inverse]
    from_anchor = xy_m[member] - xy_m[anchor]
    if period is not None:
        from_anchor = period.nearest_image(from_anchor)
    size = np.bincount(inverse)
    centre = np.stack([np.bincount(inverse, from_anchor[:, k]) / size for k in range(2)], axis=-1)
    to_centre = centre[inverse] - from_anchor
    e = direction[member]
    ahead = dot(to_centre, e)
    sideways = to_centre - ahead[:, None] * e
    bent = e + LATERAL_PULL_PER_M * sideways
    norm = length(bent)
    walking = dot(e, e) > 0
    new_direction, new_speed = direction.copy(), speed_mps.copy()
    new_direction[member[walking]] = bent[walking] / np.maximum(norm[walking], 1e-9)[:, None]
    new_speed[member] *= np.clip(1.0 + PACE_PER_M * ahead, *PACE_RANGE)
    return new_direction, new_speed
