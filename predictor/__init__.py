"""Trajectory predictors: the SingularTrajectory model and constant-velocity baselines.

Dimension letters used across the project's docstrings:
    N agents, T steps (0.4 s each; T_obs observed, 12 predicted), S samples per agent,
    K singular vectors (Singular-space dimension), B batch, G groups (windows).
Units: metres, world frame unless a docstring says "agent frame" (last observed point at the origin,
heading along +x).
"""

from predictor.baselines import BASELINES, ConstantVelocity, ConstantVelocitySampler, LinearFit
from predictor.protocol import Predictor

__all__ = ["BASELINES", "ConstantVelocity", "ConstantVelocitySampler", "LinearFit", "Predictor"]
