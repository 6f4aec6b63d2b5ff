"""Prediction metrics: best-of-S ADE/FDE, map violations, pairwise collisions (all in metres), the check of a
predictor's output, and a paired bootstrap interval for comparing two predictors on the same windows.

A rate or mean over nothing is None, not 0.0 (which would read as a perfect score); ``format_metric`` prints
None as "n/a".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from replays.constants import FORECAST_LIMIT_M, T_PRED
from replays.scenes import Scene

COLLISION_DISTANCE_M = 0.2  # TrajNet++-style: two predicted agents closer than this at one step collide


class PredictionError(ValueError):
    """A predictor returned something other than (N, S, 12, 2) finite float positions within +-FORECAST_LIMIT_M."""


def check_futures(futures: Any, num_agents: int, num_samples: int, name: str) -> np.ndarray:
    """A predictor's output as (N, S, 12, 2) float32 metres; ``PredictionError`` names ``name`` and the expected shape.

    Refused: anything but a NumPy array (a list, None), a non-float dtype, another shape (another S), NaN or inf
    (also after the cast to float32), and positions beyond +-FORECAST_LIMIT_M (25 km), the farthest a straight
    extrapolation of any valid recording reaches: a future beyond it is a broken predictor, not a bad forecast to
    average into the ADE.
    """
    expected = (num_agents, num_samples, T_PRED, 2)
    if not isinstance(futures, np.ndarray):
        problem = "None" if futures is None else f"a {type(futures).__name__}"
    elif futures.dtype.kind != "f":
        problem = f"dtype {futures.dtype}"
    elif futures.shape != expected:
        problem = f"shape {futures.shape}"
    else:
        with np.errstate(over="ignore"):
            futures = futures.astype(np.float32, copy=False)
        if not np.isfinite(futures).all():
            problem = "NaN or inf positions"
        elif np.abs(futures).max(initial=0.0) > FORECAST_LIMIT_M:
            problem = (f"a position {float(np.abs(futures).max()):.4g} m from the origin, beyond the "
                       f"+-{FORECAST_LIMIT_M:g} m bound of every forecast")
        else:
            return futures
    raise PredictionError(f"predictor {name!r}: predict returned {problem}; expected a float array of shape "
                          f"(N, S, 12, 2) = {expected}, metres")


def _check_pred_gt(pred: np.ndarray, gt: np.ndarray) -> None:
    if pred.ndim != 4 or pred.shape[-1] != 2:
        raise ValueError(f"pred must be (N, S, T, 2), got shape {pred.shape}")
    if gt.shape != (pred.shape[0], pred.shape[2], 2):
        raise ValueError(f"gt must be (N, T, 2) = {(pred.shape[0], pred.shape[2], 2)}, got {gt.shape}")
    if not np.isfinite(pred).all():
        raise ValueError("pred holds NaN or inf")


def ade_fde(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best-of-S average and final displacement error per agent.

    ADE and FDE are minimised over samples independently, as the field reports them.

    Args:
        pred: (N, S, T, 2) predicted positions, metres.
        gt: (N, T, 2) ground truth, metres.

    Returns:
        ade: (N,) float64 metres.  fde: (N,) float64 metres.
    """
    pred, gt = np.asarray(pred, np.float64), np.asarray(gt, np.float64)
    _check_pred_gt(pred, gt)
    dist = np.linalg.norm(pred - gt[:, None], axis=-1)  # (N, S, T)
    return dist.mean(axis=2).min(axis=1), dist[:, :, -1].min(axis=1)


def off_map(points_m: np.ndarray, scene: Scene) -> np.ndarray:
    """(..., 2) world metres -> (...) bool: point on a non-walkable or out-of-image pixel."""
    return ~scene.is_walkable(points_m)


def mean_or_none(values: np.ndarray) -> float | None:
    """Mean of an array, or None when it is empty (nothing was measured)."""
    values = np.asarray(values, dtype=np.float64)
    return float(values.mean()) if values.size else None


def format_metric(value: float | None, spec: str = ".3f", scale: float = 1.0) -> str:
    """``value * scale`` formatted with ``spec``, or "n/a" for None (e.g. ADE over no matured prediction)."""
    return "n/a" if value is None else format(value * scale, spec)


def map_violation(points_m: np.ndarray, scene: Scene) -> float | None:
    """Share of points (..., 2) that fall on non-walkable or out-of-image pixels; None for no points."""
    return mean_or_none(off_map(points_m, scene))


def path_map_violation(paths_m: np.ndarray, scene: Scene) -> float | None:
    """Share of paths (..., T, 2) with at least one point on a non-walkable or out-of-image pixel; None for none."""
    return mean_or_none(off_map(paths_m, scene).any(axis=-1))


def same_group_pairs(group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i < j) of samples sharing a window: two (P,) int arrays."""
    group = np.asarray(group)
    order = np.argsort(group, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(group[order]) != 0])
    sizes = np.diff(np.r_[starts, len(group)])
    firsts, seconds = [], []
    for size in np.unique(sizes):
        block = starts[sizes == size][:, None] + np.arange(size)  # (G, size) positions in order
        i, j = np.triu_indices(size, k=1)
        firsts.append(order[block[:, i]].ravel())
        seconds.append(order[block[:, j]].ravel())
    if not firsts:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    return np.concatenate(firsts), np.concatenate(seconds)


def collision_rate(pred: np.ndarray, group: np.ndarray, threshold_m: float = COLLISION_DISTANCE_M,
                   chunk_pairs: int = 20_000) -> float | None:
    """Share of (agent pair, sample) combinations whose predicted paths come within ``threshold_m``.

    Pairs are agents of the same window; sample s of one agent is compared with sample s of the other
    at the same step (TrajNet++-style prediction collision).

    Args:
        pred: (N, S, T, 2) metres.  group: (N,) window id per agent.

    Returns:
        Rate in [0, 1]; None when no window holds two agents.
    """
    pred = np.asarray(pred, np.float32)
    first, second = same_group_pairs(group)
    if len(first) == 0:
        return None
    hits = 0
    for start in range(0, len(first), chunk_pairs):
        a, b = first[start:start + chunk_pairs], second[start:start + chunk_pairs]
        gap = np.linalg.norm(pred[a] - pred[b], axis=-1).min(axis=-1)  # (P, S)
        hits += int((gap < threshold_m).sum())
    return hits / (len(first) * pred.shape[1])


def paired_bootstrap(differences: Sequence[np.ndarray], windows: Sequence[np.ndarray], resamples: int = 2000,
                     seed: int = 0, confidence: float = 0.95
                     ) -> tuple[list[tuple[float, float, float]], tuple[float, float, float]]:
    """Mean paired differences with percentile bootstrap intervals, per stratum (scene) and for their mean.

    Each stratum is resampled on its own, by whole windows with replacement (the agents of one scene moment are
    not independent). The overall figure is the unweighted mean of the strata's means, as a table's AVG row.
    Consecutive windows overlap in time and are not independent either, so the interval tends to be too narrow.

    Args:
        differences: per stratum, (N_i,) per-sample differences (e.g. FDE of B minus FDE of A) [m].
        windows: per stratum, (N_i,) window id of each sample.
        resamples: bootstrap draws, from ``np.random.default_rng(seed)``.

    Returns:
        ([(mean, low, high) per stratum], (mean, low, high) of the mean over strata), metres.
    """
    rng = np.random.default_rng(seed)
    tails = [50 * (1 - confidence), 50 * (1 + confidence)]  # percentiles of the two interval ends
    per_stratum, draws = [], []
    for difference, window in zip(differences, windows, strict=True):
        difference = np.asarray(difference, np.float64)
        if difference.size == 0:
            raise ValueError("paired_bootstrap: a stratum without samples")
        ids = np.unique(np.asarray(window), return_inverse=True)[1]
        sums, counts = np.bincount(ids, weights=difference), np.bincount(ids)
        pick = rng.integers(0, len(sums), size=(resamples, len(sums)))  # (R, windows)
        draws.append(sums[pick].sum(axis=1) / counts[pick].sum(axis=1))
        per_stratum.append((float(difference.mean()), *map(float, np.percentile(draws[-1], tails))))
    mean = float(np.mean([m for m, _, _ in per_stratum]))
    return per_stratum, (mean, *map(float, np.percentile(np.mean(draws, axis=0), tails)))
