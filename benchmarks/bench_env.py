"""Environment steps per second: replay (STCrowd-Zara1-v0) and simulated (STCrowd-SimCrossing-v1), with CVM and
with SingularTrajectory in the loop.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/bench_env.py

Each configuration runs several times for a fixed number of steps with seeded random actions
(episodes restart as they end); the figure is steps per wall-clock second, with the share of time
spent inside the predictor's ``predict``.
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers the ids)
import predictor
from predictor.baselines import ConstantVelocity

CONFIGS = (  # (label, env id, extra kwargs, shipped checkpoint for SingularTrajectory)
    ("replay zara1, ego", "STCrowd-Zara1-v0", {}, "stochastic/zara1"),
    ("replay zara1, spectator", "STCrowd-Zara1-v0", {"ego": False}, "stochastic/zara1"),
    ("sim crossing, ego", "STCrowd-SimCrossing-v1", {}, "universal"),
    ("sim crossing, spectator", "STCrowd-SimCrossing-v1", {"ego": False}, "universal"),
)


class TimedPredictor:
    """Wraps a predictor and adds up the wall-clock time spent in its ``predict``."""

    def __init__(self, inner) -> None:
        self.inner, self.seconds = inner, 0.0

    def predict(self, obs, group, scene=None, num_samples=1):
        start = time.perf_counter()
        futures = self.inner.predict(obs, group, scene, num_samples)
        self.seconds += time.perf_counter() - start
        return futures


def timed_run(env_id: str, kwargs: dict, steps: int, seed: int, inner) -> tuple[float, float, int]:
    """(steps per second, share of time in predict, episodes) of one run of ``steps`` steps."""
    model = TimedPredictor(inner)
    env = gym.make(env_id, predictor=model, **kwargs)
    env.action_space.seed(seed)
    start = time.perf_counter()
    env.reset(seed=seed)
    episodes = 1
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
            episodes += 1
    elapsed_s = time.perf_counter() - start
    env.close()
    return steps / elapsed_s, model.seconds / elapsed_s, episodes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000, help="env steps per run (default: 1000)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per configuration (default: 3)")
    parser.add_argument("--predictors", nargs="+", default=["cvm", "singular"], choices=["cvm", "singular"],
                        help="predictors in the loop (default: cvm singular)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}, {args.steps} steps x "
          f"{args.repeats} runs, random actions, stochastic task (T_obs 8, S 20)")
    for name in args.predictors:
        for label, env_id, kwargs, checkpoint in CONFIGS:
            inner = ConstantVelocity() if name == "cvm" else predictor.load_pretrained(checkpoint)
            runs = [timed_run(env_id, kwargs, args.steps, seed, inner) for seed in range(args.repeats)]
            rates = np.array([r[0] for r in runs])
            share = np.mean([r[1] for r in runs])
            print(f"{name:8s} {label:26s} {rates.mean():8.0f} steps/s (runs: {', '.join(f'{r:.0f}' for r in rates)}),"
                  f" predict {100 * share:4.1f} % of the time, {sum(r[2] for r in runs)} episodes")


if __name__ == "__main__":
    main()
