"""Baselines (NumPy only): CVM, CVM-S (Schöller et al. 2020), a least-squares line, and "none" (nobody moves)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from predictor.normalize import rotate
from predictor.protocol import check_inputs
from replays.constants import T_PRED
from replays.scenes import Scene

FUTURE_STEPS = np.arange(1, T_PRED + 1, dtype=np.float32)  # (12,) steps ahead of the last observation
SIGMA_GRID_RAD = np.linspace(0.0, 1.0, 41)  # CVM-S heading-noise candidates [rad]
FIT_MAX_SAMPLES = 4000  # sigma is fitted on at most this many training samples (fixed subset)


def constant_velocity(obs: np.ndarray) -> np.ndarray:
    """(N, T_obs, 2) checked observations [m] -> (N, 12, 2) paths repeating the last step [m]."""
    velocity = obs[:, -1] - obs[:, -2]  # (N, 2) metres per 0.4 s step
    return obs[:, None, -1] + FUTURE_STEPS[None, :, None] * velocity[:, None]


class ConstantVelocity:
    """Repeat the last observed displacement for 12 steps; all S samples are the same path."""

    name = "cvm"

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None = None,
                num_samples: int = 1) -> np.ndarray:
        """(N, T_obs, 2) metres -> (N, S, 12, 2) float32 metres."""
        obs, group = check_inputs(obs, group, num_samples)
        return np.repeat(constant_velocity(obs)[:, None], num_samples, axis=1).astype(np.float32)


class Stationary:
    """No prediction: every future point is the last observed position (a planner given these assumes that nobody
    moves, and they cost nothing to compute)."""

    name = "none"

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None = None,
                num_samples: int = 1) -> np.ndarray:
        """(N, T_obs, 2) metres -> (N, S, 12, 2) float32 metres, all at the last observed position."""
        obs, group = check_inputs(obs, group, num_samples)
        return np.broadcast_to(obs[:, None, None, -1], (len(obs), num_samples, T_PRED, 2)).copy()


@dataclass
class ConstantVelocitySampler:
    """CVM-S: the last displacement rotated by a heading drawn from N(0, sigma^2), one per sample.

    The S headings are one seeded draw shared by every agent, so an agent's futures never depend on which
    other agents are in the same call (stream and offline evaluation agree) and the same input always
    gives the same output.
    """

    sigma_rad: float = 0.25
    """heading noise standard deviation [rad]; pick it on training data with ``fit_sigma``"""
    seed: int = 0
    """seed of the per-call generator"""
    name: str = field(default="cvm-s", init=False)

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None = None,
                num_samples: int = 20) -> np.ndarray:
        """(N, T_obs, 2) metres -> (N, S, 12, 2) float32 metres."""
        obs, group = check_inputs(obs, group, num_samples)
        rng = np.random.default_rng(self.seed)
        angles = np.broadcast_to(rng.normal(0.0, self.sigma_rad, size=(1, num_samples)), (len(obs), num_samples))
        velocity = rotate((obs[:, -1] - obs[:, -2])[:, None], angles)  # (N, S, 2)
        paths = obs[:, None, None, -1] + FUTURE_STEPS[None, None, :, None] * velocity[:, :, None]
        return paths.astype(np.float32)

    def fit_sigma(self, obs: np.ndarray, fut: np.ndarray, num_samples: int = 20,
                  grid_rad: np.ndarray = SIGMA_GRID_RAD) -> float:
        """Set ``sigma_rad`` to the grid value with the lowest best-of-S ADE + FDE on (obs, fut); returns it."""
        from st_sim.metrics import ade_fde

        if len(obs) > FIT_MAX_SAMPLES:
            keep = np.random.default_rng(self.seed).choice(len(obs), FIT_MAX_SAMPLES, replace=False)
            obs, fut = obs[np.sort(keep)], fut[np.sort(keep)]
        scores = []
        for sigma in grid_rad:
            self.sigma_rad = float(sigma)
            ade, fde = ade_fde(self.predict(obs, np.zeros(len(obs)), None, num_samples), fut)
            scores.append(ade.mean() + fde.mean())
        self.sigma_rad = float(grid_rad[int(np.argmin(scores))])
        return self.sigma_rad


class LinearFit:
    """Least-squares straight line through the observed points, extrapolated 12 steps."""

    name = "linear"

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None = None,
                num_samples: int = 1) -> np.ndarray:
        """(N, T_obs, 2) metres -> (N, S, 12, 2) float32 metres."""
        obs, group = check_inputs(obs, group, num_samples)
        t_obs = obs.shape[1]
        t = np.arange(t_obs, dtype=np.float64) - (t_obs - 1)  # last observation at t = 0
        design = np.stack([np.ones_like(t), t], axis=1)  # (T_obs, 2)
        coef = np.linalg.pinv(design) @ obs.astype(np.float64)  # (N, 2 [offset, slope], 2 [x, y])
        future = np.stack([np.ones(T_PRED), FUTURE_STEPS], axis=1)  # (12, 2)
        path = np.einsum("tc,ncd->ntd", future, coef)
        return np.repeat(path[:, None], num_samples, axis=1).astype(np.float32)


BASELINES = {"cvm": ConstantVelocity, "cvm-s": ConstantVelocitySampler, "linear": LinearFit, "none": Stationary}
