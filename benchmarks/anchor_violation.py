"""Map-violation rate of fixed (prototype) vs map-adaptive anchors, and of the refined futures, per scene.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/anchor_violation.py

Uses the shipped leave-one-out stochastic checkpoints on each scene's test windows (S = 20). Also times the
vectorised adaptation of all test agents x 20 prototypes.
"""

from __future__ import annotations

import time

import numpy as np
import torch

import predictor
from predictor.anchors import adapt_paths
from replays import load_scene, load_windows
from replays.scenes import SCENE_NAMES
from st_sim.metrics import ade_fde, map_violation, path_map_violation


def main() -> None:
    torch.set_num_threads(1)
    print("| scene | agents | fixed anchors: points (paths) | adaptive anchors: points (paths) | futures | GT | "
          "anchor ADE/FDE fixed -> adaptive | adaptation time |")
    print("|---|---|---|---|---|---|---|---|")
    for name in SCENE_NAMES:
        scene, test = load_scene(name), load_windows("stochastic", name, "test")
        detail = predictor.load_pretrained(f"stochastic/{name}").predict_detailed(test.obs, test.group, scene)
        start = time.perf_counter()
        adapt_paths(detail.prototype_anchors.astype(np.float64), scene)
        adapt_ms = 1000 * (time.perf_counter() - start)
        fixed_ade, fixed_fde = ade_fde(detail.prototype_anchors, test.fut)
        adapt_ade, adapt_fde = ade_fde(detail.adapted_anchors, test.fut)
        cells = [f"{100 * map_violation(p, scene):.2f}% ({100 * path_map_violation(p, scene):.1f}%)"
                 for p in (detail.prototype_anchors, detail.adapted_anchors)]
        print(f"| {name} | {len(test)} | {cells[0]} | {cells[1]} | {100 * map_violation(detail.futures, scene):.2f}% | "
              f"{100 * map_violation(test.fut, scene):.2f}% | {fixed_ade.mean():.3f}/{fixed_fde.mean():.3f} -> "
              f"{adapt_ade.mean():.3f}/{adapt_fde.mean():.3f} | {adapt_ms:.0f} ms |")


if __name__ == "__main__":
    main()
