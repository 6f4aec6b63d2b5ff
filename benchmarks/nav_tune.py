"""Tune the MPC on a seed range of its own: named variants of ``MpcConfig`` x predictors, seeded episodes.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/nav_tune.py \\
        --env STCrowd-SimCrossing-v1 --seed 10000 --episodes 100 --jobs 2 \\
        --variant base use_prior=false top_samples=20 --variant prior --variant tight safety_margin_m=0.1

The table's episodes are seeds 0..N-1; tuning runs start at --seed (default 10000), so the chosen setting
never saw a table episode. Each variant is a name followed by ``field=value`` overrides of the defaults
(tuples as ``a,b,c``); each (variant, predictor) cell is cached as ``OUT/<env>__<variant>__<predictor>.json``
(a cell whose file holds as many episodes is reused). Prints success, collisions and time to goal per cell.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import fields, replace
from multiprocessing import Pool
from pathlib import Path

from replays.atomic import write_text_atomic
from st_sim.apps.navigation.episodes import NavRun, run_navigation
from st_sim.apps.navigation.mpc import MpcConfig

SEE_EGO = {"yes": True, "no": False, "default": None}


def parse_variant(words: list[str]) -> tuple[str, MpcConfig]:
    """("name", MpcConfig) from ``name field=value ...``; values are parsed as the field's default type."""
    name, overrides = words[0], {}
    defaults = MpcConfig()
    kinds = {f.name: type(getattr(defaults, f.name)) for f in fields(MpcConfig)}
    for word in words[1:]:
        key, _, text = word.partition("=")
        if key not in kinds:
            raise SystemExit(f"--variant {name}: unknown MpcConfig field {key!r}")
        kind = kinds[key]
        if kind is bool:
            overrides[key] = text.lower() in ("1", "true", "yes")
        elif kind is tuple:
            overrides[key] = tuple(float(v) for v in text.split(","))
        else:
            overrides[key] = kind(text)
    return name, replace(defaults, **overrides)


def run_cell(job: tuple[str, NavRun, str]) -> str:
    """Run one (variant, predictor) cell unless cached; returns its file."""
    variant, run, out = job
    see = "" if run.pedestrians_see_ego is None else f"__see-ego-{'yes' if run.pedestrians_see_ego else 'no'}"
    path = Path(out) / f"{run.env_id}{see}__{variant}__{run.predictor}__seed{run.seed}.json"
    if path.exists() and len(json.loads(path.read_text())["episodes"]) >= run.episodes:
        return str(path)
    result = {"variant": variant, **run_navigation(run, progress=False)}
    write_text_atomic(path, json.dumps(result, indent=1))
    return str(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="STCrowd-SimCrossing-v1", help="env id (default: STCrowd-SimCrossing-v1)")
    parser.add_argument("--predictors", nargs="+", default=["none", "cvm", "singular"],
                        help="predictors (default: none cvm singular)")
    parser.add_argument("--variant", nargs="+", action="append", required=True,
                        help="a name and MpcConfig overrides field=value (repeatable)")
    parser.add_argument("--episodes", type=int, default=100, help="episodes per cell (default: 100)")
    parser.add_argument("--seed", type=int, default=10_000, help="first episode seed (default: 10000)")
    parser.add_argument("--pedestrians-see-ego", choices=list(SEE_EGO), default="default",
                        help="simulated envs: yes / no (default: the env's setting)")
    parser.add_argument("--out", default="runs/nav/tune", help="cell files (default: runs/nav/tune)")
    parser.add_argument("--jobs", type=int, default=2, help="cells in parallel processes (default: 2)")
    args = parser.parse_args()

    variants = [parse_variant(words) for words in args.variant]
    see_ego = SEE_EGO[args.pedestrians_see_ego]
    jobs = [(name, NavRun(args.env, "mpc", predictor, args.episodes, args.seed, see_ego, mpc=cfg), args.out)
            for name, cfg in variants for predictor in args.predictors]
    if args.jobs > 1:
        with Pool(args.jobs) as pool:
            paths = pool.map(run_cell, jobs, chunksize=1)
    else:
        paths = [run_cell(job) for job in jobs]
    print(f"{args.env}, seeds {args.seed}..{args.seed + args.episodes - 1}\n"
          "| variant | predictor | success | collision | time to goal [s] | path ratio | decisions/s |\n"
          "|---|---|---|---|---|---|---|")
    for path in paths:
        result = json.loads(Path(path).read_text())
        s = result["summary"]
        print(f"| {result['variant']} | {result['predictor']} | {s['success']['value']:.3f} | "
              f"{s['collision']['value']:.3f} | {s['time_to_goal_s']['value']:.1f} | {s['path_ratio']['value']:.2f} | "
              f"{result['decisions_per_s']:.0f} |")


if __name__ == "__main__":
    main()
