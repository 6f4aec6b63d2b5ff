"""Crowd measures for validation: Weidmann's fundamental diagram, walking speeds, lane order, flow through a
line, and distances between distributions.
"""

from __future__ import annotations

from typing import Final

import numpy as np
from scipy.stats import wasserstein_distance

from replays.constants import STEP_S
from st_sim.sim.layout import Period

WEIDMANN_V0_MPS: Final[float] = 1.34  # free walking speed of Weidmann's fundamental diagram [m/s]
WEIDMANN_GAMMA_M2: Final[float] = 1.913  # shape of Weidmann's speed-density relation [m^2]
WEIDMANN_JAM_PER_M2: Final[float] = 5.4  # Weidmann's jam density [1/m^2]
SPECIFIC_FLOW_RANGE: Final[tuple[float, float]] = (1.6, 2.0)  # published bottleneck flow per door width [1/(m s)]


def weidmann_speed_mps(density_per_m2: np.ndarray | float) -> np.ndarray:
    """Weidmann's walking speed [m/s] at a density [1/m^2]: v0 (1 - exp(-gamma (1/rho - 1/rho_jam))), >= 0."""
    rho = np.asarray(density_per_m2, dtype=np.float64)
    with np.errstate(divide="ignore"):
        factor = 1.0 - np.exp(-WEIDMANN_GAMMA_M2 * (1.0 / rho - 1.0 / WEIDMANN_JAM_PER_M2))
    return WEIDMANN_V0_MPS * np.clip(factor, 0.0, 1.0)


def step_displacements_m(before_m: np.ndarray, after_m: np.ndarray, period: Period | None) -> np.ndarray:
    """(N, 2) displacement [m] of N agents over one step (nearest image across a periodic seam)."""
    moved = np.asarray(after_m, np.float64) - np.asarray(before_m, np.float64)
    return moved if period is None else period.nearest_image(moved)


def mean_speed_mps(displacements_m: np.ndarray) -> float:
    """Mean walking speed [m/s] of (..., 2) displacements over 0.4 s steps."""
    return float(np.linalg.norm(displacements_m, axis=-1).mean() / STEP_S) if displacements_m.size else 0.0


def lane_index(xy_m: np.ndarray, sign: np.ndarray, band_m: float, window_m: float,
               period: Period | None = None) -> float:
    """Lane order of a two-way flow along x, in [0, 1]: 1 = every agent walks in a lane of its own direction.

    For each agent, the agents within band_m sideways and window_m along x count as its lane; the agent
    scores ((same - opposite) / (same + opposite))^2 over them (0 if alone), and the index is the mean
    score. Well-mixed flows score about 1 / (agents per lane).

    Args:
        xy_m: (N, 2) positions [m].  sign: (N,) +1 walking toward +x, -1 toward -x.
        band_m: half-width of a lane [m].  window_m: half-length of a lane [m].  period: wrap-around or None.
    """
    offset = xy_m[None, :, :] - xy_m[:, None, :]  # (N, N, 2)
    if period is not None:
        offset = period.nearest_image(offset.reshape(-1, 2)).reshape(offset.shape)
    in_lane = (np.abs(offset[..., 1]) < band_m) & (np.abs(offset[..., 0]) < window_m)
    np.fill_diagonal(in_lane, False)
    same = (in_lane & (sign[None, :] == sign[:, None])).sum(axis=1)
    total = in_lane.sum(axis=1)
    score = np.where(total > 0, ((2 * same - total) / np.maximum(total, 1)) ** 2, 0.0)
    return float(score.mean()) if len(score) else 0.0


def steady_flow_per_s(times_s: np.ndarray, skip: int) -> float:
    """Flow [1/s] between the skip-th first and the skip-th last passage of sorted passage times (N,)."""
    times_s = np.sort(times_s)
    if len(times_s) < 2 * skip + 2:
        return 0.0
    first, last = times_s[skip], times_s[-1 - skip]
    return float((len(times_s) - 2 * skip - 1) / max(last - first, STEP_S))


def speed_distance_mps(a_mps: np.ndarray, b_mps: np.ndarray) -> float:
    """1-D Wasserstein distance [m/s] between two samples of speeds."""
    return float(wasserstein_distance(a_mps, b_mps))
