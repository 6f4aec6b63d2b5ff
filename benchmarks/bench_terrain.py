"""Cost-to-go fields per second: the terrain's grid graph built once per body radius and kept, against built afresh
for every goal (as before it was kept), in the same run.

    OMP_NUM_THREADS=1 python benchmarks/bench_terrain.py --goals 40 --repeats 3

Each scene's env is reset once; its terrain's goal fields (``Terrain.cost_to_go``'s, ``GridGraph.geodesic``) are made
for ``--goals`` walkable goals drawn with the seed, with the robot's wall clearance, first rebuilding the graph for
each goal, then from the graph the terrain keeps (``Terrain.grid_graph``). The fields of the two are checked equal,
bit for bit. Every env step of a learned planner's features and every MPC decision asks for the field of its
episode's goal, made once per new goal (``Terrain`` keeps the last 16).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from envs.common.terrain import GridGraph, Terrain
from st_sim.apps.navigation.world import world_of

SCENES = {"sim-crossing": ("STCrowd-SimCrossing-v1", {}), "sim-bottleneck": ("STCrowd-SimBottleneck-v1", {}),
          "univ": ("STCrowd-Univ-v0", {"pedestrians": "log"}), "eth": ("STCrowd-Eth-v0", {"pedestrians": "log"})}


def fields_per_s(terrain: Terrain, goals: np.ndarray, body_m: float, kept: bool) -> tuple[float, np.ndarray]:
    """(fields per second, the fields (G, Gy, Gx) [m]) for ``goals`` (G, 2) [m]: from the graph the terrain keeps
    (built before timing), or from a graph built afresh for each goal."""
    graph = terrain.grid_graph(body_m)
    fields = []
    start = time.perf_counter()
    for goal in goals:
        used = graph if kept else GridGraph.of(graph.eligible, graph.cell_m)
        fields.append(used.geodesic(terrain.cell_centres_m, goal))
    return len(goals) / (time.perf_counter() - start), np.stack(fields)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goals", type=int, default=40, help="goals per scene and run (default: 40)")
    parser.add_argument("--repeats", type=int, default=3, help="alternating repeats (default: 3)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the goals (default: 0)")
    args = parser.parse_args()
    print("| scene | grid | repeat | graph per goal, fields/s | graph kept, fields/s | ratio |")
    print("|---|---|---|---|---|---|")
    for name, (env_id, kwargs) in SCENES.items():
        env = gym.make(env_id, predictor="none", **kwargs)
        env.reset(seed=args.seed)
        world = world_of(env)
        terrain, body_m = world.terrain, world.wall_clearance_m
        free = np.argwhere(terrain.clearance_m >= body_m)
        rng = np.random.default_rng(args.seed)
        goals = terrain.cell_centres_m[tuple(free[rng.integers(len(free), size=args.goals)].T)]
        for repeat in range(args.repeats):
            afresh, fresh_fields = fields_per_s(terrain, goals, body_m, kept=False)
            kept, kept_fields = fields_per_s(terrain, goals, body_m, kept=True)
            assert np.array_equal(fresh_fields, kept_fields), "the kept graph must give the same fields"
            print(f"| {name} | {terrain.free.shape[1]} x {terrain.free.shape[0]} | {repeat + 1} | {afresh:.1f} | "
                  f"{kept:.1f} | {kept / afresh:.2f} |", flush=True)
        env.close()


if __name__ == "__main__":
    main()
