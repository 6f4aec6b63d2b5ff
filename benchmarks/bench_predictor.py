"""SingularTrajectory speed on this machine: inference latency and (with --train) time to a trained model.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/bench_predictor.py [--train univ zara1]

Inference: 50 agents x 20 samples x 12 steps on one core (target <= 10 ms), split into input preparation
(agent frames, Singular-space projection, map-adaptive anchors) and the 10-step refiner, with the on-map step
of the output (part of the total) timed alone; the constant-velocity
baseline is timed in the same run for a ratio. Training: one stochastic model per named scene with the
default configuration, then its test ADE/FDE beside the paper's (target: within 0.005 m in <= 10 min).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

import numpy as np
import torch

from predictor.anchors import onto_walkable
from predictor.baselines import ConstantVelocity
from replays import load_scene, load_windows

N_AGENTS = 50


def timed(fn, repeats: int) -> list[float]:
    """Wall milliseconds of ``repeats`` calls (after 3 warm-up calls)."""
    for _ in range(3):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(1000 * (time.perf_counter() - start))
    return times


def inference(model, repeats: int) -> None:
    test = load_windows("stochastic", "univ", "test")
    group_sizes = np.bincount(test.group)
    g = int(np.flatnonzero(group_sizes >= N_AGENTS)[0])  # a real crowded window of UNIV
    idx = np.flatnonzero(test.group == g)[:N_AGENTS]
    obs, group, scene = test.obs[idx], test.group[idx], load_scene("univ")
    full = timed(lambda: model.predict(obs, group, scene, 20), repeats)
    prep = timed(lambda: model.prepare(obs, group, [scene], np.zeros(len(obs), np.int64)), repeats)
    cvm = timed(lambda: ConstantVelocity().predict(obs, group, scene, 20), repeats)
    futures = model.predict(obs, group, scene, 20).astype(np.float64)
    on_map = timed(lambda: onto_walkable(futures, scene, model.cfg.on_map_tolerance_m), repeats)
    med = statistics.median
    print(f"inference, {N_AGENTS} agents x 20 samples x 12 steps, 1 thread, {repeats} repeats (median ms):")
    print(f"  SingularTrajectory total   {med(full):7.2f} ms  (p90 {np.percentile(full, 90):.2f})")
    print(f"    input prep + anchors     {med(prep):7.2f} ms")
    print(f"    refiner ({model.cfg.steps} DDIM steps) {med(full) - med(prep):7.2f} ms")
    print(f"    on-map step (in total)   {med(on_map):7.2f} ms")
    print(f"  constant velocity          {med(cvm):7.2f} ms   ratio {med(full) / med(cvm):.0f}x")


def training(scene: str) -> None:
    from predictor.checkpoint import load
    from predictor.train import TrainConfig, main
    from st_sim.scoring import evaluate_offline

    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        best = main(TrainConfig(task="stochastic", scene=scene, out=out, progress=False))
        wall = time.perf_counter() - start
        r = evaluate_offline(load(best), "stochastic", scene)
    within = abs(r.ade - r.paper_ade) <= 0.005 and abs(r.fde - r.paper_fde) <= 0.005
    print(f"training stochastic/{scene} (default config, 1 thread): {wall:.0f} s wall including data preparation")
    print(f"  test ADE {r.ade:.4f}  FDE {r.fde:.4f}   paper {r.paper_ade} / {r.paper_fde}   "
          f"delta {r.ade - r.paper_ade:+.4f} / {r.fde - r.paper_fde:+.4f}   "
          f"{'within' if within else 'NOT within'} 0.005 m of the paper, {'in' if wall <= 600 else 'over'} 10 min")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", default=None, help="checkpoint to time (default: shipped stochastic/zara1)")
    parser.add_argument("--repeats", type=int, default=50, help="timed calls (default: 50)")
    parser.add_argument("--train", nargs="*", default=[], metavar="SCENE",
                        help="also train one stochastic model per scene and score it (default: none)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    import predictor

    model = predictor.load(args.checkpoint) if args.checkpoint else predictor.load_pretrained("stochastic/zara1")
    inference(model, args.repeats)
    for scene in args.train:
        training(scene)


if __name__ == "__main__":
    main()
