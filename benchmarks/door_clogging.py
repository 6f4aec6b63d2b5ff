"""How often a door clogs in the crowd simulator: the bottleneck scenario of ``st_sim.sim.validation`` (60 people
leave an 8.5 m x 8 m room) over many seeds and door widths, with the default CrowdConfig.

Prints per door: the share of seeds in which the room did not empty (a clog: nobody passed for the stall time),
the share with a specific flow under 0.8 /(m s), and the 1st/5th/50th percentiles of the flow.

    OMP_NUM_THREADS=1 python benchmarks/door_clogging.py --seeds 300 --doors 1.2 2.0
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from tqdm import tqdm

from st_sim.sim import CrowdConfig
from st_sim.sim.validation import bottleneck_flow

FLOW_FLOOR = 0.8  # /(m s): half the published 1.6-2.0, the bound the validation tests hold the median to


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=300, help="seeds per door (default: 300)")
    parser.add_argument("--doors", type=float, nargs="+", default=[1.2, 2.0], help="door widths [m]")
    parser.add_argument("--people", type=int, default=60, help="pedestrians in the room (default: 60)")
    args = parser.parse_args()
    seeds = np.random.default_rng(1).integers(0, 2**32 - 1, args.seeds).tolist()
    cfg = CrowdConfig()
    for door in args.doors:
        runs = [bottleneck_flow(cfg, door, n=args.people, seed=s) for s in tqdm(seeds, desc=f"door {door} m")]
        flow = np.array([f for f, _ in runs])
        clogged = np.array([math.isinf(t) for _, t in runs])
        p1, p5, p50 = np.percentile(flow, [1, 5, 50])
        print(f"door {door:.1f} m, {len(seeds)} seeds: clogged {clogged.mean():.1%}, flow < {FLOW_FLOOR} "
              f"{(flow < FLOW_FLOOR).mean():.1%}, flow /(m s) p1 {p1:.2f} p5 {p5:.2f} median {p50:.2f}")


if __name__ == "__main__":
    main()
