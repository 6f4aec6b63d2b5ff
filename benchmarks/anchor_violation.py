"""Where forecasts leave the walkable map, per scene: the prototype anchors, the map-adapted anchors, the refined
futures as the refiner returns them, after the output bending (end points onto the map), and after the on-map
step (points still deeper than 0.1 m off the map moved onto it; the default), against the ground truth.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/anchor_violation.py

Uses the shipped leave-one-out stochastic checkpoints on each scene's test windows (S = 20). Shares are of points
on non-walkable or off-image pixels, with the share of paths holding at least one in parentheses. "mid-path" is
the share of the bent futures' off-map points whose path ends on the map (what bending end points cannot reach);
"GT > 0.1 m" is the ground truth's share deeper than 0.1 m off the map (how much of it the map itself misses).
Also times the vectorised adaptation of all test agents x 20 prototypes.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import torch

import predictor
from predictor.anchors import adapt_paths, onto_walkable
from replays import load_scene, load_windows
from replays.scenes import SCENE_NAMES
from st_sim.metrics import ade_fde, map_violation, path_map_violation

STAGES = {"refined": {"adapt_output": False, "output_on_map": False},
          "+ bent": {"adapt_output": True, "output_on_map": False},
          "+ on map": {"adapt_output": True, "output_on_map": True}}


def share(paths_m: np.ndarray, scene) -> str:
    """Off-map share of points (and of paths) of (..., 12, 2) world paths."""
    return f"{100 * map_violation(paths_m, scene):.2f}% ({100 * path_map_violation(paths_m, scene):.1f}%)"


def main() -> None:
    torch.set_num_threads(1)
    print("| scene | agents | fixed anchors | adaptive anchors | " + " | ".join(STAGES) +
          " | mid-path | GT | GT > 0.1 m | anchor ADE/FDE fixed -> adaptive | adaptation time |")
    print("|---" * (10 + len(STAGES) - 3) + "|---|---|")
    for name in SCENE_NAMES:
        scene, test = load_scene(name), load_windows("stochastic", name, "test")
        model = predictor.load_pretrained(f"stochastic/{name}")
        futures = {}
        for stage, settings in STAGES.items():
            model.cfg = replace(model.cfg, **settings)
            detail = model.predict_detailed(test.obs, test.group, scene)
            futures[stage] = detail.futures
        start = time.perf_counter()
        adapt_paths(detail.prototype_anchors.astype(np.float64), scene)
        adapt_ms = 1000 * (time.perf_counter() - start)
        bent = futures["+ bent"]
        off = ~scene.is_walkable(bent)  # (N, S, 12)
        mid_path = (off & scene.is_walkable(bent[..., -1:, :])).sum() / max(off.sum(), 1)
        gt_deep = onto_walkable(test.fut.astype(np.float64), scene, 0.1)[1].mean()
        fixed_ade, fixed_fde = ade_fde(detail.prototype_anchors, test.fut)
        adapt_ade, adapt_fde = ade_fde(detail.adapted_anchors, test.fut)
        stages = " | ".join(share(f, scene) for f in futures.values())
        print(f"| {name} | {len(test)} | {share(detail.prototype_anchors, scene)} | "
              f"{share(detail.adapted_anchors, scene)} | {stages} | {100 * mid_path:.0f}% | "
              f"{100 * map_violation(test.fut, scene):.2f}% | {100 * gt_deep:.2f}% | "
              f"{fixed_ade.mean():.3f}/{fixed_fde.mean():.3f} -> {adapt_ade.mean():.3f}/{adapt_fde.mean():.3f} | "
              f"{adapt_ms:.0f} ms |")


if __name__ == "__main__":
    main()
