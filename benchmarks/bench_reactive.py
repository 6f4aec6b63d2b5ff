"""Reactive replays' speed: UNIV replayed from its log against reactive (one env each), and the native vector env of
reactive replays against one reactive env, all in one run.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/bench_reactive.py
    python benchmarks/bench_reactive.py --episodes 20 --rounds 3 --num-envs 16 --vector-steps 40

Every env is ``STCrowd-Univ-v0`` (``--env``) driven by the straight planner (full speed to the goal, avoiding nobody)
with no predictor in the observation (``predictor="none"``: the forecast costs nothing), so that the time is the
env's. Both parts alternate their two sides within each round, so that a busy machine slows both alike, and report
the ratios of each round and their median:

- log against reactive: episodes ``seed`` ... ``seed + episodes - 1`` with ``pedestrians="log"``, then the same
  episodes with ``"reactive"``; env steps per second (resets included).
- vector env against one env: ``vector-steps`` steps of ``gym.make_vec(env, num_envs=N, pedestrians="reactive")``
  (its crowds stepped in one batched call per step, sub-env i reset with seed + i), then as many env steps of one
  reactive env (episodes from the same seeds); env steps per second, a vector step counting N.

``--digest FILE`` times nothing: it writes, for the same episodes of UNIV and ZARA1 with reactive pedestrians, one
SHA-256 line per episode over the reactive crowd's whole state after every step (positions, route points, offsets,
who is off its log, stuck, detouring ...) and the rewards, to compare two commits bit for bit (``diff``):

    git worktree add ../base 7af71e1
    (cd ../base && PYTHONPATH=. python "$OLDPWD/benchmarks/bench_reactive.py" --episodes 60 \
        --digest "$OLDPWD/runs/digest-base.txt")
    python benchmarks/bench_reactive.py --episodes 60 --digest runs/digest-head.txt
    diff runs/digest-base.txt runs/digest-head.txt
"""

from __future__ import annotations

import argparse
import hashlib
import time
from dataclasses import fields
from pathlib import Path

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
from st_sim.apps.navigation.straight import StraightPlanner
from st_sim.apps.navigation.world import world_of


def single_rate(env_id: str, pedestrians: str, seeds: list[int], max_steps: int | None = None) -> float:
    """Env steps per second of one env over the episodes of ``seeds`` (resets included; stops after ``max_steps``
    steps if given, starting the next episode while there are steps left)."""
    env = gym.make(env_id, predictor="none", pedestrians=pedestrians)
    planner = StraightPlanner(world_of(env))
    steps, k = 0, 0
    start = time.perf_counter()
    while (max_steps is None and k < len(seeds)) or (max_steps is not None and steps < max_steps):
        obs, _ = env.reset(seed=seeds[k % len(seeds)])
        k += 1
        done = False
        while not done and (max_steps is None or steps < max_steps):
            obs, _, terminated, truncated, _ = env.step(planner.act(obs))
            done, steps = terminated or truncated, steps + 1
    elapsed_s = time.perf_counter() - start
    env.close()
    return steps / elapsed_s


def vector_rate(env_id: str, num_envs: int, seed: int, vector_steps: int) -> float:
    """Env steps per second of the native vector env of ``num_envs`` reactive replays (a vector step counts
    ``num_envs``; autoresets included)."""
    vec = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                       predictor="none", pedestrians="reactive")
    planner = StraightPlanner(world_of(vec.envs[0]))
    start = time.perf_counter()
    obs, _ = vec.reset(seed=seed)
    for _ in range(vector_steps):
        actions = np.stack([planner.act({"ego": ego}) for ego in obs["ego"]])
        obs, *_ = vec.step(actions)
    elapsed_s = time.perf_counter() - start
    vec.close()
    return num_envs * vector_steps / elapsed_s


def digest_lines(env_id: str, seeds: list[int]) -> list[str]:
    """One line per episode of ``env_id`` with reactive pedestrians and the straight planner: the seed, the steps and
    a SHA-256 over the crowd's state after every step and every reward."""
    env = gym.make(env_id, predictor="none", pedestrians="reactive")
    planner = StraightPlanner(world_of(env))
    lines = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        digest, steps, done = hashlib.sha256(), 0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(planner.act(obs))
            state = env.unwrapped.reactive.state
            for field in fields(state):  # but the traits, constant over the episode (and new on 2026-11-28)
                if field.name != "traits":
                    digest.update(np.ascontiguousarray(getattr(state, field.name)).tobytes())
            digest.update(np.float64(reward).tobytes())
            done, steps = terminated or truncated, steps + 1
        lines.append(f"{env_id} seed {seed} steps {steps} {digest.hexdigest()}")
    env.close()
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="STCrowd-Univ-v0", help="replay id (default: STCrowd-Univ-v0)")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per side of log/reactive (default: 20)")
    parser.add_argument("--seed", type=int, default=0, help="episode i resets with seed + i (default: 0)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of each comparison (default: 2)")
    parser.add_argument("--num-envs", type=int, default=16, help="sub-envs of the vector env (default: 16)")
    parser.add_argument("--vector-steps", type=int, default=40, help="vector env steps per round (default: 40)")
    parser.add_argument("--digest", type=Path, help="write the episodes' digests of UNIV and ZARA1 here, time nothing")
    args = parser.parse_args(argv)
    seeds = list(range(args.seed, args.seed + args.episodes))
    if args.digest is not None:
        lines = digest_lines("STCrowd-Univ-v0", seeds) + digest_lines("STCrowd-Zara1-v0", seeds)
        args.digest.parent.mkdir(parents=True, exist_ok=True)
        args.digest.write_text("\n".join(lines) + "\n")
        print(f"wrote {len(lines)} episode digests to {args.digest}")
        return 0
    single_rate(args.env, "reactive", seeds[:1])  # load the data and the compiled kernels once, untimed

    print(f"{args.env}, straight planner, no predictor; env steps per second")
    ratios = []
    for r in range(args.rounds):
        log, reactive = single_rate(args.env, "log", seeds), single_rate(args.env, "reactive", seeds)
        ratios.append(reactive / log)
        print(f"round {r + 1}: log {log:7.1f}  reactive {reactive:7.1f}  reactive / log {reactive / log:.3f}")
    print(f"reactive / log, median of {args.rounds}: {np.median(ratios):.3f}")

    speedups = []
    for r in range(args.rounds):
        vector = vector_rate(args.env, args.num_envs, args.seed, args.vector_steps)
        one = single_rate(args.env, "reactive", seeds, max_steps=args.num_envs * args.vector_steps)
        speedups.append(vector / one)
        print(f"round {r + 1}: vector env of {args.num_envs} {vector:7.1f}  one env {one:7.1f}  "
              f"vector / one {vector / one:.2f}")
    print(f"reactive vector env of {args.num_envs} / one env, median of {args.rounds}: {np.median(speedups):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
