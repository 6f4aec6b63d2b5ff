"""Design choices measured: the denoiser's width, and the refiner's zero start and minimum optimiser steps.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/design_choices.py --runs runs/design --workers 1 [--executor ray --ray-address HOST:PORT]

1. Denoiser width 128 (default) against 256: stochastic ZARA1, three seeds (test ADE/FDE per seed, then mean and
   standard deviation), and the inference time of 50 agents x 20 samples, the two widths timed alternately in the
   same run (median ms, one thread).
2. The refiner's output layer starting at zero (default) against a random start, and at least 300 optimiser steps
   (default) against no minimum (the task's epochs alone: 16 for few-shot, 6 for domain): few-shot on all five
   scenes and the domain pairs from ETH (101 training samples), seed 0.
All models train as one grid, then are scored as another (``st_sim.apps.grid``; see ``ablations.py`` for the
folders). Finished runs and scores are reused, so the script resumes; the timing runs after the grids, alone.
About an hour on one core (33 models of 1-4 minutes, the scoring, the timing).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import torch
from ablations import Model, add_arguments, grid_options, train_and_score

from predictor.checkpoint import load
from replays import load_scene, load_windows

WIDTHS = (128, 256)
WIDTH_SCENES = ("zara1",)
SEEDS = (0, 1, 2)
SCENES = ("eth", "hotel", "univ", "zara1", "zara2")
START_VARIANTS = {"default": {}, "random start": {"zero_start": False}, "no step minimum": {"min_steps": 0}}
START_CASES = ([("fewshot", scene, 0) for scene in SCENES]
               + [("domain", pair, 0) for pair in ("A2B", "A2C", "A2D", "A2E")])
WIDTH_MODELS = [Model("stochastic", scene, {"denoiser_dim": width}, seed)
                for scene in WIDTH_SCENES for width in WIDTHS for seed in SEEDS]
START_MODELS = [Model(task, scene, overrides, seed) for task, scene, seed in START_CASES
                for overrides in START_VARIANTS.values()]


def chunks(rows: list[dict], size: int) -> list[list[dict]]:
    """``rows`` cut into consecutive lists of ``size``."""
    return [rows[i:i + size] for i in range(0, len(rows), size)]


def width_table(rows: list[dict]) -> None:
    print("| scene | denoiser width | ADE / FDE per seed (0, 1, 2) | mean ADE / FDE | sd ADE / FDE |")
    print("|---|---|---|---|---|")
    cells = iter(chunks(rows, len(SEEDS)))
    for scene in WIDTH_SCENES:
        for width in WIDTHS:
            seeds = next(cells)
            ade, fde = np.array([r["ade"] for r in seeds]), np.array([r["fde"] for r in seeds])
            per_seed = ", ".join(f"{a:.3f} / {f:.3f}" for a, f in zip(ade, fde, strict=True))
            print(f"| {scene} | {width} | {per_seed} | {ade.mean():.3f} / {fde.mean():.3f} | "
                  f"{ade.std(ddof=1):.3f} / {fde.std(ddof=1):.3f} |")


def width_timing(runs: Path, repeats: int, root: str | None) -> None:
    folders = {width: Model("stochastic", "zara1", {"denoiser_dim": width}).config(runs, root).out for width in WIDTHS}
    models = {width: load(Path(folder) / "best.pt") for width, folder in folders.items()}
    test = load_windows("stochastic", "univ", "test", root)
    crowded = int(np.flatnonzero(np.bincount(test.group) >= 50)[0])
    idx = np.flatnonzero(test.group == crowded)[:50]
    obs, group, scene = test.obs[idx], test.group[idx], load_scene("univ", root)
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


def start_table(rows: list[dict]) -> None:
    print("\n| task | scene | seed | " + " | ".join(START_VARIANTS) + " |")
    print("|---|---|---|" + "---|" * len(START_VARIANTS))
    for (task, scene, seed), variants in zip(START_CASES, chunks(rows, len(START_VARIANTS)), strict=True):
        cells = [f"{r['ade']:.3f} / {r['fde']:.3f}" for r in variants]
        print(f"| {task} | {scene} | {seed} | {' | '.join(cells)} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser, "runs/design")
    parser.add_argument("--repeats", type=int, default=300, help="timed calls per width (default: 300)")
    args = parser.parse_args()
    runs = Path(args.runs)
    rows = train_and_score(WIDTH_MODELS + START_MODELS, runs, grid_options(args), args.data_root)
    torch.set_num_threads(1)
    width_table(rows[:len(WIDTH_MODELS)])
    width_timing(runs, args.repeats, args.data_root)
    start_table(rows[len(WIDTH_MODELS):])


if __name__ == "__main__":
    main()
