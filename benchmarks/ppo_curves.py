"""Learning curves of PPO training runs in one PNG: success rate and mean return of the last 100 training episodes
against env steps, one colour per label (each run folder's ``curve.json``, written by ``train_ppo``). A label with
several run folders (seeds) is drawn as their smoothed mean with a band over the runs. Prints each run's last point
and its success and return over the first and the last five points.

    python benchmarks/ppo_curves.py runs/nav/ppo-predictions runs/nav/ppo-no-predictions --out results/ppo/curves.png
    python benchmarks/ppo_curves.py predictions=runs/nav/p-seed0,runs/nav/p-seed1 --out runs/nav/seeds.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from st_sim.apps.navigation.train_ppo import plot_curve
from st_sim.charts import new_figure


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", metavar="[LABEL=]DIR[,DIR...]",
                        help="train_ppo output folders; LABEL defaults to the (first) folder's name")
    parser.add_argument("--out", type=Path, default=Path("results/ppo/curves.png"), help="PNG to write")
    parser.add_argument("--title", default="PPO on STCrowd-SimCrossing-v1", help="title of the figure")
    args = parser.parse_args()
    new_figure()  # fails now, with the install command, if matplotlib is missing
    curves: dict[str, list[list[dict]]] = {}
    for item in args.runs:
        label, _, folders = item.rpartition("=")
        runs = [Path(folder) for folder in folders.split(",")]
        label = label or runs[0].name
        for run in runs:
            path = run / "curve.json"
            if not path.is_file():
                parser.error(f"{path}: no such file (is {run} a train_ppo output folder?)")
            curve = json.loads(path.read_text())
            curves.setdefault(label, []).append(curve)
            print(f"{label}: {run}: {len(curve)} points, last {curve[-1] if curve else {}}")
            if curve:  # the mean of the first and of the last five points (each 100 training episodes)
                ends = {key: (np.mean([p[key] for p in curve[:5]]), np.mean([p[key] for p in curve[-5:]]))
                        for key in ("success", "return")}
                print("  first / last five points: " + ", ".join(f"{key} {first:.3f} / {last:.3f}"
                                                                  for key, (first, last) in ends.items()))
    print(f"wrote {plot_curve(curves, args.out, args.title)}")


if __name__ == "__main__":
    main()
