"""Offline scoring: a predictor on one task's test windows -> ADE/FDE, map violations, collisions.

Sits below the predictor in the layering: any object with ``predict(obs, group, scene, num_samples)``
is scored (duck typing), so the predictor package can use this module without importing the apps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from replays.constants import DOMAIN_TASKS, TASKS
from replays.scenes import Scene, load_scene, scene_info
from replays.windows import Windows, load_windows
from st_sim.metrics import ade_fde, check_futures, collision_rate, map_violation, mean_or_none, path_map_violation
from st_sim.paper import paper_numbers


@dataclass
class SceneResult:
    """Scores of one predictor on one scene's (or domain pair's) test windows. Distances in metres."""

    scene: str
    samples: int
    ade: float | None
    fde: float | None
    map_violation: float | None
    """share of predicted points on non-walkable or off-image pixels"""
    path_map_violation: float | None
    """share of predicted paths with at least one such point"""
    gt_map_violation: float | None
    """the same share for the ground-truth futures (annotation noise)"""
    collision_rate: float | None
    """share of (same-window agent pair, sample) whose predictions come within 0.2 m"""
    wall_s: float
    paper_ade: float | None = None
    paper_fde: float | None = None
    checkpoint: str | None = None
    """the checkpoint the predictions came from (None for the baselines)"""
    stream_samples: int | None = None
    """samples scored through the spectator environment (None: not run)"""
    stream_ade: float | None = None
    stream_fde: float | None = None
    sample_ade: list[float] | None = None
    """best-of-S ADE of every test sample, in window order, rounded to 1e-5 m (for paired comparisons)"""
    sample_fde: list[float] | None = None
    """best-of-S FDE of every test sample, in window order, rounded to 1e-5 m"""
    window_sizes: list[int] | None = None
    """samples in each test window, in order (the samples of window g follow those of window g - 1)"""


def score_predictions(pred: np.ndarray, windows: Windows, scene: Scene) -> dict[str, Any]:
    """Metrics of predictions (N, S, 12, 2) against ``windows.fut``, on ``scene``'s map (None: nothing to score),
    with the per-sample errors and window sizes of ``SceneResult``."""
    ade, fde = ade_fde(pred, windows.fut)
    return {
        "ade": mean_or_none(ade), "fde": mean_or_none(fde),
        "map_violation": map_violation(pred, scene), "path_map_violation": path_map_violation(pred, scene),
        "gt_map_violation": map_violation(windows.fut, scene),
        "collision_rate": collision_rate(pred, windows.group),
        "sample_ade": np.round(ade, 5).tolist(), "sample_fde": np.round(fde, 5).tolist(),
        "window_sizes": np.unique(windows.group, return_counts=True)[1].tolist(),
    }


def target_scene(task: str, scene: str) -> str:
    """Scene whose map the test windows live on (the target of a domain pair)."""
    return scene_info(scene.upper().split("2")[1]).name if task in DOMAIN_TASKS else scene_info(scene).name


def evaluate_offline(predictor: Any, task: str, scene: str, num_samples: int | None = None,
                     momentary_from_8: bool = False, root=None, steps: int | None = None) -> SceneResult:
    """Score ``predictor`` on the test windows of one scene (or domain pair ``"A2B"``).

    Args:
        predictor: any object with ``predict(obs, group, scene, num_samples) -> (N, S, 12, 2)`` metres
            (and ``predict_detailed(..., steps)`` when ``steps`` is given).
        momentary_from_8: for the momentary task, score the 8-frame protocol's samples using only their
            last 2 observed frames instead of the loader's own 2-frame windows.
        steps: DDIM steps for predictors that take them (ablation); None = as trained.
    """
    start = time.perf_counter()
    if task == "momentary" and momentary_from_8:
        windows = load_windows("stochastic", scene, "test", root).last_observed(2)
    else:
        windows = load_windows(task, scene, "test", root)
    map_scene = load_scene(target_scene(task, scene), root)
    samples = num_samples or TASKS[task]["num_samples"]
    if steps is not None:
        pred = predictor.predict_detailed(windows.obs, windows.group, map_scene, samples, steps).futures
    else:
        pred = predictor.predict(windows.obs, windows.group, map_scene, samples)
    pred = check_futures(pred, len(windows), samples, getattr(predictor, "name", type(predictor).__name__))
    scores = score_predictions(pred, windows, map_scene)
    paper = paper_numbers(task, scene.upper() if task in DOMAIN_TASKS else scene)
    return SceneResult(scene=scene, samples=len(windows), **scores, wall_s=time.perf_counter() - start,
                       paper_ade=paper[0] if paper else None, paper_fde=paper[1] if paper else None,
                       checkpoint=getattr(predictor, "source", None))
