"""The output adaptation, measured on the same checkpoints: refined futures as the refiner gives them, and
bent onto the map like the anchors (end points on walkable pixels inside the image, the default).

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/anchor_pull.py --runs runs \\
        --tasks stochastic deterministic

For every ``runs/<task>/<scene>/seed<k>/best.pt`` present, scores the test split twice (``adapt_output`` off,
then on) and prints the mean over seeds of ADE / FDE and of the map-violation rate of the predicted points.
"""

from __future__ import annotations

import argparse
import statistics
from dataclasses import replace
from pathlib import Path

from predictor.checkpoint import load
from replays.scenes import SCENE_NAMES
from st_sim.scoring import evaluate_offline


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="runs", help="training folder <task>/<scene>/seed<k>/ (default: runs)")
    parser.add_argument("--tasks", nargs="+", default=["stochastic", "deterministic"], help="tasks (default: "
                        "stochastic deterministic)")
    args = parser.parse_args()
    print("| task | scene | seeds | ADE / FDE, output as refined | map-viol. | ADE / FDE, output adapted | map-viol. |")
    print("|---|---|---|---|---|---|---|")
    for task in args.tasks:
        for scene in SCENE_NAMES:
            checkpoints = sorted(Path(args.runs, task, scene).glob("seed*/best.pt"))
            if not checkpoints:
                continue
            cells = []
            for adapt in (False, True):
                results = []
                for path in checkpoints:
                    model = load(path)
                    model.cfg = replace(model.cfg, adapt_output=adapt)
                    results.append(evaluate_offline(model, task, scene))
                cells.append(f"{statistics.fmean(r.ade for r in results):.3f} / "
                             f"{statistics.fmean(r.fde for r in results):.3f} | "
                             f"{100 * statistics.fmean(r.map_violation for r in results):.2f}%")
            print(f"| {task} | {scene} | {len(checkpoints)} | {cells[0]} | {cells[1]} |")


if __name__ == "__main__":
    main()
