"""Forecasts kept on the walkable map: the shipped seed-0 checkpoints with ``ModelConfig.output_on_map`` off and on.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/on_map.py --tasks stochastic deterministic momentary

For each task and scene: ADE / FDE (best of S) and the share of predicted points (and paths) on non-walkable or
off-image pixels, without and with the output moved onto walkable ground (points deeper than
``on_map_tolerance_m`` inside a wall move to the nearest walkable pixel), beside the ground truth's share.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import predictor
from replays.constants import TASKS
from st_sim.scoring import evaluate_offline

SCENES = ("eth", "hotel", "univ", "zara1", "zara2")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=["stochastic", "deterministic", "momentary"],
                        choices=[t for t in TASKS if t in ("stochastic", "deterministic", "momentary")])
    parser.add_argument("--tolerance-m", type=float, default=0.1, help="on_map_tolerance_m (default: 0.1)")
    args = parser.parse_args()
    print("| task | scene | off: ADE / FDE | off: map violation points (paths) | on: ADE / FDE "
          "| on: map violation points (paths) | ground truth |")
    print("|---|---|---|---|---|---|---|")
    for task in args.tasks:
        for scene in SCENES:
            model = predictor.load_pretrained(f"{task}/{scene}")
            cells = []
            for on in (False, True):
                model.cfg = replace(model.cfg, output_on_map=on, on_map_tolerance_m=args.tolerance_m)
                r = evaluate_offline(model, task, scene)
                cells.append(f"{r.ade:.4f} / {r.fde:.4f} | {100 * r.map_violation:.2f} % "
                             f"({100 * r.path_map_violation:.1f} %)")
            print(f"| {task} | {scene} | {' | '.join(cells)} | {100 * r.gt_map_violation:.2f} % |", flush=True)


if __name__ == "__main__":
    main()
