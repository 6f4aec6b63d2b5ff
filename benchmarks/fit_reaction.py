"""Fit the reactive pedestrians' reaction (``envs.common.reaction.Reaction``) to CITR's pedestrians reacting to a cart.

    export OMP_NUM_THREADS=1 STCROWD_CITR=$PWD/../shared/datasets/citr
    python benchmarks/fit_reaction.py --sweeps 4 --out envs/common/reaction_fit.json

Fitted on CITR's ``vci_front``, ``vci_back`` and ``vci_lat_uni`` only (the cart head-on, from behind, across a one-way
group); ``vci_lat_bi`` is held out and never looked at here. The cases are those of ``python -m st_sim
reactive-validate`` (the same intents, the same scores). The loss, per fitted folder averaged over the three:
the reactive pedestrians' ADE as a share of the blind ones' plus the relative error of their median least clearance to
the cart against the recorded one; plus ``COLLISION_WEIGHT`` times the share of simulated pedestrians inside the cart.

The search is a coordinate descent over fixed grids (``GRIDS``): each sweep tries every value of one parameter with
the others held (every pair of values of the field of view and the hearing distance, and of the costs of delay and
of standing aside, which trade off), keeps the best, and goes on to the next; it stops after a sweep that improves
nothing (or after ``--sweeps``). ``--search NAME ...`` searches only those grids, in that order:

    python benchmarks/fit_reaction.py --search delay_cost+aside_cost+crossing_s clearance_m --sweeps 1 \
        --out runs/reaction/joint.json
    python -m st_sim reactive-validate --reaction runs/reaction/joint.json --json runs/reaction/joint-citr.json
    python benchmarks/fit_reaction.py --start runs/reaction/joint.json --sweeps 2 --out runs/reaction/full.json

Deterministic: the same data gives the same fit. Writes the parameters, the fitted figures, the number of
evaluations, the parameters it started from (the shipped ones, or ``--start FIT``) and this command into ``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import itertools
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from envs.common.footprint import Body
from envs.common.reaction import FIT_PATH, Reaction, read_reaction
from replays import strict_json
from replays.atomic import write_text_atomic
from replays.citr import CART_LENGTH_M, CART_WIDTH_M, find_experiments
from replays.data_root import CITR, data_root
from st_sim.apps.reactive_validate import HELD_OUT, Case, cases, score, walk

FITTED_ON = ("vci_back", "vci_front", "vci_lat_uni")
COLLISION_WEIGHT = 10.0  # loss of simulated pedestrians inside the cart, per share of them [-]
PER_MPS = (0.0, 0.1, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0, 1.3, 1.6, 2.0)  # room per m/s of the robot's speed [s]
GRIDS: dict[str, tuple[tuple[float, ...], ...]] = {  # parameters joined by "+" are searched together
    "fov_deg+hearing_m": ((30.0, 45.0, 60.0, 75.0, 90.0, 105.0, 120.0, 150.0, 180.0),
                          (0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)),
    "reaction_s": ((0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.6, 2.0),),
    "anticipation_s": ((0.4, 0.8, 1.2, 1.6, 2.0, 2.4, 3.2, 4.0),),
    "clearance_m": ((0.0, 0.15, 0.3, 0.5, 0.75, 1.0, 1.5),),
    "head_on_s": (PER_MPS,),
    "behind_s": (PER_MPS,),
    "crossing_s": (PER_MPS,),
    "delay_cost+aside_cost": ((0.25, 0.5, 1.0), (0.5, 1.0, 2.0)),  # aside at least half a frame's delay a metre, so
    # that they rejoin their logs (tests/test_envs_reactive.py's draws); with the crossing room, which they trade with:
    "delay_cost+aside_cost+crossing_s": ((0.25, 0.5, 1.0), (0.5, 1.0, 2.0), PER_MPS),
}


def figures(fit_cases: list[Case], body: Body, reaction: Reaction | None, blind: dict[str, float]) -> dict[str, dict]:
    """Per fitted folder: the reactive ADE as a share of the blind one, the median least clearance simulated and
    recorded [m], the collisions and the pedestrians."""
    rows: dict[str, list[tuple[dict, dict]]] = {}
    for case in fit_cases:
        simulated = score(case.grid, case.intent, walk(case.grid, case.intent, body, reaction), body)
        rows.setdefault(case.group, []).extend(zip(simulated, case.recorded, strict=True))
    return {group: {"ade_ratio": float(np.mean([s["ade_m"] for s, _ in pairs])) / blind[group],
                    "clearance_m": float(np.median([s["min_clearance_m"] for s, _ in pairs])),
                    "recorded_clearance_m": float(np.median([r["min_clearance_m"] for _, r in pairs])),
                    "collisions": int(sum(s["collision"] for s, _ in pairs)), "pedestrians": len(pairs)}
            for group, pairs in sorted(rows.items())}


def loss(per_group: dict[str, dict]) -> float:
    """The fit's loss (module docstring)."""
    terms = [g["ade_ratio"] + abs(g["clearance_m"] - g["recorded_clearance_m"]) / g["recorded_clearance_m"]
             for g in per_group.values()]
    collisions = sum(g["collisions"] for g in per_group.values()) / sum(g["pedestrians"] for g in per_group.values())
    return float(np.mean(terms)) + COLLISION_WEIGHT * collisions


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="CITR folder (default: $STCROWD_CITR or the cache)")
    parser.add_argument("--sweeps", type=int, default=4, help="most sweeps over the parameters (default: 4)")
    parser.add_argument("--out", default="envs/common/reaction_fit.json", help="where the fit is written")
    parser.add_argument("--start", default=FIT_PATH, metavar="FIT",
                        help="the fit the search starts from (default: the shipped one)")
    parser.add_argument("--search", nargs="+", choices=list(GRIDS), default=list(GRIDS), metavar="NAME",
                        help=f"the grids searched, in this order (default: all, {' '.join(GRIDS)})")
    args = parser.parse_args()
    root = data_root(dataset=CITR) if args.data is None else Path(args.data)
    body = Body(CART_LENGTH_M, CART_WIDTH_M)
    fit_cases = [case for case in cases(find_experiments(root), body) if case.group in FITTED_ON]
    assert not any(case.group in HELD_OUT for case in fit_cases)
    unit = dict.fromkeys(FITTED_ON, 1.0)  # the blind pedestrians' ADE as a share of 1 m: their ADE
    blind = {group: g["ade_ratio"] for group, g in figures(fit_cases, body, None, unit).items()}
    best = start = read_reaction(Path(args.start))
    best_figures = figures(fit_cases, body, best, blind)
    best_loss, evaluations = loss(best_figures), 1
    print(f"start {dataclasses.asdict(best)}: loss {best_loss:.4f}")
    for sweep in range(args.sweeps):
        improved = False
        for name in args.search:
            grid = GRIDS[name]
            for values in tqdm(list(itertools.product(*grid)), desc=f"sweep {sweep + 1} {name}", leave=False):
                change = dict(zip(name.split("+"), values, strict=True))
                if all(getattr(best, key) == value for key, value in change.items()):
                    continue
                trial = dataclasses.replace(best, **change)
                trial_figures = figures(fit_cases, body, trial, blind)
                trial_loss, evaluations = loss(trial_figures), evaluations + 1
                if trial_loss < best_loss - 1e-9:
                    best, best_figures, best_loss, improved = trial, trial_figures, trial_loss, True
            chosen = ", ".join(f"{key} = {getattr(best, key)}" for key in name.split("+"))
            print(f"sweep {sweep + 1} {chosen}: loss {best_loss:.4f}", flush=True)
        if not improved:
            break
    table = {"params": dataclasses.asdict(best), "started_from": dataclasses.asdict(start),
             "figures": {**best_figures, "loss": best_loss},
             "blind_ade_m": blind, "evaluations": evaluations, "fitted_on": list(FITTED_ON),
             "held_out": list(HELD_OUT), "fitted_by": "benchmarks/fit_reaction.py " + " ".join(sys.argv[1:]),
             "date": datetime.date.today().isoformat()}
    write_text_atomic(args.out, strict_json.dumps(table, indent=2) + "\n")
    print(strict_json.dumps(table, indent=2))


if __name__ == "__main__":
    main()
