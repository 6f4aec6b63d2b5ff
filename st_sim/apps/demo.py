"""Demo: the benchmark's best planner crosses a simulated crowd (STCrowd-SimCrossing-v1) with SingularTrajectory.

The ego runs the prediction-aware sampling MPC (``st_sim.apps.navigation.mpc``): every 0.4 s it rolls out
candidate velocity commands for 3.2 s and scores them against every sample the shipped universal
SingularTrajectory model predicts for every pedestrian. Whole episodes run until the step budget is used;
each prints how it ended (goal, pedestrian collision, wall collision, timeout) and its metrics, and the run
ends with the success and collision figures. Runs headless; with a Rerun path every step is recorded.

    python -m st_sim demo --steps 150 --rerun demo.rrd
"""

from __future__ import annotations

import time

from st_sim.apps.navigation.episodes import NavRun, make_nav_env, run_episode
from st_sim.apps.navigation.metrics import episode_metrics
from st_sim.apps.navigation.planners import make_planner
from st_sim.apps.navigation.world import world_of
from st_sim.metrics import format_metric

ENV_ID = "STCrowd-SimCrossing-v1"
PLANNER, PREDICTOR = "mpc", "singular"  # the benchmark's best pair (RESULTS.md, "Navigation benchmark")
OUTCOMES = ("goal", "pedestrian collision", "wall collision", "timeout")


def run_demo(steps: int = 150, rerun_path: str | None = None, seed: int = 0) -> dict:
    """Run whole episodes (seeds seed, seed + 1, ...) until ``steps`` env steps are used; print each and a summary.

    Returns:
        {"env_id", "planner", "predictor", "steps" (env steps run), "seed", "episodes": [per-episode dict:
        seed, outcome, steps and the navigation metrics, plus the env's prediction metrics], "counts":
        {outcome: episodes}, "steps_per_s"}.
    """
    env = make_nav_env(NavRun(env_id=ENV_ID, policy=PLANNER, predictor=PREDICTOR), rerun_path)
    world = world_of(env)
    planner = make_planner(PLANNER, world, PREDICTOR)
    episodes: list[dict] = []
    used = 0
    start = time.perf_counter()
    while used < steps:
        trace, _ = run_episode(env, planner, world, seed + len(episodes))
        metrics = {"seed": seed + len(episodes), **episode_metrics(trace), **dict(env.unwrapped.metrics.summary())}
        episodes.append(metrics)
        used += metrics["steps"]
        print(f"episode {len(episodes) - 1} (seed {metrics['seed']}): {metrics['steps']} steps, {metrics['outcome']}, "
              f"closest pedestrian {metrics['min_step_end_gap_m']:.2f} m from the robot's body, "
              f"ADE/FDE {format_metric(metrics['ade_m'], '.2f')}/{format_metric(metrics['fde_m'], '.2f')} m over "
              f"{metrics['matured']} predictions")
    elapsed_s = time.perf_counter() - start
    env.close()
    counts = {outcome: sum(e["outcome"] == outcome for e in episodes) for outcome in OUTCOMES}
    n = len(episodes)
    print(f"{PLANNER} + {PREDICTOR} on {ENV_ID}: {n} episodes, goal {counts['goal']}/{n} "
          f"({100 * counts['goal'] / n:.0f} %), pedestrian collisions {counts['pedestrian collision']}, "
          f"wall collisions {counts['wall collision']}, timeouts {counts['timeout']}")
    for path in env.unwrapped.rerun_paths:  # an existing recording is never overwritten: the new one is numbered
        print(f"wrote {path}")
    return {"env_id": ENV_ID, "planner": PLANNER, "predictor": PREDICTOR, "steps": used, "seed": seed,
            "episodes": episodes, "counts": counts, "steps_per_s": used / elapsed_s if elapsed_s > 0 else float("inf")}
