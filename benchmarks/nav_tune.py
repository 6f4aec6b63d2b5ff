"""Tune the MPC on seeds of its own: named variants of ``MpcConfig`` x predictors x envs, seeded episodes.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/nav_tune.py --envs STCrowd-SimCrossing-v1 STCrowd-Zara1-v0:reactive STCrowd-Univ-v0:reactive \\
        --seed 10000 --episodes 100 --out runs/nav/tune \\
        --variant default --variant no-stop safe_stop=false --variant no-modes track_modes=false

The table's episodes are seeds 0..N-1; tuning runs start at --seed (default 10000), so the chosen setting never
saw a table episode. Each variant is a name followed by ``field=value`` overrides of the defaults (tuples as
``a,b,c``). Every (env, variant, predictor) cell is one job of the grid runner (``st_sim.apps.grid``: resumable,
``--executor ray`` for a cluster), written to ``OUT/<env>[__<mode>]__<variant>__<predictor>__<N>ep_seed<seed>.json``.
Prints success, collisions (any and at fault), timeouts and time to goal per cell.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import fields, replace
from pathlib import Path

from nav_table import env_and_mode

from st_sim.apps.grid import raise_on_failure, run_jobs
from st_sim.apps.navigation.episodes import NavRun, grid_job
from st_sim.apps.navigation.mpc import MpcConfig
from st_sim.apps.navigation.predictors import PREDICTORS
from st_sim.command_line import add_grid_arguments

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["STCrowd-SimCrossing-v1"],
                        help="env ids, replays as id:log or id:reactive (default: STCrowd-SimCrossing-v1)")
    parser.add_argument("--predictors", nargs="+", default=["cvm", "singular"], choices=list(PREDICTORS),
                        help="predictors (default: cvm singular)")
    parser.add_argument("--variant", nargs="+", action="append", required=True,
                        help="a name and MpcConfig overrides field=value (repeatable)")
    parser.add_argument("--episodes", type=int, default=100, help="episodes per cell (default: 100)")
    parser.add_argument("--seed", type=int, default=10_000, help="first episode seed (default: 10000)")
    parser.add_argument("--pedestrians-see-ego", choices=list(SEE_EGO), default="default",
                        help="simulated envs: yes / no (default: the env's setting)")
    parser.add_argument("--out", default="runs/nav/tune", help="cell files (default: runs/nav/tune)")
    parser.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    add_grid_arguments(parser)
    args = parser.parse_args()
    if args.seed < 10_000:
        print(f"warning: --seed {args.seed} overlaps the table's seeds (0..N-1); tune on 10000 and up")

    variants = [parse_variant(words) for words in args.variant]
    see_ego, out = SEE_EGO[args.pedestrians_see_ego], Path(args.out)
    cells = []
    for env_id, mode in map(env_and_mode, args.envs):
        for name, cfg in variants:
            for predictor in args.predictors:
                run = NavRun(env_id, "mpc", predictor, args.episodes, args.seed, see_ego, mode,
                             data_root=args.data_root, mpc=cfg)
                label = f"{env_id}{f'__{mode}' if mode else ''}__{name}__{predictor}__{args.episodes}ep_seed{args.seed}"
                cells.append((name, grid_job(f"tune/{label}", run, out / f"{label}.json")))
    reports = run_jobs([job for _, job in cells], executor=args.executor, workers=args.workers,
                       address=args.ray_address, desc="cells")
    raise_on_failure(reports)
    print(f"seeds {args.seed}..{args.seed + args.episodes - 1}\n"
          "| env | variant | predictor | success | collision | at fault | timeout | time to goal [s] | decisions/s |\n"
          "|---|---|---|---|---|---|---|---|---|")
    for name, job in cells:
        result = json.loads(Path(job.output).read_text())
        s = result["summary"]
        env = result["env_id"] + (f" {result['pedestrians']}" if result.get("pedestrians") else "")
        print(f"| {env} | {name} | {result['predictor']} | {s['success']['value']:.3f} | "
              f"{s['collision']['value']:.3f} | {s['collision_at_fault']['value']:.3f} | {s['timeout']['value']:.3f} | "
              f"{s['time_to_goal_s']['value']:.1f} | {result['decisions_per_s']:.0f} |")


if __name__ == "__main__":
    main()
