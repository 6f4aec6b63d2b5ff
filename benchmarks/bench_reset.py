"""Resets per second of the replay envs: drawing the frame, the robot's start and goal, histories and observation.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/bench_reset.py --resets 200

Each scene's ``STCrowd-<Scene>-v0`` (log pedestrians, no predictor) is made once and reset ``--resets`` times with
seeds 0, 1, ...; prints each scene's resets per second. To compare two commits, run it in each checkout
(``PYTHONPATH=<checkout> python benchmarks/bench_reset.py``), or time both with ``farm-bench --vs``.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym

import envs  # noqa: F401  (registers the ids)
from envs import REPLAY_SCENES


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resets", type=int, default=200, help="resets per scene (default: 200)")
    parser.add_argument("--scenes", nargs="+", default=list(REPLAY_SCENES))
    args = parser.parse_args()
    for scene in args.scenes:
        env = gym.make(f"STCrowd-{scene.capitalize()}-v0", predictor="none")
        env.reset(seed=0)  # built and warm
        start = time.perf_counter()
        for seed in range(args.resets):
            env.reset(seed=seed)
        print(f"{scene}: {args.resets / (time.perf_counter() - start):.1f} resets/s")
        env.close()


if __name__ == "__main__":
    main()
