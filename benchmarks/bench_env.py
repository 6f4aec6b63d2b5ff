"""Environment steps per second: replay (STCrowd-Zara1-v0) and simulated (STCrowd-SimCrossing-v1), with CVM and
with SingularTrajectory in the loop; and one env against the batched vector env.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/bench_env.py
    python benchmarks/bench_env.py --only-vector --vector 16 64 256 --shards 2      # one env against the vector env

Each single-env configuration runs several times for a fixed number of steps with seeded random actions
(episodes restart as they end); the figure is steps per wall-clock second, with the share of time spent inside
the predictor's ``predict``.

``--vector N ...`` measures, in one run and alternating, on SimCrossing-v1 with SingularTrajectory (``--predictors``)
and a 5 m sensor range, a goal-seeking robot with noise (the policy PPO meets early in training): one env at one
thread, one env at torch's default thread count, and the native vector env of each N (one process; and with
``--shards K`` also split into K worker processes). It prints env steps per second (a vector step counts N), each
one's ratio to one env at one thread, and for the one-process vector env the shares of the time spent in the crowd
simulator (``SimCrowdEnv._step_worlds`` and ``_reset_worlds``: stepping and warming up the crowds), in the
forecast (``predict``) and in the rest (observations, rewards, metrics, sensing, autoresets), and the process's
peak memory.
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers the ids)
import predictor
from envs.common.config import EnvConfig
from predictor.baselines import ConstantVelocity

SENSOR_RANGE_M = 5.0  # CrowdNav++'s sensor range
DEFAULT_THREADS = torch.get_num_threads()  # torch's own choice in this process, before the benchmark sets one
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


class SectionTimer:
    """Adds up the wall-clock time spent in some classmethods of an env class, patched while in a ``with`` block."""

    def __init__(self, cls: type, names: tuple[str, ...]):
        self.cls, self.names, self.seconds = cls, names, 0.0
        self._originals = {name: cls.__dict__[name] for name in names}

    def __enter__(self) -> SectionTimer:
        for name, original in self._originals.items():
            def timed(klass, *args, _inner=original.__func__, **kwargs):
                start = time.perf_counter()
                try:
                    return _inner(klass, *args, **kwargs)
                finally:
                    self.seconds += time.perf_counter() - start

            setattr(self.cls, name, classmethod(timed))
        return self

    def __exit__(self, *exc: object) -> None:
        for name, original in self._originals.items():
            setattr(self.cls, name, original)


def goal_seeking(obs: dict[str, np.ndarray], rng: np.random.Generator) -> np.ndarray:
    """(..., 2) float32 full speed toward the goal plus N(0, 0.5 m/s) noise per axis, for one env or a batch."""
    to_goal = obs["ego"][..., 4:6] - obs["ego"][..., :2]
    velocity = 1.5 * to_goal / np.maximum(np.linalg.norm(to_goal, axis=-1, keepdims=True), 1e-6)
    return (velocity + rng.normal(0.0, 0.5, velocity.shape)).astype(np.float32)


def single_rate(steps: int, seed: int, model, threads: int | None, sensor_range_m: float = SENSOR_RANGE_M,
                envs_made: tuple[tuple[str, dict], ...] = (("STCrowd-SimCrossing-v1", {}),)) -> float:
    """Env steps per second of one env (``sensor_range_m`` sensing) with a goal-seeking noisy robot, at ``threads``
    torch threads (None: default): ``steps`` steps in each of ``envs_made`` ((id, ``gym.make`` keywords) pairs; by
    default SimCrossing-v1 alone), all steps over all the time."""
    default = torch.get_num_threads()
    torch.set_num_threads(threads or DEFAULT_THREADS)
    elapsed = 0.0
    try:
        for env_id, kwargs in envs_made:
            env = gym.make(env_id, predictor=model, config=EnvConfig(sensor_range_m=sensor_range_m), **kwargs)
            rng = np.random.default_rng(seed)
            obs, _ = env.reset(seed=seed)
            start = time.perf_counter()
            for _ in range(steps):
                obs, _, terminated, truncated, _ = env.step(goal_seeking(obs, rng))
                if terminated or truncated:
                    obs, _ = env.reset()
            elapsed += time.perf_counter() - start
            env.close()
    finally:
        torch.set_num_threads(default)
    return steps * len(envs_made) / elapsed


def vector_rate(num_envs: int, steps: int, seed: int, model, shards: int = 1) -> tuple[float, float, float]:
    """(env steps per second, share of time in the crowd simulator, share in predict) of the vector env of
    ``num_envs``; with shards the predictor is named (``model`` a name) and the shares are NaN (other processes)."""
    from envs.sim_env import SimCrowdEnv

    config = EnvConfig(sensor_range_m=SENSOR_RANGE_M)
    if shards > 1:
        vec = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=num_envs, shards=shards, predictor=model, config=config)
    else:
        vec = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=num_envs, vectorization_mode="vector_entry_point",
                           predictor=model, config=config)
    rng = np.random.default_rng(seed)
    steps = max(1, steps // num_envs)
    with SectionTimer(SimCrowdEnv, ("_step_worlds", "_reset_worlds")) as crowd:
        obs, _ = vec.reset(seed=seed)
        crowd.seconds, predicting = 0.0, getattr(model, "seconds", 0.0)
        start = time.perf_counter()
        for _ in range(steps):
            obs, *_ = vec.step(goal_seeking(obs, rng))
        elapsed_s = time.perf_counter() - start
    vec.close()
    if shards > 1:
        return steps * num_envs / elapsed_s, float("nan"), float("nan")
    return steps * num_envs / elapsed_s, crowd.seconds / elapsed_s, (model.seconds - predicting) / elapsed_s


def compare_vector(sizes: list[int], names: list[str], steps: int, repeats: int, shards: int) -> None:
    """One env (one thread, default threads) against the vector env of each size, alternating runs."""
    for name in names:
        inner = ConstantVelocity() if name == "cvm" else predictor.load_pretrained("universal")
        rows: dict[str, list] = {}
        for seed in range(repeats):
            rows.setdefault("one env, 1 thread", []).append((single_rate(steps, seed, TimedPredictor(inner), 1),))
            rows.setdefault(f"one env, {DEFAULT_THREADS} threads (torch default)", []).append(
                (single_rate(steps, seed, TimedPredictor(inner), None),))
            for n in sizes:
                rows.setdefault(f"vector env x{n}", []).append(vector_rate(n, steps, seed, TimedPredictor(inner)))
                if shards > 1:
                    rows.setdefault(f"vector env x{n}, {shards} shards", []).append(
                        vector_rate(n, steps, seed, name, shards))
        base = np.median([r[0] for r in rows["one env, 1 thread"]])
        print(f"\n{name}, STCrowd-SimCrossing-v1, sensor range {SENSOR_RANGE_M:g} m, goal-seeking noisy robot, "
              f"{repeats} runs (median)")
        print("| configuration | env steps/s | ratio to one env at 1 thread | crowd simulator | forecast | rest |")
        print("|---|---|---|---|---|---|")
        for label, runs in rows.items():
            rate = float(np.median([r[0] for r in runs]))
            shares = [float(np.median([r[k] for r in runs])) if len(runs[0]) > k else float("nan") for k in (1, 2)]
            cells = [f"{100 * v:.0f} %" if np.isfinite(v) else "–" for v in shares]
            rest = f"{100 * (1 - sum(shares)):.0f} %" if all(np.isfinite(shares)) else "–"
            print(f"| {label} | {rate:.0f} | {rate / base:.2f} | {cells[0]} | {cells[1]} | {rest} |")
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak memory of this process: {peak_mb:.0f} MB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000, help="env steps per run (default: 1000)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per configuration (default: 3)")
    parser.add_argument("--predictors", nargs="+", default=["cvm", "singular"], choices=["cvm", "singular"],
                        help="predictors in the loop (default: cvm singular)")
    parser.add_argument("--vector", type=int, nargs="+", default=[], metavar="N",
                        help="also compare one env with the native vector env of each N sub-envs (default: off)")
    parser.add_argument("--shards", type=int, default=1,
                        help="with --vector, also run each vector env split into this many worker processes")
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
        compare_vector(args.vector, args.predictors, args.steps, args.repeats, args.shards)


if __name__ == "__main__":
    main()
