"""Yielding against stepping aside: how the reaction's costs of delay and of standing aside move CITR's figures.

    export OMP_NUM_THREADS=1 STCROWD_CITR=$PWD/../shared/datasets/citr
    python benchmarks/reaction_styles.py
    python benchmarks/reaction_styles.py --delay 0.5 1.0 --aside 0.5 1.0 2.0 --crossing 1.3 1.6 --json runs/styles.json

For every combination of ``Reaction.delay_cost`` (per 0.4 s frame behind the log), ``Reaction.aside_cost`` (per metre
to the side of the route) and ``Reaction.crossing_s`` (room per m/s of a robot crossing the way), the other fields as
shipped (``st_sim/reactive/reaction_fit.json``), one row: the fit's loss on the folders it is fitted on
(``benchmarks/fit_reaction.py``'s), the reactive ADE as a share of the blind one on the fitted folders and on the
held-out ``vci_lat_bi``, the held-out median least clearance (recorded) and the held-out collisions. The dearer the
side against the delay, the more a pedestrian slows or waits and passes behind the vehicle. Deterministic.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools

import numpy as np
from fit_reaction import FITTED_ON  # benchmarks/ is the script's folder, first on sys.path
from tqdm import tqdm

from replays import strict_json
from replays.atomic import write_text_atomic
from replays.citr import CART_LENGTH_M, CART_WIDTH_M, find_experiments
from replays.data_root import CITR, data_root
from st_sim.apps.reaction_search import Scorer, loss
from st_sim.apps.vehicle_cases import cases
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import fitted_reaction

HELD_OUT = ("vci_lat_bi",)  # the shipped fit's folder left out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--delay", type=float, nargs="+", default=[0.5, 1.0], help="delay costs [1/frame]")
    parser.add_argument("--aside", type=float, nargs="+", default=[0.5, 1.0, 2.0], help="aside costs [1/m]")
    parser.add_argument("--crossing", type=float, nargs="+", default=[1.3, 1.6], help="crossing_s values [s]")
    parser.add_argument("--json", default=None, help="also write the rows here (JSON)")
    args = parser.parse_args()
    body = Body(CART_LENGTH_M, CART_WIDTH_M)
    scorer = Scorer(cases(find_experiments(data_root(dataset=CITR)), body), body)
    shipped = fitted_reaction()
    rows = []
    grid = list(itertools.product(args.delay, args.aside, args.crossing))
    for delay, aside, crossing in tqdm(grid, desc="reactions"):
        reaction = dataclasses.replace(shipped, delay_cost=delay, aside_cost=aside, crossing_s=crossing)
        on_fitted, on_held = scorer.figures(FITTED_ON, reaction), scorer.figures(HELD_OUT, reaction)
        rows.append({"delay_cost": delay, "aside_cost": aside, "crossing_s": crossing, "fit_loss": loss(on_fitted),
                     "fitted_ade_ratio": float(np.mean([g["ade_ratio"] for g in on_fitted.values()])),
                     **{f"held_out_{key}": value for key, value in on_held[HELD_OUT[0]].items()}})
    print("| delay_cost | aside_cost | crossing_s | fit loss | ADE / blind, fitted (mean) | ADE / blind, held out "
          "| held-out clearance [m] (recorded) | held-out collisions |")
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(f"| {row['delay_cost']:g} | {row['aside_cost']:g} | {row['crossing_s']:g} | {row['fit_loss']:.4f} | "
              f"{row['fitted_ade_ratio']:.3f} | {row['held_out_ade_ratio']:.3f} | "
              f"{row['held_out_clearance_m']:.2f} ({row['held_out_recorded_clearance_m']:.2f}) | "
              f"{row['held_out_collisions']} |")
    if args.json:
        table = {"rows": rows, "shipped": dataclasses.asdict(shipped)}
        write_text_atomic(args.json, strict_json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
