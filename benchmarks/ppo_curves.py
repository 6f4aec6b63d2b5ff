"""Learning curves of PPO training runs in one PNG: success rate and mean return of the last 100 training episodes
against env steps, one colour per run (each run folder's ``curve.json``, written by ``train_ppo``).

    python benchmarks/ppo_curves.py runs/nav/ppo-predictions runs/nav/ppo-no-predictions --out results/ppo/curves.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from st_sim.apps.navigation.train_ppo import plot_curve


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, help="train_ppo output folders")
    parser.add_argument("--out", type=Path, default=Path("results/ppo/curves.png"), help="PNG to write")
    parser.add_argument("--title", default="PPO on STCrowd-SimCrossing-v1", help="title of the figure")
    args = parser.parse_args()
    curves = {}
    for run in args.runs:
        path = run / "curve.json"
        if not path.is_file():
            parser.error(f"{path}: no such file (is {run} a train_ppo output folder?)")
        curves[run.name] = json.loads(path.read_text())
        last = curves[run.name][-1] if curves[run.name] else {}
        print(f"{run.name}: {len(curves[run.name])} points, last {last}")
    print(f"wrote {plot_curve(curves, args.out, args.title)}")


if __name__ == "__main__":
    main()
