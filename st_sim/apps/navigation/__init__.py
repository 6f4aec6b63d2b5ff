"""Crowd navigation on the STCrowd envs: planners that use the predicted futures, and a benchmark to score them.

    python -m st_sim navigate --env STCrowd-SimCrossing-v1 --policy mpc --predictor singular --episodes 100
    python -m st_sim benchmark --policy mypkg.policy:MyPolicy --out runs/bench/mine

Modules, one concept each:
- ``planners``: the registry (straight, orca, mpc, ppo, ppo-reactive, ppo-suite, ppo-suite-shield, ppo-suite-2) and the
  ``Planner`` interface (``reset``, ``act``); ``policies``: any policy by spec (a shipped name,
  package.module:name, sb3:PATH.zip); ``sb3_zip``: a stable-baselines3 model file read without running anything
  stored in it;
  ``straight``, ``orca``, ``mpc``, ``ppo``: one planner class each; ``shield``: another planner's commands vetted by
  the MPC over the forecasts;
- ``predictors``: the predictor names (none, cvm, cvm-s, singular) and "none" (nobody moves);
- ``world``, ``pedestrians``: what a planner knows (limits, radii, the map grid and cost-to-go of
  ``envs.common.terrain``) and sees;
- ``features``, ``train_ppo``: the learned policy's inputs and its stable-baselines3 training script;
- ``episodes``, ``metrics``, ``social_metrics``, ``report``, ``cli``: seeded episodes, their figures in three groups
  with 95 % intervals, the command;
- ``benchmark``, ``leaderboard``, ``benchmark_cli``: any policy through the versioned suite (``envs.suite``), results
  side by side.

Application layer: it imports envs, predictor, replays and st_sim; nothing below imports it.
"""
