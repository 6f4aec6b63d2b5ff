"""How often a robot that never moves is hit by replayed pedestrians, in log and in reactive mode.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/standing_robot.py --scenes univ zara1 --episodes 150

Episode i starts from ``reset(seed=i)`` (the robot placed as in every replay episode, at least 1 m from everyone),
then commands zero velocity for up to 60 steps (24 s). A pedestrian collision ends the episode; in log mode the
pedestrians cannot see the robot, in reactive mode they step round it. Prints hits per mode and, for reactive
mode, the mean distance of the pedestrians from their logs.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import envs  # noqa: F401  (registers the ids)

STEPS = 60


def standing_episodes(scene: str, mode: str, episodes: int) -> tuple[list[tuple[int, int]], float]:
    """(the (seed, step) of every hit, mean log deviation [m]) over ``episodes`` standing-robot episodes."""
    env = gym.make(f"STCrowd-{scene.capitalize()}-v0", predictor="cvm", pedestrians=mode)
    hits, deviation = [], []
    for seed in tqdm(range(episodes), desc=f"{scene} {mode}", leave=False):
        env.reset(seed=seed)
        for step in range(STEPS):
            _, _, terminated, truncated, info = env.step(np.zeros(2))
            deviation.append(info.get("log_deviation_m", 0.0))
            if terminated or truncated:
                if info["termination"] == "pedestrian_collision":
                    hits.append((seed, step))
                break
    env.close()
    return hits, float(np.mean(deviation))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["univ", "zara1"], help="replay scenes (default: univ zara1)")
    parser.add_argument("--episodes", type=int, default=150, help="episodes per scene and mode (default: 150)")
    parser.add_argument("--modes", nargs="+", default=["log", "reactive"], choices=["log", "reactive"])
    args = parser.parse_args()
    print("| scene | pedestrians | episodes | robot hit | first hits (seed, step) | mean distance from the log [m] |")
    print("|---|---|---|---|---|---|")
    for scene in args.scenes:
        for mode in args.modes:
            hits, deviation = standing_episodes(scene, mode, args.episodes)
            print(f"| {scene} | {mode} | {args.episodes} | {len(hits)} | {hits[:5]} | {deviation:.4f} |")


if __name__ == "__main__":
    main()
