"""The navigation table: every planner x predictor on each env, seeded episodes, 95 % intervals, paired tests.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/nav_table.py \\
        --envs STCrowd-SimCrossing-v1 STCrowd-Zara1-v0 STCrowd-Univ-v0 --episodes 500 --out runs/nav/table --jobs 2

Each cell (env, planner, predictor) is one ``run_navigation`` over episodes seed .. seed + N - 1 (the same
episodes for every cell of an env) and is written to ``OUT/<env>__<planner>__<predictor>.json``; a cell whose
file exists with enough episodes is reused, so an interrupted run resumes. Planners that ignore predictions
(straight, ORCA) run once, with predictor "none". The script prints one markdown table per env and McNemar's
paired test of MPC with SingularTrajectory against MPC with CVM and with no prediction (collisions), and of
PPO with predictions against PPO without (successes).
"""

from __future__ import annotations

import argparse
import json
from multiprocessing import Pool
from pathlib import Path

from replays.atomic import write_text_atomic
from st_sim.apps.navigation.episodes import NavRun, run_navigation
from st_sim.apps.navigation.metrics import paired_collision_test, paired_success_test
from st_sim.apps.navigation.planners import PLANNERS, USES_PREDICTIONS
from st_sim.apps.navigation.predictors import PREDICTORS
from st_sim.apps.navigation.report import markdown_header, markdown_row, see_ego_label

SEE_EGO = {"yes": True, "no": False, "default": None}


def cells(planners: list[str], predictors: list[str]) -> list[tuple[str, str]]:
    """(planner, predictor) pairs; planners that ignore predictions get "none" only."""
    return [(planner, predictor) for planner in planners
            for predictor in (predictors if USES_PREDICTIONS[planner] else ["none"])]


def cell_path(out: Path, run: NavRun) -> Path:
    see = "" if run.pedestrians_see_ego is None else f"__see-ego-{'yes' if run.pedestrians_see_ego else 'no'}"
    return out / f"{run.env_id}__{run.policy}__{run.predictor}{see}.json"


def run_cell(job: tuple[NavRun, str]) -> str:
    """Run one cell unless its file already holds enough episodes; returns the file path."""
    run, out = job
    path = cell_path(Path(out), run)
    if path.exists() and len(json.loads(path.read_text())["episodes"]) >= run.episodes:
        return str(path)
    result = run_navigation(run, progress=False)
    write_text_atomic(path, json.dumps(result, indent=1))
    print(f"{path.name}: success {result['summary']['success']['value']:.3f}, "
          f"collision {result['summary']['collision']['value']:.3f} ({result['wall_time_s'] / 60:.1f} min)",
          flush=True)
    return str(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["STCrowd-SimCrossing-v1", "STCrowd-Zara1-v0", "STCrowd-Univ-v0"],
                        help="env ids (default: SimCrossing, Zara1, Univ)")
    parser.add_argument("--planners", nargs="+", default=list(PLANNERS), help="planners (default: all)")
    parser.add_argument("--predictors", nargs="+", default=list(PREDICTORS), help="predictors (default: all)")
    parser.add_argument("--episodes", type=int, default=500, help="episodes per cell (default: 500)")
    parser.add_argument("--seed", type=int, default=0, help="first episode seed (default: 0)")
    parser.add_argument("--pedestrians-see-ego", choices=list(SEE_EGO), default="default",
                        help="simulated envs that offer it: yes / no (default: the env's setting)")
    parser.add_argument("--out", default="runs/nav/table",
                        help="folder of the per-cell JSON files (default: runs/nav/table)")
    parser.add_argument("--jobs", type=int, default=1, help="cells run in parallel processes (default: 1)")
    args = parser.parse_args()

    see_ego = SEE_EGO[args.pedestrians_see_ego]
    jobs = [(NavRun(env_id, planner, predictor, args.episodes, args.seed, see_ego), args.out)
            for env_id in args.envs for planner, predictor in cells(args.planners, args.predictors)]
    if args.jobs > 1:
        with Pool(args.jobs) as pool:
            paths = pool.map(run_cell, jobs, chunksize=1)
    else:
        paths = [run_cell(job) for job in jobs]

    results = [json.loads(Path(p).read_text()) for p in paths]
    for env_id in args.envs:
        rows = [r for r in results if r["env_id"] == env_id]
        print(f"\n### {env_id} ({see_ego_label(rows[0]['pedestrians_see_ego'])}, seeds {args.seed}.."
              f"{args.seed + args.episodes - 1})\n")
        print(markdown_header())
        print("\n".join(markdown_row(r) for r in rows))
        by_predictor = {r["predictor"]: r for r in rows if r["policy"] == "mpc"}
        for other in ("cvm", "cvm-s", "none"):
            if "singular" in by_predictor and other in by_predictor:
                test = paired_collision_test(by_predictor["singular"]["episodes"], by_predictor[other]["episodes"])
                print(f"\nMPC singular vs MPC {other}: collisions {test['a_collisions']} vs {test['b_collisions']} "
                      f"of {test['n']}; only singular {test['only_a']}, only {other} {test['only_b']}; "
                      f"one-sided McNemar p = {test['p_value']:.4f}")
        ppo = {r["predictor"]: r for r in rows if r["policy"] == "ppo"}
        if {"singular", "none"} <= set(ppo):
            test = paired_success_test(ppo["singular"]["episodes"], ppo["none"]["episodes"])
            print(f"\nPPO with vs without predictions: successes {test['a_successes']} vs {test['b_successes']} "
                  f"of {test['n']}; only with {test['only_a']}, only without {test['only_b']}; "
                  f"one-sided McNemar p = {test['p_value']:.4f}")


if __name__ == "__main__":
    main()
