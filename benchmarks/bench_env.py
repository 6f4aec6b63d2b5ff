"""Environment steps per second: replay (STCrowd-Zara1-v0) and simulated (STCrowd-SimCrossing-v1), with CVM and
with SingularTrajectory in the loop.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/bench_env.py
    OMP_NUM_THREADS=1 python benchmarks/bench_env.py --vector 16 --predictors singular   # + the native vector env

Each configuration runs several times for a fixed number of steps with seeded random actions
(episodes restart as they end); the figure is steps per wall-clock second, with the share of time
spent inside the predictor's ``predict``. ``--vector N`` then runs SimCrossing-v1 (ego) as one env and as the
native vector env of N sub-envs (``gym.make_vec``, one batched forecast per step), with and without a 5 m sensor
range, alternating, and prints the rates side by side with their ratios (env steps: a vector step counts N).
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
from envs.common.config import EnvConfig
from predictor.baselines import ConstantVelocity

SENSOR_RANGE_M = 5.0  # CrowdNav++'s sensor range
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


def timed_run(env_id: str, kwargs: dict, steps: int, seed: int, inner, keep_forecasts: bool = True
              ) -> tuple[float, float, int]:
    """(steps per second, share of time in predict, episodes) of one run of ``steps`` steps."""
    model = TimedPredictor(inner)
    env = gym.make(env_id, predictor=model, **kwargs)
    if not keep_forecasts:
        env.unwrapped.forecasts = None
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


def vector_run(env_id: str, num_envs: int, steps: int, seed: int, inner, **kwargs) -> tuple[float, float]:
    """(env steps per second, share of time in predict) of the native vector env over ``steps`` env steps."""
    model = TimedPredictor(inner)
    vec = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", predictor=model, **kwargs)
    vec.action_space.seed(seed)
    start = time.perf_counter()
    vec.reset(seed=seed)
    for _ in range(max(1, steps // num_envs)):
        vec.step(vec.action_space.sample())
    elapsed_s = time.perf_counter() - start
    vec.close()
    return max(1, steps // num_envs) * num_envs / elapsed_s, model.seconds / elapsed_s


def compare_vector(num_envs: int, names: list[str], steps: int, repeats: int) -> None:
    """One env against the vector env of ``num_envs``, alternating runs, SimCrossing-v1 with the ego."""
    env_id, checkpoint = "STCrowd-SimCrossing-v1", "universal"
    for name in names:
        inner = ConstantVelocity() if name == "cvm" else predictor.load_pretrained(checkpoint)
        single, vector, near = [], [], []
        for seed in range(repeats):
            single.append(timed_run(env_id, {}, steps, seed, inner)[:2])
            vector.append(vector_run(env_id, num_envs, steps, seed, inner))
            near.append(vector_run(env_id, num_envs, steps, seed, inner,
                                   config=EnvConfig(sensor_range_m=SENSOR_RANGE_M)))
        one, many, fewer = (np.mean([r[0] for r in runs]) for runs in (single, vector, near))
        share = [100 * np.mean([r[1] for r in runs]) for runs in (single, vector, near)]
        print(f"{name:8s} {env_id}: one env {one:.0f} steps/s (predict {share[0]:.0f} %) | vector env x{num_envs} "
              f"{many:.0f} steps/s (predict {share[1]:.0f} %), ratio {many / one:.2f} | the same with sensor_range_m="
              f"{SENSOR_RANGE_M:g} {fewer:.0f} steps/s (predict {share[2]:.0f} %), ratio {fewer / one:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000, help="env steps per run (default: 1000)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per configuration (default: 3)")
    parser.add_argument("--predictors", nargs="+", default=["cvm", "singular"], choices=["cvm", "singular"],
                        help="predictors in the loop (default: cvm singular)")
    parser.add_argument("--vector", type=int, default=0, metavar="N",
                        help="also compare one env with the native vector env of N sub-envs (default: 0, off)")
    parser.add_argument("--only-vector", action="store_true", help="skip the single-env table")
    parser.add_argument("--no-forecast-cache", action="store_true",
                        help="predict afresh on every frame of a log replay (envs keep forecasts by default)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}, {args.steps} steps x "
          f"{args.repeats} runs, random actions, stochastic task (T_obs 8, S 20)")
    for name in [] if args.only_vector else args.predictors:
        for label, env_id, kwargs, checkpoint in CONFIGS:
            inner = ConstantVelocity() if name == "cvm" else predictor.load_pretrained(checkpoint)
            runs = [timed_run(env_id, kwargs, args.steps, seed, inner, not args.no_forecast_cache)
                    for seed in range(args.repeats)]
            rates = np.array([r[0] for r in runs])
            share = np.mean([r[1] for r in runs])
            print(f"{name:8s} {label:26s} {rates.mean():8.0f} steps/s (runs: {', '.join(f'{r:.0f}' for r in rates)}),"
                  f" predict {100 * share:4.1f} % of the time, {sum(r[2] for r in runs)} episodes")
    if args.vector:
        compare_vector(args.vector, args.predictors, args.steps, args.repeats)


if __name__ == "__main__":
    main()
