"""The predictors of the open-loop / closed-loop study as plug-ins (``study_models:<name>``), all answering with
S = 20 samples of 12 steps from 8 observed frames, so that every one runs in the same stochastic envs and windows.

- ``stochastic``, ``deterministic``, ``momentary``: SingularTrajectory's shipped leave-one-out model of the scene (the
  universal models in a simulated env); the deterministic model's one path fills all 20 samples, the momentary
  model sees only the last 2 observed frames;
- ``universal``: the model trained on all five scenes;
- ``fewshot``: trained on every 10th training window of the scene, read from
  ``$STCROWD_STUDY_RUNS/fewshot/<scene>/seed0/best.pt`` (``open_closed_loop.py`` trains it first);
- ``singular5``: the stochastic model's 5 likeliest samples, each repeated 4 times.

Run from ``benchmarks/`` on the path (``python benchmarks/open_closed_loop.py`` puts it there).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

import predictor
from replays import Scene, Windows

SAMPLES = 20


class Filled:
    """A model's first ``keep`` samples, each repeated to fill SAMPLES; ``last`` = observed frames it sees."""

    def __init__(self, model, keep: int, last: int | None = None):
        self.model, self.keep, self.last = model, keep, last

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None, num_samples: int) -> np.ndarray:
        """(N, T_obs, 2) metres -> (N, num_samples, 12, 2) float32 metres."""
        seen = obs if self.last is None else obs[:, -self.last:]
        futures = self.model.predict(seen, group, scene, self.keep)
        return np.tile(futures, (1, -(-num_samples // self.keep), 1, 1))[:, :num_samples]


def _shipped(kind: str, scene: str | None) -> str:
    if scene is None:
        return "momentary/universal" if kind == "momentary" else "universal"
    return f"{kind}/{scene}"


def stochastic(task: str, scene: str | None, train: Windows, val: Windows, data_root: Path) -> Filled:
    return Filled(predictor.load_pretrained(_shipped("stochastic", scene)), SAMPLES)


def deterministic(task: str, scene: str | None, train: Windows, val: Windows, data_root: Path) -> Filled:
    name = "universal" if scene is None else f"deterministic/{scene}"
    return Filled(predictor.load_pretrained(name), 1)


def momentary(task: str, scene: str | None, train: Windows, val: Windows, data_root: Path) -> Filled:
    return Filled(predictor.load_pretrained(_shipped("momentary", scene)), SAMPLES, last=2)


def universal(task: str, scene: str | None, train: Windows, val: Windows, data_root: Path) -> Filled:
    return Filled(predictor.load_pretrained("universal"), SAMPLES)


def singular5(task: str, scene: str | None, train: Windows, val: Windows, data_root: Path) -> Filled:
    return Filled(predictor.load_pretrained(_shipped("stochastic", scene)), 5)


def fewshot(task: str, scene: str | None, train: Windows, val: Windows, data_root: Path) -> Filled:
    if scene is None:
        raise ValueError("the few-shot model is trained per scene; it has no simulated-env version")
    runs = Path(os.environ.get("STCROWD_STUDY_RUNS", "runs/study"))
    return Filled(predictor.load(runs / "fewshot" / scene / "seed0" / "best.pt"), SAMPLES)
