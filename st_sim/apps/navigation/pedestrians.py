"""The pedestrians of one observation as planners use them: where they are, how they move, where they will be."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from replays.constants import STEP_S, T_PRED


@dataclass(frozen=True, eq=False)
class Pedestrians:
    """The P pedestrians present now (world frame).

    Attributes:
        xy_m: (P, 2) positions now [m].
        velocity_mps: (P, 2) last observed displacement per step / 0.4 s [m/s]; 0 if seen in one frame only.
        futures_m: (P, S, H, 2) positions 1..H steps ahead [m]: the predictor's samples where the row has
            predictions, the constant-velocity path otherwise (repeated over S); all at ``xy_m`` (S = 1) when
            predictions are not used.
        predicted: (P,) bool, the row's futures come from the predictor.
    """

    xy_m: np.ndarray
    velocity_mps: np.ndarray
    futures_m: np.ndarray
    predicted: np.ndarray

    def __len__(self) -> int:
        return len(self.xy_m)

    def __repr__(self) -> str:
        return f"Pedestrians({len(self)} present, {int(self.predicted.sum())} predicted)"


def pedestrians_of(obs: dict[str, np.ndarray], horizon_steps: int = T_PRED, use_predictions: bool = True
                   ) -> Pedestrians:
    """Pedestrians of an STCrowd observation.

    Args:
        obs: the env's observation (history (N_max, T_obs, 2), history_mask, futures (N_max, S, 12, 2),
            futures_mask), metres.
        horizon_steps: H, future steps kept (<= 12).
        use_predictions: False = everybody stays where they are (the "none" predictor).
    """
    present = obs["history_mask"][:, -1]
    xy = obs["history"][present, -1].astype(np.float64)
    seen_before = obs["history_mask"][present, -2] if obs["history"].shape[1] > 1 else np.zeros(len(xy), bool)
    step = np.where(seen_before[:, None], xy - obs["history"][present, -2], 0.0)
    ahead = np.arange(1, horizon_steps + 1)[None, :, None]
    if not use_predictions:
        return Pedestrians(xy, step / STEP_S, np.repeat(xy[:, None, None], horizon_steps, axis=2),
                           np.zeros(len(xy), bool))
    predicted = obs["futures_mask"][present]
    samples = obs["futures"].shape[1]
    futures = np.repeat((xy[:, None] + ahead[0] * step[:, None])[:, None], samples, axis=1)  # (P, S, H, 2)
    futures[predicted] = obs["futures"][present][predicted][:, :, :horizon_steps]
    return Pedestrians(xy, step / STEP_S, futures, predicted)
