"""A navigation policy package of your own, benchmarked by STCrowd without editing STCrowd.

- ``keep_clear.KeepClear``: a hand-written policy (NumPy only) that heads for the goal and steers away from where
  people are predicted to be.
- ``train_sb3``: the few lines that train a stable-baselines3 model on the suite env ``STCrowd-Suite-v1`` (the
  suite's train split through a fixed-size view, ``envs.view``), which ``--policy sb3:PATH.zip`` runs in every
  scenario (``python -m examples.my_policy.train_sb3``).

    python -m st_sim benchmark --policy examples.my_policy.keep_clear:KeepClear --out runs/bench/keep-clear
    python -m st_sim leaderboard runs/bench/keep-clear

Run from the repository root (or put this package's parent folder on PYTHONPATH) so that ``examples`` imports.
"""
