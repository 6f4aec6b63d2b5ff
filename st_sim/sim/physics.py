"""pymunk set-up of a crowd: the space, wall segments, pedestrian and ego discs, batched state I/O.

Bodies are plain dynamic discs in a zero-gravity space. Every substep one batched call (no per-body Python
loop) writes all velocities (speculatively trimmed, used to move the bodies) and forces (the steering
model's velocity change, applied before pymunk resolves the contacts).
"""

from __future__ import annotations

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


def _add_disc(space: pymunk.Space, xy_m: np.ndarray, vxy_mps: np.ndarray, radius_m: float,
              mass_kg: float, collision_type: int) -> pymunk.Body:
    body = pymunk.Body(mass_kg, float("inf"))  # infinite moment: discs slide, never spin
    body.position = float(xy_m[0]), float(xy_m[1])
    body.velocity = float(vxy_mps[0]), float(vxy_mps[1])
    disc = pymunk.Circle(body, radius_m)
    disc.friction = 0.0
    disc.elasticity = 0.0
    disc.collision_type = collision_type
    space.add(body, disc)
    return body


def add_pedestrian(space: pymunk.Space, xy_m: np.ndarray, vxy_mps: np.ndarray, radius_m: float) -> pymunk.Body:
    """A pedestrian disc at xy_m (2,) [m] moving at vxy_mps (2,) [m/s]."""
    return _add_disc(space, xy_m, vxy_mps, radius_m, PED_MASS_KG, PED_TYPE)


def add_ego(space: pymunk.Space, xy_m: np.ndarray, radius_m: float) -> pymunk.Body:
    """The ego disc at xy_m (2,) [m], at rest."""
    return _add_disc(space, xy_m, np.zeros(2), radius_m, EGO_MASS_KG, EGO_TYPE)


class BodyBatch:
    """Read the state of every moving body and write their velocities and forces, one call each (pymunk.batch).

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

    def read(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions (K, 2) [m] and velocities (K, 2) [m/s] of the moving bodies, in iteration order."""
        self._out.clear()
        fields = pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.VELOCITY
        pymunk.batch.get_space_bodies(self.space, fields, self._out)
        state = np.frombuffer(self._out.float_buf(), dtype=np.float64).reshape(-1, 4)[:-1]
        return state[:, 0:2].copy(), state[:, 2:4].copy()

    def write(self, vxy_mps: np.ndarray, force_n: np.ndarray) -> None:
        """Set the moving bodies' velocities (K, 2) [m/s] and forces (K, 2) [N], in iteration order.

        In the next space step pymunk moves every body with its velocity, then adds force / mass x dt to the
        velocity and resolves the contacts; it clears the forces afterwards. The static body stays at rest.
        """
        rows = np.zeros((len(vxy_mps) + 1, 4))
        rows[:-1, 0:2] = vxy_mps
        rows[:-1, 2:4] = force_n
        self._in.set_float_buf(rows.reshape(-1))
        fields = pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.FORCE
        pymunk.batch.set_space_bodies(self.space, fields, self._in)
