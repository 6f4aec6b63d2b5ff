"""Where the stochastic error comes from, by observed speed: anchors alone against refined futures.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/speed_bands.py [--scenes eth]

For each scene's test windows and its shipped leave-one-out checkpoint (S = 20), agents are split by their
recent speed (the agent-frame scale: last minus third-last point, per 0.4 s step). Per band: agent count,
the median ratio of future to observed progress along the heading in the test split and in the training
split, best-of-20 FDE of the map-adapted anchors alone and of the refined futures, and the band's share of
the scene's summed FDE.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

import predictor
from predictor.normalize import SLOW_SPEED_M, agent_frames
from replays import load_scene, load_windows
from replays.constants import T_PRED
from replays.scenes import SCENE_NAMES
from st_sim.metrics import ade_fde

BANDS_M = ((0.0, SLOW_SPEED_M), (SLOW_SPEED_M, 0.6), (0.6, np.inf))  # metres per 0.4 s step


def progress_ratio(obs: np.ndarray, fut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) final progress along the heading over (12 x observed speed), and (N,) observed speed [m/step],
    0 for the slow population (which is not speed-scaled)."""
    frames = agent_frames(obs)
    return frames.to_agent(fut.astype(np.float64))[:, -1, 0] / T_PRED, frames.scale_m * ~frames.slow


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=list(SCENE_NAMES), choices=SCENE_NAMES)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print("| scene | speed band (m/step) | agents | progress ratio test (train) | FDE anchors | FDE refined | "
          "share of FDE |")
    print("|---|---|---|---|---|---|---|")
    for name in args.scenes:
        test, train = load_windows("stochastic", name, "test"), load_windows("stochastic", name, "train")
        detail = predictor.load_pretrained(f"stochastic/{name}").predict_detailed(test.obs, test.group,
                                                                                    load_scene(name))
        _, fde_anchor = ade_fde(detail.adapted_anchors, test.fut)
        _, fde = ade_fde(detail.futures, test.fut)
        ratio, speed = progress_ratio(test.obs, test.fut)
        train_ratio, train_speed = progress_ratio(train.obs, train.fut)
        for low, high in BANDS_M:
            band = (speed >= low) & (speed < high)
            train_band = (train_speed >= low) & (train_speed < high)
            label = f"{low:.1f}-{high:.1f}" if np.isfinite(high) else f">= {low:.1f}"
            if low == 0.0:
                label = f"slow (< {high:.1f})"  # the slow population (its speed reads 0 above)
            if not band.any():
                continue
            ratios = "–" if low == 0.0 else (f"{np.median(ratio[band]):.2f} "
                                             f"({np.median(train_ratio[train_band]):.2f})")
            print(f"| {name} | {label} | {band.sum()} | {ratios} | {fde_anchor[band].mean():.3f} | "
                  f"{fde[band].mean():.3f} | {fde[band].sum() / fde.sum():.0%} |")


if __name__ == "__main__":
    main()
