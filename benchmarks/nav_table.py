"""The navigation table: every planner x predictor on each env, seeded episodes, 95 % intervals, paired tests.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/nav_table.py --episodes 500 --out runs/nav/table            # the RESULTS table
    python benchmarks/nav_table.py --envs STCrowd-Zara1-v0:reactive --planners mpc --episodes 50 --out runs/nav/t
    python benchmarks/nav_table.py ... --executor ray --ray-address HEAD:6379        # on a Ray cluster

An env is an id, and for a replay ``id:log`` or ``id:reactive`` (its pedestrians' mode; the default list has both
for ZARA1 and UNIV). Each cell (env, mode, planner, predictor) is one ``run_navigation`` over episodes seed ..
seed + N - 1 (the same episodes for every cell of an env) and one job of the grid runner (``st_sim.apps.grid``),
written to ``OUT/<env>[__<mode>]__<planner>__<predictor>__<N>ep_seed<seed>.json``: a finished cell is reused, so
an interrupted run resumes. Planners that ignore predictions (straight, ORCA) run once, with predictor "none".
The script prints one markdown table per env and McNemar's paired tests of MPC with SingularTrajectory against
MPC with CVM, CVM-S and no prediction (every collision, and the at-fault ones), of each learned policy (``ppo``,
``ppo-reactive``, ``ppo-suite``) with predictions against without (successes), and of each with predictions against
the MPC with SingularTrajectory (successes, at-fault collisions).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from st_sim.apps.grid import raise_on_failure, run_jobs
from st_sim.apps.navigation.episodes import NavRun, grid_job
from st_sim.apps.navigation.metrics import paired_collision_test, paired_success_test
from st_sim.apps.navigation.planners import PLANNERS, USES_PREDICTIONS
from st_sim.apps.navigation.predictors import PREDICTORS
from st_sim.apps.navigation.report import markdown_header, markdown_row, see_ego_label
from st_sim.command_line import add_grid_arguments

ENVS = ("STCrowd-SimCrossing-v1", "STCrowd-Zara1-v0:log", "STCrowd-Zara1-v0:reactive", "STCrowd-Univ-v0:log",
        "STCrowd-Univ-v0:reactive")
SEE_EGO = {"yes": True, "no": False, "default": None}


def cells(planners: list[str], predictors: list[str]) -> list[tuple[str, str]]:
    """(planner, predictor) pairs; planners that ignore predictions get "none" only."""
    return [(planner, predictor) for planner in planners
            for predictor in (predictors if USES_PREDICTIONS[planner] else ["none"])]


def env_and_mode(spec: str) -> tuple[str, str | None]:
    """``id`` or ``id:log`` / ``id:reactive`` -> (id, mode or None)."""
    env_id, _, mode = spec.partition(":")
    if mode not in ("", "log", "reactive"):
        raise SystemExit(f"--envs {spec}: the mode after ':' must be log or reactive")
    return env_id, mode or None


def cell_name(run: NavRun) -> str:
    see = "" if run.pedestrians_see_ego is None else f"__see-ego-{'yes' if run.pedestrians_see_ego else 'no'}"
    mode = f"__{run.pedestrians}" if run.pedestrians else ""
    return f"{run.env_id}{mode}{see}__{run.policy}__{run.predictor}__{run.episodes}ep_seed{run.seed}"


def paired_lines(rows: list[dict]) -> list[str]:
    """The paired tests of one env's rows."""
    lines = []
    mpc = {r["predictor"]: r for r in rows if r["policy"] == "mpc"}
    for other in ("cvm", "cvm-s", "none"):
        if "singular" in mpc and other in mpc:
            for at_fault in (False, True):
                test = paired_collision_test(mpc["singular"]["episodes"], mpc[other]["episodes"], at_fault)
                kind = "at-fault collisions" if at_fault else "collisions (any)"
                lines.append(f"- MPC singular vs MPC {other}, {kind}: {test['a_collisions']} vs {test['b_collisions']} "
                             f"of {test['n']}; only singular {test['only_a']}, only {other} {test['only_b']}; "
                             f"one-sided McNemar p = {test['p_value']:.4f}")
    for learned in ("ppo", "ppo-reactive", "ppo-suite"):
        ppo = {r["predictor"]: r for r in rows if r["policy"] == learned}
        if {"singular", "none"} <= set(ppo):
            test = paired_success_test(ppo["singular"]["episodes"], ppo["none"]["episodes"])
            lines.append(f"- {learned} with vs without predictions, successes: {test['a_successes']} vs "
                         f"{test['b_successes']} of {test['n']}; only with {test['only_a']}, only without "
                         f"{test['only_b']}; one-sided McNemar p = {test['p_value']:.4f}")
        if "singular" in ppo and "singular" in mpc:
            mine, teacher = ppo["singular"]["episodes"], mpc["singular"]["episodes"]
            test = paired_success_test(mine, teacher)
            fault = paired_collision_test(mine, teacher, at_fault=True)
            lines.append(f"- {learned} + singular vs MPC singular, successes: {test['a_successes']} vs "
                         f"{test['b_successes']} of {test['n']} (p = {test['p_value']:.4f}); at-fault collisions "
                         f"{fault['a_collisions']} vs {fault['b_collisions']} (fewer: p = {fault['p_value']:.4f})")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=list(ENVS), help="env ids, replays as id:log or id:reactive "
                        "(default: SimCrossing, ZARA1 and UNIV in both modes)")
    parser.add_argument("--planners", nargs="+", default=list(PLANNERS), choices=list(PLANNERS),
                        help="planners (default: all)")
    parser.add_argument("--predictors", nargs="+", default=list(PREDICTORS), choices=list(PREDICTORS),
                        help="predictors (default: all)")
    parser.add_argument("--episodes", type=int, default=500, help="episodes per cell (default: 500)")
    parser.add_argument("--seed", type=int, default=0, help="first episode seed (default: 0)")
    parser.add_argument("--pedestrians-see-ego", choices=list(SEE_EGO), default="default",
                        help="simulated envs that offer it: yes / no (default: the env's setting)")
    parser.add_argument("--out", default="runs/nav/table", help="folder of the per-cell JSON (default: runs/nav/table)")
    parser.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    add_grid_arguments(parser)
    args = parser.parse_args()
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")

    see_ego, out = SEE_EGO[args.pedestrians_see_ego], Path(args.out)
    runs = [NavRun(env_id, planner, predictor, args.episodes, args.seed, see_ego, mode, data_root=args.data_root)
            for env_id, mode in map(env_and_mode, args.envs) for planner, predictor in cells(args.planners,
                                                                                            args.predictors)]
    jobs = [grid_job(f"nav/{cell_name(run)}", run, out / f"{cell_name(run)}.json") for run in runs]
    reports = run_jobs(jobs, executor=args.executor, workers=args.workers, address=args.ray_address, desc="cells")
    raise_on_failure(reports)
    results = [json.loads(Path(job.output).read_text()) for job in jobs]
    for spec in args.envs:
        env_id, mode = env_and_mode(spec)
        rows = [r for run, r in zip(runs, results, strict=True) if (run.env_id, run.pedestrians) == (env_id, mode)]
        where = f", {rows[0]['pedestrians']} pedestrians" if rows[0].get("pedestrians") else ""
        print(f"\n### {env_id}{where} ({see_ego_label(rows[0]['pedestrians_see_ego'])}, seeds {args.seed}.."
              f"{args.seed + args.episodes - 1})\n")
        print(markdown_header())
        print("\n".join(markdown_row(r) for r in rows))
        print("\n" + "\n".join(paired_lines(rows)))


if __name__ == "__main__":
    main()
