"""A plug-in predictor: k nearest neighbours over normalised histories, fitted in about a second on a CPU.

Every training window is turned into its agent frame (last observed point at the origin, the observed
motion along +x); a query's S futures are the normalised futures of its S nearest training histories, turned
back into the query's world frame. With S = 1 the answer is the mean of the 10 nearest futures.

    python -m st_sim evaluate --task stochastic --predictor cvm examples.knn_predictor:make
    python -m st_sim navigate --env STCrowd-Zara1-v0 --policy mpc --predictor examples.knn_predictor:make
    python -m examples.knn_predictor            # fits on zara1's training windows and prints its test ADE/FDE

Run from the repository root, so that ``examples`` imports.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from replays import Scene, Windows

MAX_TRAIN_WINDOWS = 20_000  # training samples kept (a fixed subsample above this) [-]
MEAN_OF = 10  # S = 1: the mean future of this many neighbours [-]
STILL_M = 1e-3  # observed motion shorter than this keeps the world's heading [m]


def to_agent_frame(obs_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origin at each agent's last observed point, heading of its observed motion along +x.

    Args:
        obs_m: (N, T_obs, 2) metres, world frame.

    Returns:
        history: (N, T_obs, 2) metres, agent frame.  origin: (N, 2) metres.  cos_sin: (N, 2) of the heading.
    """
    origin = obs_m[:, -1]
    motion = obs_m[:, -1] - obs_m[:, 0]
    length = np.linalg.norm(motion, axis=1, keepdims=True)
    cos_sin = np.where(length > STILL_M, motion / np.maximum(length, STILL_M), np.array([1.0, 0.0]))
    return rotate(obs_m - origin[:, None], cos_sin, inverse=True), origin, cos_sin


def rotate(xy: np.ndarray, cos_sin: np.ndarray, inverse: bool = False) -> np.ndarray:
    """Rotate (N, ..., 2) points by each agent's heading (N, 2) (``inverse``: into the agent frame)."""
    shape = (len(xy),) + (1,) * (xy.ndim - 2)
    c, s = cos_sin[:, 0].reshape(shape), cos_sin[:, 1].reshape(shape) * (-1.0 if inverse else 1.0)
    x, y = xy[..., 0], xy[..., 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1)


class KnnPredictor:
    """The training set's normalised (history, future) pairs in a k-d tree over the flattened histories."""

    name = "knn"

    def __init__(self, train: Windows, max_windows: int = MAX_TRAIN_WINDOWS, seed: int = 0):
        obs, fut = train.obs.astype(np.float64), train.fut.astype(np.float64)
        if len(obs) > max_windows:
            keep = np.sort(np.random.default_rng(seed).choice(len(obs), max_windows, replace=False))
            obs, fut = obs[keep], fut[keep]
        history, origin, cos_sin = to_agent_frame(obs)
        self.futures = rotate(fut - origin[:, None], cos_sin, inverse=True)  # (M, 12, 2) metres, agent frame
        self.tree = cKDTree(history.reshape(len(history), -1))

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None, num_samples: int) -> np.ndarray:
        """(N, T_obs, 2) metres -> (N, S, 12, 2) float32 metres, world frame."""
        history, origin, cos_sin = to_agent_frame(np.asarray(obs, np.float64))
        k = MEAN_OF if num_samples == 1 else num_samples
        _, index = self.tree.query(history.reshape(len(history), -1), k=min(k, self.tree.n))
        index = index.reshape(len(history), -1)  # (N, min(k, M)), nearest first
        index = index[:, np.arange(k) % index.shape[1]]  # fewer training samples than k: they repeat
        futures = self.futures[index]  # (N, k, 12, 2) agent frame
        if num_samples == 1:
            futures = futures.mean(axis=1, keepdims=True)
        world = rotate(futures.reshape(len(history), -1, 2), cos_sin) + origin[:, None]
        return world.reshape(len(history), num_samples, -1, 2).astype(np.float32)


def make(task: str, scene: str | None, train: Windows, val: Windows, data_root: Path, seed: int = 0) -> KnnPredictor:
    """The plug-in factory (``examples.knn_predictor:make``): fit on ``train``, ``seed`` choosing the subsample when
    there are more than ``MAX_TRAIN_WINDOWS`` (``evaluate --seeds`` passes it); the other arguments are unused."""
    return KnnPredictor(train, seed=seed)


def main() -> None:
    """Fit on zara1's stochastic training windows and print the best-of-20 ADE/FDE on its test windows."""
    from replays import load_windows
    from st_sim.metrics import ade_fde

    model = KnnPredictor(load_windows("stochastic", "zara1", "train"))
    test = load_windows("stochastic", "zara1", "test")
    ade, fde = ade_fde(model.predict(test.obs, test.group, None, 20), test.fut)
    print(f"knn on zara1 (stochastic, best of 20): ADE {ade.mean():.3f} m, FDE {fde.mean():.3f} m")


if __name__ == "__main__":
    main()
