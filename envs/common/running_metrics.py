"""Episode metrics of the predictor and the ego, updated every step (reported in ``info["metrics"]``).

Predictions are scored the way the benchmark windows are: a prediction made at step t is scored at
step t + 12 if its agent was present in all 12 following frames ("matured"), and only when at least two
predictions of step t matured (a Social-GAN window holds at least two agents). A value with nothing to
average yet is None ("n/a"), never a 0.0 that would read as a perfect score.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from envs.common.tracks import TrackBuffer
from replays.constants import MIN_AGENTS_PER_WINDOW, T_PRED
from replays.scenes import Scene
from st_sim.frozen_mapping import FrozenMapping
from st_sim.metrics import ade_fde, off_map


class Metrics(FrozenMapping):
    """Read-only metric values by name; None where nothing has been measured yet ("n/a", JSON null).

    A ``FrozenMapping``: a float from one env and a None from another cannot share one of gymnasium's typed arrays,
    so a ``Metrics`` stays whole, one per env in an object array (``infos["metrics"][i]["ade_m"]``).
    ``dict(metrics)`` gives a plain, JSON-ready dict.
    """


class RunningMetrics:
    """Running sums over one episode; ``summary()`` gives the current values."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.pending: deque[tuple[np.ndarray, np.ndarray]] = deque()  # (ids (P,), futures (P, S, 12, 2)) per step
        self.reset()

    def reset(self) -> None:
        self.pending.clear()
        self.ade_sum_m = self.fde_sum_m = 0.0
        self.matured = 0
        self.off_map_points = self.predicted_points = 0
        self.ego_collisions = 0
        self.min_ego_distance_m = float("inf")

    def update_predictions(self, tracks: TrackBuffer, ids: np.ndarray, futures: np.ndarray) -> None:
        """Score the predictions of 12 steps ago against ``tracks``, then queue this step's.

        Args:
            tracks: frames up to now (this step's frame already pushed).
            ids: (P,) agents predicted this step.  futures: (P, S, 12, 2) metres.
        """
        if len(self.pending) == T_PRED:
            old_ids, old_futures = self.pending.popleft()
            matured = tracks.run_of(old_ids) >= T_PRED + 1  # present at the prediction step and the 12 after
            if matured.sum() >= MIN_AGENTS_PER_WINDOW:
                truth = tracks.recent_path(old_ids[matured], T_PRED)
                ade, fde = ade_fde(old_futures[matured], truth)
                self.ade_sum_m += float(ade.sum())
                self.fde_sum_m += float(fde.sum())
                self.matured += int(matured.sum())
        self.pending.append((ids, futures))
        if futures.size:
            self.off_map_points += int(off_map(futures, self.scene).sum())
            self.predicted_points += futures.size // 2

    def update_ego(self, collided: bool, nearest_m: float) -> None:
        """Count a collision and track the least ego-pedestrian centre distance (``nearest_m``, the least during
        the step: contacts between two frames count) [m]."""
        self.ego_collisions += int(collided)
        self.min_ego_distance_m = min(self.min_ego_distance_m, float(nearest_m))

    def summary(self) -> Metrics:
        """Current values, distances in metres; None where there is nothing to report yet.

        Keys: ade_m, fde_m (best of S, mean over matured predictions; None until one matures), matured
        (count), map_violation (share of predicted points off the walkable map; None before any prediction),
        ego_collisions (count), min_ego_ped_distance_m (inf without ego or pedestrians: nobody came near).
        """
        return Metrics({
            "ade_m": self.ade_sum_m / self.matured if self.matured else None,
            "fde_m": self.fde_sum_m / self.matured if self.matured else None,
            "matured": self.matured,
            "map_violation": self.off_map_points / self.predicted_points if self.predicted_points else None,
            "ego_collisions": self.ego_collisions,
            "min_ego_ped_distance_m": self.min_ego_distance_m,
        })
