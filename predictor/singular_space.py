"""Singular space: the K dominant motion vectors of normalised future paths (truncated SVD).

A path of any length T is expressed by K coefficients against the basis resampled to T steps with
the B-spline length adapter C_T, so histories (2 or 8 steps) and futures (12) share one space.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from predictor.bspline import resampling_matrix
from replays.constants import T_PRED

T_WIN = T_PRED  # window length of the decomposed paths (12 steps)


@dataclass(frozen=True)
class SingularSpace:
    """Basis V_K of one population.

    Attributes:
        basis: (2 T_win, K) float64 right singular vectors, rows ordered (t0x, t0y, t1x, ...).
        singular_values: (K,) float64.
    """

    basis: np.ndarray
    singular_values: np.ndarray
    _projections: dict[int, np.ndarray] = field(default_factory=dict, repr=False, compare=False)

    @property
    def k(self) -> int:
        return self.basis.shape[1]

    def basis_at(self, steps: int) -> np.ndarray:
        """(2 steps, K) basis resampled to ``steps`` with C_T."""
        vectors = self.basis.T.reshape(self.k, T_WIN, 2)  # (K, T_win, 2)
        resampled = np.einsum("tw,kwc->ktc", resampling_matrix(steps, T_WIN), vectors)
        return resampled.reshape(self.k, 2 * steps).T

    def project(self, paths: np.ndarray) -> np.ndarray:
        """(N, T, 2) agent-frame paths -> (N, K) coefficients (least squares; exact projection at T = 12)."""
        steps = paths.shape[1]
        flat = paths.reshape(len(paths), 2 * steps)
        if steps == T_WIN:
            return flat @ self.basis
        if steps not in self._projections:  # (2 steps, K) least-squares projector, computed once per length
            self._projections[steps] = np.linalg.pinv(self.basis_at(steps)).T
        return flat @ self._projections[steps]

    def reconstruct(self, coefficients: np.ndarray, steps: int = T_WIN) -> np.ndarray:
        """(..., K) coefficients -> (..., steps, 2) agent-frame paths."""
        basis = self.basis if steps == T_WIN else self.basis_at(steps)
        return (coefficients @ basis.T).reshape(*coefficients.shape[:-1], steps, 2)


def fit_singular_space(paths: np.ndarray, k: int) -> SingularSpace:
    """Truncated SVD of (L, 12, 2) agent-frame future paths; keeps the top ``k`` right singular vectors."""
    if len(paths) < k:
        raise ValueError(f"need at least {k} paths to fit a {k}-dimensional Singular space, got {len(paths)}")
    matrix = paths.reshape(len(paths), -1).astype(np.float64)
    _, values, vt = np.linalg.svd(matrix, full_matrices=False)
    basis = vt[:k].T
    sign = np.sign(basis[np.abs(basis).argmax(axis=0), np.arange(k)])  # deterministic sign per vector
    return SingularSpace(basis * sign, values[:k])
