"""Decisions per second of the navigation planners with about 50 pedestrians in view (UNIV replay, one thread).

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/nav_speed.py

Collects observations of the UNIV replay (students001) whose frame holds at least --min-peds pedestrians,
then times, per decision, the planner's ``act`` alone and the whole decision: SingularTrajectory predicting
S = 20 futures for every pedestrian with 8 observed steps, plus ``act``. Times are CPU seconds of this
process (``time.process_time``, one thread), so other jobs on the machine do not inflate them; the wall-clock
median is printed beside. Prints medians and decisions per second over --repeats passes.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

from envs.common.predictors import predict_futures
from st_sim.apps.navigation.episodes import NavRun, make_nav_env
from st_sim.apps.navigation.planners import make_planner
from st_sim.apps.navigation.world import world_of


def crowded_observations(env, count: int, min_peds: int) -> list[dict]:
    """``count`` observations (seeded resets) whose frame holds at least ``min_peds`` pedestrians."""
    found = []
    for seed in range(10_000):
        obs, _ = env.reset(seed=seed)
        if int(obs["history_mask"][:, -1].sum()) >= min_peds:
            found.append(obs)
            if len(found) == count:
                return found
    raise RuntimeError(f"only {len(found)} frames with {min_peds}+ pedestrians found")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--planners", nargs="+", default=["mpc", "orca", "straight"], help="planners to time")
    parser.add_argument("--observations", type=int, default=20, help="crowded observations (default: 20)")
    parser.add_argument("--min-peds", type=int, default=50, help="least pedestrians in view (default: 50)")
    parser.add_argument("--repeats", type=int, default=3, help="passes over the observations (default: 3)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}, torch threads {torch.get_num_threads()}, "
          f"load average {os.getloadavg()[0]:.1f}")

    env = make_nav_env(NavRun(env_id="STCrowd-Univ-v0", predictor="singular"))
    crowd_env, world = env.unwrapped, world_of(env)
    observations = crowded_observations(env, args.observations, args.min_peds)
    people = [int(o["history_mask"][:, -1].sum()) for o in observations]
    predicted = [int(o["futures_mask"].sum()) for o in observations]
    print(f"{len(observations)} UNIV frames: {min(people)}-{max(people)} pedestrians in view, "
          f"{min(predicted)}-{max(predicted)} with predictions")
    for name in args.planners:
        try:
            planner = make_planner(name, world, "singular")
        except ImportError as err:
            print(f"{name}: skipped ({err})")
            continue
        act_ms, total_ms, wall_ms = [], [], []
        for _ in range(args.repeats):
            for obs in observations:
                planner.reset()
                rows = obs["futures_mask"]
                wall_start, start = time.perf_counter(), time.process_time()
                predict_futures(crowd_env.predictor, obs["history"][rows], crowd_env.scene, crowd_env.num_samples)
                middle = time.process_time()
                planner.act(obs)
                end = time.process_time()
                act_ms.append(1000 * (end - middle))
                total_ms.append(1000 * (end - start))
                wall_ms.append(1000 * (time.perf_counter() - wall_start))
        act, total = float(np.median(act_ms)), float(np.median(total_ms))
        print(f"{name:>8}: act {act:6.1f} ms CPU ({1000 / act:6.1f} decisions/s); with SingularTrajectory's "
              f"prediction {total:6.1f} ms CPU ({1000 / total:6.1f} decisions/s; wall {np.median(wall_ms):.1f} ms)")


if __name__ == "__main__":
    main()
