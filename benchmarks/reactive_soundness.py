"""Do reactive replay pedestrians behave like people round a standing robot? Frozen, far from their logs, overlapping,
in walls or off the image, measured against their own recordings.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/reactive_soundness.py --scenes univ zara1 --episodes 50 --busiest-episodes 30 \
        --log-end-episodes 30 --seed 1000 [--reaction-traits drawn]

Each episode starts from ``reset(seed=seed + i)`` of ``STCrowd-<Scene>-v0`` with ``pedestrians="reactive"`` (and
``reaction_traits``: every pedestrian the fitted one, or each with traits drawn from the fitted spread) and the
robot commanded to stand still for up to 200 steps, either where the env spawned it (at least 1 m from everybody, the
benchmark's own setting) or moved, right after the reset, to the busiest clear spot (the walkable point at least 1 m
from everybody then that the most logged pedestrian-frames of the episode pass within 1 m of) or onto a log's end
(the walkable point at least 1 m from everybody then nearest to where a log present now ends within the episode, the
log ending soonest first). Everything is measured from the observations (who is present where) against the
recording:

- frozen: a pedestrian that moves under 2 cm per step for 10 steps in a row while its log moves more than 1 m over
  them (episodes with one);
- leave far: a pedestrian that leaves the scene more than 1 m from the nearest places clear of the robot (its body
  and the pedestrian's apart) to where its log ends: more than 1 m from the end, plus, where the robot stands on the
  end, the way from the end out of the robot's reach (any side of it);
- overlap: a pair of pedestrians closer than 0.3 m (bodies of 0.2 m overlapping by more than 10 cm) whose logs are
  not that close at that frame (distinct pairs);
- in a wall: pedestrian-steps on a non-walkable pixel where the log is walkable, and those more than 0.3 m deeper in
  the non-walkable area than their log;
- off the image: pedestrian-steps off the scene's image;
- robot hit: pedestrian collisions of the standing robot (episodes).
"""

from __future__ import annotations

import argparse
from collections import defaultdict

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import envs  # noqa: F401  (registers the ids)
from envs.replay_env import REACTION_TRAITS
from st_sim.reactive.routes import run_bounds
from st_sim.sim.map_depth import MapDepth

STEPS = 200
FROZEN_STEP_M, FROZEN_STEPS, FROZEN_LOG_M = 0.02, 10, 1.0
LEAVE_FAR_M = 1.0
OVERLAP_M = 0.3  # centre distance of two 0.2 m bodies overlapping by 10 cm
DEEP_M = 0.3


def busiest_clear_spot(env: gym.Env) -> np.ndarray:
    """The walkable arena point >= 1 m from everybody now that most logged pedestrian-frames of the next STEPS
    frames pass within 1 m of."""
    replay, index = env.unwrapped.replay, env.unwrapped.index
    candidates = env.unwrapped.candidates_m
    now = replay.xy_m[index][replay.present[index]]
    clear = np.linalg.norm(candidates[:, None] - now[None], axis=-1).min(axis=1) >= 1.0 if len(now) else \
        np.ones(len(candidates), bool)
    logged = replay.xy_m[index:index + STEPS][replay.present[index:index + STEPS]]
    traffic = (np.linalg.norm(candidates[clear][:, None] - logged[None], axis=-1) < 1.0).sum(axis=1)
    return candidates[clear][np.argmax(traffic)].copy()


def log_end_spot(env: gym.Env) -> np.ndarray:
    """The walkable arena point >= 1 m from everybody now nearest to the end of a log present now that ends within
    the next STEPS frames (the soonest such end); the busiest clear spot where no log ends so."""
    replay, index = env.unwrapped.replay, env.unwrapped.index
    candidates = env.unwrapped.candidates_m
    now = replay.xy_m[index][replay.present[index]]
    clear = np.linalg.norm(candidates[:, None] - now[None], axis=-1).min(axis=1) >= 1.0 if len(now) else \
        np.ones(len(candidates), bool)
    _, run_last = run_bounds(replay.present)
    last = np.where(replay.present[index], run_last[index], -1)  # (A,) the frame each present log's run ends
    ending = np.flatnonzero((last >= index) & (last < min(index + STEPS, len(replay.present) - 1)))
    if not ending.size or not clear.any():
        return busiest_clear_spot(env)
    soonest = ending[np.argmin(last[ending])]
    end = replay.xy_m[last[soonest], soonest]
    return candidates[clear][np.argmin(np.linalg.norm(candidates[clear] - end, axis=1))].copy()


PLACEMENTS = {"at its spawn": None, "busiest clear spot": busiest_clear_spot, "on a log's end": log_end_spot}
"""where the robot stands: as the env spawned it, or moved right after the reset by the function"""


def run_episode(env: gym.Env, seed: int, placement: str, depth: MapDepth) -> dict[str, float]:
    _, info = env.reset(seed=seed)
    unwrapped = env.unwrapped
    if PLACEMENTS[placement] is not None:
        unwrapped.ego_xy_m = PLACEMENTS[placement](env)
    robot = unwrapped.ego_xy_m.copy()
    apart_m = unwrapped.cfg.ego_radius_m + unwrapped.cfg.pedestrian_radius_m  # bodies touching
    replay = unwrapped.replay
    column = {agent: k for k, agent in enumerate(replay.agents.tolist())}
    _, run_last = run_bounds(replay.present)  # (F, A): the last frame of the log's run of presence holding frame f
    last_seen: dict[int, int] = {}  # agent -> the latest frame index at which its log was present
    previous: dict[int, np.ndarray] = {}
    still = defaultdict(list)  # agent -> (moved [m], log moved [m]) of the latest steps
    counts = dict.fromkeys(["frozen", "leave_far", "overlap", "in_wall", "deep", "off_image", "hit"], 0)
    overlapping: set[tuple[int, int]] = set()
    for _ in range(STEPS):
        index_before = unwrapped.index
        obs, _, terminated, truncated, info = env.step(np.zeros(2))
        index = unwrapped.index
        present = info["agent_ids"] >= 0
        ids = info["agent_ids"][present].tolist()
        xy = obs["history"][present, -1].astype(np.float64)
        here = dict(zip(ids, xy, strict=True))
        cols = np.array([column[i] for i in ids], int)
        for i, col in zip(ids, cols, strict=True):
            if replay.present[index, col]:
                last_seen[i] = index
        ends = np.array([run_last[last_seen[i], col] for i, col in zip(ids, cols, strict=True)], int)
        log = replay.xy_m[ends.clip(max=index), cols]  # the log now, or where it ended (one still on its way out)
        for agent in set(previous) - set(here):  # left the scene
            col = column[agent]
            end = replay.xy_m[run_last[last_seen[agent], col], col]
            free_m = max(apart_m - float(np.linalg.norm(end - robot)), 0.0)  # from the end out of the robot's body
            counts["leave_far"] += bool(np.linalg.norm(previous[agent] - end) > LEAVE_FAR_M + free_m)
        for k, agent in enumerate(ids):
            if agent in previous:
                col = column[agent]
                log_step = replay.xy_m[index, col] - replay.xy_m[index_before, col]
                log_moved = float(np.linalg.norm(np.nan_to_num(log_step)))
                still[agent].append((float(np.linalg.norm(xy[k] - previous[agent])), log_moved))
                latest = still[agent][-FROZEN_STEPS:]
                if len(latest) == FROZEN_STEPS and max(m for m, _ in latest) < FROZEN_STEP_M and \
                        sum(lm for _, lm in latest) > FROZEN_LOG_M:
                    counts["frozen"] = 1
        if len(xy) > 1:
            gap = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
            log_gap = np.linalg.norm(log[:, None] - log[None], axis=-1)
            for a, b in zip(*np.nonzero(np.triu((gap < OVERLAP_M) & (log_gap >= OVERLAP_M), 1)), strict=True):
                overlapping.add((ids[a], ids[b]))
        depth_now, depth_log = depth.at(xy), depth.at(log)
        counts["off_image"] += int(np.isinf(depth_now).sum())
        counts["in_wall"] += int(((depth_now > 0) & (depth_log == 0)).sum())
        counts["deep"] += int((depth_now > np.maximum(depth_log, 0.0) + DEEP_M).sum())
        previous = here
        if terminated or truncated:
            counts["hit"] = int(info["termination"] == "pedestrian_collision")
            break
    counts["overlap"] = len(overlapping)
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["univ", "zara1"])
    parser.add_argument("--episodes", type=int, default=50, help="episodes with the robot where it spawns")
    parser.add_argument("--busiest-episodes", type=int, default=30, help="episodes at the busiest clear spot")
    parser.add_argument("--log-end-episodes", type=int, default=30, help="episodes on a log's end")
    parser.add_argument("--seed", type=int, default=1000, help="episode i starts from reset(seed=seed + i)")
    parser.add_argument("--per-episode", action="store_true",
                        help="also print the seed and counts of every episode with something to count but wall steps")
    parser.add_argument("--reaction-traits", choices=REACTION_TRAITS, default="fitted",
                        help="the env's reaction_traits (default: fitted)")
    args = parser.parse_args()
    print("| scene | robot stands | episodes | frozen (episodes) | leave > 1 m from log end | overlapping pairs "
          "| steps in a wall (log walkable) | > 0.3 m deeper than log | off the image | robot hit (episodes) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for scene in args.scenes:
        env = gym.make(f"STCrowd-{scene.capitalize()}-v0", predictor="cvm", pedestrians="reactive",
                       reaction_traits=args.reaction_traits)
        depth = MapDepth(env.unwrapped.scene)
        for where, episodes in zip(PLACEMENTS, (args.episodes, args.busiest_episodes, args.log_end_episodes),
                                   strict=True):
            total: dict[str, int] = defaultdict(int)
            for i in tqdm(range(episodes), desc=f"{scene} {where}", leave=False):
                counts = run_episode(env, args.seed + i, where, depth)
                for key, value in counts.items():
                    total[key] += value
                if args.per_episode and any(value for key, value in counts.items() if key != "in_wall"):
                    tqdm.write(f"{scene}, {where}, seed {args.seed + i}: {counts}")
            print(f"| {scene} | {where} | {episodes} | {total['frozen']} | {total['leave_far']} | {total['overlap']} | "
                  f"{total['in_wall']} | {total['deep']} | {total['off_image']} | {total['hit']} |")
        env.close()


if __name__ == "__main__":
    main()
