"""CPU time of an env step with the constant-velocity predictor (so the step's own cost shows, not the forecast's):
one replay, one simulated crowd, and the native vector env of 64, driven by seeded random actions.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/bench_step_cost.py --out runs/cost-head
    git worktree add ../base COMMIT && (cd ../base && PYTHONPATH=. python "$OLDPWD/benchmarks/bench_step_cost.py" \\
        --out "$OLDPWD/runs/cost-base")       # the same at another commit; alternate the two, compare the medians

It times with the process's CPU clock (``time.process_time``: robust to other jobs on the machine, unlike wall time)
and writes one JSON line per configuration: milliseconds of CPU per env step (a vector step counts 64), the median
of ``--repeats`` runs. Only gymnasium's API is used, with each env's defaults, so the script runs at any commit.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

import envs  # noqa: F401  (registers the ids)
from replays.strict_json import dumps

CONFIGS = (("replay zara1", "STCrowd-Zara1-v0", 1), ("sim crossing", "STCrowd-SimCrossing-v1", 1),
           ("vector of 64, sim crossing", "STCrowd-SimCrossing-v1", 64))


def cpu_ms_per_step(env_id: str, num_envs: int, steps: int, seed: int) -> float:
    """CPU milliseconds per env step of ``steps`` steps (episodes restart as they end)."""
    rng = np.random.default_rng(seed)
    if num_envs == 1:
        env = gym.make(env_id, predictor="cvm")
        env.reset(seed=seed)
    else:
        env = gym.make_vec(env_id, num_envs=num_envs, predictor="cvm")
        env.reset(seed=seed)
    shape = env.action_space.shape
    start = time.process_time()
    for _ in range(steps):
        action = rng.uniform(-1.5, 1.5, shape).astype(np.float32)
        if num_envs == 1:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        else:
            env.step(action)
    spent = time.process_time() - start
    env.close()
    return 1e3 * spent / (steps * num_envs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=400, help="env steps per run (vector: vector steps / 8)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, required=True, help="JSON lines file the figures are appended to")
    args = parser.parse_args()
    torch.set_num_threads(1)
    for label, env_id, num_envs in CONFIGS:
        steps = args.steps if num_envs == 1 else max(1, args.steps // 8)
        runs = [cpu_ms_per_step(env_id, num_envs, steps, seed) for seed in range(args.repeats)]
        line = {"config": label, "ms_per_step": float(np.median(runs)), "runs": runs}
        print(dumps(line), flush=True)
        with args.out.open("a") as out:
            out.write(dumps(line) + "\n")


if __name__ == "__main__":
    main()
