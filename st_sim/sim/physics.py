"""pymunk set-up of a crowd: the space, wall segments, pedestrian and ego discs, batched state I/O.

Bodies are plain dynamic discs in a zero-gravity space. Every substep one batched call per space (no per-body
Python loop) writes all velocities (speculatively trimmed, used to move the bodies) and forces (the steering
model's velocity change, applied before pymunk resolves the contacts).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import accumulate

import numpy as np
import pymunk
import pymunk.batch

from st_sim.sim.config import EGO_MASS_KG, PED_MASS_KG, WALL_RADIUS_M, CrowdConfig

PED_TYPE = 1  # pymunk collision_type of pedestrian shapes
EGO_TYPE = 2  # pymunk collision_type of the ego shape
WALL_TYPE = 3  # pymunk collision_type of wall segments


def make_space(cfg: CrowdConfig) -> pymunk.Space:
    """A zero-gravity, undamped space; contact solver iterations, slop and bias from cfg."""
    space = pymunk.Space()
    space.gravity = (0.0, 0.0)
    space.damping = 1.0  # no velocity decay: the steering model owns the velocities
    space.iterations = cfg.solver_iterations
    space.collision_slop = cfg.collision_slop_m
    space.collision_bias = cfg.collision_bias
    return space


def add_walls(space: pymunk.Space, walls_m: np.ndarray) -> None:
    """Static segments (radius WALL_RADIUS_M) on the space's static body; walls_m is (W, 2, 2) metres."""
    for (ax, ay), (bx, by) in walls_m.tolist():
        line = pymunk.Segment(space.static_body, (ax, ay), (bx, by), WALL_RADIUS_M)
        line.friction = 0.0
        line.elasticity = 0.0
        line.collision_type = WALL_TYPE
        space.add(line)


def _add_discs(space: pymunk.Space, xy_m: np.ndarray, vxy_mps: np.ndarray, radius_m: float, mass_kg: float,
               collision_type: int) -> list[pymunk.Body]:
    """Discs at xy_m (M, 2) [m] moving at vxy_mps (M, 2) [m/s], added in one call: pymunk takes the bodies, then
    the shapes, each in row order, as if added disc by disc. Friction and elasticity keep pymunk's default, 0."""
    bodies, discs = [], []
    for position, velocity in zip(np.asarray(xy_m, np.float64).reshape(-1, 2).tolist(),
                                  np.asarray(vxy_mps, np.float64).reshape(-1, 2).tolist(), strict=True):
        body = pymunk.Body(mass_kg, float("inf"))  # infinite moment: discs slide, never spin
        body.position = position
        body.velocity = velocity
        disc = pymunk.Circle(body, radius_m)
        disc.collision_type = collision_type
        bodies.append(body)
        discs.append(disc)
    space.add(*bodies, *discs)
    return bodies


def add_pedestrians(space: pymunk.Space, xy_m: np.ndarray, vxy_mps: np.ndarray, radius_m: float
                    ) -> list[pymunk.Body]:
    """Pedestrian discs at xy_m (M, 2) [m] moving at vxy_mps (M, 2) [m/s], in row order."""
    return _add_discs(space, xy_m, vxy_mps, radius_m, PED_MASS_KG, PED_TYPE)


def add_ego(space: pymunk.Space, xy_m: np.ndarray, radius_m: float) -> pymunk.Body:
    """The ego disc at xy_m (2,) [m], at rest."""
    return _add_discs(space, xy_m, np.zeros(2), radius_m, EGO_MASS_KG, EGO_TYPE)[0]


class BodyBatch:
    """One space's bodies for pymunk.batch: their ids, and the buffers through which ``read_bodies`` and
    ``write_bodies`` move the state of several spaces' bodies, one pymunk call per space.

    pymunk visits the moving bodies in an internal order that changes when bodies are added or removed
    (call ``body_ids`` after such changes to learn it), then the space's static body, which carries the
    walls: its row is dropped on reading and written as zeros.
    """

    def __init__(self, space: pymunk.Space):
        self.space = space
        self._out = pymunk.batch.Buffer()
        self._in = pymunk.batch.Buffer()

    def body_ids(self) -> np.ndarray:
        """(K,) int64 pymunk ids of the moving bodies, in iteration order."""
        self._out.clear()
        pymunk.batch.get_space_bodies(self.space, pymunk.batch.BodyFields.BODY_ID, self._out)
        ids = np.frombuffer(self._out.int_buf(), dtype=np.uintp).astype(np.int64)
        assert ids[-1] == self.space.static_body.id, "pymunk no longer visits the static body last"
        return ids[:-1]


def _ends(sizes: Sequence[int]) -> list[int]:
    """One past each space's rows (K_s moving bodies, then its static body), spaces one after another."""
    return list(accumulate(size + 1 for size in sizes))


def read_bodies(batches: Sequence[BodyBatch], sizes: Sequence[int]) -> np.ndarray:
    """(M, 4) positions [m] and velocities [m/s] (x, y, vx, vy) of the moving bodies of several spaces, space after
    space, each in iteration order; sizes: (S,) moving bodies per space, M in all."""
    out = batches[0]._out  # every space appends its rows to one buffer
    out.clear()
    fields = pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.VELOCITY
    for batch in batches:
        pymunk.batch.get_space_bodies(batch.space, fields, out)
    rows = np.frombuffer(out.float_buf(), dtype=np.float64).reshape(-1, 4)
    ends = _ends(sizes)
    assert len(rows) == ends[-1], "the spaces hold other bodies than sizes says"
    return np.concatenate([rows[end - size - 1:end - 1] for end, size in zip(ends, sizes, strict=True)])


def write_bodies(batches: Sequence[BodyBatch], sizes: Sequence[int], vxy_mps: np.ndarray, force_n: np.ndarray
                 ) -> None:
    """Set the velocities (M, 2) [m/s] and forces (M, 2) [N] of the moving bodies of several spaces, rows as
    ``read_bodies``'.

    In the next space step pymunk moves every body with its velocity, then adds force / mass x dt to the
    velocity and resolves the contacts; it clears the forces afterwards. The static bodies stay at rest.
    """
    ends = _ends(sizes)
    rows = np.zeros((ends[-1], 4))
    moving = np.ones(len(rows), bool)
    moving[np.array(ends) - 1] = False
    rows[moving, 0:2] = vxy_mps
    rows[moving, 2:4] = force_n
    fields = pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.FORCE
    for batch, end, size in zip(batches, ends, sizes, strict=True):
        batch._in.set_float_buf(rows[end - size - 1:end].reshape(-1))
        pymunk.batch.set_space_bodies(batch.space, fields, batch._in)
