"""Fit the reactive pedestrians' reaction (``st_sim.reactive.reaction.Reaction``) to CITR's pedestrians reacting to a
cart.

    export OMP_NUM_THREADS=1 STCROWD_CITR=$PWD/../shared/datasets/citr
    python benchmarks/fit_reaction.py --cross-validate --out runs/reaction_cv/fit.json
    python benchmarks/fit_reaction.py --cross-validate --variants reactive attentive --out runs/reaction_cv/fit.json
    python benchmarks/fit_reaction.py --cross-validate --clearance-tolerances 0 0.25 --out runs/reaction_cv/fit.json
    python benchmarks/fit_reaction.py --sweeps 4 --out runs/reaction/fit.json

**Cross-validated** (``--cross-validate``; how a fit is chosen): the fitting procedure of each candidate, every
``--variants`` entry with every ``--clearance-tolerances`` entry (``st_sim.apps.reaction_search``: the loss and its
clearance tolerance, the coordinate descent over fixed grids, the variants), runs once per CITR vehicle folder
(``vci_back``, ``vci_front``, ``vci_lat_bi``, ``vci_lat_uni``) on the three others and is scored on the one left
out: its held-out ADE ratio (reactive / blind). The candidate chosen is the one whose held-out ratios have the
lowest ``cv_criterion``: max(mean / 0.8, worst / 0.9) (ties: the lower mean, then the order given); that criterion
and nothing else chooses. The chosen procedure then runs on all four folders, and that fit is written to ``--out``
with every candidate's CV score. Each fold's fit is written to ``--fold-fits`` as it ends and reused by a later run
of the same procedure on the same data, so an interrupted run resumes. Unless given, the procedure is
``CV_PROCEDURE``: from ``FIRST_GUESS`` (guesses made before any data was looked at: a start fitted on some folders
would carry them into the folds that hold them out), every grid but the joint ``delay_cost+aside_cost+crossing_s``
at coarse values, one sweep.

**One fit** (without ``--cross-validate``): the same search on ``--fit-on`` only (default: ``vci_back``,
``vci_front`` and ``vci_lat_uni``, the folders of the shipped fit, ``vci_lat_bi`` left out), from ``--start``
(default: the shipped fit), every grid at full resolution, every clearance error counted (the first
``--clearance-tolerances`` entry, default 0):

    python benchmarks/fit_reaction.py --search delay_cost+aside_cost+crossing_s clearance_m --sweeps 1 \
        --out runs/reaction/joint.json
    python -m st_sim reactive-validate --reaction runs/reaction/joint.json --json runs/reaction/joint-citr.json

Deterministic: the same data gives the same fit. Writes the parameters, the fitted figures, the number of
evaluations, the parameters it started from, the folders fitted on and this command into ``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import itertools
import sys
from pathlib import Path

from replays import strict_json
from replays.atomic import write_text_atomic
from replays.citr import CART_LENGTH_M, CART_WIDTH_M, find_experiments
from replays.data_root import CITR, data_root
from st_sim.apps.reaction_search import (
    CV_PROCEDURE,
    GRIDS,
    VARIANTS,
    Fit,
    Procedure,
    Scorer,
    cross_validate,
    cv_score,
    fold_fit,
    held_out_ratios,
)
from st_sim.apps.vehicle_cases import cases
from st_sim.command_line import non_negative_float
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import FIT_PATH, read_reaction

FITTED_ON = ("vci_back", "vci_front", "vci_lat_uni")  # the shipped fit's folders (one fit, without --cross-validate)


def procedure(args: argparse.Namespace, variant: str, clearance_tolerance: float) -> Procedure:
    """The fitting procedure the flags ask for: ``CV_PROCEDURE``'s with ``--cross-validate``, the full grids from the
    shipped fit without; ``--start``, ``--search``, ``--sweeps`` and ``--coarse`` override."""
    base = CV_PROCEDURE if args.cross_validate else Procedure(variant, read_reaction(FIT_PATH), tuple(GRIDS), 4)
    return Procedure(variant, base.start if args.start is None else read_reaction(Path(args.start)),
                     base.search if args.search is None else tuple(args.search),
                     base.sweeps if args.sweeps is None else args.sweeps, base.coarse or args.coarse,
                     clearance_tolerance)


def fit_table(fit: Fit, scorer: Scorer, chosen: Procedure) -> dict:
    """What ``--out`` holds of one fit: its parameters and figures, where it started, the blind ADE per folder, the
    folders fitted on and left out, and how it was fitted."""
    return {**fit.record(), "started_from": dataclasses.asdict(chosen.first), "blind_ade_m": scorer.blind_ade_m,
            "held_out": [group for group in scorer.groups if group not in fit.fitted_on],
            "procedure": chosen.record(), "fitted_by": "benchmarks/fit_reaction.py " + " ".join(sys.argv[1:]),
            "date": datetime.date.today().isoformat()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="CITR folder (default: $STCROWD_CITR or the cache)")
    parser.add_argument("--out", required=True, help="where the fit is written (the shipped one: "
                                                     "st_sim/reactive/reaction_fit.json)")
    parser.add_argument("--cross-validate", action="store_true",
                        help="choose among --variants by leave-one-folder-out, then fit the chosen one on every folder")
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=["reactive"],
                        help="with --cross-validate: the variants compared (default: reactive); without: the first "
                             "is fitted")
    parser.add_argument("--clearance-tolerances", nargs="+", type=non_negative_float, default=None, metavar="T",
                        help=f"the loss's clearance tolerance (relative errors of the median least clearance up to T "
                             f"cost nothing); with --cross-validate: the tolerances compared, each with every variant "
                             f"(default: {CV_PROCEDURE.clearance_tolerance:g}); without: the first is fitted (default: "
                             f"0, every error counts, as the shipped fit was fitted)")
    parser.add_argument("--fold-fits", default="runs/reaction_cv", metavar="DIR",
                        help="with --cross-validate: each fold's fit is kept here and reused (default: "
                             "runs/reaction_cv)")
    parser.add_argument("--fit-on", nargs="+", default=list(FITTED_ON), metavar="FOLDER",
                        help=f"without --cross-validate: the folders fitted on (default: {' '.join(FITTED_ON)})")
    parser.add_argument("--sweeps", type=int, default=None,
                        help="most sweeps over the grids (default: 1 with --cross-validate, else 4)")
    parser.add_argument("--start", default=None, metavar="FIT",
                        help="the fit the search starts from (default: FIRST_GUESS with --cross-validate, else the "
                             "shipped one)")
    parser.add_argument("--search", nargs="+", choices=list(GRIDS), default=None, metavar="NAME",
                        help=f"the grids searched, in this order (default with --cross-validate: all but the joint "
                             f"delay_cost+aside_cost+crossing_s; without: all, {' '.join(GRIDS)})")
    parser.add_argument("--coarse", action="store_true",
                        help="every other value of each grid (always with --cross-validate's default procedure)")
    args = parser.parse_args()
    if args.clearance_tolerances is None:
        args.clearance_tolerances = [CV_PROCEDURE.clearance_tolerance if args.cross_validate else 0.0]
    root = data_root(dataset=CITR) if args.data is None else Path(args.data)
    body = Body(CART_LENGTH_M, CART_WIDTH_M)
    scorer = Scorer(cases(find_experiments(root), body), body)
    if not args.cross_validate:
        chosen = procedure(args, args.variants[0], args.clearance_tolerances[0])
        unknown = sorted(set(args.fit_on) - set(scorer.groups))
        if unknown:
            sys.exit(f"error: --fit-on {unknown[0]}: no such folder with a vehicle (found {', '.join(scorer.groups)})")
        table = fit_table(fold_fit(scorer, args.fit_on, chosen, None), scorer, chosen)
    else:
        folder = Path(args.fold_fits)
        candidates = [procedure(args, variant, tolerance)
                      for variant, tolerance in itertools.product(args.variants, args.clearance_tolerances)]
        scores = {}
        for candidate in candidates:
            fits = cross_validate(scorer, candidate, folder)
            score = cv_score(held_out_ratios(scorer, {g: fit.reaction for g, fit in fits.items()}))
            scores[candidate.name] = {"variant": candidate.variant,
                                      "clearance_tolerance": candidate.clearance_tolerance, **score,
                                      "folds": {g: fit.record() for g, fit in fits.items()}}
            print(f"{candidate.name}: held-out ADE ratios {score['held_out_ade_ratios']}, mean "
                  f"{score['mean_ade_ratio']:.3f}, worst {score['worst_ade_ratio']:.3f}, "
                  f"criterion {score['criterion']:.3f}", flush=True)
        chosen = min(candidates, key=lambda c: (scores[c.name]["criterion"], scores[c.name]["mean_ade_ratio"]))
        table = {**fit_table(fold_fit(scorer, scorer.groups, chosen, folder), scorer, chosen),
                 "chosen": chosen.name, "cross_validation": scores,
                 "selected_by": "the lowest max(mean / 0.8, worst / 0.9) of the held-out ADE ratios (ties: mean)"}
    write_text_atomic(args.out, strict_json.dumps(table, indent=2) + "\n")
    print(strict_json.dumps({key: table[key] for key in ("params", "figures", "evaluations", "fitted_on")}, indent=2))


if __name__ == "__main__":
    main()
