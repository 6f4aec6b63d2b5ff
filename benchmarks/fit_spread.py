"""Choose how much reactive pedestrians differ (``st_sim.reactive.reaction.Spread``) by the cross-validated realism
score.

    export OMP_NUM_THREADS=1 STCROWD_CITR=$PWD/../shared/datasets/citr
    python benchmarks/fit_spread.py --folds results/reactive_validation/citr-cv.json --sigmas 0 0.15 0.3 0.5 \
        --rollouts 16 --workers 2 --out st_sim/reactive/spread_fit.json

One sigma for all four traits (noticing distance, reaction time, room, patience: ``reaction.TRAITS``), each
pedestrian's factors drawn as exp(N(0, sigma)). The score is the WOSAC-style realism meta score of the reactive
pedestrians' seeded rollouts (``st_sim.apps.sim_agents``; paces as ``reactive-validate``'s).

- **Cross-validated**: for each CITR folder left out, the reactive pedestrians take the reaction that the fold fitted
  on the three other folders (``folds[].reaction`` of a ``reactive-validate --cross-validate`` JSON, ``--folds``);
  the sigma chosen is the one with the highest meta score on those three folders, and it is scored on the folder left
  out, beside sigma 0 there.
- **Shipped**: the sigma with the highest meta score of the shipped reaction (``st_sim/reactive/reaction_fit.json``) on
  all four folders, written to ``--out`` with every figure.

Every (reaction, sigma) pair is one job, run by ``--workers`` processes; its per-experiment likelihoods are kept in
``--cache`` and reused, so an interrupted run resumes. The same data and seed give the same figures.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import hashlib
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from envs.common.errors import ConfigError
from replays import strict_json
from replays.atomic import atomic_path, write_text_atomic
from replays.citr import CART_LENGTH_M, CART_WIDTH_M, CITR_FPS, find_experiments
from replays.data_root import CITR, data_root
from st_sim.apps.sim_agents import case_likelihoods, pooled_realism
from st_sim.apps.vehicle_cases import Case, Variety, cases
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import FIT_PATH, TRAITS, Reaction, Spread, fitted_reaction, reaction_of

SEP, MIN_ADE = "|", "min_ade_m"  # a kept job's keys: experiment, then feature (or the min ADE)


def job_path(cache: Path, reaction: Reaction, sigma: float, rollouts: int, seed: int, pace_sigma: float) -> Path:
    """Where the job of ``reaction`` and ``sigma`` keeps its likelihoods, named by the settings of the job (not by
    the data or the code: delete ``--cache`` after changing either)."""
    key = strict_json.dumps([dataclasses.asdict(reaction), sigma, rollouts, seed, pace_sigma], sort_keys=True)
    return cache / f"{hashlib.sha256(key.encode()).hexdigest()[:16]}.npz"


def run_job(task: tuple[list[Case], Body, Reaction, float, int, int, float, Path]) -> dict[str, Any]:
    """Rollouts of every case with ``reaction`` and ``sigma``: ``{case name: case_likelihoods}``, from the cache when
    it is there."""
    found, body, reaction, sigma, rollouts, seed, pace_sigma, path = task
    if not path.exists():
        variety = Variety(pace_sigma, Spread.even(sigma))
        arrays = {}
        for case in found:
            values, closest = case_likelihoods(case, body, reaction, rollouts, seed, variety)
            arrays |= {f"{case.name}{SEP}{name}": value for name, value in values.items()}
            arrays[f"{case.name}{SEP}{MIN_ADE}"] = closest
        with atomic_path(path) as tmp, tmp.open("wb") as file:
            np.savez(file, **arrays)
    scored: dict[str, Any] = {}
    with np.load(path, allow_pickle=False) as kept:
        for key in kept.files:
            name, column = key.split(SEP)
            values, _ = scored.setdefault(name, ({}, None))
            if column == MIN_ADE:
                scored[name] = (values, kept[key])
            else:
                values[column] = kept[key]
    return scored


def meta(scored: dict[str, Any], found: list[Case], groups: set[str]) -> float:
    """The realism meta score of the pedestrians of the cases of ``groups``."""
    return float(pooled_realism([scored[case.name] for case in found if case.group in groups])["meta"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--folds", type=Path, required=True,
                        help="a reactive-validate --cross-validate JSON: each fold's reaction")
    parser.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 0.15, 0.3, 0.5])
    parser.add_argument("--rollouts", type=int, default=16, help="seeded rollouts per pedestrian (default: 16)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pace-sigma", type=float, default=Variety.pace_sigma)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--cache", type=Path, default=Path("runs/spread_fit"))
    parser.add_argument("--data", default=None, help="CITR's layout (default: $STCROWD_CITR or the cache)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    bad = [s for s in args.sigmas if not 0 <= s <= 2]
    if bad:
        parser.error(f"--sigmas: {bad} outside [0, 2]")
    if args.rollouts < 1 or args.workers < 1:
        parser.error(f"--rollouts {args.rollouts} and --workers {args.workers}: each at least 1")
    try:
        folds = json.loads(args.folds.read_text())["folds"]
        fold_reactions = {fold["held_out"]: reaction_of(fold["reaction"], f"--folds {args.folds}",
                                                        f"folds[{i}].reaction") for i, fold in enumerate(folds)}
    except ConfigError as err:
        parser.error(str(err))
    except (OSError, ValueError, KeyError, TypeError) as err:
        parser.error(f"--folds {args.folds}: not a cross-validation JSON with folds[].held_out and .reaction ({err})")
    body = Body(length_m=CART_LENGTH_M, width_m=CART_WIDTH_M)
    root = Path(args.data) if args.data else data_root(dataset=CITR)
    found = cases(find_experiments(root, fps=CITR_FPS), body)
    groups = sorted({case.group for case in found})
    if sorted(fold_reactions) != groups:
        parser.error(f"--folds {args.folds}: folds {sorted(fold_reactions)} are not the data's folders {groups}")
    args.cache.mkdir(parents=True, exist_ok=True)
    reactions = {**{f"fold {name}": reaction for name, reaction in fold_reactions.items()},
                 "shipped": fitted_reaction()}
    tasks = [(label, sigma, (found, body, reaction, sigma, args.rollouts, args.seed, args.pace_sigma,
                             job_path(args.cache, reaction, sigma, args.rollouts, args.seed, args.pace_sigma)))
             for label, reaction in reactions.items() for sigma in args.sigmas]
    results: dict[tuple[str, float], dict[str, Any]] = {}
    with ProcessPoolExecutor(args.workers) as pool:
        for (label, sigma, _), scored in tqdm(zip(tasks, pool.map(run_job, [t[2] for t in tasks]), strict=True),
                                              total=len(tasks), desc="rollouts", unit="job"):
            results[label, sigma] = scored
    cv = []
    for held_out in groups:
        fitted = set(groups) - {held_out}
        on_fitted = {sigma: meta(results[f"fold {held_out}", sigma], found, fitted) for sigma in args.sigmas}
        chosen = max(args.sigmas, key=lambda s: (on_fitted[s], -s))  # ties: the narrower spread
        held = {sigma: meta(results[f"fold {held_out}", sigma], found, {held_out}) for sigma in args.sigmas}
        cv.append({"held_out": held_out, "meta_on_fitted": on_fitted, "chosen_sigma": chosen,
                   "held_out_meta": held[chosen], "held_out_meta_sigma_0": held.get(0.0), "held_out_meta_all": held})
        print(f"{held_out}: chosen sigma {chosen:g} on the fitted folders; held out meta {held[chosen]:.3f}"
              + (f" (sigma 0: {held[0.0]:.3f})" if 0.0 in held else ""))
    shipped = {sigma: meta(results["shipped", sigma], found, set(groups)) for sigma in args.sigmas}
    sigma = max(args.sigmas, key=lambda s: (shipped[s], -s))
    print("shipped reaction, all folders: " + ", ".join(f"sigma {s:g} {m:.3f}" for s, m in shipped.items()))
    print(f"spread chosen: sigma {sigma:g}")
    out = {"spread": dict.fromkeys(TRAITS, sigma), "meta_all_folders": shipped, "cross_validation": cv,
           "settings": {"sigmas": args.sigmas, "rollouts": args.rollouts, "seed": args.seed,
                        "pace_sigma": args.pace_sigma, "folds": str(args.folds), "reaction": str(FIT_PATH.name)},
           "fitted_by": "benchmarks/fit_spread.py " + " ".join(sys.argv[1:] if argv is None else argv),
           "date": datetime.date.today().isoformat()}
    write_text_atomic(args.out, strict_json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
