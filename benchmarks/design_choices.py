"""Design choices measured: denoiser width, slow-agent threshold for S = 1, the refiner's zero start, min steps.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/design_choices.py --runs runs/design

1. Denoiser width 128 (default) against 256: stochastic ETH, UNIV and ZARA1, three seeds each (test ADE/FDE
   per seed, then mean and standard deviation), and inference time of 50 agents x 20 samples, the two widths
   timed alternately in the same run (median ms, one thread).
2. Slow-population threshold for deterministic models (S = 1): 0.1 m/step (default) against 0.3 m/step
   (the stochastic default), on all five scenes, seed 0: test ADE / FDE and the validation FDE that
   selected the checkpoint.
3. The refiner's output layer starting at zero (default) against a random start, and at least 300
   optimiser steps (default) against plain 6 epochs: stochastic UNIV (18 batches per epoch; seeds 0-2),
   few-shot on all five scenes and the domain pairs from ETH (101 training samples), seed 0.
Checkpoints are reused when present, so the script resumes.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import torch
from ablations import run_variant

from predictor.checkpoint import load
from replays import load_scene, load_windows

WIDTHS = (128, 256)
WIDTH_SCENES = ("eth", "univ", "zara1")
SEEDS = (0, 1, 2)
THRESHOLDS_M = (0.1, 0.3)
SCENES = ("eth", "hotel", "univ", "zara1", "zara2")
START_VARIANTS = {"default": {}, "random start": {"zero_start": False}, "6 epochs only": {"min_steps": 0}}
START_CASES = ([("stochastic", "univ", seed) for seed in SEEDS] + [("fewshot", scene, 0) for scene in SCENES]
               + [("domain", pair, 0) for pair in ("A2B", "A2C", "A2D", "A2E")])


def width_table(runs: Path) -> None:
    print("| scene | denoiser width | ADE / FDE per seed (0, 1, 2) | mean ADE / FDE | sd ADE / FDE |")
    print("|---|---|---|---|---|")
    for scene in WIDTH_SCENES:
        for width in WIDTHS:
            rows = [run_variant(runs, f"width{width} {scene} seed{seed}", scene,
                                {"denoiser_dim": width, "seed": seed}) for seed in SEEDS]
            ade, fde = np.array([r["ade"] for r in rows]), np.array([r["fde"] for r in rows])
            seeds = ", ".join(f"{a:.3f} / {f:.3f}" for a, f in zip(ade, fde, strict=True))
            print(f"| {scene} | {width} | {seeds} | {ade.mean():.3f} / {fde.mean():.3f} | "
                  f"{ade.std(ddof=1):.3f} / {fde.std(ddof=1):.3f} |")


def width_timing(runs: Path, repeats: int) -> None:
    models = {width: load(runs / f"width{width}_zara1_seed0" / "best.pt") for width in WIDTHS}
    test = load_windows("stochastic", "univ", "test")
    crowded = int(np.flatnonzero(np.bincount(test.group) >= 50)[0])
    idx = np.flatnonzero(test.group == crowded)[:50]
    obs, group, scene = test.obs[idx], test.group[idx], load_scene("univ")
    times = {width: [] for width in WIDTHS}
    for _ in range(repeats):
        for width, model in models.items():  # alternate, so both widths see the same machine load
            start = time.perf_counter()
            model.predict(obs, group, scene, 20)
            times[width].append(1000 * (time.perf_counter() - start))
    print(f"\ninference, 50 agents x 20 samples, 1 thread, {repeats} alternating calls per width (median ms):")
    for width, ms in times.items():
        print(f"  width {width}: {statistics.median(ms[10:]):.2f} ms")
    print(f"  ratio 128 / 256: {statistics.median(times[128][10:]) / statistics.median(times[256][10:]):.2f}")


def threshold_table(runs: Path) -> None:
    print("\n| scene | deterministic, slow threshold 0.1 m/step (default): test ADE / FDE (val FDE) | 0.3 m/step |")
    print("|---|---|---|")
    for scene in SCENES:
        cells = []
        for threshold in THRESHOLDS_M:
            r = run_variant(runs, f"deterministic slow{threshold} {scene}", scene, {"slow_speed_m": threshold},
                            task="deterministic")
            cells.append(f"{r['ade']:.3f} / {r['fde']:.3f} ({r['val_fde']:.3f})")
        print(f"| {scene} | {' | '.join(cells)} |")


def start_table(runs: Path) -> None:
    print("\n| task | scene | seed | " + " | ".join(START_VARIANTS) + " |")
    print("|---|---|---|" + "---|" * len(START_VARIANTS))
    for task, scene, seed in START_CASES:
        cells = []
        for variant, overrides in START_VARIANTS.items():
            # the default stochastic UNIV runs are the width-128 runs above
            name = (f"width128 {scene} seed{seed}" if (task, variant) == ("stochastic", "default")
                    else f"{task} {variant} {scene} seed{seed}")
            r = run_variant(runs, name, scene, {"seed": seed, **overrides}, task=task)
            cells.append(f"{r['ade']:.3f} / {r['fde']:.3f}")
        print(f"| {task} | {scene} | {seed} | {' | '.join(cells)} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="runs/design", help="checkpoint folder (default: runs/design)")
    parser.add_argument("--repeats", type=int, default=300, help="timed calls per width (default: 300)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    runs = Path(args.runs)
    width_table(runs)
    width_timing(runs, args.repeats)
    threshold_table(runs)
    start_table(runs)


if __name__ == "__main__":
    main()
