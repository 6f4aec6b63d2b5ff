"""A multi-person tracker between the sensor and the predictor: constant-velocity Kalman filters, one per track,
detections assigned by minimum total distance (``scipy.optimize.linear_sum_assignment``) within a gate.

A track starts from a detection nobody else claimed, tentative; it is confirmed after ``min_hits`` detections in a
row and reported from then on; it coasts on its prediction through up to ``max_misses`` steps without a detection
and ends after that. So the histories a predictor gets start short, break when a person is lost, and may swap
identity when two people pass close.

The filter runs on each axis alone with the same 2x2 covariance (the model and the noise are isotropic), written out
with ``+ - * /`` (no matrix product, whose rounding depends on the CPU's BLAS kernel), so that every track is the same
to the last bit on every CPU (``tests/test_cpu_dispatch.py`` runs the ``realistic`` tracker under emulated CPUs).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from replays.constants import STEP_S

GATE_M = 1.0  # a detection farther than this from a track's predicted position is not assigned to it [m]
MIN_HITS = 2  # detections in a row that confirm a track [-]
MAX_MISSES = 3  # steps a confirmed track coasts without a detection before it ends [-]
ACCEL_NOISE = 1.0  # spectral density of the white-noise acceleration of a walker [m^2/s^3]
START_SPEED_SD_MPS = 1.0  # spread of a new track's unknown velocity [m/s]
MIN_MEASUREMENT_SD_M = 0.02  # least measurement spread the filter assumes, even for exact detections [m]


@dataclass
class Tracks:
    """Every live track (K of them), as arrays.

    Attributes:
        ids: (K,) int64 track ids, unique within an episode, in order of birth.
        xy_m, v_mps: (K, 2) filtered position [m] and velocity [m/s].
        p_xx, p_xv, p_vv: (K,) the per-axis covariance of position and velocity.
        hits: (K,) detections in a row (0 after a miss).  misses: (K,) steps in a row without one.
        confirmed: (K,) bool, reported from now on.
        source: (K,) int64 the true id of the last detection assigned (-1: a false one), for evaluation only.
    """

    ids: np.ndarray
    xy_m: np.ndarray
    v_mps: np.ndarray
    p_xx: np.ndarray
    p_xv: np.ndarray
    p_vv: np.ndarray
    hits: np.ndarray
    misses: np.ndarray
    confirmed: np.ndarray
    source: np.ndarray

    @classmethod
    def empty(cls) -> Tracks:
        zeros = np.zeros(0)
        return cls(np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 2)), zeros, zeros.copy(), zeros.copy(),
                   np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, np.int64))

    def take(self, keep: np.ndarray) -> Tracks:
        """The tracks selected by ``keep`` (a bool mask or indices)."""
        return Tracks(*(getattr(self, name)[keep] for name in self.__dataclass_fields__))


class Tracker:
    """Tracks over an episode (module docstring); ``step`` once per env step, ``reset`` at every episode start.

    Args:
        capacity: most tracks reported at once (the observation's rows); beyond it the youngest are left out.
        gate_m, min_hits, max_misses: as the module's constants.
    """

    def __init__(self, capacity: int, gate_m: float = GATE_M, min_hits: int = MIN_HITS, max_misses: int = MAX_MISSES):
        self.capacity, self.gate_m, self.min_hits, self.max_misses = capacity, gate_m, min_hits, max_misses
        self.reset()

    def reset(self) -> None:
        """Forget every track; ids start again from 0."""
        self.tracks = Tracks.empty()
        self._next_id = 0

    def step(self, xy_m: np.ndarray, sd_m: np.ndarray, source: np.ndarray) -> Tracks:
        """Predict every track 0.4 s ahead, assign the detections ``xy_m`` (D, 2) [m] (their measurement spread
        ``sd_m`` (D,) [m], their true ``source`` (D,) for evaluation), update, start and end tracks; returns the
        tracks reported now (confirmed, at most ``capacity``, oldest first)."""
        tracks = self._predicted(self.tracks)
        xy_m = np.asarray(xy_m, np.float64).reshape(-1, 2)
        sd_m = np.maximum(np.asarray(sd_m, np.float64), MIN_MEASUREMENT_SD_M)
        rows, cols = self._assign(tracks.xy_m, xy_m)
        matched = np.zeros(len(tracks.ids), bool)
        matched[rows] = True
        tracks = self._updated(tracks, rows, xy_m[cols], sd_m[cols], np.asarray(source, np.int64)[cols])
        tracks.misses[~matched] += 1
        tracks.hits[~matched] = 0
        alive = tracks.misses <= np.where(tracks.confirmed, self.max_misses, 0)
        fresh = np.ones(len(xy_m), bool)
        fresh[cols] = False
        self.tracks = self._joined(tracks.take(alive), xy_m[fresh], sd_m[fresh], np.asarray(source)[fresh])
        return self.tracks.take(np.flatnonzero(self.tracks.confirmed)[:self.capacity])

    def _assign(self, predicted_xy: np.ndarray, xy_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(track rows, detection rows) assigned: least total distance, pairs within the gate only."""
        if not len(predicted_xy) or not len(xy_m):
            return np.zeros(0, np.intp), np.zeros(0, np.intp)
        dx = predicted_xy[:, None, 0] - xy_m[None, :, 0]
        dy = predicted_xy[:, None, 1] - xy_m[None, :, 1]
        distance = np.sqrt(dx * dx + dy * dy)
        cost = np.where(distance <= self.gate_m, distance, 1e6)
        rows, cols = linear_sum_assignment(cost)
        within = cost[rows, cols] < 1e6
        return rows[within], cols[within]

    @staticmethod
    def _predicted(tracks: Tracks) -> Tracks:
        """Every track 0.4 s ahead at constant velocity, its covariance grown by the acceleration noise."""
        dt, q = STEP_S, ACCEL_NOISE
        p_xx = tracks.p_xx + 2 * dt * tracks.p_xv + dt * dt * tracks.p_vv + q * dt * dt * dt / 3
        p_xv = tracks.p_xv + dt * tracks.p_vv + q * dt * dt / 2
        p_vv = tracks.p_vv + q * dt
        return Tracks(tracks.ids, tracks.xy_m + dt * tracks.v_mps, tracks.v_mps, p_xx, p_xv, p_vv, tracks.hits,
                      tracks.misses, tracks.confirmed, tracks.source)

    def _updated(self, tracks: Tracks, rows: np.ndarray, z_m: np.ndarray, sd_m: np.ndarray,
                 source: np.ndarray) -> Tracks:
        """The tracks ``rows`` corrected by their detections ``z_m`` (M, 2) of spread ``sd_m`` (M,)."""
        tracks = tracks.take(np.arange(len(tracks.ids)))  # a copy to write into
        p_xx, p_xv, p_vv = tracks.p_xx[rows], tracks.p_xv[rows], tracks.p_vv[rows]
        innovation_var = p_xx + sd_m * sd_m
        gain_x, gain_v = p_xx / innovation_var, p_xv / innovation_var
        residual = z_m - tracks.xy_m[rows]
        tracks.xy_m[rows] = tracks.xy_m[rows] + gain_x[:, None] * residual
        tracks.v_mps[rows] = tracks.v_mps[rows] + gain_v[:, None] * residual
        tracks.p_xx[rows] = (1 - gain_x) * p_xx
        tracks.p_xv[rows] = (1 - gain_x) * p_xv
        tracks.p_vv[rows] = p_vv - gain_v * p_xv
        tracks.hits[rows] += 1
        tracks.misses[rows] = 0
        tracks.confirmed[rows] |= tracks.hits[rows] >= self.min_hits
        tracks.source[rows] = source
        return tracks

    def _joined(self, tracks: Tracks, xy_m: np.ndarray, sd_m: np.ndarray, source: np.ndarray) -> Tracks:
        """``tracks`` and a new tentative track at each unclaimed detection (velocity unknown)."""
        count = len(xy_m)
        if count == 0:
            return tracks
        ids = self._next_id + np.arange(count, dtype=np.int64)
        self._next_id += count
        born = Tracks(ids, xy_m.copy(), np.zeros((count, 2)), sd_m * sd_m, np.zeros(count),
                      np.full(count, START_SPEED_SD_MPS * START_SPEED_SD_MPS), np.ones(count, np.int64),
                      np.zeros(count, np.int64), np.full(count, self.min_hits <= 1), np.asarray(source, np.int64))
        return Tracks(*(np.concatenate([getattr(tracks, name), getattr(born, name)])
                        for name in Tracks.__dataclass_fields__))
