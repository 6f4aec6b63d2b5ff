"""Where the time of the navigation suite goes, scenario by scenario: the world's step, the forecast, the policy.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/suite_time.py --policy mpc \
        --predictor singular --episodes 10

Runs ``--episodes`` test episodes of every scenario of the suite (or ``--scenarios``) with the policy, as
``python -m st_sim benchmark`` does, and splits each step's CPU time (``time.process_time``, one thread, so other jobs
on the machine do not inflate it) into the world's step (the crowd: pymunk, or the replay and its reactive
pedestrians), the forecast (``predict_futures``), the policy's ``act``, and the rest (observation, metrics, trace).
Prints one row per scenario, milliseconds per step and the CPU seconds 100 episodes would take, and the suite's total
on one core.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from envs.suite import load_suite, make_scenario_env
from st_sim.apps.navigation.episodes import run_episode
from st_sim.apps.navigation.policies import load_policy
from st_sim.apps.navigation.world import world_of

PARTS = ("world", "forecast", "policy", "other")


class Stopwatch:
    """CPU seconds spent in the functions it wraps, by name."""

    def __init__(self):
        self.seconds = dict.fromkeys(PARTS, 0.0)

    def wrap(self, name: str, function: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                self.seconds[name] += time.process_time() - start
        return timed


def time_scenario(scenario: Any, policy_spec: str, predictor: str, seeds: tuple[int, ...]) -> dict[str, float]:
    """CPU seconds per part over ``seeds`` episodes of ``scenario``, with the steps taken."""
    watch = Stopwatch()
    env = make_scenario_env(scenario, predictor)
    world = world_of(env)
    policy = load_policy(policy_spec, world, predictor)
    crowd = env.unwrapped
    crowd.advance_all = watch.wrap("world", crowd.advance_all)  # instance attributes: this env only
    crowd._forecast = watch.wrap("forecast", crowd._forecast)
    policy.act = watch.wrap("policy", policy.act)
    steps, start = 0, time.process_time()
    for seed in seeds:
        trace, _ = run_episode(env, policy, world, seed)
        steps += len(trace.ego_xy_m) - 1
    total = time.process_time() - start
    env.close()
    watch.seconds["other"] = total - sum(watch.seconds[p] for p in PARTS[:3])
    return {**watch.seconds, "total": total, "steps": steps}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--policy", default="mpc", help="policy spec (default: mpc)")
    parser.add_argument("--predictor", default="singular", help="the envs' predictor (default: singular)")
    parser.add_argument("--episodes", type=int, default=10, help="test episodes per scenario (default: 10)")
    parser.add_argument("--scenarios", nargs="+", default=None, help="default: the whole suite")
    args = parser.parse_args(argv)
    suite = load_suite()
    seeds = suite.seeds_of("test", args.episodes)
    print(f"{args.policy} + {args.predictor}, {args.episodes} test episodes per scenario, CPU time of one thread\n")
    print("| scenario | steps | ms/step: world | forecast | policy | other | CPU s per 100 episodes |")
    print("|---|---|---|---|---|---|---|")
    per_100 = []
    for scenario in suite.select(args.scenarios):
        t = time_scenario(scenario, args.policy, args.predictor, seeds)
        ms = {part: 1e3 * t[part] / max(t["steps"], 1) for part in PARTS}
        per_100.append(t["total"] * 100 / args.episodes)
        print(f"| {scenario.name} | {t['steps']} | " + " | ".join(f"{ms[p]:.1f}" for p in PARTS)
              + f" | {per_100[-1]:.0f} |", flush=True)
    print(f"\nsuite, 100 episodes per scenario: {np.sum(per_100) / 60:.1f} CPU min on one core "
          f"({np.sum(per_100) / 120:.1f} min on two, if the scenarios share them evenly)")


if __name__ == "__main__":
    main()
