"""A navigation policy package of your own, benchmarked by STCrowd without editing STCrowd.

- ``keep_clear.KeepClear``: a hand-written policy (NumPy only) that heads for the goal and steers away from where
  people are predicted to be.
- ``nearest``: a fixed-size view of any STCrowd observation (the K nearest people), the gym wrapper to train a
  stable-baselines3 model on it, and ``Sb3Nearest``, the policy that runs that model in every scenario.
- ``train_sb3``: the few lines that train it (``python -m examples.my_policy.train_sb3``).

    python -m st_sim benchmark --policy examples.my_policy.keep_clear:KeepClear --out runs/bench/keep-clear
    python -m st_sim leaderboard runs/bench/keep-clear

Run from the repository root (or put this package's parent folder on PYTHONPATH) so that ``examples`` imports.
"""
