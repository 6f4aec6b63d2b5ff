"""Agent pairs closer than a cutoff, with their geometry, and how each agent of a pair sees the other.

In a periodic layout (``Layout.period``) pairs are found across the seam and their offsets are the nearest
images, so the steering and the contacts never see the seam.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from st_sim.sim.exact import dot, exp, length
from st_sim.sim.layout import Period

SQUEEZE_M = 0.05  # a walker may brush past another this much inside body contact (shoulders turn) [m]


@dataclass(frozen=True)
class Neighbours:
    """Agent pairs closer than a cutoff, with their geometry.

    Attributes:
        i, j: (P,) int agent indices, i < j.
        offset_m: (P, 2) position of j minus position of i [m] (nearest image in a periodic layout).
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
    def within(cls, xy_m: np.ndarray, radius_m: np.ndarray, cutoff_m: float | np.ndarray,
               period: Period | None = None, tile: np.ndarray | None = None) -> Neighbours:
        """All pairs of the discs at xy_m (N, 2) [m] with radii radius_m (N,) [m] whose centres are closer than
        cutoff_m [m] (one value, or (N,) one per disc: a pair is kept when closer than its first disc's), sorted by
        i then j (k-d tree search; across the seam of a periodic layout).

        With ``tile`` (N,) int, discs of different tiles never pair: one search serves many crowds laid side by side
        (each tile is moved apart in y for the search only), and each crowd gets the pairs, in the order, that a
        search of its own discs would give.
        """
        cutoff = np.broadcast_to(np.asarray(cutoff_m, np.float64), (len(xy_m),))
        reach = float(cutoff.max(initial=0.0))
        coordinates = xy_m
        if tile is not None and len(xy_m):
            span = float(np.ptp(xy_m[:, 1])) + 2 * reach + 1.0
            coordinates = xy_m + np.stack([np.zeros(len(xy_m)), np.asarray(tile, np.float64) * span], axis=-1)
        search = reach * (1 + 1e-9) + 1e-9  # the tree's rounding must not drop a pair that the exact test keeps
        if period is None:
            tree = cKDTree(coordinates, balanced_tree=False, compact_nodes=False)  # quicker to build for a few hundred
        else:
            coordinates, boxsize = period.tree_input(coordinates, search)
            tree = cKDTree(coordinates, balanced_tree=False, compact_nodes=False, boxsize=boxsize)
        pairs = tree.query_pairs(search, output_type="ndarray").reshape(-1, 2)
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
        i, j = pairs[:, 0], pairs[:, 1]
        offset = xy_m[j] - xy_m[i]
        if period is not None:
            offset = period.nearest_image(offset)
        dist = length(offset)
        keep = dist < cutoff[i]
        i, j, offset, dist = i[keep], j[keep], offset[keep], dist[keep]
        return cls(i, j, offset, dist, offset / np.maximum(dist, 1e-9)[:, None], radius_m[i] + radius_m[j])

    def take(self, keep: np.ndarray) -> Neighbours:
        """The pairs selected by keep, a (P,) bool mask or index array."""
        return Neighbours(self.i[keep], self.j[keep], self.offset_m[keep], self.dist_m[keep], self.unit[keep],
                          self.contact_m[keep])


@dataclass(frozen=True)
class Directed:
    """Every pair of ``Neighbours`` seen from both ends: row k is agent ``me[k]`` looking at ``other[k]``.

    Attributes:
        me, other: (2P,) int agent indices.  offset_m: (2P, 2) position of other minus position of me [m].
        dist_m: (2P,) centre distance [m].  contact_m: (2P,) sum of the two radii [m].
    """

    me: np.ndarray
    other: np.ndarray
    offset_m: np.ndarray
    dist_m: np.ndarray
    contact_m: np.ndarray

    @classmethod
    def of(cls, nb: Neighbours) -> Directed:
        """Rows i -> j, then j -> i."""
        return cls(np.concatenate([nb.i, nb.j]), np.concatenate([nb.j, nb.i]),
                   np.concatenate([nb.offset_m, -nb.offset_m]), np.concatenate([nb.dist_m, nb.dist_m]),
                   np.concatenate([nb.contact_m, nb.contact_m]))

    def ahead_across(self, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(2P,) distance of other along me's unit heading (N, 2) [m] (< 0: behind), and (2P,) signed distance
        off me's line of walk [m] (> 0: on me's left)."""
        e, off = heading[self.me], self.offset_m
        return off[:, 0] * e[:, 0] + off[:, 1] * e[:, 1], e[:, 0] * off[:, 1] - e[:, 1] * off[:, 0]

    def take(self, keep: np.ndarray) -> Directed:
        """The rows selected by keep, a (2P,) bool mask or index array."""
        return Directed(self.me[keep], self.other[keep], self.offset_m[keep], self.dist_m[keep], self.contact_m[keep])


def free_walk_m(me: np.ndarray, ahead_m: np.ndarray, across_m: np.ndarray, contact_m: np.ndarray,
                n: int) -> np.ndarray:
    """(n,) how far each agent can walk along a heading before touching anybody [m].

    Args:
        me: (Q,) the agent of each directed pair.  ahead_m, across_m: (Q,) the other agent's distance along and
            off the heading [m].  contact_m: (Q,) sum of the radii [m].

    Another agent blocks when it is ahead and less than c = the sum of radii minus SQUEEZE_M off the line of walk
    (so neighbours walking abreast do not stop each other); the distance is ahead - sqrt(c^2 - across^2)
    (negative for an overlap); inf when nobody blocks.
    """
    contact = contact_m - SQUEEZE_M
    blocking = (ahead_m > 0) & (np.abs(across_m) < contact)
    gap = np.full(n, np.inf)
    np.minimum.at(gap, me[blocking], ahead_m[blocking] - np.sqrt(contact[blocking] ** 2 - across_m[blocking] ** 2))
    return gap


@dataclass(frozen=True)
class Facing:
    """How each agent of a pair sees the other, relative to a heading of each (its desired direction).

    Attributes:
        ahead_i, ahead_j: (P,) distance of the other agent along i's (j's) heading [m] (< 0: behind).
        across_i, across_j: (P,) distance of the other agent off i's (j's) line of walk [m].
        same_way: (P,) bool, headings less than 90 degrees apart.
    """

    ahead_i: np.ndarray
    ahead_j: np.ndarray
    across_i: np.ndarray
    across_j: np.ndarray
    same_way: np.ndarray

    @classmethod
    def of(cls, nb: Neighbours, heading: np.ndarray) -> Facing:
        """Facing of the pairs nb given unit headings (N, 2)."""
        e_i, e_j, off = heading[nb.i], heading[nb.j], nb.offset_m
        return cls(dot(off, e_i), -dot(off, e_j), np.abs(off[:, 0] * e_i[:, 1] - off[:, 1] * e_i[:, 0]),
                   np.abs(off[:, 0] * e_j[:, 1] - off[:, 1] * e_j[:, 0]), dot(e_i, e_j) > 0)


def headway_m(nb: Neighbours, facing: Facing, n: int, same_way_only: bool) -> np.ndarray:
    """(n,) free gap [m] from each agent to the nearest agent whose disc lies across its line of walk ahead.

    An agent j blocks i when it is ahead of i (along i's heading) and less than the sum of radii c off i's line
    of walk; with same_way_only, only agents heading the same way (less than 90 degrees apart) block.
    The gap is how far i can walk along its heading before the discs touch: ahead - sqrt(c^2 - across^2)
    (negative when they already overlap); inf when nobody blocks.
    """
    gap = np.full(n, np.inf)
    for me, ahead, across in ((nb.i, facing.ahead_i, facing.across_i), (nb.j, facing.ahead_j, facing.across_j)):
        blocking = (ahead > 0) & (across < nb.contact_m)
        if same_way_only:
            blocking &= facing.same_way
        reach = np.sqrt(nb.contact_m[blocking] ** 2 - across[blocking] ** 2)
        np.minimum.at(gap, me[blocking], ahead[blocking] - reach)
    return gap


def oncoming_urge(nb: Neighbours, facing: Facing, n: int, margin_m: float, decay_m: float) -> np.ndarray:
    """(n,) urge in [0, 1] to sidestep to the right: oncoming agents (headings more than 90 degrees apart)
    ahead and less than the sum of radii plus margin_m off one's line of walk, each weighted by
    exp(-free distance ahead / decay_m)."""
    urge = np.zeros(n)
    for me, ahead, across in ((nb.i, facing.ahead_i, facing.across_i), (nb.j, facing.ahead_j, facing.across_j)):
        oncoming = ~facing.same_way & (ahead > 0) & (across < nb.contact_m + margin_m)
        gap = np.maximum(ahead[oncoming] - nb.contact_m[oncoming], 0.0)
        urge += np.bincount(me[oncoming], exp(-gap / decay_m), minlength=n)
    return np.minimum(urge, 1.0)


def right_of(heading: np.ndarray) -> np.ndarray:
    """(N, 2) unit vectors 90 degrees clockwise of the unit headings (N, 2)."""
    return np.stack([heading[:, 1], -heading[:, 0]], axis=-1)


def closest_approach(nb: Neighbours, velocity_mps: np.ndarray, horizon_s: float) -> np.ndarray:
    """(P, 2) offset j - i [m] at the pair's closest approach within horizon_s, extrapolating velocities (N, 2).

    Pairs moving apart keep their current offset.
    """
    closing = velocity_mps[nb.j] - velocity_mps[nb.i]
    t_near = np.minimum(np.maximum(-dot(nb.offset_m, closing) / np.maximum(dot(closing, closing), 1e-9), 0.0),
                        horizon_s)
    return nb.offset_m + t_near[:, None] * closing


def pair_sum(nb: Neighbours, weight_i: np.ndarray, weight_j: np.ndarray, vector: np.ndarray, n: int) -> np.ndarray:
    """(n, 2) sum over pairs of -weight_i x vector for agent i and +weight_j x vector for agent j.

    With vector pointing from i toward j, positive weights push the two apart.
    """
    out = np.empty((n, 2))
    for k in range(2):
        out[:, k] = (np.bincount(nb.j, weight_j * vector[:, k], minlength=n)
                     - np.bincount(nb.i, weight_i * vector[:, k], minlength=n))
    return out
