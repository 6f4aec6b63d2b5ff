"""What a sensor and a tracker add to a step of the MPC with SingularTrajectory: the same episodes stepped with the
oracle's eyes and at a sensing level, alternating, in one process on one thread.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/bench_sensing.py --levels realistic

For each env and level it runs ``--episodes`` episodes (seeds 0.., up to ``--steps`` steps each) of the MPC driving
on the env's forecasts, ``--repeats`` times alternating with the oracle, and prints the wall seconds per step (env
step and the planner's decision together), the share of it spent in the sensor and tracker
(``Perception.sense``), the ratio to the oracle measured in the same round (the median over rounds), and the share
of the pedestrians (tracks) in the observation that got a forecast (a track needs T_obs = 8 steps for one).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers the ids)
from st_sim.apps.navigation.policies import load_policy
from st_sim.apps.navigation.world import world_of
from st_sim.perception import Perception

ENVS = (("STCrowd-SimCrossing-v1", {}), ("STCrowd-Univ-v0", {}), ("STCrowd-Zara1-v0", {"pedestrians": "reactive"}))


class TimedSense:
    """Adds up the wall seconds spent in ``Perception.sense`` (patched for the measurement)."""

    seconds = 0.0
    original = Perception.sense

    @classmethod
    def install(cls) -> None:
        def timed(self, *args, **kwargs):
            start = time.perf_counter()
            try:
                return cls.original(self, *args, **kwargs)
            finally:
                cls.seconds += time.perf_counter() - start
        Perception.sense = timed


def run(env_id: str, kwargs: dict, level: str, episodes: int, steps: int) -> tuple[float, float, int, float]:
    """(wall seconds, of them in sensing, steps, share of observed pedestrians forecast) of the MPC's episodes at
    ``level``."""
    env = gym.make(env_id, predictor="singular", sensing=level, **kwargs)
    world = world_of(env)
    policy = load_policy("mpc", world, "singular")
    TimedSense.seconds, total, count, present, forecast = 0.0, 0.0, 0, 0, 0
    for seed in range(episodes):
        obs, _ = env.reset(seed=seed)
        policy.reset()
        for _ in range(steps):
            start = time.perf_counter()
            obs, _, terminated, truncated, _ = env.step(policy.act(obs))
            total += time.perf_counter() - start
            count += 1
            present += int(obs["history_mask"][:, -1].sum())
            forecast += int(obs["futures_mask"].sum())
            if terminated or truncated:
                break
    env.close()
    return total, TimedSense.seconds, count, forecast / max(present, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--levels", nargs="+", default=["realistic"])
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    TimedSense.install()
    print(f"{'env':<34}{'level':<11}{'ms/step':>9}{'sensing %':>11}{'x oracle':>10}{'forecast share':>16}")
    for env_id, kwargs in ENVS:
        name = env_id + (f" ({kwargs['pedestrians']})" if kwargs else "")
        for level in args.levels:
            ratios, per_step, shares, forecast = [], [], [], []
            for _ in range(args.repeats):
                base_s, _, base_n, _ = run(env_id, kwargs, "oracle", args.episodes, args.steps)
                seconds, sensing_s, n, share = run(env_id, kwargs, level, args.episodes, args.steps)
                forecast.append(share)
                ratios.append((seconds / n) / (base_s / base_n))
                per_step.append(1e3 * seconds / n)
                shares.append(100 * sensing_s / seconds)
            print(f"{name:<34}{level:<11}{np.median(per_step):>9.2f}{np.median(shares):>11.1f}"
                  f"{np.median(ratios):>10.3f}{np.median(forecast):>16.2f}", flush=True)


if __name__ == "__main__":
    main()
