"""How well the robot saw the crowd over an episode: CLEAR MOT (Bernardin and Stiefelhagen 2008: MOTA, MOTP, identity
switches) and IDF1 (Ristani et al. 2016), between the true people and the tracks reported.

Per step, truth and tracks are matched within ``MATCH_M``: a pair matched at the last step keeps its match while it
stays within reach, the others are matched by least total distance. MOTA = 1 - (misses + false tracks + identity
switches) / true people, summed over the steps; MOTP = the mean distance of the matched pairs [m]. IDF1 matches whole
identities instead: each true person to at most one track id over the episode, the pairing that maximises the steps
they are within reach of each other (IDTP); IDF1 = 2 IDTP / (true people + tracks, summed over the steps).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

MATCH_M = 0.5  # a track within this distance of a true person may stand for them [m]


class MotAccumulator:
    """The episode's counts; ``update`` once per step, then ``summary``."""

    def __init__(self, match_m: float = MATCH_M):
        self.match_m = match_m
        self.truth_total = self.track_total = self.matches = self.misses = self.false = self.switches = 0
        self.distance_sum = 0.0
        self._last: dict[int, int] = {}  # true id -> track id it was matched to last
        self._together: dict[tuple[int, int], int] = {}  # (true id, track id) -> steps within reach

    def update(self, true_ids: np.ndarray, true_xy: np.ndarray, track_ids: np.ndarray, track_xy: np.ndarray) -> None:
        """One step: the true people in view (T,) at (T, 2) [m] and the tracks reported (K,) at (K, 2) [m]."""
        true_ids, track_ids = np.asarray(true_ids, np.int64), np.asarray(track_ids, np.int64)
        true_xy = np.asarray(true_xy, np.float64).reshape(-1, 2)
        track_xy = np.asarray(track_xy, np.float64).reshape(-1, 2)
        self.truth_total += len(true_ids)
        self.track_total += len(track_ids)
        if not len(true_ids) or not len(track_ids):
            self.misses += len(true_ids)
            self.false += len(track_ids)
            return
        dx = true_xy[:, None, 0] - track_xy[None, :, 0]
        dy = true_xy[:, None, 1] - track_xy[None, :, 1]
        distance = np.sqrt(dx * dx + dy * dy)
        within = distance <= self.match_m
        for i, k in zip(*np.nonzero(within), strict=True):
            key = (int(true_ids[i]), int(track_ids[k]))
            self._together[key] = self._together.get(key, 0) + 1
        pairs = self._matched(true_ids, track_ids, distance, within)
        for i, k in pairs:
            truth, track = int(true_ids[i]), int(track_ids[k])
            if truth in self._last and self._last[truth] != track:
                self.switches += 1
            self._last[truth] = track
            self.distance_sum += float(distance[i, k])
        self.matches += len(pairs)
        self.misses += len(true_ids) - len(pairs)
        self.false += len(track_ids) - len(pairs)

    def _matched(self, true_ids: np.ndarray, track_ids: np.ndarray, distance: np.ndarray,
                 within: np.ndarray) -> list[tuple[int, int]]:
        """(truth row, track row) pairs of this step: last step's pairs still within reach, then the least total
        distance among the rest."""
        pairs, used_truth, used_track = [], set(), set()
        column = {int(t): k for k, t in enumerate(track_ids)}
        for i, truth in enumerate(true_ids.tolist()):
            k = column.get(self._last.get(truth, -1))
            if k is not None and within[i, k]:
                pairs.append((i, k))
                used_truth.add(i)
                used_track.add(k)
        rest_truth = [i for i in range(len(true_ids)) if i not in used_truth]
        rest_track = [k for k in range(len(track_ids)) if k not in used_track]
        if rest_truth and rest_track:
            cost = np.where(within[np.ix_(rest_truth, rest_track)], distance[np.ix_(rest_truth, rest_track)], 1e6)
            rows, cols = linear_sum_assignment(cost)
            pairs += [(rest_truth[r], rest_track[c]) for r, c in zip(rows, cols, strict=True) if cost[r, c] < 1e6]
        return pairs

    def summary(self) -> dict[str, float | int]:
        """{mota, motp_m, idf1, id_switches, misses, false_tracks, true_people}: NaN where nothing was there to
        measure (no true person in view: MOTA; no match: MOTP; nobody at all: IDF1)."""
        mota = 1.0 - (self.misses + self.false + self.switches) / self.truth_total if self.truth_total else math.nan
        motp = self.distance_sum / self.matches if self.matches else math.nan
        everyone = self.truth_total + self.track_total
        return {"mota": mota, "motp_m": motp, "idf1": 2.0 * self._idtp() / everyone if everyone else math.nan,
                "id_switches": self.switches, "misses": self.misses, "false_tracks": self.false,
                "true_people": self.truth_total}

    def _idtp(self) -> int:
        """Steps a true person and the one track id paired with them over the episode are within reach, summed over
        the pairing that makes it largest."""
        if not self._together:
            return 0
        truths = sorted({t for t, _ in self._together})
        tracks = sorted({k for _, k in self._together})
        row, col = {t: i for i, t in enumerate(truths)}, {k: i for i, k in enumerate(tracks)}
        weight = np.zeros((len(truths), len(tracks)))
        for (t, k), steps in self._together.items():
            weight[row[t], col[k]] = steps
        rows, cols = linear_sum_assignment(weight, maximize=True)
        return int(weight[rows, cols].sum())
