"""Trajectory predictors: the SingularTrajectory model, constant-velocity baselines, plug-ins from elsewhere.

Dimension letters used across the project's docstrings:
    N agents, T steps (0.4 s each; T_obs observed, 12 predicted), S samples per agent,
    K singular vectors (Singular-space dimension), B batch, G groups (windows), P populations.
Units: metres, world frame unless a docstring says "agent frame" (last observed point at the origin,
heading along +x, moving agents' lengths in units of their recent speed per step).

    import predictor
    model = predictor.load_pretrained("stochastic/zara1")   # or "universal", or predictor.load(path)
    futures = model.predict(obs, group, scene, num_samples=20)   # (N, 20, 12, 2) metres
    own = predictor.load_plugin("examples.knn_predictor:make", "stochastic", "zara1")   # a plug-in (predictor.plugins)
"""

from predictor.baselines import BASELINES, ConstantVelocity, ConstantVelocitySampler, LinearFit, Stationary
from predictor.plugins import PluginError, load_plugin
from predictor.protocol import Predictor

__all__ = ["BASELINES", "ConstantVelocity", "ConstantVelocitySampler", "LinearFit", "PluginError", "Predictor",
           "Stationary", "load", "load_plugin", "load_pretrained"]


def __getattr__(name: str):
    """``load`` and ``load_pretrained`` import torch only when first used."""
    if name in ("load", "load_pretrained"):
        from predictor import checkpoint

        return getattr(checkpoint, name)
    raise AttributeError(f"module 'predictor' has no attribute {name!r}")
