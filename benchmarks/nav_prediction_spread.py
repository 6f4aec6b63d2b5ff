"""How the predictors' samples look to a planner: best-of-S error against the error of a typical sample.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/nav_prediction_spread.py

Runs each env as a spectator for --steps steps (seed 0) and scores, over the MPC's 3.2 s horizon (8 steps),
every prediction whose agent stays present: the best-of-S ADE and FDE (the benchmark metric), the ADE of the
mean over samples, and the FDE of the average sample. A planner that avoids every sample pays for the
typical sample's error, not for the best one's.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)

HORIZON = 8  # steps of 0.4 s (the MPC's rollout)


def spread(env_id: str, predictor: str, steps: int) -> dict[str, float]:
    """Mean best-of-S ADE/FDE, mean-path ADE and average-sample FDE [m] over ``steps`` spectator steps."""
    env = gym.make(env_id, ego=False, predictor=predictor, max_episode_steps=100_000)
    obs, info = env.reset(seed=0)
    predictions, positions = [], []
    for _ in range(steps):
        rows = obs["futures_mask"]
        predictions.append((info["agent_ids"][rows], obs["futures"][rows, :, :HORIZON]))
        present = obs["history_mask"][:, -1]
        positions.append(dict(zip(info["agent_ids"][present].tolist(), obs["history"][present, -1], strict=True)))
        obs, _, _, truncated, info = env.step(np.zeros(2))
        if truncated:
            break
    rows = []
    for t, (ids, futures) in enumerate(predictions[: len(positions) - HORIZON]):
        for agent, samples in zip(ids.tolist(), futures, strict=True):
            if all(agent in positions[t + k] for k in range(1, HORIZON + 1)):
                truth = np.array([positions[t + k][agent] for k in range(1, HORIZON + 1)])
                error = np.linalg.norm(samples - truth, axis=-1)  # (S, HORIZON)
                rows.append((error.mean(axis=1).min(), error[:, -1].min(),
                             np.linalg.norm(samples.mean(axis=0) - truth, axis=-1).mean(), error[:, -1].mean()))
    best_ade, best_fde, mean_path_ade, sample_fde = np.mean(rows, axis=0)
    return {"n": len(rows), "best_ade_m": best_ade, "best_fde_m": best_fde, "mean_path_ade_m": mean_path_ade,
            "average_sample_fde_m": sample_fde}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["STCrowd-SimCrossing-v1", "STCrowd-Zara1-v0"])
    parser.add_argument("--predictors", nargs="+", default=["cvm", "cvm-s", "singular"])
    parser.add_argument("--steps", type=int, default=150, help="spectator steps per env (default: 150)")
    args = parser.parse_args()
    print("| env | predictor | predictions | best-of-S ADE | best-of-S FDE | ADE of the sample mean | "
          "FDE of the average sample |\n|---|---|---|---|---|---|---|")
    for env_id in args.envs:
        for predictor in args.predictors:
            s = spread(env_id, predictor, args.steps)
            print(f"| {env_id} | {predictor} | {s['n']} | {s['best_ade_m']:.3f} | {s['best_fde_m']:.3f} | "
                  f"{s['mean_path_ade_m']:.3f} | {s['average_sample_fde_m']:.3f} |")


if __name__ == "__main__":
    main()
