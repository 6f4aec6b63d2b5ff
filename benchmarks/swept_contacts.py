"""Contacts between two frames: does the env report every robot-pedestrian contact, at the impact, with its fault?

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/swept_contacts.py --envs STCrowd-Zara1-v0 STCrowd-Univ-v0 --episodes 100 --seed 5000

Drives the straight planner (full speed at the goal, avoiding nothing) through log-replay episodes and checks every
step independently of the env: robot and pedestrians are moved linearly between the two frames and sampled at 400
instants; a pedestrian present in both frames whose centre comes closer than the contact distance at any instant
is a contact (a pedestrian who appears this frame counts where it appears). Prints, per env, the contacts this check
finds, those the env did not report (target 0), the collisions the env reports, and how many of those the old rule
(the bodies' positions at the end of the step, the robot at fault unless stopped or every pedestrian touched was
behind it) would have judged not at fault although the env, judging at the impact by who closed the gap
(``envs.common.fault``), finds the robot at fault.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import envs  # noqa: F401  (registers the ids)
from st_sim.sim.sweep import TOUCH_SLACK_M

SAMPLES = 400  # instants per 0.4 s step of the independent check
END_OF_STEP_STOPPED_MPS = 0.2  # the end-of-step rule's robot was stopped below this speed [m/s]


def dense_contact(ego_from: np.ndarray, ego_to: np.ndarray, before: np.ndarray, after: np.ndarray,
                  reach_m: float) -> bool:
    """True if robot and any pedestrian (rows of ``before``/``after`` (P, 2), NaN rows absent at that frame) come
    closer than ``reach_m`` at one of ``SAMPLES`` instants of the step."""
    t = np.linspace(0.0, 1.0, SAMPLES)[:, None, None]
    both = ~np.isnan(before).any(1) & ~np.isnan(after).any(1)
    ego = ego_from + t[:, 0] * (ego_to - ego_from)  # (T, 2)
    peds = before[both] + t * (after[both] - before[both])  # (T, P, 2)
    swept = bool((np.linalg.norm(peds - ego[:, None], axis=-1) < reach_m).any())
    new = np.isnan(before).any(1) & ~np.isnan(after).any(1)
    return swept or bool((np.linalg.norm(after[new] - ego_to, axis=1) < reach_m).any())


def old_rule_at_fault(ego_xy: np.ndarray, velocity: np.ndarray, peds_xy: np.ndarray, reach_m: float) -> bool:
    """The fault rule as it was before judging at the impact: the bodies where the step ended, the robot at fault
    unless it was (nearly) stopped or every pedestrian it touched was behind it."""
    if np.hypot(*velocity) < END_OF_STEP_STOPPED_MPS or len(peds_xy) == 0:
        return False
    distance = np.linalg.norm(peds_xy - ego_xy, axis=1)
    near = distance < reach_m + TOUCH_SLACK_M
    if not near.any():
        near[np.argmin(distance)] = True
    return bool(((peds_xy[near] - ego_xy) @ velocity >= 0).any())


def positions(obs: dict[str, np.ndarray], info: dict, column: int) -> dict[int, np.ndarray]:
    """Agent id -> (2,) position in history column ``column`` of ``obs``."""
    seen = obs["history_mask"][:, column] & (info["agent_ids"] >= 0)
    return dict(zip(info["agent_ids"][seen].tolist(), obs["history"][seen, column].astype(np.float64), strict=True))


def check_env(env_id: str, episodes: int, seed: int) -> dict[str, int]:
    env = gym.make(env_id, predictor="cvm")
    cfg = env.unwrapped.cfg
    reach_m = cfg.ego_radius_m + cfg.pedestrian_radius_m
    counts = dict.fromkeys(["episodes", "steps", "found", "unreported", "collisions", "at_fault",
                            "old_rule_not_at_fault"], 0)
    for episode in tqdm(range(episodes), desc=env_id, leave=False):
        obs, info = env.reset(seed=seed + episode)
        counts["episodes"] += 1
        done = False
        while not done:
            ego_from = obs["ego"][:2].astype(np.float64)
            goal = obs["ego"][4:6].astype(np.float64)
            heading = goal - ego_from
            obs, _, terminated, truncated, info = env.step(1.5 * heading / max(np.linalg.norm(heading), 1e-9))
            done = terminated or truncated
            counts["steps"] += 1
            ego_to = obs["ego"][:2].astype(np.float64)
            before, after = positions(obs, info, -2), positions(obs, info, -1)
            ids = sorted(after)
            start = np.array([before.get(i, (np.nan, np.nan)) for i in ids]).reshape(-1, 2)
            end = np.array([after[i] for i in ids]).reshape(-1, 2)
            found = dense_contact(ego_from, ego_to, start, end, reach_m)
            reported = info["termination"] == "pedestrian_collision"
            counts["found"] += found
            counts["unreported"] += found and not reported
            if reported:
                counts["collisions"] += 1
                counts["at_fault"] += bool(info["at_fault"])
                velocity = (ego_to - ego_from) / 0.4
                counts["old_rule_not_at_fault"] += bool(info["at_fault"]) and not old_rule_at_fault(
                    ego_to, velocity, end, reach_m)
    env.close()
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=["STCrowd-Zara1-v0", "STCrowd-Univ-v0"])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=5000, help="episode i starts from reset(seed=seed + i)")
    args = parser.parse_args()
    print("| env | episodes | steps | contacts found (400 instants/step) | not reported by the env | collisions "
          "reported | at fault | at fault but not by the end-of-step rule |")
    print("|---|---|---|---|---|---|---|---|")
    for env_id in args.envs:
        c = check_env(env_id, args.episodes, args.seed)
        print(f"| {env_id} | {c['episodes']} | {c['steps']} | {c['found']} | {c['unreported']} | {c['collisions']} | "
              f"{c['at_fault']} | {c['old_rule_not_at_fault']} |")


if __name__ == "__main__":
    main()
