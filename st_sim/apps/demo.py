"""Demo: an ego robot crosses a simulated crowd (STCrowd-SimCrossing-v0), a predictor in the loop.

The ego picks, every step, the velocity that brings it closest to its goal while keeping clear of the
pedestrians' predicted positions over the next 1.6 s; each finished episode prints its metrics. Runs
headless; with a Rerun path the run is also written as a ``.rrd`` recording.

    python -m st_sim demo --steps 150 --rerun demo.rrd
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from replays.constants import STEP_S
from replays.scenes import Scene

ENV_ID = "STCrowd-SimCrossing-v0"
HEADINGS = 16  # candidate directions of the ego's velocity [-]
SPEED_FRACTIONS = (1.0, 0.6, 0.3)  # candidate speeds as shares of the max [-]
LOOKAHEAD_STEPS = 4  # predicted steps (of 0.4 s) the ego checks its candidates against
CONTACT_MARGIN_M = 0.25  # clearance wanted beyond body contact [m]
CLEARANCE_WEIGHT = 4.0  # cost per metre of missing clearance, relative to one metre of progress [-]
WALL_PROBE_M = 0.4  # the ego's footprint is probed for walkability this far around its centre [m]


def goal_seeking_action(obs: dict[str, np.ndarray], max_speed_mps: float, contact_m: float,
                        scene: Scene | None = None) -> np.ndarray:
    """Velocity (2,) [m/s] toward the goal that keeps clear of pedestrians' predicted positions.

    Candidate velocities (16 headings x 3 speeds, and standing still) are rolled out for 4 steps at
    constant velocity; each is scored by its progress to the goal minus a penalty for coming within
    ``contact_m`` + 0.25 m of any predicted future (every sample) or current position of a pedestrian
    without predictions, and discarded if it leaves the walkable map. The best one wins.

    Args:
        obs: an STCrowd observation (metres, world frame).
        max_speed_mps: the ego's speed limit [m/s].
        contact_m: ego radius + pedestrian radius [m].
        scene: walkability map, or None to ignore walls.
    """
    ego_xy, goal = obs["ego"][:2].astype(np.float64), obs["ego"][4:6].astype(np.float64)
    angles = np.linspace(0.0, 2 * np.pi, HEADINGS, endpoint=False)
    unit = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    candidates = np.concatenate([(unit[None] * np.array(SPEED_FRACTIONS)[:, None, None]).reshape(-1, 2)
                                 * max_speed_mps, np.zeros((1, 2))])  # (K, 2) m/s
    ahead = np.arange(1, LOOKAHEAD_STEPS + 1) * STEP_S
    ego_path = ego_xy + candidates[:, None] * ahead[None, :, None]  # (K, L, 2)
    futures = obs["futures"][obs["futures_mask"], :, :LOOKAHEAD_STEPS].transpose(2, 0, 1, 3).reshape(
        LOOKAHEAD_STEPS, -1, 2)  # (L, P*S, 2)
    standing = obs["history"][obs["history_mask"][:, -1] & ~obs["futures_mask"], -1]  # (Q, 2)
    others = np.concatenate([futures, np.broadcast_to(standing, (LOOKAHEAD_STEPS, *standing.shape))], axis=1)
    if others.shape[1]:
        clearance = np.linalg.norm(ego_path[:, :, None] - others[None], axis=-1).min(axis=(1, 2))
    else:
        clearance = np.full(len(candidates), np.inf)
    progress = np.linalg.norm(goal - ego_xy) - np.linalg.norm(goal - ego_path[:, -1], axis=1)
    cost = -progress + CLEARANCE_WEIGHT * np.clip(contact_m + CONTACT_MARGIN_M - clearance, 0.0, None)
    if scene is not None:
        probes = ego_path[:, :, None] + WALL_PROBE_M * np.concatenate([unit[::4], np.zeros((1, 2))])[None, None]
        cost[~scene.is_walkable(probes).all(axis=(1, 2))] = np.inf
    return candidates[int(np.argmin(cost))]


def _episode_summary(index: int, steps: int, episode_return: float, truncated: bool, info: dict) -> dict:
    parts = info["reward_parts"]
    outcome = ("goal" if parts["goal"] else "collision" if parts["collision"] else
               "time limit" if truncated else "demo over")
    metrics = info["metrics"]
    print(f"episode {index}: {steps} steps, {outcome}, return {episode_return:+.2f}, "
          f"ADE/FDE {metrics['ade_m']:.3f}/{metrics['fde_m']:.3f} m over {metrics['matured']} predictions, "
          f"map violation {100 * metrics['map_violation']:.1f} %, "
          f"closest pedestrian {metrics['min_ego_ped_distance_m']:.2f} m")
    return {"steps": steps, "outcome": outcome, "return": episode_return, **metrics}


def run_demo(steps: int = 150, rerun_path: str | None = None, seed: int = 0) -> dict:
    """Run ``steps`` env steps (episodes restart as they end) and print each episode's metrics.

    Returns:
        {"env_id", "steps", "seed", "episodes": [per-episode dict: steps, outcome, return and the env's
        metrics], "steps_per_s"}.
    """
    env = gym.make(ENV_ID, rerun=rerun_path)  # the shipped universal SingularTrajectory model predicts
    cfg, scene = env.unwrapped.cfg, env.unwrapped.scene
    contact_m = cfg.ego_radius_m + env.unwrapped.crowd_cfg.radius_m
    obs, info = env.reset(seed=seed)
    episodes: list[dict] = []
    episode_steps, episode_return = 0, 0.0
    start = time.perf_counter()
    for step in range(steps):
        action = goal_seeking_action(obs, cfg.max_speed_mps, contact_m, scene)
        obs, reward, terminated, truncated, info = env.step(action)
        episode_steps, episode_return = episode_steps + 1, episode_return + reward
        if terminated or truncated or step == steps - 1:
            episodes.append(_episode_summary(len(episodes), episode_steps, episode_return, truncated, info))
            if step < steps - 1:
                obs, info = env.reset()
                episode_steps, episode_return = 0, 0.0
    elapsed_s = time.perf_counter() - start
    env.close()
    if rerun_path is not None:
        print(f"wrote {rerun_path}")
    return {"env_id": ENV_ID, "steps": steps, "seed": seed, "episodes": episodes,
            "steps_per_s": steps / elapsed_s if elapsed_s > 0 else float("inf")}
