"""Which predicted sample each pedestrian follows: a running belief over sample indices, per observation row.

A SingularTrajectory checkpoint's samples come from anchors in a fixed order, so sample i is the same kind of
motion from one step to the next. After every step the belief of a pedestrian who stayed in its row is multiplied
by how well each sample's first predicted step matched where it went (a Gaussian of ``sigma_m``), then mixed with
the prior (share ``floor``) so that no sample is ever ruled out. A new pedestrian in a row starts at the prior.
"""

from __future__ import annotations

import numpy as np


class SampleBelief:
    """Per-row weights (N_max, S) over the predicted samples of an STCrowd observation.

    Args:
        prior: (S,) prior weights of the sample indices (summing to 1).
        sigma_m: spread of the one-step likelihood [m].  floor: share of the prior mixed in after every update [-].
    """

    def __init__(self, prior: np.ndarray, sigma_m: float = 0.15, floor: float = 0.1):
        self.prior = np.asarray(prior, np.float64) / np.sum(prior)
        self.sigma_m, self.floor = sigma_m, floor
        self.reset()

    def reset(self) -> None:
        """Forget every pedestrian (at an episode start)."""
        self._weights: np.ndarray | None = None  # (N_max, S)
        self._last_xy: np.ndarray | None = None  # (N_max, 2) positions seen last step
        self._first_step: np.ndarray | None = None  # (N_max, S, 2) where each sample put them one step on
        self._had_futures: np.ndarray | None = None  # (N_max,) bool

    def update(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """Fold in the step that led to ``obs`` and return the (N_max, S) weights for its futures."""
        history, mask = obs["history"], obs["history_mask"]
        n_rows, samples = obs["futures"].shape[:2]
        if self._weights is None or self._weights.shape != (n_rows, samples):
            self._weights = np.broadcast_to(self.prior, (n_rows, samples)).copy()
        else:
            same = (mask[:, -1] & mask[:, -2] & self._had_futures
                    & np.all(np.abs(history[:, -2] - self._last_xy) < 1e-4, axis=1))  # the same agent stayed
            miss = np.linalg.norm(self._first_step[same] - history[same, -1][:, None], axis=-1)  # (M, S)
            likelihood = np.exp(-0.5 * (miss / self.sigma_m) ** 2)
            posterior = self._weights[same] * likelihood
            total = posterior.sum(axis=1, keepdims=True)
            posterior = np.where(total > 1e-12, posterior / np.maximum(total, 1e-12), self.prior)
            self._weights[same] = (1 - self.floor) * posterior + self.floor * self.prior
            self._weights[~same] = self.prior
        self._last_xy = history[:, -1].copy()
        self._first_step = obs["futures"][:, :, 0].copy()
        self._had_futures = obs["futures_mask"].copy()
        return self._weights
