"""The predictors a planner can be run with, by name, and "none": pedestrians assumed to stand still."""

from __future__ import annotations

from typing import Any

import numpy as np

from replays.constants import T_PRED
from replays.scenes import Scene

PREDICTORS: tuple[str, ...] = ("none", "cvm", "cvm-s", "singular")
"""predictor names of the navigation benchmark, no prediction first"""


class StaticPredictor:
    """No prediction: every future point is the last observed position (the env then costs nothing to predict)."""

    name = "none"

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None = None,
                num_samples: int = 1) -> np.ndarray:
        """(N, T_obs, 2) metres -> (N, S, 12, 2) float32 metres, all at the last observed position."""
        last = np.asarray(obs, np.float32)[:, -1]
        return np.broadcast_to(last[:, None, None], (len(last), num_samples, T_PRED, 2)).copy()


def env_predictor(name: str) -> Any:
    """The env's ``predictor=`` argument for a benchmark predictor name (see ``PREDICTORS``)."""
    if name not in PREDICTORS:
        raise ValueError(f"predictor={name!r}: expected one of {', '.join(PREDICTORS)}")
    return StaticPredictor() if name == "none" else name
