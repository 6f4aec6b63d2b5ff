"""The last few frames of a crowd: observation rows that stay with their agent, histories, run lengths."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from replays.constants import POSITION_LIMIT_M, T_PRED


class TooManyAgentsError(ValueError):
    """A frame holds more pedestrians than the observation has rows (N_max); nothing is ever dropped."""


@dataclass(frozen=True, eq=False)
class Frame:
    """The pedestrians of one moment.

    Attributes:
        frame: frame id of the recording (replays) or step count (simulation).
        ids: (N,) int64 agent ids, unique, >= 0.
        xy_m: (N, 2) float64 positions, metres, world frame.
    """

    frame: int
    ids: np.ndarray
    xy_m: np.ndarray


def lookup(sorted_ids: np.ndarray, query: np.ndarray) -> np.ndarray:
    """(Q,) index of every ``query`` id in the sorted (M,) ``sorted_ids``, -1 where absent."""
    if len(sorted_ids) == 0:
        return np.full(len(query), -1, np.intp)
    idx = np.minimum(np.searchsorted(sorted_ids, query), len(sorted_ids) - 1)
    return np.where(sorted_ids[idx] == query, idx, -1)


class TrackBuffer:
    """Keeps the last ``max(T_obs, 13)`` frames and gives each present agent a fixed row in [0, N_max).

    An agent keeps its row while it is present in consecutive pushed frames; a newcomer takes the lowest
    free row. ``run`` counts consecutive pushed frames of presence up to now (1 = appeared this frame).
    ``row_ids`` holds -1 in empty rows, so agent ids must be >= 0 (``push`` refuses others). Every row's positions
    over the kept frames are also held by row in a ring of columns, so ``history`` is a copy, not a search.
    """

    def __init__(self, n_max: int, t_obs: int, where: str):
        self.n_max, self.t_obs, self.where = n_max, t_obs, where
        self.depth = max(t_obs, T_PRED + 1)
        self.frames: deque[Frame] = deque(maxlen=self.depth)
        self.row_ids = np.full(n_max, -1, np.int64)
        self._run = np.zeros(0, np.int64)  # aligned with the sorted ids of the newest frame
        self._ring_xy = np.zeros((self.depth, n_max, 2))  # column pushes % depth: every row's position then [m]
        self._ring_seen = np.zeros((self.depth, n_max), bool)
        self._pushes = 0

    def clear(self) -> None:
        self.frames.clear()
        self.row_ids[:] = -1
        self._run = np.zeros(0, np.int64)
        self._ring_seen[:] = False
        self._pushes = 0

    def push(self, frame: Frame) -> None:
        """Append a frame (any id order).

        Raises:
            TooManyAgentsError: more than N_max agents.
            ValueError: a negative or repeated id, or a position that is not a finite (N, 2) array.
        """
        order = np.argsort(frame.ids, kind="stable")
        ids = np.asarray(frame.ids, np.int64)[order]
        xy_m = np.asarray(frame.xy_m, np.float64)
        if len(ids) and ids[0] < 0:
            raise ValueError(f"{self.where}: frame {frame.frame} has agent id {ids[0]}; ids must be >= 0 "
                             "(-1 marks an empty observation row)")
        if xy_m.size or len(ids):
            if xy_m.shape != (len(ids), 2) or not np.isfinite(xy_m).all():
                raise ValueError(f"{self.where}: frame {frame.frame}: positions must be finite, one (x, y) per agent")
            xy_m = xy_m[order]
        else:
            xy_m = np.zeros((0, 2))
        if len(ids) > self.n_max:
            raise TooManyAgentsError(
                f"{self.where}: frame {frame.frame} holds {len(ids)} pedestrians, more than N_max = {self.n_max}; "
                "raise the scene's pedestrian limit instead of dropping agents")
        if np.any(np.diff(ids) == 0):
            raise ValueError(f"{self.where}: frame {frame.frame} lists an agent id twice")
        previous = self.frames[-1].ids if self.frames else np.zeros(0, np.int64)
        before = lookup(previous, ids)
        run = np.ones(len(ids), np.int64)
        run[before >= 0] += self._run[before[before >= 0]]
        self._run = run
        self.row_ids[lookup(ids, self.row_ids) < 0] = -1  # ids sorted; -1 (empty) is never among them
        newcomers = ids[lookup(np.sort(self.row_ids), ids) < 0]
        new_rows = np.flatnonzero(self.row_ids < 0)[:len(newcomers)]
        self.row_ids[new_rows] = newcomers
        self._ring_seen[:, self.row_ids < 0] = False
        self._take_history(new_rows, newcomers)
        column = self._pushes % self.depth
        self._ring_seen[column] = False
        rows = self._rows_of(ids)
        self._ring_xy[column, rows] = xy_m
        self._ring_seen[column, rows] = True
        self._pushes += 1
        self.frames.append(Frame(frame.frame, ids, xy_m))

    def _rows_of(self, ids: np.ndarray) -> np.ndarray:
        """(Q,) the rows of ``ids``, which hold rows."""
        order = np.argsort(self.row_ids)
        return order[np.searchsorted(self.row_ids, ids, sorter=order)]

    def _take_history(self, rows: np.ndarray, ids: np.ndarray) -> None:
        """Fill the ring of rows just given to agents ``ids`` with where the kept frames saw them (an agent may come
        back within the kept frames, in another row)."""
        if not len(ids):
            return
        self._ring_seen[:, rows] = False
        for age, kept in enumerate(reversed(self.frames), start=1):
            idx = lookup(kept.ids, ids)
            seen = idx >= 0
            if seen.any():
                column = (self._pushes - age) % self.depth
                self._ring_xy[column, rows[seen]] = kept.xy_m[idx[seen]]
                self._ring_seen[column, rows[seen]] = True

    @property
    def now(self) -> Frame:
        """The newest frame (ids sorted)."""
        return self.frames[-1]

    def run_of(self, ids: np.ndarray) -> np.ndarray:
        """(Q,) consecutive frames of presence up to now of each id (0 if absent now)."""
        idx = lookup(self.now.ids, ids)
        run = np.zeros(len(idx), np.int64)
        run[idx >= 0] = self._run[idx[idx >= 0]]  # nobody present now: every id gets 0 (no index into an empty run)
        return run

    def history(self) -> tuple[np.ndarray, np.ndarray]:
        """Observed positions of the present agents, one row per agent (see ``row_ids``).

        Returns:
            xy_m: (N_max, T_obs, 2) float32 metres, oldest step first, last column = now; 0 where unobserved;
                clipped to +-POSITION_LIMIT_M (the observation space's bound).
            mask: (N_max, T_obs) bool, True where the agent was present in that frame.
        """
        columns = (self._pushes - self.t_obs + np.arange(self.t_obs)) % self.depth
        mask = self._ring_seen[columns].T.copy()
        mask[:, : max(self.t_obs - self._pushes, 0)] = False  # before the first frame
        xy = np.where(mask[..., None], np.clip(self._ring_xy[columns].transpose(1, 0, 2), -POSITION_LIMIT_M,
                                               POSITION_LIMIT_M), 0.0).astype(np.float32)
        return xy, mask

    def predictable_rows(self) -> np.ndarray:
        """(P,) rows whose agent has been present for at least T_obs consecutive frames."""
        rows = np.flatnonzero(self.row_ids >= 0)
        return rows[self.run_of(self.row_ids[rows]) >= self.t_obs]

    def recent_path(self, ids: np.ndarray, steps: int) -> np.ndarray:
        """(Q, steps, 2) float64 positions of ``ids`` over the last ``steps`` frames; ids must be present in all."""
        assert len(self.frames) >= steps, f"only {len(self.frames)} frames kept, {steps} asked"
        rows = self._rows_of(ids)
        columns = (self._pushes - steps + np.arange(steps)) % self.depth
        assert self._ring_seen[columns][:, rows].all(), "recent_path asked for an agent absent from a kept frame"
        return self._ring_xy[columns][:, rows].transpose(1, 0, 2).copy()
