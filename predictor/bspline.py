"""Length adapter C_T: resample a curve given at T_win = 12 steps to any T steps (paper eq. 6-7).

The 12 samples define a clamped quadratic (degree-2) B-spline with 12 control points on the unit
parameter interval; C_T evaluates that spline at T evenly spaced parameters. C_12 is the identity.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from scipy.interpolate import BSpline

DEGREE = 2


def _design_matrix(n_ctrl: int, params: np.ndarray) -> np.ndarray:
    """(len(params), n_ctrl) values of the clamped uniform B-spline basis functions."""
    interior = np.linspace(0.0, 1.0, n_ctrl - DEGREE + 1)[1:-1]
    knots = np.r_[np.zeros(DEGREE + 1), interior, np.ones(DEGREE + 1)]
    return BSpline.design_matrix(params, knots, DEGREE).toarray()


@cache
def resampling_matrix(t_out: int, t_in: int = 12) -> np.ndarray:
    """C_T: (t_out, t_in) float64 matrix mapping a (t_in, 2) curve to the same curve at t_out steps.

    Apply per coordinate: ``C @ path`` for a path of shape (t_in, 2).
    """
    if t_out < 1 or t_in < DEGREE + 1:
        raise ValueError(f"cannot resample {t_in} steps to {t_out}")
    fit = _design_matrix(t_in, np.linspace(0.0, 1.0, t_in))  # samples -> control points (square, invertible)
    evaluate = _design_matrix(t_in, np.linspace(0.0, 1.0, t_out)) if t_out > 1 else _design_matrix(t_in, np.ones(1))
    matrix = evaluate @ np.linalg.inv(fit)
    if t_out == t_in:
        matrix = np.eye(t_in)  # exact round trip where it must be
    matrix.setflags(write=False)
    return matrix
