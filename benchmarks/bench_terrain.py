"""Cost-to-go fields per second: scipy's Dijkstra on the terrain's grid graph built afresh for every goal (as before
the graph was kept), on the graph built once per body radius and kept (as before the search was compiled), and the
compiled search on the kept graph (``GridGraph.geodesic``), in the same run; and robot frames along the path per
second: the compiled directions against the numpy code they replaced, in the same run.

    OMP_NUM_THREADS=1 python benchmarks/bench_terrain.py --goals 40 --repeats 3 --robots 1 4 56 --calls 200

Each scene's env is reset once; its terrain's goal fields (``Terrain.cost_to_go``'s) are made for ``--goals``
walkable goals drawn with the seed, with the robot's wall clearance, in the three ways one after the other (scipy's:
``reference_geodesic`` of ``tests/test_terrain_compiled.py``, the code before). The fields of the three are checked
equal, bit for bit. Every env step of a learned planner's features and every MPC decision asks for the field of its
episode's goal, made once per new goal (``Terrain`` keeps the last 16).

Then ``envs.view.frames_along_path`` (every env step of a learned planner's features and of ``FixedView``) for B
robots of ``--robots``: ``--calls`` batches of B float32 ego rows, each robot at a walkable place (a cell with the
wall clearance, jittered within it) heading to one of the first 8 goals (their fields made before timing, as an
episode's goal field is kept), through ``Terrain.directions_to`` (compiled), then through the numpy code of
``tests/test_terrain_compiled.py`` (``reference_directions_to``, the code before); the frames of the two are checked
equal, bit for bit. A training run calls it once per sub-env and step (B = 1).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from envs.common.terrain import GridGraph, Terrain
from envs.view import frames_along_path
from st_sim.apps.navigation.world import world_of

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_terrain_compiled import reference_directions_to, reference_geodesic

SCENES = {"sim-crossing": ("STCrowd-SimCrossing-v1", {}), "sim-bottleneck": ("STCrowd-SimBottleneck-v1", {}),
          "univ": ("STCrowd-Univ-v0", {"pedestrians": "log"}), "eth": ("STCrowd-Eth-v0", {"pedestrians": "log"})}


FIELD_WAYS = ("rebuilt, scipy", "kept, scipy", "kept, compiled")
"""how the fields are made: scipy's Dijkstra on a graph built afresh for each goal or on the graph the terrain keeps
(built before timing), or the compiled search on the kept graph"""


def fields_per_s(terrain: Terrain, goals: np.ndarray, body_m: float, way: str) -> tuple[float, np.ndarray]:
    """(fields per second, the fields (G, Gy, Gx) [m]) for ``goals`` (G, 2) [m], made the ``way`` of FIELD_WAYS."""
    graph = terrain.grid_graph(body_m)
    fields = []
    start = time.perf_counter()
    for goal in goals:
        if way == "kept, compiled":
            fields.append(graph.geodesic(terrain.cell_centres_m, goal))
        else:
            used = graph if way == "kept, scipy" else GridGraph.of(graph.eligible, graph.cell_m)
            fields.append(reference_geodesic(used, terrain.cell_centres_m, goal))
    return len(goals) / (time.perf_counter() - start), np.stack(fields)


class NumpyDirections:
    """A terrain whose ``directions_to`` is the numpy code before the kernels (``frames_along_path`` needs no more)."""

    def __init__(self, terrain: Terrain):
        self.terrain = terrain

    def directions_to(self, xy_m: np.ndarray, goal_m: np.ndarray, body_m: float) -> np.ndarray:
        return reference_directions_to(self.terrain, xy_m, goal_m, body_m)


def ego_batches(terrain: Terrain, goals: np.ndarray, body_m: float, robots: int, calls: int,
                rng: np.random.Generator) -> list[np.ndarray]:
    """``calls`` float32 ego rows (robots, 6) as observations have them: robots at walkable places [m] (cells with
    ``body_m`` of clearance, jittered within the cell), standing, each heading to one of ``goals`` (G, 2) [m]."""
    free = np.argwhere(terrain.clearance_m >= body_m)
    batches = []
    for _ in range(calls):
        ego = np.zeros((robots, 6), np.float32)
        ego[:, :2] = terrain.cell_centres_m[tuple(free[rng.integers(len(free), size=robots)].T)] + rng.uniform(
            -terrain.cell_m / 2, terrain.cell_m / 2, (robots, 2))
        ego[:, 4:6] = goals[rng.integers(len(goals), size=robots)]
        batches.append(ego)
    return batches


def frames_per_s(batches: list[np.ndarray], terrain: Terrain | NumpyDirections, body_m: float
                 ) -> tuple[float, np.ndarray]:
    """(``frames_along_path`` calls per second, the frames (calls, B, 2, 2)) over ``batches`` of ego rows."""
    start = time.perf_counter()
    frames = [frames_along_path(ego, terrain, body_m) for ego in batches]
    return len(batches) / (time.perf_counter() - start), np.stack(frames)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--goals", type=int, default=40, help="goals per scene and run (default: 40)")
    parser.add_argument("--repeats", type=int, default=3, help="alternating repeats (default: 3)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the goals and robots (default: 0)")
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 4, 56],
                        help="robots B per frames_along_path call (default: 1 4 56)")
    parser.add_argument("--calls", type=int, default=200, help="frames_along_path calls per run (default: 200)")
    args = parser.parse_args()
    fields_table(args)
    frames_table(args)


def scene_terrains(seed: int, goals: int) -> Iterator[tuple[str, Terrain, float, np.ndarray]]:
    """Yield (scene name, its terrain, the robot's wall clearance [m], ``goals`` walkable goals (goals, 2) [m] drawn
    with ``seed``) for each of SCENES, its env reset with the seed."""
    for name, (env_id, kwargs) in SCENES.items():
        env = gym.make(env_id, predictor="none", **kwargs)
        env.reset(seed=seed)
        world = world_of(env)
        terrain, body_m = world.terrain, world.wall_clearance_m
        free = np.argwhere(terrain.clearance_m >= body_m)
        rng = np.random.default_rng(seed)
        yield name, terrain, body_m, terrain.cell_centres_m[tuple(free[rng.integers(len(free), size=goals)].T)]
        env.close()


def fields_table(args: argparse.Namespace) -> None:
    """Print the table of goal fields per second, made each of FIELD_WAYS."""
    print(f"| scene | grid | repeat | {' | '.join(f'{way}, fields/s' for way in FIELD_WAYS)} | kept / rebuilt | "
          "compiled / scipy |")
    print("|---|---|---|---|---|---|---|---|")
    for name, terrain, body_m, goals in scene_terrains(args.seed, args.goals):
        fields_per_s(terrain, goals[:1], body_m, "kept, compiled")  # the kernel loaded from numba's cache
        for repeat in range(args.repeats):
            rates, fields = zip(*(fields_per_s(terrain, goals, body_m, way) for way in FIELD_WAYS), strict=True)
            assert all(np.array_equal(fields[0], other) for other in fields[1:]), "the fields must be the same"
            print(f"| {name} | {terrain.free.shape[1]} x {terrain.free.shape[0]} | {repeat + 1} | "
                  f"{' | '.join(f'{rate:.1f}' for rate in rates)} | {rates[1] / rates[0]:.2f} | "
                  f"{rates[2] / rates[1]:.2f} |", flush=True)


def frames_table(args: argparse.Namespace) -> None:
    """Print the table of ``frames_along_path`` calls per second, numpy directions against compiled."""
    print("\n| scene | robots B | repeat | numpy, calls/s | compiled, calls/s | ratio |")
    print("|---|---|---|---|---|---|")
    for name, terrain, body_m, goals in scene_terrains(args.seed, 8):
        goals = goals.astype(np.float32)
        for goal in goals:  # the episodes' fields, made before timing
            terrain.cost_to_go(goal, goal, body_m)
        rng = np.random.default_rng(args.seed)
        for robots in args.robots:
            batches = ego_batches(terrain, goals, body_m, robots, args.calls, rng)
            frames_per_s(batches[:2], terrain, body_m)  # the kernels loaded from numba's cache
            for repeat in range(args.repeats):
                plain, plain_frames = frames_per_s(batches, NumpyDirections(terrain), body_m)
                compiled, compiled_frames = frames_per_s(batches, terrain, body_m)
                assert np.array_equal(plain_frames, compiled_frames), "the kernels must give the same frames"
                print(f"| {name} | {robots} | {repeat + 1} | {plain:.0f} | {compiled:.0f} | {compiled / plain:.1f} |",
                      flush=True)


if __name__ == "__main__":
    main()
